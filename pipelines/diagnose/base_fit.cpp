// Stage 1 of the diagnosis: the base calibration (or a finished one, --result), then the same
// search the candidates get on the base parameters alone: an effect must beat the best the base
// model can do with that search, not a less refined fit.
#include "diagnose_internal.hpp"

#include "demcal/pipelines/surrogate_data.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>

namespace demcal::pipelines {

long candidate_budget(const DiagnoseOptions& options, const CampaignConfig& config) {
  return options.candidate_simulations > 0 ? options.candidate_simulations : config.optimiser.evaluation_budget();
}

}  // namespace demcal::pipelines

namespace demcal::pipelines::detail {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::map<std::string, double> base_fit(const CampaignConfig& config, const DiagnoseOptions& options, CaseRunner& runner,
                                       double* fitness, std::vector<ParameterSet>& runs) {
  if (!options.result.empty()) {
    fs::path result = options.result;
    if (fs::is_directory(result)) result /= "result.json";
    progress(options, "base parameters from " + result.string());
    const auto params = read_result_parameters(result.string());
    // a calibration of this campaign's parameters, or the diagnosis would start from another model
    if (const std::string why = outside_space(config.space, params); !why.empty())
      throw CampaignError(result.string() + ": " + why + " (--result must be a calibration of this campaign's parameters)");
    std::ifstream in(result);
    const json j = json::parse(in, nullptr, false);
    *fitness = j.is_object() && j.contains("best") && j["best"].contains("fitness") && j["best"]["fitness"].is_number()
                   ? j["best"]["fitness"].get<double>()
                   : Diagnosis::kNaN;
    return params;
  }
  CampaignConfig base = fitted_cases(config, options);
  base.output = (fs::path(options.out) / "base").string();
  base.archive = diagnosis_archive(options);
  base.report = options.report;
  fix_search_rounds(base);
  if (options.max_simulations > 0)
    base.optimiser.max_evaluations = std::min(base.optimiser.evaluation_budget(), options.max_simulations / 2);
  progress(options, "base calibration (" + std::to_string(base.optimiser.evaluation_budget()) + " simulations) in " +
                        base.output);
  RunOptions run;
  run.resume = options.resume;
  run.progress = options.progress;
  const CampaignResult result = run_campaign(base, run);
  runner.add_campaign(result);
  runs.insert(runs.end(), result.all.begin(), result.all.end());
  if (result.status != CampaignStatus::completed || result.best.params.empty())
    throw CampaignError("the base calibration failed: " + result.message);
  *fitness = result.best.fitness;
  return result.best.params;
}

// The refinement: the candidates' search on the base parameters alone from the best set so far,
// into `folder`; its best replaces that set where it scores better (any set where the window has
// changed: `d.base_fitness` NaN). Its evaluated sets are appended to `runs`.
void refine_base(DiagnosisRun& run, const fs::path& folder, std::vector<ParameterSet>& runs) {
  const CampaignConfig& config = run.config;
  const DiagnoseOptions& options = run.options;
  Diagnosis& d = run.d;
  // Within a total budget the refinement takes at most a quarter of what the base fit left.
  const long refine_budget = options.max_simulations > 0
                                 ? std::min(run.per_candidate, (options.max_simulations - run.runner.simulations()) / 4)
                                 : run.per_candidate;
  if (refine_budget < 2 * config.optimiser.population) return;
  ExtendedModel plain;
  plain.config = config;
  const CampaignConfig refine = extended_campaign(plain, config, d.base_params, options, refine_budget, folder, d.base_params);
  progress(options, "refining the base fit (" + std::to_string(refine_budget) + " simulations) in " + folder.string());
  RunOptions run_options;
  run_options.resume = options.resume;
  run_options.progress = options.progress;
  const CampaignResult r = run_campaign(refine, run_options);
  run.runner.add_campaign(r);
  runs.insert(runs.end(), r.all.begin(), r.all.end());
  if (r.status == CampaignStatus::completed && std::isfinite(r.best.fitness) &&
      (!std::isfinite(d.base_fitness) || r.best.fitness < d.base_fitness)) {
    d.base_params = r.best.params;
    d.base_fitness = r.best.fitness;
  }
}

// Under the paper's window a channel is compared over what both curves reach, so a base fit whose
// simulated gauge hardly moves matches that gauge over a sliver of its measured range and is free
// to miss the rest: every extended search would then start from a compensation the data never
// judged. Where the base fit covers less than kNarrowWindow of a fitted channel, the diagnosis
// compares every channel over its measured range from here on (Diagnosis::widened_window); true
// when it does.
bool widen_a_narrow_window(DiagnosisRun& run) {
  if (run.config.objective_options.window != smoothing::ObjectiveWindow::common) return false;
  const Evaluation best = run.runner.evaluate(run.config, complete_parameters(run.config, run.d.base_params));
  if (!best.ok) return false;
  for (const auto& r : best.residuals)
    if (r.coverage < kNarrowWindow) run.d.widened_window[key_of(r)] = r.coverage;
  if (run.d.widened_window.empty()) return false;
  run.config.objective_options.window = smoothing::ObjectiveWindow::measured;
  run.d.base_fitness = Diagnosis::kNaN;  // over the other window
  progress(run.options, "the base fit is compared with part of the measured range only (" +
                            listed_coverage({run.d.widened_window.begin(), run.d.widened_window.end()}) +
                            "): every channel is compared over its measured range from here on");
  return true;
}

}  // namespace

void fit_base(DiagnosisRun& run) {
  const CampaignConfig& config = run.config;
  const DiagnoseOptions& options = run.options;
  Diagnosis& d = run.d;
  std::vector<ParameterSet> runs;  // every set the base calibrations evaluated
  d.base_params = base_fit(config, options, run.runner, &d.base_fitness, runs);
  run.per_candidate = candidate_budget(options, config);
  refine_base(run, fs::path(options.out) / "base-refined", runs);
  if (widen_a_narrow_window(run)) {
    runs.clear();  // the further starts are ordered by fitness: the sets of one window only
    refine_base(run, fs::path(options.out) / "base-refined-measured-window", runs);
  }
  run.base_params = complete_parameters(config, d.base_params);
  run.d.further_starts =
      further_start_sets(d.base_params, runs, config.space, options.candidate_starts - 1, options.start_separation);
}

}  // namespace demcal::pipelines::detail
