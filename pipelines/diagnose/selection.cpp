// Stage 5 of the diagnosis: the candidates' criteria against the base, the verdict (select_effect),
// and further searches of the fits that leave the residual above the noise, after which the verdict
// is taken again.
#include "diagnose_internal.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <set>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using namespace detail;

namespace {

// The chosen effect's finding in a structural engineer's words, from its fitted parameters.
std::string finding(const EffectCandidate& c, const std::map<std::string, double>& base) {
  return dem::describe_fit(dem::find_effect(c.effect), {c.params, base, c.target});
}

}  // namespace

namespace detail {

std::vector<double> score_candidates(Diagnosis& d) {
  std::vector<EffectCandidate*> scored;
  std::vector<const std::vector<ChannelResidual>*> fits = {&d.base_residuals};
  for (auto& c : d.candidates)
    if (c.tried && c.residuals.size() == d.base_residuals.size()) {
      scored.push_back(&c);
      fits.push_back(&c.residuals);
    }
  std::vector<int> from;
  const std::vector<double> points = common_effective_points(fits, &from);
  for (std::size_t i = 0; i < points.size(); ++i) {
    d.effective_points[key_of(d.base_residuals[i])] = points[i];
    d.effective_points_from[key_of(d.base_residuals[i])] =
        from[i] == 0 ? "base" : scored[static_cast<std::size_t>(from[i] - 1)]->effect;
  }
  for (auto* c : scored) c->score = information_criterion_change(d.base_residuals, c->residuals, c->effect_parameters, points);
  return points;
}

double floor_of(const Diagnosis& d, const DiagnoseOptions& options) {
  return error_floor(overall_noise(d.base_residuals), overall(d.scatter), options);
}

std::string base_errors_text(const Diagnosis& d) {
  return "RMS force error " + format_number(d.error_before, 3) + " N, noise about " +
         format_number(overall_noise(d.base_residuals), 3) + " N, simulation scatter about " +
         format_number(overall(d.scatter), 3) + " N";
}

const EffectCandidate* chosen_candidate(const Diagnosis& d) {
  if (d.chosen.empty()) return nullptr;
  for (const auto& c : d.candidates)
    if (c.effect == d.chosen.front()) return &c;
  return nullptr;
}

const EffectCandidate* unexplained_chosen(const Diagnosis& d, const DiagnoseOptions& options) {
  const EffectCandidate* c = d.chosen.size() == 1 ? chosen_candidate(d) : nullptr;
  return c && c->error > options.noise_level_ratio * floor_of(d, options) ? c : nullptr;
}

}  // namespace detail

namespace {

// Each tried candidate judged alone: rejected (with its reason) or, when its criterion falls by
// more than the evidence threshold, it lowers the error and it does not spoil the held-out data,
// passing (into `accepted`); those short of the criterion also go to `short_of_criterion`.
void judge_alone(Diagnosis& d, const DiagnoseOptions& options, std::vector<EffectCandidate*>& accepted,
                 std::vector<EffectCandidate*>& short_of_criterion) {
  for (auto& c : d.candidates) {
    if (!c.tried) continue;
    if (!std::isfinite(c.score)) {
      c.verdict = CandidateVerdict::rejected;
      if (c.reason.empty()) c.reason = "no usable fit";
    } else if (c.score < -options.evidence && c.error < d.error_before) {
      if (const HeldOutCheck check = check_held_out(c, d, options); check.spoils) {
        c.verdict = CandidateVerdict::rejected;
        c.reason = "fits the calibrated curves (criterion change " + format_number(c.score, 3) +
                   ") but spoils the data it was not fitted to, which the base fit reproduces: error there " +
                   format_number(check.base_error, 3) + " -> " + format_number(check.candidate_error, 3) + " N";
      } else {
        accepted.push_back(&c);
      }
    } else {
      c.verdict = CandidateVerdict::rejected;
      c.reason = c.score < -options.evidence
                     ? "the criterion falls (" + format_number(c.score, 3) + ") but the RMS error does not (" +
                           format_number(d.error_before, 3) + " -> " + format_number(c.error, 3) + " N)"
                     : "the fit does not improve enough for its extra parameters (criterion change " +
                           format_number(c.score, 3) + ", needs < -" + format_number(options.evidence, 3) + ")";
      short_of_criterion.push_back(&c);
    }
  }
  std::sort(accepted.begin(), accepted.end(), [](auto* a, auto* b) { return a->score < b->score; });
}

// The passing candidates (best criterion first) that the data cannot tell from the best one, with
// each one's reason (into `tie_reasons`); the others are rejected. A curve fit better by less than
// the noise does not dispute the criterion.
std::vector<EffectCandidate*> tied_with_the_best(const std::vector<EffectCandidate*>& accepted, double noise,
                                                 const DiagnoseOptions& options,
                                                 std::map<const EffectCandidate*, std::string>& tie_reasons) {
  std::vector<EffectCandidate*> tied;
  for (auto* c : accepted) {
    const auto* front = accepted.front();
    if (c->score - front->score < options.tie_margin) {
      tied.push_back(c);
      tie_reasons[c] = "explains the data as well as the other tied effects (criteria within " +
                       format_number(options.tie_margin, 3) + ")";
    } else if (c->error < front->error - noise) {
      // Both pass, the criterion prefers the front and the curves prefer this one by more than the
      // noise (a channel the front fits better outweighs the others, or the front adds fewer
      // parameters): the two measures disagree.
      tied.push_back(c);
      tie_reasons[c] = "passes the criterion less clearly than " + front->effect + " (" + format_number(c->score, 3) +
                       " against " + format_number(front->score, 3) + ") but fits the curves better (error " +
                       format_number(c->error, 3) + " against " + format_number(front->error, 3) + " N)";
    } else {
      c->verdict = CandidateVerdict::rejected;
      c->reason = "explains the data clearly less well than " + front->effect + " (criterion " +
                  format_number(c->score, 3) + " against " + format_number(front->score, 3) + ")";
      if (c->error < front->error)
        c->reason += "; its closer fit of the curves (error " + format_number(c->error, 3) + " against " +
                     format_number(front->error, 3) + " N) is within the noise (" + format_number(noise, 3) + " N)";
    }
  }
  return tied;
}

// One effect passes, and another that does not is as good by one of the two measures: it fits the
// curves better by more than the noise (it adds more parameters, or its gain lies on a channel
// with few independent points), or its criterion is within the tie margin of the passing one's
// while it lowers the error too (the passing one is then preferred no more clearly than between
// two that both pass). The data cannot tell them apart: both tied, and the verdict says so (true).
bool tied_with_a_rival(Diagnosis& d, EffectCandidate* passing, const std::vector<EffectCandidate*>& short_of_criterion,
                       double noise, const DiagnoseOptions& options) {
  std::string rivals;  // each rival with its error, criterion and why it ties
  for (auto* c : short_of_criterion) {
    if (!std::isfinite(c->error)) continue;
    const bool fits_better = c->error < passing->error - noise;
    const bool as_likely = c->score - passing->score < options.tie_margin && c->error < d.error_before;
    if (!fits_better && !as_likely) continue;
    c->verdict = CandidateVerdict::tied;
    c->reason = fits_better ? "fits the curves better than " + passing->effect + " (error " + format_number(c->error, 3) +
                                  " against " + format_number(passing->error, 3) + " N) but does not pass the criterion (" +
                                  format_number(c->score, 3) + ")"
                            : "does not pass the criterion (" + format_number(c->score, 3) + ") but falls short of " +
                                  passing->effect + "'s (" + format_number(passing->score, 3) + ") by less than " +
                                  format_number(options.tie_margin, 3) + ", with the error lowered to " +
                                  format_number(c->error, 3) + " N";
    rivals += (rivals.empty() ? "" : "; ") + c->effect + " (" + format_number(c->error, 3) + " N, criterion " +
              format_number(c->score, 3) + ") " +
              (fits_better ? "comes closer to the curves without passing the criterion"
                           : "falls short of its criterion by less than " + format_number(options.tie_margin, 3));
  }
  if (rivals.empty()) return false;
  passing->verdict = CandidateVerdict::tied;
  passing->reason = "passes the criterion (" + format_number(passing->score, 3) + "), but " + rivals;
  d.chosen.clear();
  d.error_after = d.error_before;
  d.outcome = DiagnosisOutcome::undecided;
  d.verdict = "The data cannot tell which effect is missing: " + passing->effect + " passes the criterion (error " +
              format_number(d.error_before, 3) + " -> " + format_number(passing->error, 3) + " N, criterion " +
              format_number(passing->score, 3) + "), but " + rivals +
              ". Each explains part of the residual, none clearly better (measurement noise about " +
              format_number(noise, 3) + " N); the model is not extended.";
  return true;
}

// The verdict where no candidate passes: "no effect found" when the base fit misses the curves by
// far more than the noise (the model lacks something, which "no effect needed" would hide).
void no_effect_verdict(Diagnosis& d, const std::vector<EffectCandidate*>& short_of_criterion,
                       const DiagnoseOptions& options) {
  d.chosen.clear();
  d.error_after = d.error_before;
  const double floor = floor_of(d, options);
  const std::string errors = base_errors_text(d);
  const EffectCandidate* closest = nullptr;
  for (const auto* c : short_of_criterion)
    if (closest == nullptr || c->error < closest->error) closest = c;
  if (d.error_before > kUnexplainedRatio * floor) {
    d.outcome = DiagnosisOutcome::unexplained;
    d.verdict = "No effect found: the base fit misses the curves by " + format_number(d.error_before / floor, 2) +
                " x the noise and scatter combined (" + errors + "), so the model lacks something, but ";
    if (closest != nullptr) {
      d.verdict += "none of the candidate effects explains enough of it for its extra parameters (closest: " + closest->effect +
                   ", " + format_number(d.error_before, 3) + " -> " + format_number(closest->error, 3) + " N, criterion " +
                   format_number(closest->score, 3) + "). The missing effect is not among those tried, or their searches "
                   "did not reach its fit.";
    } else {
      std::string reasons;
      for (const auto& c : d.candidates)
        if (!c.reason.empty()) reasons += (reasons.empty() ? "" : "; ") + c.effect + ": " + c.reason;
      d.verdict += "no candidate effect could be fitted (" + (reasons.empty() ? std::string("none was tried") : reasons) + ").";
    }
    d.verdict += unfitted_data_note(d);
  } else {
    d.outcome = DiagnosisOutcome::no_effect_needed;
    d.verdict = "No effect needed: none of the candidate effects explains the residual better than its extra "
                "parameters cost (" + errors + ")." + unfitted_data_note(d);
  }
}

}  // namespace

void select_effect(Diagnosis& d, const DiagnoseOptions& options) {
  std::vector<EffectCandidate*> accepted, short_of_criterion;
  judge_alone(d, options, accepted, short_of_criterion);
  const double noise = overall_noise(d.base_residuals);
  std::map<const EffectCandidate*, std::string> tie_reasons;
  const std::vector<EffectCandidate*> tied = tied_with_the_best(accepted, noise, options, tie_reasons);
  if (tied.size() == 1 && tied_with_a_rival(d, tied.front(), short_of_criterion, noise, options)) return;
  if (tied.size() == 1) {
    auto* c = tied.front();
    c->verdict = CandidateVerdict::accepted;
    c->reason = "criterion change " + format_number(c->score, 3) + "; error " + format_number(d.error_before, 3) + " -> " +
                format_number(c->error, 3) + " N";
    if (std::isfinite(d.held_out_error))
      c->reason += "; on data not fitted " + format_number(d.held_out_error, 3) + " -> " + format_number(c->held_out_error, 3) + " N";
    d.chosen = {c->effect};
    d.error_after = c->error;
    d.outcome = DiagnosisOutcome::missing_effect;
    d.verdict = "The base model misses one effect: " + finding(*c, d.base_params) + ". Adding " + c->effect +
                " lowers the RMS force error from " + format_number(d.error_before, 3) + " N to " +
                format_number(c->error, 3) + " N (measurement noise about " + format_number(noise, 3) + " N).";
  } else if (tied.size() > 1) {
    std::string names;
    for (auto* c : tied) {
      c->verdict = CandidateVerdict::tied;
      c->reason = tie_reasons[c];
      names += (names.empty() ? "" : " or ") + c->effect;
    }
    d.chosen.clear();
    d.error_after = d.error_before;
    d.outcome = DiagnosisOutcome::undecided;
    d.verdict = "The data cannot tell which effect is missing: " + names +
                " explain the residual equally well. Another test (a further channel, or a test of the same structure) "
                "is needed to choose; the model is not extended.";
  } else {
    no_effect_verdict(d, short_of_criterion, options);
  }
}

const EffectCandidate* detail::unexplained_lead(const Diagnosis& d, const DiagnoseOptions& options) {
  const EffectCandidate* best = nullptr;
  for (const auto& c : d.candidates) {
    if (!c.tried || !(c.score < 0) || !(c.error < d.error_before) || check_held_out(c, d, options).spoils) continue;
    if (best == nullptr || c.score < best->score) best = &c;
  }
  return best;
}

std::vector<std::string> candidates_to_search_further(const Diagnosis& d, const DiagnoseOptions& options) {
  const double floor = floor_of(d, options);
  const double explained = options.noise_level_ratio * floor;
  const auto open = [&](const EffectCandidate& c) { return c.tried && c.continued.simulations == 0 && c.error > explained; };
  // an accepted fit above the level: its own search first
  for (const auto& c : d.candidates)
    if (c.verdict == CandidateVerdict::accepted && open(c)) return {c.effect};
  // an accepted fit at the level explains the residual; so does a base fit near it
  const bool explained_fit = std::any_of(d.candidates.begin(), d.candidates.end(), [&](const EffectCandidate& c) {
    return c.verdict == CandidateVerdict::accepted && !(c.error > explained);
  });
  if (explained_fit) return {};
  const bool unexplained_base = d.error_before > kUnexplainedRatio * floor;
  std::vector<std::string> names;
  for (const auto& c : d.candidates) {
    if (!open(c) || c.verdict == CandidateVerdict::accepted) continue;
    const bool passes = c.score < -options.evidence && !check_held_out(c, d, options).spoils;
    if (c.verdict == CandidateVerdict::tied || (unexplained_base && passes)) names.push_back(c.effect);
  }
  // no contender and nothing accepted on an unexplained residual: the lead, the fit a tentative
  // effect would start from, once, before any other search has gone on
  const bool none_accepted = std::none_of(d.candidates.begin(), d.candidates.end(),
                                          [](const EffectCandidate& c) { return c.verdict == CandidateVerdict::accepted; });
  const bool none_continued = std::none_of(d.candidates.begin(), d.candidates.end(),
                                           [](const EffectCandidate& c) { return c.continued.simulations > 0; });
  if (names.empty() && unexplained_base && none_accepted && none_continued)
    if (const EffectCandidate* lead = unexplained_lead(d, options); lead != nullptr && open(*lead))
      names.push_back(lead->effect);
  return names;
}

std::string tentative_effect(const Diagnosis& d, const DiagnoseOptions& options) {
  if (!options.tentative_effect || !options.removal_check || options.max_effects == 1 ||
      d.outcome != DiagnosisOutcome::unexplained)
    return "";
  const EffectCandidate* best = unexplained_lead(d, options);
  return best == nullptr ? "" : best->effect;
}

void conclude_tentative(Diagnosis& d, const EffectCandidate& first) {
  const std::string alone = "No effect passed alone (base error " + format_number(d.error_before, 3) + " N); " +
                            first.effect + ", of lowest criterion among those that lower it (to " +
                            format_number(first.error, 3) + " N, criterion change " + format_number(first.score, 3) +
                            "), was added tentatively and its model diagnosed for a further effect (the notes).";
  if (d.verdict.rfind(d.conclusion, 0) == 0) d.verdict = alone + d.verdict.substr(d.conclusion.size());
  d.conclusion = alone;
}

void conclude_on_base_alone(Diagnosis& d, const std::string& settled, double floor, long per_candidate) {
  d.chosen.clear();
  d.outcome =
      d.error_after > kUnexplainedRatio * floor ? DiagnosisOutcome::unexplained : DiagnosisOutcome::no_effect_needed;
  d.frequency.verdict = d.frequency.none;
  if (d.outcome == DiagnosisOutcome::no_effect_needed) {
    const std::string advice = more_search_note(d.advised_candidate_simulations, per_candidate);
    d.advised_candidate_simulations = 0;
    if (!advice.empty()) {
      if (const auto at = d.verdict.find(advice); at != std::string::npos) d.verdict.erase(at, advice.size());
      std::erase(d.notes, advice.substr(advice.find_first_not_of(' ')));
    }
  }
  if (d.conclusion.empty() || d.verdict.rfind(d.conclusion, 0) != 0) return;
  const std::string before = "Before the removal check: " + d.conclusion;
  const std::string conclusion =
      (d.outcome == DiagnosisOutcome::unexplained ? "No effect found: " : "No effect needed: ") + settled + ".";
  d.verdict = conclusion + " " + before + d.verdict.substr(d.conclusion.size());
  d.notes.insert(d.notes.begin(), before);
  d.conclusion = conclusion;
}

double error_floor(double noise, double scatter, const DiagnoseOptions& options) {
  if (!std::isfinite(scatter)) return noise;
  return std::hypot(noise, std::min(scatter, options.scatter_floor_ratio * noise));
}

std::vector<std::string> held_out_checks(const Diagnosis& d, const DiagnoseOptions& options) {
  std::vector<std::string> keys;
  for (const auto& [key, rms] : d.held_out_rms) {
    const auto noise = d.held_out_noise.find(key);
    if (noise != d.held_out_noise.end() && std::isfinite(noise->second) &&
        rms <= options.held_out_ratio * noise->second)
      keys.push_back(key);
  }
  return keys;
}

HeldOutCheck check_held_out(const EffectCandidate& c, const Diagnosis& d, const DiagnoseOptions& options) {
  HeldOutCheck check;
  double base = 0, candidate = 0, noise = 0;
  bool reached = true;
  for (const auto& key : held_out_checks(d, options)) {
    ++check.channels;
    base += d.held_out_rms.at(key) * d.held_out_rms.at(key);
    noise += d.held_out_noise.at(key) * d.held_out_noise.at(key);
    const auto found = c.held_out_rms.find(key);
    if (found == c.held_out_rms.end() || !std::isfinite(found->second)) reached = false;
    else candidate += found->second * found->second;
  }
  if (check.channels == 0) return check;
  check.base_error = std::sqrt(base / check.channels);
  check.candidate_error = reached ? std::sqrt(candidate / check.channels) : Diagnosis::kNaN;
  check.spoils = !reached || check.candidate_error > check.base_error +
                                 std::max(std::sqrt(noise / check.channels), options.held_out_tolerance * check.base_error);
  return check;
}

namespace detail {
namespace {

// The verdict where the base fit is already within the noise: every effect listed, none tried.
void nothing_to_explain(DiagnosisRun& run) {
  Diagnosis& d = run.d;
  for (const auto* e : run.effects) {
    EffectCandidate c;
    c.effect = e->name;
    c.reason = "the base fit is already within the noise and the simulation's scatter";
    d.candidates.push_back(c);
  }
  run.effective_points = score_candidates(d);
  d.error_after = d.error_before;
  d.outcome = DiagnosisOutcome::no_effect_needed;
  d.verdict = "No effect needed: the base fit is already within the measurement noise and the simulation's own "
              "scatter (RMS force error " + format_number(d.error_before, 3) + " N; noise about " + format_number(run.noise, 3) +
              " N, scatter of the simulated curve about " + format_number(run.scatter, 3) + " N)." + unfitted_data_note(d);
}

// A further search of `name`'s fit, of `budget` simulations with another seed, whose surrogate
// trains on the first search's runs; the better fit is kept (c.continued says which). Writes only
// `name`'s candidate, best set and searched sets (whose entries exist), so that several run side by
// side; `quiet`: no line per round of its search.
void search_further(DiagnosisRun& run, const std::string& name, long budget, double explained, bool quiet) {
  DiagnoseOptions options = run.options;
  auto& c = *std::find_if(run.d.candidates.begin(), run.d.candidates.end(), [&](const auto& x) { return x.effect == name; });
  const fs::path folder = fs::path(options.out) / "candidates" / (c.effect + "-continued");
  progress(options, c.effect + "'s fit stays above the noise and scatter (" + format_number(c.error, 3) + " against " +
                        format_number(explained, 3) + " N): its search continued (" + std::to_string(budget) +
                        " simulations) in " + folder.string());
  options.progress = options.progress && !quiet;
  const ContinuedSearch continued =
      continue_search(c, run.best_sets.at(c.effect), run.models.at(c.effect), run.config, run.d.base_params, options,
                      budget, folder, run.base.residuals, run.runner, c.effect, &run.searched.at(c.effect));
  c.continued = continued;
  if (quiet)
    progress(run.options, c.effect + "'s continued search: error " + format_number(continued.error_found, 3) + " N after " +
                              std::to_string(continued.simulations) + " simulations" + (continued.kept ? ", kept" : ""));
}

}  // namespace

void select_and_search_further(DiagnosisRun& run) {
  if (run.at_noise) return nothing_to_explain(run);
  const DiagnoseOptions& options = run.options;
  Diagnosis& d = run.d;
  run.effective_points = score_candidates(d);
  select_effect(d, options);
  // A search continued while the selection leaves the residual above the floor: the search, not
  // the effect, may be what leaves the error there (a stiffness whose truth is a narrow valley).
  const double explained = options.noise_level_ratio * floor_of(d, options);
  const long continued_budget = run.continued_budget();
  std::set<std::string> searched_further;
  while (continued_budget > 0) {
    std::vector<std::string> names = candidates_to_search_further(d, options);
    std::erase_if(names, [&](const std::string& n) { return searched_further.count(n) || !run.models.count(n); });
    if (names.empty()) break;
    // an accepted effect's own search takes what is left; contenders get the same search or none
    const bool accepted_alone =
        names.size() == 1 && std::any_of(d.candidates.begin(), d.candidates.end(), [&](const EffectCandidate& c) {
          return c.effect == names.front() && c.verdict == CandidateVerdict::accepted;
        });
    const long budget = accepted_alone ? run.within_budget(continued_budget) : continued_budget;
    const bool affordable = options.max_simulations <= 0 ||
                            run.runner.simulations() + static_cast<long>(names.size()) * (budget + 1 + options.scatter_runs) <=
                                options.max_simulations;
    if (budget < 2 * run.config.optimiser.population || !affordable) {
      progress(options, "no further search of " + std::to_string(names.size()) + " effect(s): " +
                            std::to_string(continued_budget) + " simulations each are short of two populations or "
                            "over --max-simulations");
      break;
    }
    // side by side: each within the budget checked above for all of them
    std::vector<std::function<void()>> tasks;
    const bool quiet = run.runner.runs_together(names.size(), true);
    for (const auto& name : names) {
      searched_further.insert(name);
      run.best_sets[name];  // the entries each search writes, made before any runs
      run.searched[name];
      tasks.push_back([&run, name, budget, explained, quiet] { search_further(run, name, budget, explained, quiet); });
    }
    run.runner.side_by_side(tasks, true);
    run.effective_points = score_candidates(d);
    select_effect(d, options);
  }
  for (const auto& c : d.candidates)
    if (c.continued.simulations > 0) add_note(d, " " + c.continued.describe(c.effect));
  add_note(d, unexplained_fit_note(d, options));
}

}  // namespace detail
}  // namespace demcal::pipelines
