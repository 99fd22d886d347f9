// Stage 8 of the diagnosis: after an effect is accepted, the model with it becomes the base (its
// fit the base fit, the effects not yet in it the candidates) and stages 2 to 7 run again, until no
// further effect passes or --max-effects is reached. Each step's diagnosis.json and report.md are
// in a folder of its own; the diagnosis lists the effects added with the error at each step.
#include "diagnose_internal.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>

namespace demcal::pipelines::detail {

namespace fs = std::filesystem;

namespace {

Diagnosis::AddedEffect added_effect(const DiagnosisRun& run, const std::string& folder) {
  const EffectCandidate& c = *chosen_candidate(run.d);
  return {c.effect, c.target, fitted_effect_parameters(c, run.d), run.d.error_before, c.error, folder,
          run.d.frequency.verdict};
}

// The next step: the model of `run`'s chosen effect as the base, its fit as the base fit, the
// effects in neither model as the candidates; null when no effect is left or the budget is spent.
std::unique_ptr<DiagnosisRun> next_step(const DiagnosisRun& run, const std::vector<std::string>& in_model,
                                        const fs::path& folder) {
  const EffectCandidate& c = *chosen_candidate(run.d);
  const ExtendedModel& m = run.models.at(c.effect);
  const auto& best = run.best_sets.at(c.effect);
  DiagnoseOptions options = run.options;
  options.out = folder.string();
  options.result.clear();
  options.effects.clear();
  for (const auto* e : run.effects)
    if (std::find(in_model.begin(), in_model.end(), e->name) == in_model.end()) options.effects.push_back(e->name);
  if (options.effects.empty()) return nullptr;
  if (options.max_simulations > 0) {
    options.max_simulations -= run.runner.simulations();
    if (options.max_simulations < 4L * run.config.optimiser.population) return nullptr;
  }
  // the space the effect was calibrated in: the base parameters' and the effect's own
  CampaignConfig config = m.config;
  config.space = extended_space(m, run.config, run.d.base_params, run.options);
  fs::create_directories(folder);
  auto next = std::make_unique<DiagnosisRun>(config, options);
  next->per_candidate = run.per_candidate;
  next->d.base_params = c.params;
  next->d.base_fitness = c.fitness;
  next->base_params = best;
  return next;
}

}  // namespace

void add_further_effects(DiagnosisRun& run) {
  Diagnosis& d = run.d;
  if (d.outcome != DiagnosisOutcome::missing_effect) return;
  d.added = {added_effect(run, "")};
  std::vector<std::string> in_model = {d.chosen.front()};
  std::vector<std::unique_ptr<DiagnosisRun>> steps;  // each step's models stay for the next
  const DiagnosisRun* last = &run;
  while (run.options.max_effects == 0 || static_cast<int>(in_model.size()) < run.options.max_effects) {
    std::string name;
    for (const auto& e : in_model) name += (name.empty() ? "with-" : "+") + e;
    const fs::path folder = fs::path(run.options.out) / name;
    auto next = next_step(*last, in_model, folder);
    if (!next) break;
    const auto start = std::chrono::steady_clock::now();
    progress(run.options, "the model with " + in_model.back() + " is the new base: diagnosing it for a further effect in " +
                              folder.string());
    diagnose_from_base(*next);
    finish_diagnosis(*next, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    run.runner.add_runs_of(next->runner);
    const Diagnosis& step = next->d;
    if (step.outcome != DiagnosisOutcome::missing_effect) {
      add_note(d, " With " + in_model.back() + " added, the diagnosis ran again on the extended model (" +
                      folder.string() + "): " + step.headline);
      break;
    }
    d.added.push_back(added_effect(*next, folder.string()));
    add_note(d, " With " + in_model.back() + " added, the diagnosis ran again on the extended model (" +
                    folder.string() + "): " + step.conclusion);
    in_model.push_back(step.chosen.front());
    d.chosen.push_back(step.chosen.front());
    d.error_after = step.error_after;
    last = next.get();
    steps.push_back(std::move(next));
  }
  if (d.added.size() > 1) {
    std::string effects, errors = format_number(d.error_before, 3), shares;
    for (const auto& a : d.added) {
      effects += (effects.empty() ? "" : "; ") + a.effect + (a.target.empty() ? "" : " at " + a.target) + ": " + a.parameters;
      errors += " → " + format_number(a.error_after, 3);
      if (std::isfinite(a.frequency)) shares += (shares.empty() ? "" : ", ") + percent(a.frequency);
    }
    d.headline = "Missing " + std::to_string(d.added.size()) + " effects: " + effects + "; force error " + errors +
                 " N against " + format_number(run.noise, 3) + " N of noise" +
                 (shares.empty() ? "" : "; each step's choice reached by " + shares + " of its resamples") + ".";
  }
}

}  // namespace demcal::pipelines::detail
