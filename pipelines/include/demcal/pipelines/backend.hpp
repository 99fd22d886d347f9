// Evaluation backends: who runs the simulations of a batch of candidates.
//
//   threads  (ThreadBackend)  the built-in engine on a pool of threads, one simulation per task
//   command  (CommandBackend) an external program per task, from an argument template (no shell)
//   mpi      (mpi.hpp)        the built-in engine on the other ranks of an MPI job
//
// Every backend turns a task (which case, which parameter values) into a SimulationOutcome: a
// status, a message and the recorded curves (time, force, one column per gauge; SI units). A run
// that failed (a crash, a timeout, an unreadable output) is an outcome with status "failed", never
// an exception: the campaign goes on and the optimiser sees NaN.
#pragma once

#include "demcal/dem/scene.hpp"
#include "demcal/smoothing/curve.hpp"

#include <nlohmann/json.hpp>

#include <atomic>
#include <cstddef>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace demcal::dem {
struct Recording;
}

namespace demcal::pipelines {

struct SimulationTask {
  std::size_t case_index = 0;            // which case of the campaign (scene + measurement)
  std::map<std::string, double> params;  // name -> value (SI, friction_deg in degrees)
};

struct SimulationOutcome {
  std::string status = "failed";  // engine status (completed, collapsed, unstable, step_limit,
                                  // cancelled) or "failed"
  std::string message;
  smoothing::Curve curves;        // time (s), force (N), gauges (m); empty when nothing was recorded
  double wall_time_s = 0;
  nlohmann::json details = nlohmann::json::object();  // peak_force, steps, hinges, sliding_joints,
                                                       // joints, final_blocks (engine runs)
};

// Called once per task, always on the thread that called run(), in completion order.
using OutcomeCallback = std::function<void(std::size_t task_index, SimulationOutcome&& outcome)>;

class EvaluationBackend {
 public:
  virtual ~EvaluationBackend() = default;
  virtual std::string name() const = 0;
  // Identity of a case's model for the archive key (scene hash, or hash of command and case).
  virtual std::string model_hash(std::size_t case_index) const = 0;
  // Runs every task; returns when all have been reported through on_done.
  virtual void run(const std::vector<SimulationTask>& tasks, const OutcomeCallback& on_done) = 0;
  // Simulations that can run at the same time.
  virtual int workers() const = 0;
};

// Recording -> outcome (curves with columns time, force and the gauges; details from the engine).
SimulationOutcome outcome_from_recording(const dem::Recording& recording);

// One engine run: a copy of `scene` with every parameter set (dem::set_parameter), simulated.
// Bad parameter names or values give a "failed" outcome naming them.
SimulationOutcome simulate_with_parameters(const dem::Scene& scene, const std::map<std::string, double>& params,
                                           const std::atomic<bool>* cancel = nullptr);

// Built-in engine on a thread pool.
class ThreadBackend : public EvaluationBackend {
 public:
  // threads <= 0: every hardware thread.
  ThreadBackend(std::vector<dem::Scene> scenes, int threads = 0);
  std::string name() const override { return "threads"; }
  std::string model_hash(std::size_t case_index) const override;
  void run(const std::vector<SimulationTask>& tasks, const OutcomeCallback& on_done) override;
  int workers() const override { return threads_; }

 private:
  std::vector<dem::Scene> scenes_;
  std::vector<std::string> hashes_;
  int threads_;
};

// External program per task. Placeholders in the template (process.hpp rules, no shell):
//   {<parameter>}  the value, printed with 17 significant digits (e.g. {kn}, {friction_deg})
//   {output}       path of the CSV the program must write: a `force` column (N) and one column per
//                  gauge (m), optionally `time` — the convention of `demcal fitness`
//   {workdir}      a fresh, empty folder for this run (the program also starts there)
//   {case}         the case name;  {scene}  the case's scene file ("" when it has none)
// A run fails (status "failed", fitness NaN, the message saying why, with stderr's last lines)
// when the program cannot start, exits non-zero, dies of a signal, outlives timeout_s, writes a
// file larger than max_output_bytes (stdout and stderr included: the kernel stops it with SIGXFSZ),
// or leaves an output that is missing, empty, unreadable as a curve (the reader's message, naming
// file, line and column), without a `force` column, with fewer than 2 rows, or with a NaN or
// infinite value (named by file, line, column and value). Whatever the program leaves running is
// killed and reaped when it ends (process.hpp); a run that completed but left processes behind
// says so in its message.
struct CommandBackendOptions {
  std::string command;            // the template, e.g. "python3 sim.py {kn} {friction_deg} {output}"
  double timeout_s = 0;           // s per run, 0 = none
  int parallel = 0;               // programs running at once; <= 0: every hardware thread
  std::string work_root;          // per-run folders are made under it (must be writable)
  std::vector<std::string> case_names;
  std::vector<std::string> scene_files;  // per case, may be ""
  std::vector<std::string> parameter_names;  // every name a task may carry (checks the template)
  long long max_output_bytes = 64ll << 20;   // largest file a run may write, bytes (> 0)
  // Throws std::invalid_argument: empty or malformed template, an unknown placeholder, no {output},
  // negative timeout, empty work_root, max_output_bytes <= 0.
  void Validate() const;
};

// The placeholders of a command template that name parameters: all but {output}, {workdir},
// {case} and {scene}, in order of first appearance. Throws std::invalid_argument as
// split_command_line does.
std::vector<std::string> command_parameter_placeholders(const std::string& command);

class CommandBackend : public EvaluationBackend {
 public:
  explicit CommandBackend(CommandBackendOptions options);
  std::string name() const override { return "command"; }
  std::string model_hash(std::size_t case_index) const override;
  void run(const std::vector<SimulationTask>& tasks, const OutcomeCallback& on_done) override;
  int workers() const override { return parallel_; }
  // One task, on the calling thread (what the pool runs).
  SimulationOutcome run_one(const SimulationTask& task) const;

 private:
  CommandBackendOptions options_;
  std::vector<std::string> words_;
  int parallel_;
};

// Runs `work(i)` for i in [0, count) on `threads` threads and hands each result to on_done on the
// calling thread, in completion order. Shared by the thread and command backends.
void run_pool(std::size_t count, int threads, const std::function<SimulationOutcome(std::size_t)>& work,
              const OutcomeCallback& on_done);

// Hardware threads (at least 1).
int hardware_threads();

}  // namespace demcal::pipelines
