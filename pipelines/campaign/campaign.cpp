// run_campaign as a list of named stages (docs/pipelines.md, "Stages of run_campaign").
#include "demcal/pipelines/campaign.hpp"

#include "campaign_internal.hpp"
#include "demcal/limits/limits.hpp"
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
#include <limits>
#include <memory>
#include <optional>
#include <set>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using nlohmann::json;

using detail::build_scenes;
using detail::case_curve_grid;
using detail::FitnessWorkers;
using detail::fitness_thread_count;
using detail::identifiability;
using detail::make_backend;
using detail::prepare_cases;
using detail::PreparedCases;
using detail::top_distinct;
using detail::usable_status;

namespace {

// ---- run_campaign's stages ----------------------------------------------------------------------

// Wall time since it was made: the campaign's (this session), a stage's.
class Stopwatch {
 public:
  double elapsed_s() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

void validate_and_create_output(const CampaignConfig& config) {
  config.Validate();
  std::error_code ec;
  fs::create_directories(config.output, ec);
  if (ec) throw CampaignError(config.output + ": cannot create the output folder: " + ec.message());
}

std::string archive_path(const CampaignConfig& config) {
  return config.archive.empty() ? (fs::path(config.output) / "archive.sqlite").string() : config.archive;
}

// The campaign's identity in the archive and, with --resume, the newest campaign that has it.
struct CampaignLookup {
  std::string config_key;                  // hash of the result-defining configuration
  std::optional<CampaignRecord> previous;  // --resume only
};

CampaignLookup look_up_campaign(const CampaignConfig& config, const RunOptions& options, const RunArchive& archive) {
  CampaignLookup lookup;
  lookup.config_key = hash_text(config.result_defining_json().dump());
  if (options.resume) lookup.previous = archive.latest_campaign(lookup.config_key);
  return lookup;
}

// What the surrogate is trained on: the archive's runs of these scenes and objectives up to the
// horizon (the newest run when the campaign started, kept in the campaign record so a resume sees the
// same earlier runs) plus this campaign's committed evaluations; and, optionally, a model trained
// beforehand whose hyperparameters are kept.
struct SurrogateSetup {
  bool bayes = false;       // algorithm "bo": the surrogate proposes the candidates
  bool screening = false;   // pre-screening of the swarm's candidates
  std::int64_t horizon = 0;
  std::vector<ArchivedCase> archived_cases;
  std::optional<surrogate::SurrogateModel> trained_model;
  surrogate::CurveHooks hooks;  // the "mlp" kind: the fitness of predicted curves, a told point's curves
  surrogate::SurrogateOptions options;  // the campaign's, with the batch and the scoring threads resolved
  // This session's evaluation rounds: wall seconds and simulated runs (the cost of a simulation as
  // the user waits for it, fitness included), and the runs' own seconds summed.
  struct Clock {
    double round_s = 0;
    long runs = 0;
    double run_s = 0;
  };
  std::shared_ptr<Clock> clock = std::make_shared<Clock>();
};

// Earlier runs of the campaign's scenes that have no fitness for its objective (a calibration of the
// same model against another measurement) and are points of its space: scored now, so that a
// surrogate trains on every run it can use. Only where a surrogate reads earlier runs.
void score_earlier_runs(const CampaignConfig& config, const PreparedCases& prepared, const EvaluationBackend& backend,
                        RunArchive& archive) {
  if (config.optimiser.algorithm != "bo" && !config.surrogate.enabled) return;
  std::vector<std::pair<std::int64_t, size_t>> unscored;  // (run id, case)
  for (size_t k = 0; k < config.cases.size(); ++k)
    for (const auto& r : archive.unscored_runs(backend.model_hash(k), prepared.objective_keys[k]))
      if (outside_space(config.space, r.params).empty()) unscored.push_back({r.run_id, k});
  if (unscored.empty()) return;
  FitnessWorkers workers(fitness_thread_count(config), prepared, config);
  for (const auto& [id, k] : unscored) {
    auto run = archive.run(id);
    workers.submit(id, run->status, std::move(run->curves), k);
  }
  for (const auto& record : workers.finish()) archive.put_fitness(record);
}

SurrogateSetup prepare_surrogate(const CampaignConfig& config, const PreparedCases& prepared,
                                 const EvaluationBackend& backend, const RunArchive& archive,
                                 const std::optional<CampaignRecord>& previous) {
  SurrogateSetup s;
  s.bayes = config.optimiser.algorithm == "bo";
  s.screening = config.surrogate.enabled && !s.bayes;
  s.options = config.surrogate.options;
  if (s.options.batch == 0) s.options.batch = std::max(1, backend.workers());
  s.options.threads = std::max(1, hardware_threads());
  s.horizon = previous && previous->config.contains("surrogate_run_horizon")
                  ? previous->config.at("surrogate_run_horizon").get<std::int64_t>()
                  : archive.max_run_id();
  const bool curves = (s.bayes || s.screening) && config.surrogate.options.kind == "mlp";
  std::vector<std::shared_ptr<const CurveGrid>> grids;
  for (size_t k = 0; k < config.cases.size(); ++k) {
    std::shared_ptr<const CurveGrid> grid;
    if (curves) grids.push_back(grid = case_curve_grid(config, prepared, k));
    s.archived_cases.push_back({backend.model_hash(k), prepared.objective_keys[k], config.cases[k].weight, grid});
  }
  // A simulation's wall time per worker in this session, fitness included (cost-aware batches of "bo").
  s.hooks.seconds_per_simulation = [clock = s.clock, workers = std::max(1, backend.workers())] {
    return clock->runs > 0 ? clock->round_s / static_cast<double>(clock->runs) * workers : 0.0;
  };
  if (curves) {
    s.hooks.fitness = [grids](const Eigen::VectorXd& outputs) { return curve_fitness(outputs, grids); };
    // A told point's runs, found by the parameters the campaign simulated for it.
    s.hooks.outputs_at = [&config, &archive, cases = s.archived_cases](const Eigen::VectorXd& unit) {
      const auto params = config.space.values(config.space.to_physical(unit));
      std::vector<std::int64_t> run_ids;
      for (const auto& c : cases) {
        const auto run = archive.find_run(c.model_hash, params);
        if (!run) return Eigen::VectorXd();
        run_ids.push_back(run->id);
      }
      return archived_outputs(archive, run_ids, cases);
    };
  }
  if (s.screening && !config.surrogate.model_file.empty()) {
    if (auto m = limits::check_file_size(config.surrogate.model_file))
      throw CampaignError(config.surrogate.model_file + ": " + *m);
    std::ifstream in(config.surrogate.model_file);
    try {
      s.trained_model = surrogate::SurrogateModel::from_json(json::parse(in), config.surrogate.model_file);
    } catch (const std::exception& e) {
      throw CampaignError(config.surrogate.model_file + ": " + e.what());
    }
    if (s.trained_model->dimension() != config.space.dimension())
      throw CampaignError(config.surrogate.model_file + ": the model has " +
                          std::to_string(s.trained_model->dimension()) + " parameters, the campaign " +
                          std::to_string(config.space.dimension()));
    if (s.trained_model->options().kind != config.surrogate.options.kind)
      throw CampaignError(config.surrogate.model_file + ": a model of kind " + s.trained_model->options().kind +
                          ", the campaign's surrogate is of kind " + config.surrogate.options.kind);
    s.trained_model->set_hooks(s.hooks);
  }
  return s;
}

// Training rows: earlier runs (<= horizon), then this campaign's evaluations, each parameter set once.
std::vector<surrogate::TrainingRow> training_rows(const CampaignConfig& config, const SurrogateSetup& setup,
                                                  const RunArchive& archive, std::int64_t campaign_id) {
  std::vector<surrogate::TrainingRow> rows;
  std::set<std::vector<double>> seen;  // unit points (computed the same way for the same parameters)
  auto add = [&](surrogate::TrainingRow row) {
    if (seen.insert(std::vector<double>(row.unit.data(), row.unit.data() + row.unit.size())).second)
      rows.push_back(std::move(row));
  };
  for (auto& r : archive_training_rows(archive, config.space, setup.archived_cases, setup.horizon)) add(std::move(r));
  const bool curves = config.surrogate.options.kind == "mlp";
  for (const auto& e : archive.evaluations(campaign_id)) {
    Eigen::VectorXd unit = unit_point_in_space(config.space, e.params);
    if (unit.size() == 0) continue;
    Eigen::VectorXd outputs = curves && std::isfinite(e.fitness) ? archived_outputs(archive, e.run_ids, setup.archived_cases)
                                                                 : Eigen::VectorXd();
    add({std::move(unit), e.fitness, std::move(outputs)});
  }
  return rows;
}

// The campaign's optimisers: the main one (swarm, GA, NLopt or "bo") and, once it is done, the
// optional local polish from its best point.
class CampaignOptimisers {
 public:
  CampaignOptimisers(const CampaignConfig& config, const SurrogateSetup& setup, const RunArchive& archive)
      : config_(config), screening_(setup.screening) {
    try {
      optimise::OptimiserOptions o = config.optimiser;
      if (setup.bayes) {
        main_ = surrogate::make_bayes_optimiser(
            config.space, o, setup.options,
            archive_training_rows(archive, config.space, setup.archived_cases, setup.horizon), setup.hooks);
      } else {
        if (setup.screening && config.surrogate.options.k > 0)
          o.evaluations_per_iteration = config.surrogate.options.k;
        main_ = optimise::make_optimiser(config.space, o);
      }
    } catch (const std::exception& e) {
      throw CampaignError(config.source + ": " + e.what());
    }
  }

  optimise::Optimiser& main() const { return *main_; }
  const optimise::Optimiser* polisher() const { return polisher_.get(); }

  // The optimiser that asks next: the main one, then the polish; nullptr when both are done.
  optimise::Optimiser* active() {
    if (!main_->done()) return main_.get();
    if (!config_.polish.enabled || main_->best_x().size() == 0) return nullptr;
    if (!polisher_) polisher_ = optimise::make_polisher(config_.space, main_->best_x(), config_.polish.options);
    return polisher_->done() ? nullptr : polisher_.get();
  }
  double best_value() const { return std::min(main_->best_value(), polisher_ ? polisher_->best_value() : INFINITY); }
  long evaluations() const { return main_->evaluations() + (polisher_ ? polisher_->evaluations() : 0); }

  // The saved state: the main optimiser's alone, or with a polish {"swarm": ..., "polish": ...|null}.
  json save_state() const {
    if (!config_.polish.enabled) return main_->save_state();
    return {{"swarm", main_->save_state()}, {"polish", polisher_ ? polisher_->save_state() : json(nullptr)}};
  }
  // An iteration record's state; with pre-screening it is {"optimiser": ..., "screening": ...}.
  void load_state(const json& saved) {
    const json& state = screening_ ? saved.at("optimiser") : saved;
    if (!config_.polish.enabled) return main_->load_state(state);
    main_->load_state(state.at("swarm"));
    if (!state.at("polish").is_null()) {
      polisher_ = optimise::make_polisher(config_.space, main_->best_x(), config_.polish.options);
      polisher_->load_state(state.at("polish"));
    }
  }

 private:
  const CampaignConfig& config_;
  bool screening_;
  std::unique_ptr<optimise::Optimiser> main_;
  std::unique_ptr<optimise::Optimiser> polisher_;
};

// Where the evaluation loop starts: the campaign's archive id and its first iteration.
struct CampaignStart {
  std::int64_t campaign_id = 0;
  int next_iteration = 0;
};

// With --resume and a matching campaign: its id, the optimisers restored from its last iteration.
// Otherwise a new campaign record (with the surrogate's horizon).
CampaignStart start_or_resume(const CampaignConfig& config, const RunOptions& options, RunArchive& archive,
                              const CampaignLookup& lookup, const SurrogateSetup& setup,
                              CampaignOptimisers& optimisers) {
  CampaignStart start;
  if (options.resume && lookup.previous) {
    start.campaign_id = lookup.previous->id;
    if (auto last = archive.last_iteration(start.campaign_id)) {
      try {
        optimisers.load_state(json::parse(last->optimiser_state));
      } catch (const std::exception& e) {
        throw CampaignError(archive.path() + ": cannot restore the optimiser state of iteration " +
                            std::to_string(last->iteration) + ": " + e.what());
      }
      start.next_iteration = last->iteration + 1;
    }
  }
  if (options.resume && options.note_fresh_resume && start.campaign_id == 0)
    std::cerr << "demcal: note: --resume: " << archive.path() << " holds no campaign with this configuration (key "
              << lookup.config_key << ": scene, measurement, parameters, objective or optimiser differ from every "
              << "archived one); starting a new campaign\n";
  if (start.campaign_id == 0) {
    CampaignRecord record;
    record.name = config.name;
    record.config_key = lookup.config_key;
    record.config = config.to_json();
    record.config["surrogate_run_horizon"] = setup.horizon;
    record.code_version = version();
    start.campaign_id = archive.create_campaign(record);
  }
  return start;
}

// What the stages of a running campaign share (all owned by run_campaign).
struct CampaignContext {
  const CampaignConfig& config;
  const PreparedCases& prepared;
  EvaluationBackend& backend;
  RunArchive& archive;
  const SurrogateSetup& surrogate;
  const Stopwatch& clock;
  std::int64_t campaign_id;
};

// Runs simulated or read from the archive in this session (result.json's "session").
struct SessionCounts {
  long simulated = 0;
  long reused_from_archive = 0;
  double model_s = 0;        // choosing candidates: the optimiser's ask, the surrogate's fits and search
  double simulation_s = 0;   // waiting for the simulations and their fitness
};

// Progress lines: the planned totals and what is done so far.
struct CampaignProgress {
  ProgressPrinter printer;
  ProgressState state;
};

void plan_progress(const CampaignContext& ctx, const CampaignOptimisers& optimisers, ProgressState& progress) {
  const auto& config = ctx.config;
  const long budget = config.optimiser.evaluation_budget();
  const long polish_budget = config.polish.enabled ? config.polish.options.max_evaluations : 0;
  const long cases = static_cast<long>(config.cases.size());
  // Iterations are known in advance for a swarm or GA (a batch each) and for NLopt (one point
  // each), not for `bo`, whose first batch is its design; the polish asks one point at a time.
  const std::string& algorithm = config.optimiser.algorithm;
  long batch = 0;
  if (algorithm.rfind("nlopt:", 0) == 0) batch = 1;
  else if (algorithm != "bo")
    batch = ctx.surrogate.screening && config.surrogate.options.k > 0 ? config.surrogate.options.k
                                                                       : config.optimiser.population;
  progress.iterations = batch > 0 ? static_cast<int>((budget + batch - 1) / batch + polish_budget) : 0;
  progress.total = (budget + polish_budget) * cases;
  progress.done = static_cast<long>(ctx.archive.evaluations(ctx.campaign_id).size()) * cases;
  progress.best = optimisers.main().best_value();
}

// One iteration's batch as asked, and the slots of it that are evaluated (all of them, unless the
// surrogate screened the batch).
struct ProposedBatch {
  std::vector<Eigen::VectorXd> batch;
  std::vector<size_t> slots;                      // evaluated slots, ascending
  std::optional<surrogate::ScreenReport> screen;  // set when the batch was screened
  json screen_record = nullptr;                   // the screen for the iteration record
};

// Asks the optimiser. Pre-screening (main optimiser only): the model ranks a pool, substitutes the
// best of each slot's pool and withdraws all but the best k slots; only the kept slots are simulated.
// Nothing when the optimiser has no candidate left to propose.
std::optional<ProposedBatch> propose_batch(const CampaignContext& ctx, const CampaignOptimisers& optimisers,
                                           optimise::Optimiser& asking) {
  const auto& config = ctx.config;
  ProposedBatch p;
  p.batch = asking.ask();
  if (p.batch.empty()) return std::nullopt;
  p.slots.resize(p.batch.size());
  for (size_t i = 0; i < p.batch.size(); ++i) p.slots[i] = i;
  if (!ctx.surrogate.screening || &asking != &optimisers.main() || !asking.can_substitute()) return p;
  const auto rows = training_rows(config, ctx.surrogate, ctx.archive, ctx.campaign_id);
  long finite = 0;
  for (const auto& r : rows) finite += std::isfinite(r.fitness) ? 1 : 0;
  surrogate::SurrogateModel model(ctx.surrogate.options, ctx.surrogate.hooks);
  bool usable = false;
  if (ctx.surrogate.trained_model) {
    model = *ctx.surrogate.trained_model;
    usable = finite >= config.surrogate.options.min_runs ? model.condition(rows) : model.usable();
  } else if (finite >= config.surrogate.options.min_runs) {
    usable = model.fit(rows);
  }
  if (!usable) return p;
  p.screen = surrogate::prescreen(asking, model, config.surrogate.options);
  p.batch = asking.ask();
  p.slots.clear();
  for (const auto& c : p.screen->candidates)
    if (c.simulated) p.slots.push_back(static_cast<size_t>(c.slot));
  std::sort(p.slots.begin(), p.slots.end());
  p.screen_record = p.screen->to_json();
  p.screen_record["training_rows"] = model.training_rows();
  p.screen_record["log_transform"] = model.log_transformed();
  return p;
}

// Per candidate: its run in each case and its weighted fitness over the cases.
struct CandidateFitness {
  std::vector<std::vector<std::int64_t>> run_ids;  // [candidate][case]
  std::vector<double> fitness;                     // NaN when any case has no finite fitness
};

// Runs come from the archive where they exist, else are simulated (each archived as it finishes;
// duplicates inside the batch run once). Fitness jobs start as soon as a run is available, on their
// own workers; computed fitness rows are archived after the simulations, in job order.
CandidateFitness evaluate_candidates(const CampaignContext& ctx, const std::vector<std::map<std::string, double>>& candidates,
                                     int fitness_threads, SessionCounts& counts, CampaignProgress& progress) {
  const auto& config = ctx.config;
  auto& archive = ctx.archive;
  auto& backend = ctx.backend;
  const size_t cases = config.cases.size();
  FitnessWorkers workers(fitness_threads, ctx.prepared, config);
  std::map<std::pair<std::int64_t, size_t>, size_t> job_of;  // (run id, case) -> fitness job
  auto need_fitness = [&](const RunRecord& run, size_t k) {
    if (job_of.count({run.id, k})) return;
    if (auto f = archive.find_fitness(run.id, ctx.prepared.objective_keys[k])) {
      job_of[{run.id, k}] = SIZE_MAX;
      return;
    }
    job_of[{run.id, k}] = workers.submit(run.id, run.status, run.curves, k);
  };

  CandidateFitness out;
  out.run_ids.assign(candidates.size(), std::vector<std::int64_t>(cases, 0));
  std::vector<SimulationTask> tasks;
  std::map<std::pair<std::string, std::string>, size_t> queued;  // (model, parameter key) -> task
  std::vector<std::vector<std::pair<size_t, size_t>>> task_users;  // per task: (candidate, case)
  for (size_t c = 0; c < candidates.size(); ++c)
    for (size_t k = 0; k < cases; ++k) {
      const std::string model = backend.model_hash(k);
      if (auto run = archive.find_run(model, candidates[c])) {
        out.run_ids[c][k] = run->id;
        ++counts.reused_from_archive;
        ++progress.state.done;
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
  backend.run(tasks, [&](size_t index, SimulationOutcome&& outcome) {
    RunRecord run;
    run.model_hash = backend.model_hash(tasks[index].case_index);
    run.params = tasks[index].params;
    run.code_version = version();
    run.backend = backend.name();
    run.status = outcome.status;
    run.message = outcome.message;
    run.wall_time_s = outcome.wall_time_s;
    ctx.surrogate.clock->run_s += outcome.wall_time_s;
    run.curves = std::move(outcome.curves);
    run.details = std::move(outcome.details);
    run.id = archive.insert_run(run);
    need_fitness(run, tasks[index].case_index);
    for (const auto& [c, k] : task_users[index]) {
      out.run_ids[c][k] = run.id;
      ++progress.state.done;
    }
    ++counts.simulated;
    ++progress.state.done_this_session;
    progress.state.elapsed_s = ctx.clock.elapsed_s();
    progress.printer.simulation_done(progress.state);
  });

  // Fitness per (candidate, case): archived, or computed by the workers and archived now.
  const std::vector<FitnessRecord> computed = workers.finish();
  for (const auto& record : computed) archive.put_fitness(record);
  std::vector<std::vector<double>> case_fitness(candidates.size(), std::vector<double>(cases, NAN));
  for (size_t c = 0; c < candidates.size(); ++c)
    for (size_t k = 0; k < cases; ++k) {
      const size_t job = job_of.at({out.run_ids[c][k], k});
      if (job != SIZE_MAX) {
        case_fitness[c][k] = computed[job].fitness;
      } else if (auto f = archive.find_fitness(out.run_ids[c][k], ctx.prepared.objective_keys[k])) {
        case_fitness[c][k] = f->fitness;
      }
    }
  out.fitness.assign(candidates.size(), 0.0);
  for (size_t c = 0; c < candidates.size(); ++c)
    for (size_t k = 0; k < cases; ++k) out.fitness[c] += config.cases[k].weight * case_fitness[c][k];
  return out;
}

// Tells the optimiser (simulated values only: NaN for withdrawn slots) and archives the iteration's
// evaluations with the optimisers' state in one transaction. Returns the best fitness so far.
double tell_and_commit(const CampaignContext& ctx, CampaignOptimisers& optimisers, optimise::Optimiser& asking,
                       int iteration, const std::vector<std::map<std::string, double>>& candidates,
                       ProposedBatch& proposed, const CandidateFitness& evaluated) {
  const auto& fitness = evaluated.fitness;
  const auto& slots = proposed.slots;
  std::vector<EvaluationRecord> evaluations;
  for (size_t c = 0; c < candidates.size(); ++c) {
    EvaluationRecord e;
    e.campaign_id = ctx.campaign_id;
    e.iteration = iteration;
    e.position = static_cast<int>(slots[c]);
    e.params = candidates[c];
    e.run_ids = evaluated.run_ids[c];
    e.fitness = fitness[c];
    evaluations.push_back(std::move(e));
  }
  std::vector<double> told(proposed.batch.size(), std::numeric_limits<double>::quiet_NaN());
  for (size_t c = 0; c < slots.size(); ++c) told[slots[c]] = fitness[c];
  asking.tell(told);
  if (proposed.screen) {  // the model's error on what was simulated, for the report
    double error_sum = 0;
    long error_count = 0;
    for (size_t c = 0; c < slots.size(); ++c) {
      auto& entry = proposed.screen_record["candidates"][slots[c]];
      entry["simulated_fitness"] = finite_or_null(fitness[c]);
      if (std::isfinite(fitness[c]) && fitness[c] != 0) {
        error_sum += std::abs(entry["predicted_fitness"].get<double>() - fitness[c]) / std::abs(fitness[c]);
        ++error_count;
      }
    }
    proposed.screen_record["mean_relative_error"] = error_count > 0 ? json(error_sum / error_count) : json(nullptr);
  }
  IterationRecord record;
  record.campaign_id = ctx.campaign_id;
  record.iteration = iteration;
  record.optimiser_state = (ctx.surrogate.screening
                                ? json{{"optimiser", optimisers.save_state()}, {"screening", proposed.screen_record}}
                                : optimisers.save_state())
                               .dump();
  record.best_fitness = optimisers.best_value();
  record.evaluations = static_cast<int>(optimisers.evaluations());
  record.wall_time_s = ctx.clock.elapsed_s();
  ctx.archive.commit_iteration(record, evaluations);
  return record.best_fitness;
}

// The evaluation loop: ask, (screen), evaluate, tell and commit, one iteration at a time, until the
// optimisers are done.
SessionCounts run_iterations(const CampaignContext& ctx, CampaignOptimisers& optimisers, int first_iteration,
                             CampaignProgress& progress) {
  const auto& config = ctx.config;
  const int fitness_threads = fitness_thread_count(config);
  SessionCounts counts;
  for (int iteration = first_iteration;; ++iteration) {
    optimise::Optimiser* asking = optimisers.active();
    if (!asking) break;
    const Stopwatch asking_time;
    std::optional<ProposedBatch> next = propose_batch(ctx, optimisers, *asking);
    counts.model_s += asking_time.elapsed_s();
    progress.state.model_s = counts.model_s;
    if (!next) break;
    ProposedBatch& proposed = *next;
    progress.state.iteration = iteration + 1;
    std::vector<std::map<std::string, double>> candidates;
    for (size_t slot : proposed.slots) candidates.push_back(config.space.values(proposed.batch[slot]));
    const Stopwatch simulating;
    const long simulated_before = counts.simulated;
    const CandidateFitness evaluated = evaluate_candidates(ctx, candidates, fitness_threads, counts, progress);
    const double round_s = simulating.elapsed_s();
    counts.simulation_s += round_s;
    if (counts.simulated > simulated_before) {  // rounds read from the archive cost no simulation
      ctx.surrogate.clock->round_s += round_s;
      ctx.surrogate.clock->runs += counts.simulated - simulated_before;
    }
    progress.state.simulation_s = counts.simulation_s;
    progress.state.best = tell_and_commit(ctx, optimisers, *asking, iteration, candidates, proposed, evaluated);
    progress.state.elapsed_s = ctx.clock.elapsed_s();
    progress.printer.iteration_done(progress.state);
  }
  progress.printer.finish();
  return counts;
}

// Every candidate without a finite fitness, in evaluation order, with the reason archived for its
// run (its message, or why its fitness is not finite), one entry per case that failed it.
std::vector<ReportInputs::Failure> failed_runs(const CampaignContext& ctx, const std::vector<EvaluationRecord>& evaluations) {
  std::vector<ReportInputs::Failure> failures;
  for (const auto& e : evaluations) {
    if (std::isfinite(e.fitness)) continue;
    for (size_t k = 0; k < ctx.config.cases.size() && k < e.run_ids.size(); ++k) {
      const auto run = ctx.archive.run(e.run_ids[k]);
      if (!run) continue;
      std::string reason = run->message;
      if (usable_status(run->status)) {
        const auto f = ctx.archive.find_fitness(run->id, ctx.prepared.objective_keys[k]);
        if (f && std::isfinite(f->fitness)) continue;  // another case failed this candidate
        if (f && f->channels.contains("error")) {
          const json& error = f->channels.at("error");
          reason = "fitness: " + (error.is_string() ? error.get<std::string>() : error.dump());
        }
        if (reason.empty()) reason = "no finite fitness";
      }
      failures.push_back({e.iteration, e.position, ctx.config.cases[k].name, e.params, run->status, reason});
    }
  }
  return failures;
}

// The result, from the archive: a resumed campaign reports exactly what an uninterrupted one would.
CampaignResult collect_result(const CampaignContext& ctx, const CampaignOptimisers& optimisers,
                              const std::vector<EvaluationRecord>& evaluations, const SessionCounts& counts) {
  const auto& config = ctx.config;
  CampaignResult result;
  result.simulated_this_session = counts.simulated;
  result.model_time_s = counts.model_s;
  result.simulation_time_s = counts.simulation_s;
  result.run_time_s = ctx.surrogate.clock->run_s;
  result.reused_from_archive = counts.reused_from_archive;
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
  result.simulations = result.candidates * static_cast<long>(config.cases.size());
  result.iterations = evaluations.empty() ? 0 : evaluations.back().iteration + 1;
  result.top = top_distinct(result.all, 5);
  result.optimiser_status = optimise::to_string(optimisers.main().status());
  if (config.polish.enabled) {
    result.polished = true;
    const long swarm_candidates = optimisers.main().evaluations();
    result.polish_evaluations = std::max(0L, result.candidates - swarm_candidates);
    result.swarm_best_fitness = optimisers.main().best_value();
    result.polish_status = optimisers.polisher() ? optimise::to_string(optimisers.polisher()->status()) : "not started";
  }
  result.identifiability = identifiability(result.all, config);
  const auto& setup = ctx.surrogate;
  if (setup.screening || setup.bayes) {
    result.surrogate_used = true;
    result.surrogate_kind = config.surrogate.options.kind;
    for (const auto& it : ctx.archive.iterations(ctx.campaign_id)) {
      const json state = json::parse(it.optimiser_state);
      if (!setup.screening || state.at("screening").is_null()) continue;
      json entry = state.at("screening");
      entry["iteration"] = it.iteration;
      result.surrogate_screened += entry.at("pool").get<long>();
      result.surrogate_simulated += entry.at("simulated").get<long>();
      result.surrogate_screened_out += static_cast<long>(entry.at("candidates").size()) - entry.at("simulated").get<long>();
      result.surrogate_iterations.push_back(std::move(entry));
    }
    const Stopwatch statistics_time;
    if (setup.bayes) {
      result.surrogate_simulated = result.candidates;
      if (auto last = ctx.archive.last_iteration(ctx.campaign_id)) {
        const json saved = json::parse(last->optimiser_state);
        const auto summary = surrogate::summarise_bayes_state(saved.contains("swarm") ? saved.at("swarm") : saved);
        result.surrogate_batch = summary.batch;
        result.surrogate_batch_reason = summary.batch_reason;
        result.surrogate_predicted = summary.predicted;
        result.surrogate_prequential_error = summary.prequential_error;
        result.surrogate_prequential_coverage90 = summary.prequential_coverage90;
      }
    }
    const auto rows = training_rows(config, setup, ctx.archive, ctx.campaign_id);
    if (setup.bayes && config.surrogate.options.kind == "mlp") {
      // the prequential error above is the held-out check: a 5-fold one would cost five full fits
    } else if (config.surrogate.options.kind == "mlp") {
      const auto cv = surrogate::cross_validate(rows, config.surrogate.options, 5, setup.hooks);
      if (cv.finite_rows > 0) result.surrogate_cv_error = cv.relative_error;
    } else if (surrogate::SurrogateModel final_model(config.surrogate.options); final_model.fit(rows)) {
      result.surrogate_cv_error = final_model.gp().leave_one_out().relative_error;
    }
    result.model_time_s += statistics_time.elapsed_s();
  }
  if (!std::isfinite(best)) {
    // the reason the most runs share, with the first case it was archived for
    result.status = CampaignStatus::failed;
    result.message = "no run gave a finite fitness (" + std::to_string(result.failed_runs) + " failed)";
    const auto failures = failed_runs(ctx, evaluations);
    std::map<std::string, int> counts;
    for (const auto& f : failures) ++counts[f.reason];
    const ReportInputs::Failure* common = nullptr;
    for (const auto& f : failures)
      if (common == nullptr || counts[f.reason] > counts[common->reason]) common = &f;
    if (common != nullptr)
      result.message += "; " + std::to_string(counts[common->reason]) + " of the " + std::to_string(failures.size()) +
                        " failed runs: case '" + common->case_name + "', " + common->status + ": " + common->reason;
  }
  return result;
}

// <output>/result.json: the result plus what identifies the campaign and this session.
void write_result_json(const CampaignContext& ctx, const CampaignResult& result) {
  const auto& config = ctx.config;
  json out = result.to_json();
  out["name"] = config.name;
  out["code_version"] = version();
  out["objective"] = config.objective;
  out["algorithm"] = config.optimiser.algorithm;
  out["seed"] = config.optimiser.seed;
  out["archive"] = ctx.archive.path();
  out["session"]["campaign_id"] = ctx.campaign_id;
  out["session"]["backend"] = ctx.backend.name();
  std::ofstream file(fs::path(config.output) / "result.json");
  file << out.dump(2) << "\n";
  if (!file) throw CampaignError(config.output + "/result.json: cannot write");
}

// report.md and figures: the best candidate's runs (smoothed, with objective 2) and every candidate
// without a finite fitness with the reason archived for its run.
void write_campaign_report(const CampaignContext& ctx, const CampaignResult& result,
                           const std::vector<EvaluationRecord>& evaluations) {
  const auto& config = ctx.config;
  const auto& prepared = ctx.prepared;
  const auto& archive = ctx.archive;
  const size_t cases = config.cases.size();
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
  inputs.failures = failed_runs(ctx, evaluations);
  write_report(inputs, config.output);
}

}  // namespace

// Preprocess (cases, backend, archive, surrogate, optimisers, campaign record), evaluate (the
// iterations), postprocess (result from the archive, result.json, report).
CampaignResult run_campaign(const CampaignConfig& config, const RunOptions& options) {
  const Stopwatch clock;
  validate_and_create_output(config);
  const PreparedCases prepared = prepare_cases(config);
  const auto backend = make_backend(config, prepared, options);
  RunArchive archive(archive_path(config));
  const CampaignLookup lookup = look_up_campaign(config, options, archive);
  score_earlier_runs(config, prepared, *backend, archive);
  const SurrogateSetup surrogate = prepare_surrogate(config, prepared, *backend, archive, lookup.previous);
  CampaignOptimisers optimisers(config, surrogate, archive);
  const CampaignStart start = start_or_resume(config, options, archive, lookup, surrogate, optimisers);
  const CampaignContext ctx{config, prepared, *backend, archive, surrogate, clock, start.campaign_id};

  CampaignProgress progress{ProgressPrinter(options.progress), {}};
  plan_progress(ctx, optimisers, progress.state);
  const SessionCounts counts = run_iterations(ctx, optimisers, start.next_iteration, progress);

  const auto evaluations = archive.evaluations(start.campaign_id);
  CampaignResult result = collect_result(ctx, optimisers, evaluations, counts);
  result.wall_time_s = clock.elapsed_s();
  write_result_json(ctx, result);
  if (config.report && result.status == CampaignStatus::completed) write_campaign_report(ctx, result, evaluations);
  return result;
}

void run_mpi_worker(const CampaignConfig& config) {
  config.Validate();
  mpi_serve(build_scenes(config));
}

}  // namespace demcal::pipelines
