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

}  // namespace

void fit_base(DiagnosisRun& run) {
  const CampaignConfig& config = run.config;
  const DiagnoseOptions& options = run.options;
  Diagnosis& d = run.d;
  std::vector<ParameterSet> runs;  // every set the base calibrations evaluated
  d.base_params = base_fit(config, options, run.runner, &d.base_fitness, runs);
  run.per_candidate = candidate_budget(options, config);
  // Within a total budget the refinement takes at most a quarter of what the base fit left.
  const long refine_budget = options.max_simulations > 0
                                 ? std::min(run.per_candidate, (options.max_simulations - run.runner.simulations()) / 4)
                                 : run.per_candidate;
  if (refine_budget >= 2 * config.optimiser.population) {
    ExtendedModel plain;
    plain.config = config;
    const fs::path folder = fs::path(options.out) / "base-refined";
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
  run.base_params = complete_parameters(config, d.base_params);
  run.d.further_starts =
      further_start_sets(d.base_params, runs, config.space, options.candidate_starts - 1, options.start_separation);
}

}  // namespace demcal::pipelines::detail
