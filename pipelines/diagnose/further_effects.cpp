// Stage 8 of the diagnosis: after an effect is accepted, the model with it becomes the base (its
// fit the base fit, the effects not yet in it the candidates) and stages 2 to 7 run again, until no
// further effect passes or --max-effects is reached. Each step's diagnosis.json and report.md are
// in a folder of its own; the diagnosis lists the effects added with the error at each step.
#include "diagnose_internal.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <memory>

namespace demcal::pipelines::detail {

namespace fs = std::filesystem;

namespace {

Diagnosis::AddedEffect added_effect(const DiagnosisRun& run, const EffectCandidate& c, const std::string& folder,
                                    bool tentative) {
  return {c.effect, c.target, fitted_effect_parameters(c, run.d), run.d.error_before, c.error, folder,
          tentative ? Diagnosis::kNaN : run.d.frequency.verdict, tentative, c.bounds};
}

// The next step: the model of `c` (an effect of `run`) as the base, its fit as the base fit, the
// effects in neither model as the candidates; null when no effect is left or the budget is spent.
std::unique_ptr<DiagnosisRun> next_step(const DiagnosisRun& run, const EffectCandidate& c,
                                        const std::vector<std::string>& in_model, const fs::path& folder) {
  const ExtendedModel& m = run.models.at(c.effect);
  const auto& best = run.best_sets.at(c.effect);
  DiagnoseOptions options = run.options;
  options.out = folder.string();
  options.result.clear();
  options.effects.clear();
  options.tentative_effect = false;  // a tentative effect is the first step's alone
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
  next->earlier_archives = run.earlier_archives;
  next->earlier_archives.push_back(diagnosis_archive(run.options));
  next->d.base_params = c.params;
  next->d.base_fitness = c.fitness;
  next->base_params = best;
  // the added effect's searches evaluated the new base's space: their best sets of other regions
  // start the next candidates' searches too
  if (const auto searched = run.searched.find(c.effect); searched != run.searched.end())
    next->d.further_starts =
        further_start_sets(c.params, searched->second, config.space, options.candidate_starts - 1, options.start_separation);
  return next;
}

// An effect of the model with several: its registry entry, targets and the structure's scales its
// ranges were resolved with (those of the step that added it), and its fit.
struct ModelEffect {
  const dem::Effect* effect = nullptr;
  std::vector<std::string> targets;
  dem::ResponseScales scales;
  const EffectCandidate* fit = nullptr;
};

ModelEffect model_effect(const Diagnosis& step) {
  const EffectCandidate* c = chosen_candidate(step);
  ModelEffect e;
  e.effect = &dem::find_effect(c->effect);
  if (!c->target.empty()) e.targets = {c->target};
  e.scales.peak_normal_stress = std::isfinite(step.peak_normal_stress) ? step.peak_normal_stress : 0;
  e.scales.start_normal_stress = std::isfinite(step.start_normal_stress) ? step.start_normal_stress : 0;
  e.fit = c;
  return e;
}

// The base model of `run` with `effects` switched on in order (none: the base alone), calibrated
// from `full` (the complete set of the model with every effect: the start, and the caps) into
// `folder`, its fit judged on the grid of `with_all`. The fit's fields as calibrate_candidate sets
// them (its complete set into `best_set`); reason set where it failed. `quiet`: no line per round
// of its search (one of several side by side).
EffectCandidate fit_with(DiagnosisRun& run, const std::vector<ModelEffect>& effects,
                         const std::map<std::string, double>& full, const std::vector<ChannelResidual>& with_all,
                         const fs::path& folder, std::map<std::string, double>& best_set, bool quiet = false) {
  CampaignConfig config = run.config;
  for (std::size_t i = 0; i + 1 < effects.size(); ++i) {
    const ExtendedModel m = extend(config, *effects[i].effect, effects[i].targets, effects[i].scales,
                                   folder / ("model-" + std::to_string(i + 1)));
    CampaignConfig next = m.config;
    next.space = extended_space(m, config, full, run.options);
    config = std::move(next);
  }
  ExtendedModel m;
  m.config = config;
  if (!effects.empty()) {
    const ModelEffect& last = effects.back();
    m = extend(config, *last.effect, last.targets, last.scales, folder / "model");
  }
  EffectCandidate c;
  c.effect = effects.empty() ? "" : effects.back().effect->name;
  c.target = m.target;
  c.tried = true;
  const long budget = run.within_budget(run.per_candidate);
  if (budget < 2 * run.config.optimiser.population) {
    c.reason = "over the simulation budget";
    return c;
  }
  DiagnoseOptions options = run.options;
  options.progress = options.progress && !quiet;
  try {
    calibrate_candidate(c, best_set, m, config, full, options, budget, folder, full, with_all, run.runner);
  } catch (const std::exception& ex) {
    c.reason = std::string("its calibration failed: ") + ex.what();
  }
  return c;
}

// "effect at target: parameters" of each effect of `effects` at the values of `params`.
std::string effects_text(const std::vector<ModelEffect>& effects, const std::map<std::string, double>& params,
                         const Diagnosis& base) {
  std::string text;
  for (const auto& e : effects) {
    EffectCandidate c;
    c.effect = e.effect->name;
    c.params = params;
    // the ranges of the step that added it, where they hold the re-fitted value
    for (const auto& b : e.fit->bounds) {
      const auto value = params.find(b.name);
      if (value != params.end() && !(value->second < b.lower) && !(value->second > b.upper)) c.bounds.push_back(b);
    }
    text += (text.empty() ? "" : "; ") + c.effect + (e.targets.empty() ? "" : " at " + e.targets.front()) + ": " +
            fitted_effect_parameters(c, base);
  }
  return text;
}

// The outcome, conclusion (conclude_on_base_alone) and headline where the base model alone,
// re-fitted from `effect`'s fit (its error in d.error_after), does as well: what the effect gained
// was the base parameters' search, not the effect. `errors`: the error of each step before, "492 → 331".
void settle_on_base_alone(Diagnosis& d, const DiagnosisRun& run, const std::string& effect, const std::string& why,
                          const std::string& errors) {
  const std::string settled = "the base model re-fitted from the " + effect + " fit reaches " +
                              format_number(d.error_after, 3) + " N, so " + why;
  conclude_on_base_alone(d, settled, floor_of(d, run.options), run.per_candidate);
  d.headline = std::string(d.outcome == DiagnosisOutcome::unexplained ? "No effect found: " : "No effect needed: ") +
               settled + "; force error " + errors + " → " + format_number(d.error_after, 3) + " N against " +
               format_number(run.noise, 3) + " N of noise.";
}

// The level (N) at which removal_criteria calls a fit without an effect explained: step 2's.
double explained_level(const DiagnosisRun& run) { return run.options.noise_level_ratio * floor_of(run.d, run.options); }

// Why a removal check found an effect no longer needed (removal_criteria), for the verdict; `effect`:
// how the verdict names it ("it", "shear-stiffening, the closest fit,").
std::string not_needed_because(const Diagnosis::RemovalCheck& check, double evidence, const std::string& effect) {
  if (check.criterion > -evidence)
    return "removing " + effect + " costs no evidence: criterion " + format_number(check.criterion, 3);
  return "the fit without " + effect + " is already explained: " + format_number(check.error_without, 3) +
         " N against the " + format_number(check.explained_level, 3) +
         " N below which a base fit needs no effect; criterion " + format_number(check.criterion, 3);
}

// The removal check of the effects added (Diagnosis::removal_checks): each of `effects` left out in
// turn, the model with the others (the first alone: the base) calibrated again from the fit with all
// of them (`full`, its residuals `with_all`); the one whose removal costs least is dropped when it is
// no longer needed (removal_criteria), and the verdict says so with the error without it (after
// `errors`, the errors of the steps before: "492 → 331 → 133"). One pass: a dropped effect's
// partners are not checked again.
void check_removals(DiagnosisRun& run, const std::vector<ModelEffect>& effects, const std::map<std::string, double>& full,
                    const std::vector<ChannelResidual>& with_all, const std::string& errors) {
  Diagnosis& d = run.d;
  std::vector<EffectCandidate> without(effects.size());
  std::vector<std::map<std::string, double>> sets(effects.size());
  std::vector<fs::path> folders;
  std::vector<std::function<void()>> tasks;  // the models without each effect, side by side without a total budget
  const bool together = run.options.max_simulations <= 0;
  const bool quiet = run.runner.runs_together(effects.size(), together);
  for (std::size_t i = 0; i < effects.size(); ++i) {
    folders.push_back(fs::path(run.options.out) / ("without-" + effects[i].effect->name));
    progress(run.options, "removal check: the model without " + effects[i].effect->name + " calibrated in " +
                              folders.back().string());
    tasks.push_back([&, i] {
      std::vector<ModelEffect> others = effects;
      others.erase(others.begin() + static_cast<std::ptrdiff_t>(i));
      without[i] = fit_with(run, others, full, with_all, folders[i], sets[i], quiet);
    });
  }
  run.runner.side_by_side(tasks, together);
  std::vector<std::vector<ChannelResidual>> residuals;
  std::vector<int> parameters;
  const double explained = explained_level(run);
  for (std::size_t i = 0; i < effects.size(); ++i) {
    residuals.push_back(std::isfinite(without[i].error) ? without[i].residuals : std::vector<ChannelResidual>{});
    parameters.push_back(effects[i].fit->effect_parameters);
    d.removal_checks.push_back(
        {effects[i].effect->name, Diagnosis::kNaN, without[i].error, folders[i].string(), false, explained});
  }
  int drop = -1;
  const std::vector<double> criteria =
      removal_criteria(with_all, residuals, parameters, run.options.evidence, drop, explained);
  for (std::size_t i = 0; i < criteria.size(); ++i) d.removal_checks[i].criterion = criteria[i];
  if (drop < 0) {
    std::string costs;
    for (std::size_t i = 0; i < criteria.size(); ++i)
      costs += (costs.empty() ? "" : ", ") + effects[i].effect->name + " " + format_number(-criteria[i], 3);
    add_note(d, " Each effect still pays for its parameters: removing one raises the criterion by " + costs + ".");
    return;
  }
  const auto k = static_cast<std::size_t>(drop);
  Diagnosis::RemovalCheck& dropped = d.removal_checks[k];
  dropped.dropped = true;
  std::erase(d.chosen, dropped.effect);
  std::vector<ModelEffect> kept = effects;
  kept.erase(kept.begin() + drop);
  d.error_after = without[k].error;
  const std::string why =
      dropped.effect + " dropped again (" + not_needed_because(dropped, run.options.evidence, "it") + ")";
  const std::string against = " N against " + format_number(run.noise, 3) + " N of noise";
  if (kept.empty()) {
    settle_on_base_alone(d, run, dropped.effect, why, errors);
  } else {
    d.headline = std::string(kept.size() == 1 ? "Missing: " : "Missing " + std::to_string(kept.size()) + " effects: ") +
                 effects_text(kept, sets[k], run.d) + "; force error " + errors + " → " +
                 format_number(d.error_after, 3) + against + ", with " + why + ".";
  }
  add_note(d, " Removal check: " + why + "; the model without it, in " + dropped.folder + ", fits to " +
                  format_number(d.error_after, 3) + " N.");
}

// The same for the steps of several effects added one after another (the first step's run first).
void check_removals(DiagnosisRun& run, const std::vector<const DiagnosisRun*>& steps) {
  std::vector<ModelEffect> effects;
  for (const auto* step : steps) effects.push_back(model_effect(step->d));
  std::string errors = format_number(run.d.error_before, 3);
  for (const auto& a : run.d.added) errors += " → " + format_number(a.error_after, 3);
  check_removals(run, effects, steps.back()->best_sets.at(effects.back().fit->effect), effects.back().fit->residuals,
                 errors);
}

// Step 8a, where no effect passes alone and the base misses the curves: the pair search
// (search_pairs); where its pair of lowest criterion passes against the base (both effects'
// parameters counted, the effective points of every fit, reached by --verdict-share of the
// resamples), both effects are added at its fit, each bounded in the model with both, and the removal
// check re-fits each without the other. True when a pair was added.
bool add_pair(DiagnosisRun& run) {
  Diagnosis& d = run.d;
  const DiagnoseOptions& o = run.options;
  if (o.pair_rounds <= 0 || !o.removal_check || o.max_effects == 1 || d.outcome != DiagnosisOutcome::unexplained)
    return false;
  progress(o, "no effect passes alone: every pair of the candidates searched together");
  std::vector<PairFit> fits = search_pairs(run);
  PairSearch& report = d.pair_search;
  if (report.rounds == 0) return false;
  const std::string searched = " Pairs of effects searched together (" + std::to_string(report.pairs.size()) +
                               (report.pairs.size() == 1 ? " pair, " : " pairs, ") + std::to_string(report.rounds) +
                               " rounds, " + std::to_string(report.simulations) + " simulations): ";
  std::vector<const std::vector<ChannelResidual>*> all = {&d.base_residuals};
  for (const auto& c : d.candidates)
    if (c.tried && c.residuals.size() == d.base_residuals.size()) all.push_back(&c.residuals);
  for (const auto& f : fits)
    if (f.fit.residuals.size() == d.base_residuals.size()) all.push_back(&f.fit.residuals);
  const std::vector<double> points = common_effective_points(all);
  PairFit* best = nullptr;
  for (auto& f : fits) {
    if (f.fit.residuals.size() != d.base_residuals.size()) continue;
    f.fit.score = information_criterion_change(d.base_residuals, f.fit.residuals, f.fit.effect_parameters, points);
    report.pairs[f.pair].error = f.fit.error;
    report.pairs[f.pair].criterion = f.fit.score;
    if (!(f.fit.error < d.error_before) || check_held_out(f.fit, d, o).spoils) continue;
    if (best == nullptr || f.fit.score < best->fit.score) best = &f;
  }
  if (best == nullptr) {
    const auto closest = std::min_element(report.pairs.begin(), report.pairs.end(), [](const auto& a, const auto& b) {
      return !(b.best_run_error <= a.best_run_error);  // NaN last
    });
    add_note(d, searched + (fits.empty() ? "no pair's best run fitted better than both of its effects alone (the closest, " +
                                               effect_at(closest->effects[0], closest->targets[0]) + " and " +
                                               effect_at(closest->effects[1], closest->targets[1]) + ", " +
                                               format_number(closest->best_run_error, 3) + " N)."
                                         : "no pair's fit lowered the error without spoiling the held-out data."));
    return false;
  }
  const std::string pair_text =
      effect_at(best->first->effect, best->first->target) + " and " + effect_at(best->second->effect, best->second->target);
  report.effects = {best->first->effect, best->second->effect};
  report.params = best->set;
  report.rerun_errors = best->fit.rerun_errors;
  report.error = best->fit.error;
  report.criterion = best->fit.score;
  std::vector<std::vector<ChannelResidual>> base_runs;
  for (const auto& e : run.base_runs) base_runs.push_back(e.residuals);
  report.frequency = pair_frequency(base_runs, best->fit.run_residuals, best->fit.effect_parameters, points, o.evidence,
                                    o.resamples, static_cast<std::uint64_t>(run.config.optimiser.seed));
  // without resamples (--resamples 0) the criterion decides alone
  report.accepted = best->fit.score < -o.evidence && !(report.frequency < o.verdict_share);
  const auto alone = [](const EffectCandidate& c) {
    return c.effect + (c.tried ? " alone " + format_number(c.error, 3) + " N" : " not calibrated alone");
  };
  const std::string found = pair_text + " together fit to " + format_number(best->fit.error, 3) + " N (" +
                            alone(*best->first) + ", " + alone(*best->second) + "), criterion " +
                            format_number(best->fit.score, 3) + " against the base" +
                            (std::isfinite(report.frequency) ? ", passing in " + percent(report.frequency) + " of " +
                                                                   std::to_string(o.resamples) + " resamples"
                                                             : "");
  if (!report.accepted) {
    add_note(d, searched + "the closest pair, " + found + ": short of passing.");
    return false;
  }
  // each effect at the pair's fit, bounded in the model with both (the others re-fitted)
  std::vector<EffectCandidate> members = {*best->first, *best->second};
  const std::vector<const ExtendedModel*> own_models = {best->first_model, best->second_model};
  const dem::ResponseScales scales{std::isfinite(d.peak_normal_stress) ? d.peak_normal_stress : 0,
                                   std::isfinite(d.start_normal_stress) ? d.start_normal_stress : 0};
  std::vector<ModelEffect> effects;
  for (std::size_t k = 0; k < members.size(); ++k) {
    EffectCandidate& m = members[k];
    const ExtendedModel& own = *own_models[k];
    m.effect_parameters = static_cast<int>(own.parameter_names.size());
    m.params = best->set;
    m.residuals = best->fit.residuals;
    m.error = best->fit.error;
    m.bounds.clear();
    if (o.parameter_bounds) {
      ExtendedModel model = best->model;
      model.parameter_names = own.parameter_names;
      model.parameters = own.parameters;
      progress(o, "checking how tightly the data pin the parameters of " + m.effect + " in the model with " + pair_text);
      bound_effect_parameters(m, model, best->set, run.base.residuals, points, run.runner, o);
    }
  }
  for (const auto& m : members) {
    ModelEffect e;
    e.effect = &dem::find_effect(m.effect);
    if (!m.target.empty()) e.targets = {m.target};
    e.scales = scales;
    e.fit = &m;
    effects.push_back(e);
  }
  d.added.clear();
  for (const auto& m : members)
    d.added.push_back({m.effect, m.target, fitted_effect_parameters(m, d), d.error_before, best->fit.error, "",
                       report.frequency, false, m.bounds});
  d.chosen = report.effects;
  d.outcome = DiagnosisOutcome::missing_effect;
  d.error_after = best->fit.error;
  const std::string errors = format_number(d.error_before, 3) + " → " + format_number(d.error_after, 3);
  d.headline = "Missing 2 effects, found together: " + effects_text(effects, best->set, d) + "; force error " + errors +
               " N against " + format_number(run.noise, 3) + " N of noise; neither passed alone" +
               (std::isfinite(report.frequency) ? "; the pair passes in " + percent(report.frequency) + " of " +
                                                      std::to_string(o.resamples) + " resamples"
                                                : "") +
               ".";
  add_note(d, searched + found + ": both added.");
  check_removals(run, effects, best->set, best->fit.residuals, errors);
  return true;
}

}  // namespace

void check_undecided_leader(DiagnosisRun& run) {
  Diagnosis& d = run.d;
  if (d.outcome != DiagnosisOutcome::undecided || !run.options.removal_check) return;
  const EffectCandidate* leader = nullptr;
  for (const auto& c : d.candidates)
    if (c.tried && std::isfinite(c.error) && run.best_sets.count(c.effect) && (leader == nullptr || c.error < leader->error))
      leader = &c;
  if (leader == nullptr) return;
  const fs::path folder = fs::path(run.options.out) / ("without-" + leader->effect);
  progress(run.options, "removal check of the undecided verdict's closest fit: the base model re-fitted from the " +
                            leader->effect + " fit in " + folder.string());
  std::map<std::string, double> set;
  const EffectCandidate without = fit_with(run, {}, run.best_sets.at(leader->effect), leader->residuals, folder, set);
  int drop = -1;
  const double explained = explained_level(run);
  const std::vector<double> criterion = removal_criteria(
      leader->residuals, {std::isfinite(without.error) ? without.residuals : std::vector<ChannelResidual>{}},
      {leader->effect_parameters}, run.options.evidence, drop, explained);
  d.removal_checks.push_back({leader->effect, criterion.front(), without.error, folder.string(), drop == 0, explained});
  if (drop != 0) {
    add_note(d, " Removal check of the closest fit: the base model re-fitted from the " + leader->effect + " fit, in " +
                    folder.string() + ", reaches " + format_number(without.error, 3) + " N, criterion " +
                    format_number(criterion.front(), 3) + " against " + leader->effect + "'s fit: the effects stay undecided.");
    return;
  }
  d.error_after = without.error;
  const std::string why = "the undecided effects are not needed (" +
                          not_needed_because(d.removal_checks.back(), run.options.evidence,
                                             leader->effect + ", the closest fit,") + ")";
  settle_on_base_alone(d, run, leader->effect, why, format_number(d.error_before, 3));
  add_note(d, " Removal check of the closest fit (the conclusion): the base model re-fitted in " + folder.string() +
                  ".");
}

void add_further_effects(DiagnosisRun& run) {
  Diagnosis& d = run.d;
  const EffectCandidate* adding = chosen_candidate(d);
  const bool tentative = adding == nullptr;
  if (tentative) {
    if (add_pair(run)) return;
    const std::string name = tentative_effect(d, run.options);
    if (name.empty() || !run.models.count(name) || !run.best_sets.count(name)) return;
    adding = &*std::find_if(d.candidates.begin(), d.candidates.end(), [&](const auto& c) { return c.effect == name; });
  }
  const EffectCandidate* const first = adding;
  std::vector<std::string> in_model = {adding->effect};
  std::vector<Diagnosis::AddedEffect> added = {added_effect(run, *adding, "", tentative)};
  std::vector<std::unique_ptr<DiagnosisRun>> steps;  // each step's models stay for the next
  const DiagnosisRun* last = &run;
  while (run.options.max_effects == 0 || static_cast<int>(in_model.size()) < run.options.max_effects) {
    std::string name;
    for (const auto& e : in_model) name += (name.empty() ? "with-" : "+") + e;
    const fs::path folder = fs::path(run.options.out) / name;
    auto next = next_step(*last, *adding, in_model, folder);
    if (!next) break;
    const bool from_tentative = steps.empty() && tentative;
    const auto start = std::chrono::steady_clock::now();
    progress(run.options, "the model with " + in_model.back() + " is the new base" +
                              (from_tentative ? " (tentatively: no effect passed alone)" : "") +
                              ": diagnosing it for a further effect in " + folder.string());
    diagnose_from_base(*next);
    finish_diagnosis(*next, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    run.runner.add_runs_of(next->runner);
    const Diagnosis& step = next->d;
    const std::string with = " With " + in_model.back() + " added" +
                             (from_tentative ? " tentatively (it lowers the error to " +
                                                               format_number(adding->error, 3) + " N, criterion change " +
                                                               format_number(adding->score, 3) + ", short of passing alone)"
                                                         : "") +
                             ", the diagnosis ran again on the extended model (" + folder.string() + "): ";
    if (step.outcome != DiagnosisOutcome::missing_effect) {
      add_note(d, with + step.headline);
      break;
    }
    added.push_back(added_effect(*next, *chosen_candidate(step), folder.string(), false));
    add_note(d, with + step.conclusion);
    in_model.push_back(step.chosen.front());
    adding = chosen_candidate(step);
    last = next.get();
    steps.push_back(std::move(next));
  }
  if (tentative) {
    if (added.size() < 2) return;  // it stays only with a further effect that passes beside it
    // never bounded alone: its parameters as the fit with every effect has them, bounded in that
    // model (each moved with the base's and the other effects' parameters re-fitted)
    EffectCandidate with_all = *first;
    with_all.params = adding->params;
    with_all.residuals = adding->residuals;
    with_all.bounds.clear();
    if (run.options.parameter_bounds) {
      const ExtendedModel& own = run.models.at(first->effect);
      ExtendedModel model = last->models.at(adding->effect);
      model.parameter_names = own.parameter_names;
      model.parameters = own.parameters;
      progress(run.options, "checking how tightly the data pin the parameters of " + first->effect +
                                ", added tentatively, in the model with every effect");
      bound_effect_parameters(with_all, model, last->best_sets.at(adding->effect), last->base.residuals,
                              last->effective_points, run.runner, run.options);
    }
    added.front().parameters = fitted_effect_parameters(with_all, run.d);
    added.front().bounds = with_all.bounds;
    conclude_tentative(d, *first);
  }
  d.added = added;
  d.chosen = in_model;
  d.outcome = DiagnosisOutcome::missing_effect;
  if (!steps.empty()) d.error_after = steps.back()->d.error_after;
  std::vector<const DiagnosisRun*> chain = {&run};
  for (const auto& step : steps) chain.push_back(step.get());
  if (d.added.size() > 1) {
    std::string effects, errors = format_number(d.error_before, 3), shares;
    for (const auto& a : d.added) {
      effects += (effects.empty() ? "" : "; ") + effect_at(a.effect, a.target) + ": " + a.parameters;
      errors += " → " + format_number(a.error_after, 3);
      if (std::isfinite(a.frequency)) shares += (shares.empty() ? "" : ", ") + percent(a.frequency);
    }
    d.headline = "Missing " + std::to_string(d.added.size()) + " effects: " + effects + "; force error " + errors +
                 " N against " + format_number(run.noise, 3) + " N of noise" +
                 (shares.empty() ? "" : "; each step's choice reached by " + shares + " of its resamples") +
                 (tentative ? "; " + d.added.front().effect + " added tentatively (it did not pass alone)" : "") + ".";
  }
  if (run.options.removal_check) check_removals(run, chain);
}

}  // namespace demcal::pipelines::detail
