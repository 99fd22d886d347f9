#include "demcal/pipelines/campaign.hpp"

#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/backend.hpp"
#include "demcal/pipelines/mpi.hpp"
#include "demcal/pipelines/progress.hpp"
#include "demcal/pipelines/report.hpp"
#include "demcal/pipelines/surrogate_data.hpp"
#include "demcal/pipelines/version.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

bool usable_status(const std::string& status) {
  return status == "completed" || status == "collapsed" || status == "step_limit";
}

json params_json(const std::map<std::string, double>& params) {
  json j = json::object();
  for (const auto& [name, value] : params) j[name] = value;
  return j;
}

json finite_or_null(double value) { return std::isfinite(value) ? json(value) : json(nullptr); }

// Everything prepared before the first simulation: cases, objectives, backend.
struct Prepared {
  std::vector<smoothing::Curve> measured;
  std::vector<std::string> objective_keys;
  std::vector<std::unique_ptr<smoothing::Objective2>> objective2;  // per case, objective 2 only
  std::vector<dem::Scene> scenes;                                   // engine backends only
};

std::vector<std::string> all_parameter_names(const optimise::ParameterSpace& space) {
  std::vector<std::string> names = space.free_names();
  for (const auto& [name, value] : space.fixed_parameters()) names.push_back(name);
  if (space.tied_parameter()) names.push_back(space.tied_parameter()->name);
  return names;
}

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

Prepared prepare(const CampaignConfig& config) {
  Prepared p;
  for (const auto& c : config.cases) {
    p.measured.push_back(load_measured(c.measured));
    json key = {{"measured", config.result_defining_json()["cases"][p.measured.size() - 1]["measured"]},
                {"objective", config.objective},
                {"points", config.objective_options.points},
                {"weights", config.objective_options.channel_weights}};
    if (config.objective == 2) key["smoother"] = config.result_defining_json()["objective"]["smoother"];
    p.objective_keys.push_back(hash_text(key.dump()));
    try {
      smoothing::common_channels(p.measured.back(), p.measured.back(), config.objective_options);
    } catch (const std::exception& e) {
      throw CampaignError(std::string("measured curve: ") + e.what());
    }
    if (config.objective == 2)
      p.objective2.push_back(
          std::make_unique<smoothing::Objective2>(p.measured.back(), config.objective_options, config.smoother));
  }
  if (config.backend.type != "command") p.scenes = build_scenes(config);
  return p;
}

std::unique_ptr<EvaluationBackend> make_backend(const CampaignConfig& config, const Prepared& prepared,
                                                const RunOptions& options) {
  if (config.backend.type == "command") {
    CommandBackendOptions o;
    o.command = config.backend.command;
    o.timeout_s = config.backend.timeout_s;
    o.parallel = config.backend.parallel;
    o.max_output_bytes = static_cast<long long>(config.backend.max_output_mb * 1024 * 1024);
    o.work_root = (fs::path(config.output) / "runs").string();
    for (const auto& c : config.cases) {
      o.case_names.push_back(c.name);
      o.scene_files.push_back(c.scene.file);
    }
    o.parameter_names = all_parameter_names(config.space);
    try {
      return std::make_unique<CommandBackend>(o);
    } catch (const std::invalid_argument& e) {
      throw CampaignError(config.source + ": backend.command: " + e.what());
    }
  }
  if (config.backend.type == "mpi") {
    if (!mpi_compiled()) throw CampaignError("this demcal was built without MPI; use --backend threads");
    if (options.mpi_size < 1) throw CampaignError("--backend mpi must run under mpirun");
    return make_mpi_backend(prepared.scenes);
  }
  return std::make_unique<ThreadBackend>(prepared.scenes, config.backend.threads);
}

// Fitness of one run against one case: objective 1, and objective 2 when the campaign asks for it.
// Thread-safe (reads `prepared` only), so it runs on the fitness workers.
FitnessRecord compute_fitness(std::int64_t run_id, const std::string& status, const smoothing::Curve& curves,
                              size_t case_index, const Prepared& prepared, const CampaignConfig& config) {
  FitnessRecord f;
  f.run_id = run_id;
  f.objective_key = prepared.objective_keys[case_index];
  f.objective = config.objective;
  if (!usable_status(status) || curves.rows() < 2) return f;
  const auto start = std::chrono::steady_clock::now();
  try {
    const auto r = smoothing::objective1(prepared.measured[case_index], curves, config.objective_options);
    f.objective1 = r.fitness;
    if (config.objective == 1) {
      f.fitness = r.fitness;
      f.channels = r.channels;
    } else {
      const auto r2 = prepared.objective2[case_index]->evaluate(curves);
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

// Fitness jobs of one iteration on worker threads. Jobs are submitted as runs become available (from
// the archive at once, simulated ones as each finishes), so the objective-2 smoothing of finished
// runs overlaps the simulations still running. Each curve is smoothed by its own network, so a value
// does not depend on which jobs share a worker: the result is that of a sequential evaluation.
class FitnessWorkers {
 public:
  FitnessWorkers(int threads, const Prepared& prepared, const CampaignConfig& config)
      : prepared_(prepared), config_(config) {
    for (int i = 0; i < std::max(1, threads); ++i) workers_.emplace_back([this] { work(); });
  }
  ~FitnessWorkers() { stop(); }
  // Queues the fitness of run `run_id` (its status and curves) against case `case_index`; returns
  // the job's index in finish()'s result.
  size_t submit(std::int64_t run_id, std::string status, smoothing::Curve curves, size_t case_index) {
    std::lock_guard<std::mutex> lock(mutex_);
    const size_t index = jobs_.size();
    jobs_.push_back({run_id, std::move(status), std::move(curves), case_index});
    results_.emplace_back();
    queue_.push_back(index);
    wake_.notify_one();
    return index;
  }
  // Waits for every submitted job; results in submission order.
  std::vector<FitnessRecord> finish() {
    stop();
    return std::move(results_);
  }

 private:
  struct Job {
    std::int64_t run_id;
    std::string status;
    smoothing::Curve curves;
    size_t case_index;
  };
  void work() {
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
  void stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
    for (auto& t : workers_)
      if (t.joinable()) t.join();
  }
  const Prepared& prepared_;
  const CampaignConfig& config_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<size_t> queue_;
  std::deque<Job> jobs_;
  std::vector<FitnessRecord> results_;
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

std::vector<ParameterSet> top_distinct(const std::vector<ParameterSet>& all, size_t count) {
  std::vector<const ParameterSet*> sorted;
  for (const auto& s : all)
    if (std::isfinite(s.fitness)) sorted.push_back(&s);
  std::stable_sort(sorted.begin(), sorted.end(),
                   [](const ParameterSet* a, const ParameterSet* b) { return a->fitness < b->fitness; });
  std::vector<ParameterSet> top;
  std::set<std::string> seen;
  for (const auto* s : sorted) {
    if (!seen.insert(parameter_key(s->params)).second) continue;
    top.push_back(*s);
    if (top.size() == count) break;
  }
  return top;
}

Identifiability identifiability(const std::vector<ParameterSet>& all, const CampaignConfig& config) {
  Identifiability id;
  id.relative_band = config.identifiability_band > 0
                         ? config.identifiability_band
                         : 1.0 / std::sqrt(2.0 * static_cast<double>(config.objective_options.points));
  const auto top = top_distinct(all, all.size());
  if (top.empty()) return id;
  id.band_fitness = top.front().fitness * (1 + id.relative_band);
  for (const auto& name : config.space.free_names()) {
    const double best = top.front().params.at(name);
    id.parameters[name] = {best, best, best};
  }
  for (const auto& s : top) {
    if (s.fitness > id.band_fitness) break;
    ++id.sets_in_band;
    for (auto& [name, range] : id.parameters) {
      range.min = std::min(range.min, s.params.at(name));
      range.max = std::max(range.max, s.params.at(name));
    }
  }
  return id;
}

}  // namespace

json Identifiability::to_json() const {
  json params = json::object();
  for (const auto& [name, r] : parameters) {
    params[name] = {{"best", r.best}, {"min", r.min}, {"max", r.max}};
    if (r.min > 0) params[name]["max_over_min"] = r.max / r.min;
  }
  return {{"relative_band", relative_band}, {"band_fitness", finite_or_null(band_fitness)},
          {"sets_in_band", sets_in_band}, {"parameters", params}};
}

json CampaignResult::to_json() const {
  auto set_json = [](const ParameterSet& s) {
    return json{{"params", params_json(s.params)}, {"fitness", finite_or_null(s.fitness)},
                {"iteration", s.iteration}, {"position", s.position}};
  };
  json top_json = json::array();
  for (const auto& s : top) top_json.push_back(set_json(s));
  json convergence = json::array();
  for (double v : best_history) convergence.push_back(finite_or_null(v));
  json j = {{"status", status == CampaignStatus::completed ? "completed" : "failed"},
          {"message", message},
          {"best", set_json(best)},
          {"top", top_json},
          {"simulations", simulations},
          {"candidates", candidates},
          {"failed_runs", failed_runs},
          {"iterations", iterations},
          {"optimiser_status", optimiser_status},
          {"convergence", convergence},
          {"wall_time_s", wall_time_s},
          {"identifiability", identifiability.to_json()},
          {"session", {{"simulated", simulated_this_session}, {"reused_from_archive", reused_from_archive}}}};
  if (surrogate_used)
    j["surrogate"] = {{"kind", surrogate_kind},
                      {"screened", surrogate_screened},
                      {"simulated", surrogate_simulated},
                      {"screened_out", surrogate_screened_out},
                      {"cv_error", finite_or_null(surrogate_cv_error)}};
  if (polished)
    j["polish"] = {{"evaluations", polish_evaluations}, {"swarm_best_fitness", finite_or_null(swarm_best_fitness)},
                   {"status", polish_status}};
  return j;
}

CampaignResult run_campaign(const CampaignConfig& config, const RunOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  config.Validate();
  std::error_code ec;
  fs::create_directories(config.output, ec);
  if (ec) throw CampaignError(config.output + ": cannot create the output folder: " + ec.message());

  Prepared prepared = prepare(config);
  auto backend = make_backend(config, prepared, options);
  RunArchive archive(config.archive.empty() ? (fs::path(config.output) / "archive.sqlite").string() : config.archive);
  const json defining = config.result_defining_json();
  const std::string config_key = hash_text(defining.dump());
  std::optional<CampaignRecord> previous;
  if (options.resume) previous = archive.latest_campaign(config_key);

  // Surrogate: trained on the archive's runs of these scenes and objectives up to the horizon (the
  // newest run when the campaign started, kept in the campaign record so a resume sees the same
  // earlier runs) plus this campaign's committed evaluations.
  const bool bayes = config.optimiser.algorithm == "bo";
  const bool screening = config.surrogate.enabled && !bayes;
  const std::int64_t horizon = previous && previous->config.contains("surrogate_run_horizon")
                                   ? previous->config.at("surrogate_run_horizon").get<std::int64_t>()
                                   : archive.max_run_id();
  std::vector<ArchivedCase> archived_cases;
  for (size_t k = 0; k < config.cases.size(); ++k)
    archived_cases.push_back({backend->model_hash(k), prepared.objective_keys[k], config.cases[k].weight});
  std::optional<surrogate::SurrogateModel> trained_model;
  if (screening && !config.surrogate.model_file.empty()) {
    std::ifstream in(config.surrogate.model_file);
    try {
      trained_model = surrogate::SurrogateModel::from_json(json::parse(in), config.surrogate.model_file);
    } catch (const std::exception& e) {
      throw CampaignError(config.surrogate.model_file + ": " + e.what());
    }
    if (trained_model->gp().dimension() != config.space.dimension())
      throw CampaignError(config.surrogate.model_file + ": the model has " +
                          std::to_string(trained_model->gp().dimension()) + " parameters, the campaign " +
                          std::to_string(config.space.dimension()));
  }
  // Rows: earlier runs (<= horizon), then this campaign's evaluations, each parameter set once.
  auto training_rows = [&](std::int64_t campaign) {
    std::vector<surrogate::TrainingRow> rows;
    std::set<std::vector<double>> seen;  // unit points (computed the same way for the same parameters)
    auto add = [&](surrogate::TrainingRow row) {
      if (seen.insert(std::vector<double>(row.unit.data(), row.unit.data() + row.unit.size())).second)
        rows.push_back(std::move(row));
    };
    for (auto& r : archive_training_rows(archive, config.space, archived_cases, horizon)) add(std::move(r));
    for (const auto& e : archive.evaluations(campaign)) {
      Eigen::VectorXd unit = unit_point_in_space(config.space, e.params);
      if (unit.size() > 0) add({std::move(unit), e.fitness});
    }
    return rows;
  };

  std::unique_ptr<optimise::Optimiser> optimiser;
  try {
    if (bayes) {
      optimise::OptimiserOptions o = config.optimiser;
      optimiser = surrogate::make_bayes_optimiser(config.space, o, config.surrogate.options,
                                                  archive_training_rows(archive, config.space, archived_cases, horizon));
    } else {
      optimise::OptimiserOptions o = config.optimiser;
      if (screening && config.surrogate.options.k > 0) o.evaluations_per_iteration = config.surrogate.options.k;
      optimiser = optimise::make_optimiser(config.space, o);
    }
  } catch (const std::exception& e) {
    throw CampaignError(config.source + ": " + e.what());
  }

  // The saved optimiser state: the swarm's alone, or with a polish {"swarm": ..., "polish": ...|null}.
  std::unique_ptr<optimise::Optimiser> polisher;
  auto save_optimisers = [&]() -> json {
    if (!config.polish.enabled) return optimiser->save_state();
    return {{"swarm", optimiser->save_state()}, {"polish", polisher ? polisher->save_state() : json(nullptr)}};
  };
  auto load_optimisers = [&](const json& saved) {
    // With pre-screening the state is {"optimiser": ..., "screening": this iteration's record}.
    const json& state = screening ? saved.at("optimiser") : saved;
    if (!config.polish.enabled) return optimiser->load_state(state);
    optimiser->load_state(state.at("swarm"));
    if (!state.at("polish").is_null()) {
      polisher = optimise::make_polisher(config.space, optimiser->best_x(), config.polish.options);
      polisher->load_state(state.at("polish"));
    }
  };

  std::int64_t campaign_id = 0;
  int next_iteration = 0;
  if (options.resume) {
    if (previous) {
      campaign_id = previous->id;
      if (auto last = archive.last_iteration(campaign_id)) {
        try {
          load_optimisers(json::parse(last->optimiser_state));
        } catch (const std::exception& e) {
          throw CampaignError(archive.path() + ": cannot restore the optimiser state of iteration " +
                              std::to_string(last->iteration) + ": " + e.what());
        }
        next_iteration = last->iteration + 1;
      }
    }
  }
  if (options.resume && options.note_fresh_resume && campaign_id == 0)
    std::cerr << "demcal: note: --resume: " << archive.path() << " holds no campaign with this configuration (key "
              << config_key << ": scene, measurement, parameters, objective or optimiser differ from every "
              << "archived one); starting a new campaign\n";
  if (campaign_id == 0) {
    CampaignRecord record;
    record.name = config.name;
    record.config_key = config_key;
    record.config = config.to_json();
    record.config["surrogate_run_horizon"] = horizon;
    record.code_version = version();
    campaign_id = archive.create_campaign(record);
  }

  const size_t cases = config.cases.size();
  const long budget = config.optimiser.evaluation_budget();
  const int planned_iterations = static_cast<int>((budget + config.optimiser.population - 1) / config.optimiser.population);
  CampaignResult result;
  ProgressPrinter printer(options.progress);
  ProgressState progress;
  const long polish_budget = config.polish.enabled ? config.polish.options.max_evaluations : 0;
  progress.iterations = planned_iterations + static_cast<int>(polish_budget);
  progress.total = (budget + polish_budget) * static_cast<long>(cases);
  progress.done = static_cast<long>(archive.evaluations(campaign_id).size() * cases);
  progress.best = optimiser->best_value();

  // The optimiser that asks next: the swarm, then (campaign option) the local polish from its best.
  auto active = [&]() -> optimise::Optimiser* {
    if (!optimiser->done()) return optimiser.get();
    if (!config.polish.enabled || optimiser->best_x().size() == 0) return nullptr;
    if (!polisher) polisher = optimise::make_polisher(config.space, optimiser->best_x(), config.polish.options);
    return polisher->done() ? nullptr : polisher.get();
  };
  const int fitness_threads = config.backend.fitness_threads > 0 ? config.backend.fitness_threads : hardware_threads();

  for (int iteration = next_iteration;; ++iteration) {
    optimise::Optimiser* asking = active();
    if (!asking) break;
    std::vector<Eigen::VectorXd> batch = asking->ask();
    if (batch.empty()) break;
    progress.iteration = iteration + 1;
    // Pre-screening: the model ranks a pool, substitutes the best of each slot's pool and withdraws
    // all but the best k slots; only the kept slots are simulated.
    std::vector<size_t> slots(batch.size());
    for (size_t i = 0; i < batch.size(); ++i) slots[i] = i;
    json screen_record = nullptr;
    std::optional<surrogate::ScreenReport> screen;
    if (screening && asking == optimiser.get() && asking->can_substitute()) {
      const auto rows = training_rows(campaign_id);
      long finite = 0;
      for (const auto& r : rows) finite += std::isfinite(r.fitness) ? 1 : 0;
      surrogate::SurrogateModel model(config.surrogate.options);
      bool usable = false;
      if (trained_model) {
        model = *trained_model;
        usable = finite >= config.surrogate.options.min_runs ? model.condition(rows) : model.usable();
      } else if (finite >= config.surrogate.options.min_runs) {
        usable = model.fit(rows);
      }
      if (usable) {
        screen = surrogate::prescreen(*asking, model, config.surrogate.options);
        batch = asking->ask();
        slots.clear();
        for (const auto& c : screen->candidates)
          if (c.simulated) slots.push_back(static_cast<size_t>(c.slot));
        std::sort(slots.begin(), slots.end());
        screen_record = screen->to_json();
        screen_record["training_rows"] = model.training_rows();
        screen_record["log_transform"] = model.gp().log_transformed();
      }
    }
    std::vector<std::map<std::string, double>> candidates;
    for (size_t slot : slots) candidates.push_back(config.space.values(batch[slot]));

    // Runs: from the archive where they exist, else simulated (each committed as it finishes).
    // Fitness jobs start as soon as a run is available, on their own workers.
    FitnessWorkers workers(fitness_threads, prepared, config);
    std::map<std::pair<std::int64_t, size_t>, size_t> job_of;  // (run id, case) -> fitness job
    std::vector<std::vector<double>> case_fitness(candidates.size(), std::vector<double>(cases, NAN));
    auto need_fitness = [&](const RunRecord& run, size_t k) {
      if (job_of.count({run.id, k})) return;
      if (auto f = archive.find_fitness(run.id, prepared.objective_keys[k])) {
        job_of[{run.id, k}] = SIZE_MAX;
        return;
      }
      job_of[{run.id, k}] = workers.submit(run.id, run.status, run.curves, k);
    };

    std::vector<std::vector<std::int64_t>> run_ids(candidates.size(), std::vector<std::int64_t>(cases, 0));
    std::vector<SimulationTask> tasks;
    std::map<std::pair<std::string, std::string>, size_t> queued;  // duplicates inside one batch run once
    std::vector<std::vector<std::pair<size_t, size_t>>> task_users;
    for (size_t c = 0; c < candidates.size(); ++c)
      for (size_t k = 0; k < cases; ++k) {
        const std::string model = backend->model_hash(k);
        if (auto run = archive.find_run(model, candidates[c])) {
          run_ids[c][k] = run->id;
          ++result.reused_from_archive;
          ++progress.done;
          need_fitness(*run, k);
          continue;
        }
        const auto key = std::make_pair(model, parameter_key(candidates[c]));
        if (auto it = queued.find(key); it != queued.end()) {
          task_users[it->second].push_back({c, k});
          continue;
        }
        queued[key] = tasks.size();
        tasks.push_back({k, candidates[c]});
        task_users.push_back({{c, k}});
      }
    backend->run(tasks, [&](size_t index, SimulationOutcome&& outcome) {
      RunRecord run;
      run.model_hash = backend->model_hash(tasks[index].case_index);
      run.params = tasks[index].params;
      run.code_version = version();
      run.backend = backend->name();
      run.status = outcome.status;
      run.message = outcome.message;
      run.wall_time_s = outcome.wall_time_s;
      run.curves = std::move(outcome.curves);
      run.details = std::move(outcome.details);
      run.id = archive.insert_run(run);
      need_fitness(run, tasks[index].case_index);
      for (const auto& [c, k] : task_users[index]) {
        run_ids[c][k] = run.id;
        ++progress.done;
      }
      ++result.simulated_this_session;
      ++progress.done_this_session;
      progress.elapsed_s = elapsed();
      printer.simulation_done(progress);
    });

    // Fitness per (candidate, case): archived, or computed by the workers and archived now.
    const std::vector<FitnessRecord> computed = workers.finish();
    for (const auto& record : computed) archive.put_fitness(record);
    for (size_t c = 0; c < candidates.size(); ++c)
      for (size_t k = 0; k < cases; ++k) {
        const size_t job = job_of.at({run_ids[c][k], k});
        if (job != SIZE_MAX) {
          case_fitness[c][k] = computed[job].fitness;
        } else if (auto f = archive.find_fitness(run_ids[c][k], prepared.objective_keys[k])) {
          case_fitness[c][k] = f->fitness;
        }
      }

    std::vector<double> fitness(candidates.size(), 0.0);
    std::vector<EvaluationRecord> evaluations;
    for (size_t c = 0; c < candidates.size(); ++c) {
      for (size_t k = 0; k < cases; ++k) fitness[c] += config.cases[k].weight * case_fitness[c][k];
      EvaluationRecord e;
      e.campaign_id = campaign_id;
      e.iteration = iteration;
      e.position = static_cast<int>(slots[c]);
      e.params = candidates[c];
      e.run_ids = run_ids[c];
      e.fitness = fitness[c];
      evaluations.push_back(std::move(e));
    }
    // The optimiser hears simulated values only: NaN (not evaluated) for withdrawn slots.
    std::vector<double> told(batch.size(), std::numeric_limits<double>::quiet_NaN());
    for (size_t c = 0; c < slots.size(); ++c) told[slots[c]] = fitness[c];
    asking->tell(told);
    if (screen) {  // the model's error on what was simulated, for the report
      double error_sum = 0;
      long error_count = 0;
      for (size_t c = 0; c < slots.size(); ++c) {
        auto& entry = screen_record["candidates"][slots[c]];
        entry["simulated_fitness"] = finite_or_null(fitness[c]);
        if (std::isfinite(fitness[c]) && fitness[c] != 0) {
          error_sum += std::abs(entry["predicted_fitness"].get<double>() - fitness[c]) / std::abs(fitness[c]);
          ++error_count;
        }
      }
      screen_record["mean_relative_error"] = error_count > 0 ? json(error_sum / error_count) : json(nullptr);
    }
    IterationRecord record;
    record.campaign_id = campaign_id;
    record.iteration = iteration;
    record.optimiser_state =
        (screening ? json{{"optimiser", save_optimisers()}, {"screening", screen_record}} : save_optimisers()).dump();
    record.best_fitness = std::min(optimiser->best_value(), polisher ? polisher->best_value() : INFINITY);
    record.evaluations = static_cast<int>(optimiser->evaluations() + (polisher ? polisher->evaluations() : 0));
    record.wall_time_s = elapsed();
    archive.commit_iteration(record, evaluations);
    progress.best = record.best_fitness;
    progress.elapsed_s = elapsed();
    printer.iteration_done(progress);
  }
  printer.finish();

  // The result comes from the archive, so a resumed campaign reports exactly what an uninterrupted
  // one would.
  const auto evaluations = archive.evaluations(campaign_id);
  double best = INFINITY;
  for (const auto& e : evaluations) {
    ParameterSet s{e.params, e.fitness, e.iteration, e.position};
    result.all.push_back(s);
    if (std::isfinite(e.fitness) && e.fitness < best) {
      best = e.fitness;
      result.best = s;
    }
    if (!std::isfinite(e.fitness)) ++result.failed_runs;
    result.best_history.push_back(best);
  }
  result.candidates = static_cast<long>(evaluations.size());
  result.simulations = result.candidates * static_cast<long>(cases);
  result.iterations = evaluations.empty() ? 0 : evaluations.back().iteration + 1;
  result.top = top_distinct(result.all, 5);
  result.optimiser_status = optimise::to_string(optimiser->status());
  if (config.polish.enabled) {
    result.polished = true;
    const long swarm_candidates = optimiser->evaluations();
    result.polish_evaluations = std::max(0L, result.candidates - swarm_candidates);
    result.swarm_best_fitness = optimiser->best_value();
    result.polish_status = polisher ? optimise::to_string(polisher->status()) : "not started";
  }
  result.identifiability = identifiability(result.all, config);
  if (screening || bayes) {
    result.surrogate_used = true;
    result.surrogate_kind = config.surrogate.options.kind;
    for (const auto& it : archive.iterations(campaign_id)) {
      const json state = json::parse(it.optimiser_state);
      if (!screening || state.at("screening").is_null()) continue;
      json entry = state.at("screening");
      entry["iteration"] = it.iteration;
      result.surrogate_screened += entry.at("pool").get<long>();
      result.surrogate_simulated += entry.at("simulated").get<long>();
      result.surrogate_screened_out += static_cast<long>(entry.at("candidates").size()) - entry.at("simulated").get<long>();
      result.surrogate_iterations.push_back(std::move(entry));
    }
    if (bayes) result.surrogate_simulated = result.candidates;
    surrogate::SurrogateModel final_model(config.surrogate.options);
    if (final_model.fit(training_rows(campaign_id)))
      result.surrogate_cv_error = final_model.gp().leave_one_out().relative_error;
  }
  if (!std::isfinite(best)) {
    result.status = CampaignStatus::failed;
    result.message = "no run gave a finite fitness (" + std::to_string(result.failed_runs) + " failed)";
  }
  result.wall_time_s = elapsed();

  json out = result.to_json();
  out["name"] = config.name;
  out["code_version"] = version();
  out["objective"] = config.objective;
  out["algorithm"] = config.optimiser.algorithm;
  out["seed"] = config.optimiser.seed;
  out["archive"] = archive.path();
  out["session"]["campaign_id"] = campaign_id;
  out["session"]["backend"] = backend->name();
  {
    std::ofstream file(fs::path(config.output) / "result.json");
    file << out.dump(2) << "\n";
    if (!file) throw CampaignError(config.output + "/result.json: cannot write");
  }

  if (config.report && result.status == CampaignStatus::completed) {
    ReportInputs inputs;
    inputs.config = &config;
    inputs.result = &result;
    inputs.measured = prepared.measured;
    const auto& best_eval = evaluations[static_cast<size_t>(
        std::find_if(evaluations.begin(), evaluations.end(),
                     [&](const EvaluationRecord& e) {
                       return e.iteration == result.best.iteration && e.position == result.best.position;
                     }) -
        evaluations.begin())];
    for (size_t k = 0; k < cases; ++k) {
      inputs.best_runs.push_back(*archive.run(best_eval.run_ids[k]));
      if (config.objective == 2) {
        inputs.smoothed_measured.push_back(prepared.objective2[k]->smoothed_experiment());
        try {
          inputs.smoothed_best.push_back(prepared.objective2[k]->smooth_simulation(inputs.best_runs.back().curves));
        } catch (const std::exception&) {
          inputs.smoothed_best.emplace_back();
        }
      }
    }
    for (const auto& e : evaluations) {
      if (std::isfinite(e.fitness)) continue;
      for (size_t k = 0; k < cases && k < e.run_ids.size(); ++k) {
        const auto run = archive.run(e.run_ids[k]);
        if (!run) continue;
        std::string reason = run->message;
        if (usable_status(run->status)) {
          const auto f = archive.find_fitness(run->id, prepared.objective_keys[k]);
          if (f && std::isfinite(f->fitness)) continue;  // another case failed this candidate
          if (f && f->channels.contains("error")) {
            const json& error = f->channels.at("error");
            reason = "fitness: " + (error.is_string() ? error.get<std::string>() : error.dump());
          }
          if (reason.empty()) reason = "no finite fitness";
        }
        inputs.failures.push_back({e.iteration, e.position, config.cases[k].name, e.params, run->status, reason});
      }
    }
    write_report(inputs, config.output);
  }
  return result;
}

void run_mpi_worker(const CampaignConfig& config) {
  config.Validate();
  mpi_serve(build_scenes(config));
}

}  // namespace demcal::pipelines
