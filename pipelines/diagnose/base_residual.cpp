// Stage 2 of the diagnosis: the base best set's residual, judged like every candidate's on the run
// of median error among it and its re-runs, which also measure the simulation's own scatter; the
// measurement's noise; whether anything is left to explain.
#include "diagnose_internal.hpp"

namespace demcal::pipelines::detail {

void measure_base_residual(DiagnosisRun& run) {
  const DiagnoseOptions& options = run.options;
  Diagnosis& d = run.d;
  run.base_runs = runs_with_reruns(run.config, run.config, run.base_params, nullptr, options.scatter_runs, run.runner);
  const std::vector<Evaluation>& base_runs = run.base_runs;
  if (!base_runs.front().ok) throw CampaignError("the base best set cannot be simulated: " + base_runs.front().message);
  for (const auto& r : base_runs) d.base_rerun_errors.push_back(r.error);
  run.scatter = simulation_scatter(base_runs, d.scatter);
  run.base = median_run(base_runs);
  const Evaluation& base = run.base;
  d.base_residuals = base.residuals;
  for (const auto& c : base.residuals) {
    d.base_rms[key_of(c)] = c.rms;
    d.noise[key_of(c)] = c.noise;
  }
  d.error_before = base.error;
  for (const auto& c : base.held_out) {
    d.held_out_rms[key_of(c)] = c.rms;
    d.held_out_noise[key_of(c)] = c.noise;
  }
  d.held_out_error = base.held_out_error;
  d.held_out_checked = held_out_checks(d, options);
  run.noise = overall_noise(base.residuals);
  progress(options, "base RMS force error " + format_number(d.error_before, 3) + " N, noise " + format_number(run.noise, 3) +
                        " N, simulation scatter " + format_number(run.scatter, 3) + " N");
  run.at_noise = d.error_before <= options.noise_level_ratio * error_floor(run.noise, run.scatter, options);
}

}  // namespace demcal::pipelines::detail
