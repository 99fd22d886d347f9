// What a campaign evaluates with: the prepared cases, the backend and the fitness workers.
#include "campaign_internal.hpp"
#include "demcal/pipelines/surrogate_data.hpp"

#include "demcal/pipelines/mpi.hpp"
#include "demcal/pipelines/predict.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>

namespace demcal::pipelines::detail {

namespace fs = std::filesystem;
using nlohmann::json;

bool usable_status(const std::string& status) {
  return status == "completed" || status == "collapsed" || status == "step_limit";
}

namespace {

std::vector<std::string> all_parameter_names(const optimise::ParameterSpace& space) {
  std::vector<std::string> names = space.free_names();
  for (const auto& [name, value] : space.fixed_parameters()) names.push_back(name);
  if (space.tied_parameter()) names.push_back(space.tied_parameter()->name);
  return names;
}

}  // namespace

std::vector<dem::Scene> build_scenes(const CampaignConfig& config) {
  std::vector<dem::Scene> scenes;
  const auto names = all_parameter_names(config.space);
  for (size_t i = 0; i < config.cases.size(); ++i) {
    const std::string where = config.source + ": cases[" + std::to_string(i) + "].scene";
    dem::Scene scene = build_scene(config.cases[i].scene, where);
    dem::Scene probe = scene;
    for (const auto& name : names) {
      try {
        dem::set_parameter(probe, name, dem::get_parameter(scene, name));
      } catch (const std::exception& e) {
        std::string known;
        for (const auto& n : dem::parameter_names(scene)) known += (known.empty() ? "" : ", ") + n;
        throw CampaignError(config.source + ": parameter '" + name + "' is not a parameter of the scene of case '" +
                            config.cases[i].name + "' (known: " + known + ")");
      }
    }
    scenes.push_back(std::move(scene));
  }
  return scenes;
}

std::shared_ptr<const CurveGrid> case_curve_grid(const CampaignConfig& config, const PreparedCases& prepared, size_t k) {
  try {
    return std::make_shared<const CurveGrid>(make_curve_grid(prepared.measured[k], config.objective_options,
                                                             config.objective == 2 ? prepared.objective2[k].get() : nullptr,
                                                             config.cases[k].weight));
  } catch (const std::exception& e) {
    throw CampaignError(config.source + ": case '" + config.cases[k].name + "': " + e.what());
  }
}

PreparedCases prepare_cases(const CampaignConfig& config) {
  PreparedCases p;
  const json defining = config.result_defining_json();  // hashes every file: once, not per case
  const json& objective = defining["objective"];
  for (const auto& c : config.cases) {
    p.measured.push_back(load_measured(c.measured));
    json key = {{"measured", defining["cases"][p.measured.size() - 1]["measured"]},
                {"objective", config.objective},
                {"points", config.objective_options.points},
                {"weights", config.objective_options.channel_weights}};
    for (const char* optional : {"smoother", "window"})  // as the result-defining JSON has them
      if (objective.contains(optional)) key[optional] = objective[optional];
    p.objective_keys.push_back(hash_text(key.dump()));
    try {
      smoothing::common_channels(p.measured.back(), p.measured.back(), config.objective_options);
    } catch (const std::exception& e) {
      throw CampaignError(std::string("measured curve: ") + e.what());
    }
    // Every channel is scored (a weight of 0 still reports it), and one without two loading points
    // fails every run's fitness: refused before any simulation.
    const auto ends = smoothing::envelope_ends(p.measured.back(), config.objective_options);
    for (const auto& column : smoothing::displacement_columns(p.measured.back(), config.objective_options))
      if (!ends.count(column))
        throw CampaignError(p.measured.back().source + ": channel '" + column + "' of case '" + c.name +
                            "' has fewer than 2 loading points (rows whose displacement and force are finite and whose "
                            "displacement exceeds every earlier one): no simulation can be compared with it; leave the "
                            "column out of the measured data");
    if (config.objective == 2) {
      // A run's channels smoothed side by side on the fitness workers' threads: the last run of a
      // round is then scored while no simulation is left to fill the other cores (the same values).
      smoothing::SmootherOptions smoother = config.smoother;
      smoother.curve_threads = static_cast<int>(
          std::min<std::size_t>(static_cast<std::size_t>(fitness_thread_count(config)), ends.size()));  // ends: one per channel
      p.objective2.push_back(std::make_unique<smoothing::Objective2>(p.measured.back(), config.objective_options, smoother));
    }
  }
  if (config.backend.type != "command") p.scenes = build_scenes(config);
  return p;
}

}  // namespace demcal::pipelines::detail

namespace demcal::pipelines {

std::vector<CaseCurveGrid> campaign_curve_grids(const CampaignConfig& config) {
  const detail::PreparedCases prepared = detail::prepare_cases(config);
  std::vector<CaseCurveGrid> grids;
  for (size_t k = 0; k < config.cases.size(); ++k)
    grids.push_back({prepared.objective_keys[k], detail::case_curve_grid(config, prepared, k)});
  return grids;
}

}  // namespace demcal::pipelines

namespace demcal::pipelines::detail {

std::unique_ptr<CommandBackend> make_command_backend(const CampaignConfig& config, const std::string& work_root,
                                                     std::vector<std::string> parameter_names, int parallel) {
  CommandBackendOptions o;
  o.command = config.backend.command;
  o.timeout_s = config.backend.timeout_s;
  o.parallel = parallel;
  o.max_output_bytes = static_cast<long long>(config.backend.max_output_mb * 1024 * 1024);
  o.work_root = work_root;
  for (const auto& c : config.cases) {
    o.case_names.push_back(c.name);
    o.scene_files.push_back(c.scene.file);
  }
  o.parameter_names = std::move(parameter_names);
  try {
    return std::make_unique<CommandBackend>(o);
  } catch (const std::invalid_argument& e) {
    throw CampaignError(config.source + ": backend.command: " + e.what());
  }
}

std::unique_ptr<EvaluationBackend> make_backend(const CampaignConfig& config, const PreparedCases& prepared,
                                                const RunOptions& options) {
  if (config.backend.type == "command")
    return make_command_backend(config, (fs::path(config.output) / "runs").string(), all_parameter_names(config.space),
                                config.backend.parallel);
  if (config.backend.type == "mpi") {
    if (!mpi_compiled()) throw CampaignError("this demcal was built without MPI; use --backend threads");
    if (options.mpi_size < 1) throw CampaignError("--backend mpi must run under mpirun");
    return make_mpi_backend(prepared.scenes);
  }
  return std::make_unique<ThreadBackend>(prepared.scenes, config.backend.threads);
}

int fitness_thread_count(const CampaignConfig& config) {
  return config.backend.fitness_threads > 0 ? config.backend.fitness_threads : hardware_threads();
}

namespace {

// Fitness of one run against one case: objective 1, and objective 2 when the campaign asks for it.
// Thread-safe (reads `prepared` only), so it runs on the fitness workers.
FitnessRecord compute_fitness(std::int64_t run_id, const std::string& status, const smoothing::Curve& curves,
                              size_t case_index, const PreparedCases& prepared, const CampaignConfig& config) {
  FitnessRecord f;
  f.run_id = run_id;
  f.objective_key = prepared.objective_keys[case_index];
  f.objective = config.objective;
  if (!usable_status(status) || curves.rows() < 2) return f;
  const auto start = std::chrono::steady_clock::now();
  try {
    const smoothing::Curve& measured = prepared.measured[case_index];
    const smoothing::Curve scored = scored_curve(status, curves, measured, config.objective_options);
    const auto r = smoothing::objective1(measured, scored, config.objective_options);
    f.objective1 = r.fitness;
    if (config.objective == 1) {
      f.fitness = r.fitness;
      f.channels = r.channels;
    } else {
      const auto r2 = prepared.objective2[case_index]->evaluate(scored);
      f.objective2 = r2.fitness;
      f.fitness = r2.fitness;
      f.channels = r2.channels;
    }
  } catch (const std::exception& e) {
    f.fitness = NAN;
    f.objective2 = NAN;
    f.channels = {{"error", e.what()}};
  }
  f.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return f;
}

}  // namespace

FitnessWorkers::FitnessWorkers(int threads, const PreparedCases& prepared, const CampaignConfig& config)
    : prepared_(prepared), config_(config) {
  for (int i = 0; i < std::max(1, threads); ++i) workers_.emplace_back([this] { work(); });
}

FitnessWorkers::~FitnessWorkers() { stop(); }

size_t FitnessWorkers::submit(std::int64_t run_id, std::string status, smoothing::Curve curves, size_t case_index) {
  std::lock_guard<std::mutex> lock(mutex_);
  const size_t index = jobs_.size();
  jobs_.push_back({run_id, std::move(status), std::move(curves), case_index});
  results_.emplace_back();
  queue_.push_back(index);
  wake_.notify_one();
  return index;
}

std::vector<FitnessRecord> FitnessWorkers::finish() {
  stop();
  return std::move(results_);
}

void FitnessWorkers::work() {
  for (;;) {
    size_t index = 0;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) return;
      index = queue_.front();
      queue_.pop_front();
    }
    const Job* job_ptr = nullptr;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      job_ptr = &jobs_[index];  // a deque: growing it keeps references valid
    }
    const Job& job = *job_ptr;
    FitnessRecord record = compute_fitness(job.run_id, job.status, job.curves, job.case_index, prepared_, config_);
    std::lock_guard<std::mutex> lock(mutex_);
    results_[index] = std::move(record);
  }
}

void FitnessWorkers::stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  for (auto& t : workers_)
    if (t.joinable()) t.join();
}

}  // namespace demcal::pipelines::detail
