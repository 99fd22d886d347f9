#include "demcal/pipelines/mpi.hpp"

#include "demcal/pipelines/archive.hpp"

#include <cstdlib>
#include <stdexcept>

#ifdef DEMCAL_HAVE_MPI
#include <mpi.h>
#endif

namespace demcal::pipelines {

#ifdef DEMCAL_HAVE_MPI

namespace {

constexpr int kTagTask = 1;
constexpr int kTagOutcome = 2;
constexpr int kTagCurve = 3;
constexpr int kTagStop = 4;

void send_bytes(const std::string& bytes, int to, int tag) {
  MPI_Send(bytes.data(), static_cast<int>(bytes.size()), MPI_CHAR, to, tag, MPI_COMM_WORLD);
}

std::string receive_bytes(int from, int tag, MPI_Status* status_out = nullptr) {
  MPI_Status status;
  MPI_Probe(from, tag, MPI_COMM_WORLD, &status);
  int count = 0;
  MPI_Get_count(&status, MPI_CHAR, &count);
  std::string bytes(static_cast<size_t>(count), '\0');
  MPI_Recv(bytes.data(), count, MPI_CHAR, status.MPI_SOURCE, status.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  if (status_out) *status_out = status;
  return bytes;
}

class MpiBackend : public EvaluationBackend {
 public:
  explicit MpiBackend(std::vector<dem::Scene> scenes) : local_(std::move(scenes), 0) {
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }
  ~MpiBackend() override {
    for (int rank = 1; rank < size_; ++rank) MPI_Send(nullptr, 0, MPI_CHAR, rank, kTagStop, MPI_COMM_WORLD);
  }
  std::string name() const override { return "mpi"; }
  std::string model_hash(std::size_t case_index) const override { return local_.model_hash(case_index); }
  int workers() const override { return size_ > 1 ? size_ - 1 : local_.workers(); }

  void run(const std::vector<SimulationTask>& tasks, const OutcomeCallback& on_done) override {
    if (size_ == 1) {
      local_.run(tasks, on_done);
      return;
    }
    size_t next = 0, received = 0;
    auto send_task = [&](int rank) {
      const nlohmann::json task = {{"index", next}, {"case", tasks[next].case_index},
                                   {"params", parameter_key(tasks[next].params)}};
      send_bytes(task.dump(), rank, kTagTask);
      ++next;
    };
    for (int rank = 1; rank < size_ && next < tasks.size(); ++rank) send_task(rank);
    while (received < tasks.size()) {
      MPI_Status status;
      const nlohmann::json head = nlohmann::json::parse(receive_bytes(MPI_ANY_SOURCE, kTagOutcome, &status));
      const int worker = status.MPI_SOURCE;
      const std::string values = receive_bytes(worker, kTagCurve);
      ++received;
      if (next < tasks.size()) send_task(worker);
      SimulationOutcome outcome;
      outcome.status = head.at("status").get<std::string>();
      outcome.message = head.at("message").get<std::string>();
      outcome.wall_time_s = head.at("wall_time_s").get<double>();
      outcome.details = head.at("details");
      outcome.curves = unpack_curve(head.at("names").get<std::vector<std::string>>(),
                                    head.at("units").get<std::vector<std::string>>(), values,
                                    "rank " + std::to_string(worker));
      on_done(head.at("index").get<size_t>(), std::move(outcome));
    }
  }

 private:
  ThreadBackend local_;
  int size_ = 1;
};

}  // namespace

bool mpi_compiled() { return true; }

void mpi_abort(int code) {
  MPI_Abort(MPI_COMM_WORLD, code);
  std::exit(code);
}

MpiSession::MpiSession(int* argc, char*** argv) {
  int initialised = 0;
  MPI_Initialized(&initialised);
  if (!initialised) {
    int provided = 0;
    MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided);
  }
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
}

MpiSession::~MpiSession() {
  int finalised = 0;
  MPI_Finalized(&finalised);
  if (!finalised) MPI_Finalize();
}

std::unique_ptr<EvaluationBackend> make_mpi_backend(std::vector<dem::Scene> scenes) {
  return std::make_unique<MpiBackend>(std::move(scenes));
}

void mpi_serve(const std::vector<dem::Scene>& scenes) {
  while (true) {
    MPI_Status status;
    MPI_Probe(0, MPI_ANY_TAG, MPI_COMM_WORLD, &status);
    if (status.MPI_TAG == kTagStop) {
      MPI_Recv(nullptr, 0, MPI_CHAR, 0, kTagStop, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      return;
    }
    const nlohmann::json task = nlohmann::json::parse(receive_bytes(0, kTagTask));
    const size_t case_index = task.at("case").get<size_t>();
    SimulationOutcome outcome;
    if (case_index < scenes.size()) {
      outcome = simulate_with_parameters(scenes[case_index], params_from_key(task.at("params").get<std::string>()));
    } else {
      outcome.message = "MPI worker: no case " + std::to_string(case_index);
    }
    nlohmann::json names = nlohmann::json::array(), units = nlohmann::json::array();
    for (const auto& column : outcome.curves.columns) {
      names.push_back(column.name);
      units.push_back(column.unit);
    }
    const nlohmann::json head = {{"index", task.at("index")}, {"status", outcome.status},
                                 {"message", outcome.message}, {"wall_time_s", outcome.wall_time_s},
                                 {"details", outcome.details}, {"names", names}, {"units", units}};
    send_bytes(head.dump(), 0, kTagOutcome);
    send_bytes(pack_curve_values(outcome.curves), 0, kTagCurve);
  }
}

#else

bool mpi_compiled() { return false; }
void mpi_abort(int code) { std::exit(code); }
MpiSession::MpiSession(int*, char***) { throw std::runtime_error("this demcal was built without MPI"); }
MpiSession::~MpiSession() = default;
std::unique_ptr<EvaluationBackend> make_mpi_backend(std::vector<dem::Scene>) {
  throw std::runtime_error("this demcal was built without MPI");
}
void mpi_serve(const std::vector<dem::Scene>&) { throw std::runtime_error("this demcal was built without MPI"); }

#endif

}  // namespace demcal::pipelines
