// Stage 6 of the diagnosis: how tightly the data pin an accepted (or tied) effect's parameters,
// each moved with the others re-fitted (profile_bound).
#include "diagnose_internal.hpp"

#include "demcal/optimise/optimiser.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <optional>

namespace demcal::pipelines::detail {

namespace {

// Values tried for one effect parameter's bound (ParameterBound), inside its search range and, for a
// residual friction, at most the fit's friction; none equal to the best.
std::vector<double> bound_trial_values(const dem::EffectParameter& p, double best, double cap) {
  std::vector<double> values;
  const double upper = std::min(p.search_max, cap);
  constexpr double kLogFactors[] = {0.1, 1.0 / 3, 3, 10};
  constexpr double kLinearShares[] = {-0.3, -0.1, 0.1, 0.3};
  for (int k = 0; k < 4; ++k) {
    const double v = p.log_scale ? best * kLogFactors[k] : best + kLinearShares[k] * (p.search_max - p.search_min);
    const double clipped = std::clamp(v, p.search_min, std::max(upper, p.search_min));
    if (clipped != best && std::find(values.begin(), values.end(), clipped) == values.end()) values.push_back(clipped);
  }
  return values;
}

// The criterion change of a parameter set against a fit (NaN: a failed run).
using ChangeAt = std::function<double(const std::map<std::string, double>&)>;

// The other free parameters of `m` re-fitted with `name` held at `value` (LN_BOBYQA from `best`,
// at most `evaluations` runs): the smallest change, NaN when nothing else is free or every run failed.
double refitted_change(const ExtendedModel& m, const std::map<std::string, double>& best, const std::string& name,
                       double value, const ChangeAt& change_at, int evaluations) {
  const optimise::ParameterSpace& full = m.config.space;
  optimise::ParameterSpace others;
  for (const auto& spec : full.free_parameters())
    if (spec.name != name) others.add(spec);
  if (others.dimension() == 0) return Diagnosis::kNaN;
  for (const auto& [fixed_name, fixed_value] : full.fixed_parameters()) others.fix(fixed_name, fixed_value);
  others.fix(name, value);
  if (const auto& t = full.tied_parameter()) others.tie(t->name, t->source, t->ratio);
  Eigen::VectorXd start(others.dimension());
  const auto names = others.free_names();
  const Eigen::VectorXd lower = others.lower_bounds(), upper = others.upper_bounds();
  for (int i = 0; i < others.dimension(); ++i) start[i] = std::clamp(best.at(names[i]), lower[i], upper[i]);
  optimise::PolishOptions polish;
  polish.max_evaluations = evaluations;
  const auto optimiser = optimise::make_polisher(others, start, polish);
  const auto summary = optimise::minimise(*optimiser, [&](const Eigen::VectorXd& x) {
    std::map<std::string, double> params = best;
    for (const auto& [key, v] : others.values(x)) params[key] = v;
    const double change = change_at(params);
    return std::isnan(change) ? HUGE_VAL : change;
  });
  return std::isfinite(summary.best_value) ? summary.best_value : Diagnosis::kNaN;
}

}  // namespace

void bound_effect_parameters(EffectCandidate& c, const ExtendedModel& m, const std::map<std::string, double>& best,
                             const std::vector<ChannelResidual>& grid, const std::vector<double>& effective_points,
                             CaseRunner& runner, const DiagnoseOptions& options) {
  const CampaignConfig fitted = fitted_cases(m.config, options);
  const long runs_per_trial = static_cast<long>(fitted.cases.size());
  const auto within_budget = [&](long runs) {
    return options.max_simulations <= 0 || runner.simulations() + runs_per_trial * runs <= options.max_simulations;
  };
  const auto change_of = [&](const Evaluation& e) {
    return e.ok ? information_criterion_change(c.residuals, e.residuals, 0, effective_points) : Diagnosis::kNaN;
  };
  const ChangeAt change_at = [&](const std::map<std::string, double>& params) {
    return change_of(runner.evaluate(fitted, params, &grid));
  };
  // Each parameter's check is a task of its own: side by side without a total budget (one
  // parameter's re-fits, a run at a time, beside another's), else in order until one is over it.
  std::vector<std::optional<ParameterBound>> bounds(m.parameter_names.size());
  std::atomic<bool> over_budget{false};
  std::vector<std::function<void()>> tasks;
  for (std::size_t i = 0; i < m.parameter_names.size(); ++i) {
    const std::string& name = m.parameter_names[i];
    if (!best.count(name)) continue;
    tasks.push_back([&, i, name] {
      const auto values = bound_trial_values(m.parameters[i], best.at(name), parameter_cap(name, m.parameters[i], best));
      if (over_budget || !within_budget(static_cast<long>(values.size()))) {
        over_budget = true;  // the rest stay unchecked
        return;
      }
      std::vector<RunRequest> trials;  // each value with the others at the best, run at once
      for (double v : values) {
        trials.push_back({&fitted, best, &grid});
        trials.back().params[name] = v;
      }
      const std::vector<Evaluation> trial_runs = runner.evaluate_all(trials);
      const auto conditional = [&](double v) {
        return change_of(trial_runs[static_cast<std::size_t>(std::find(values.begin(), values.end(), v) - values.begin())]);
      };
      const auto refitted = [&](double v) {
        if (options.profile_simulations == 0 || !within_budget(options.profile_simulations)) return Diagnosis::kNaN;
        return refitted_change(m, best, name, v, change_at, options.profile_simulations);
      };
      bounds[i] = profile_bound(name, best.at(name), values, conditional, refitted, options.evidence);
    });
  }
  runner.side_by_side(tasks, options.max_simulations <= 0);
  for (auto& b : bounds)
    if (b) c.bounds.push_back(std::move(*b));
}

void bound_accepted_parameters(DiagnosisRun& run) {
  if (!run.options.parameter_bounds) return;
  Diagnosis& d = run.d;
  std::vector<std::string> bounds;  // of the chosen effect, for the verdict
  for (auto& c : d.candidates) {
    if (c.verdict != CandidateVerdict::accepted && c.verdict != CandidateVerdict::tied) continue;
    progress(run.options, "checking how tightly the data pin the parameters of " + c.effect);
    bound_effect_parameters(c, run.models.at(c.effect), run.best_sets.at(c.effect), run.base.residuals,
                            run.effective_points, run.runner, run.options);
    if (c.verdict == CandidateVerdict::accepted)
      for (const auto& b : c.bounds) bounds.push_back(b.describe());
  }
  if (!bounds.empty()) {
    std::string note = " How tightly the data pin it, each parameter moved with the others re-fitted:";
    for (std::size_t i = 0; i < bounds.size(); ++i) note += (i ? "; " : " ") + bounds[i];
    add_note(d, note + ".");
  }
}

}  // namespace demcal::pipelines::detail
