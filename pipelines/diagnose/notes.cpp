// The verdict's notes (diagnose.hpp): what the diagnosis saw that a reader of the verdict should
// know — a fit left above the noise, a longer search advised, a response that splits, a base fit at
// its bounds, a narrow window, a sparse measurement, data the fits were not given.
#include "diagnose_internal.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::pipelines {

using namespace detail;

std::string unexplained_fit_note(const Diagnosis& d, const DiagnoseOptions& options) {
  const EffectCandidate* chosen = unexplained_chosen(d, options);
  if (chosen == nullptr) return "";
  const double floor = floor_of(d, options);
  const double explained = options.noise_level_ratio * floor;
  const EffectCandidate* next = nullptr;  // the closest other fit
  for (const auto& c : d.candidates)
    if (&c != chosen && c.tried && std::isfinite(c.error) && (next == nullptr || c.error < next->error)) next = &c;
  std::string note = " Its fit still misses the curves by more than the noise and scatter allow (" +
                     format_number(chosen->error, 3) + " N against " + format_number(explained, 3) + " N, " +
                     format_number(options.noise_level_ratio, 3) + " x their combined " + format_number(floor, 3) +
                     " N): " + chosen->effect + " explains part of the residual, not all of it; the rest is another "
                     "effect, or a form of this one its search did not reach";
  if (next != nullptr)
    note += " (the closest other fit: " + next->effect + ", " + format_number(next->error, 3) + " N, criterion " +
            format_number(next->score, 3) + ")";
  return note + ".";
}

long advised_candidate_simulations(const Diagnosis& d, const DiagnoseOptions& options, long per_candidate) {
  bool unresolved = unexplained_chosen(d, options) != nullptr;
  if (d.chosen.empty()) {
    const bool tie =
        std::any_of(d.candidates.begin(), d.candidates.end(), [](const EffectCandidate& c) { return c.verdict == CandidateVerdict::tied; });
    const bool fitted = std::any_of(d.candidates.begin(), d.candidates.end(),
                                    [](const EffectCandidate& c) { return c.tried && std::isfinite(c.error); });
    unresolved = tie || (fitted && d.error_before > kUnexplainedRatio * floor_of(d, options));
  }
  return unresolved && per_candidate > 0 ? 2 * per_candidate : 0;
}

std::string more_search_note(long advised, long per_candidate) {
  if (advised <= 0) return "";
  return " A longer search may reach fits this one did not: run it again with --candidate-simulations " +
         std::to_string(advised) + " (twice this diagnosis's " + std::to_string(per_candidate) +
         " per candidate) to check the verdict.";
}

std::string split_response_note(const Diagnosis& d, const DiagnoseOptions& options) {
  const double noise = overall_noise(d.base_residuals), scatter = overall(d.scatter);
  if (!response_splits(scatter, noise, options)) return "";
  std::string rerun_errors;
  for (const double e : d.base_rerun_errors) rerun_errors += (rerun_errors.empty() ? "" : ", ") + format_number(e, 3);
  std::string note = " The base fit sits where the model's response splits: its re-runs, parameters moved by 1e-7, score " +
                     rerun_errors + " N and scatter by " + format_number(scatter, 3) + " N, " +
                     format_number(scatter / noise, 2) +
                     " x the noise; that scatter is the point's, not the model's, and the floor counts it up to " +
                     format_number(options.scatter_floor_ratio, 2) + " x the noise.";
  const auto tried = std::count_if(d.candidates.begin(), d.candidates.end(), [](const auto& c) { return c.tried; });
  if (tried > options.candidates)
    note += " The signatures, differences of single runs there, do not rank the effects: " + std::to_string(tried) +
            " were calibrated instead of the top " + std::to_string(options.candidates) + ".";
  return note;
}

std::string base_at_bound_note(const Diagnosis& d, const optimise::ParameterSpace& space) {
  const auto& free = space.free_parameters();
  Eigen::VectorXd physical = (space.lower_bounds() + space.upper_bounds()) / 2;  // a missing one: mid-range
  for (std::size_t j = 0; j < free.size(); ++j)
    if (const auto found = d.base_params.find(free[j].name); found != d.base_params.end())
      physical(static_cast<Eigen::Index>(j)) = found->second;
  const Eigen::VectorXd unit = space.to_unit(physical);
  std::string listed;
  for (std::size_t j = 0; j < free.size(); ++j) {
    const double u = unit(static_cast<Eigen::Index>(j));
    if (u > kAtBound && u < 1 - kAtBound) continue;
    listed += (listed.empty() ? "" : "; ") + free[j].name + " " + format_number(physical(static_cast<Eigen::Index>(j)), 3) +
              " at the " + (u <= kAtBound ? "lower" : "upper") + " end of [" + format_number(free[j].lower, 3) + ", " +
              format_number(free[j].upper, 3) + "]";
  }
  if (listed.empty()) return "";
  return " The base fit presses against its calibration range (" + listed +
         "): the data ask for more than the range allows, because the range is too narrow or because the parameter "
         "stands in for something the base model lacks; a calibration over a wider range tells the two apart.";
}

std::string detail::listed_coverage(const std::vector<std::pair<std::string, double>>& shares) {
  std::string listed;
  for (const auto& [key, share] : shares)
    listed += (listed.empty() ? "" : ", ") + key + " over " + format_number(100 * share, 2) + " %";
  return listed;
}

std::string narrow_window_note(const Diagnosis& d) {
  std::vector<std::pair<std::string, double>> short_of_range;
  for (const auto& r : d.base_residuals)
    if (r.coverage < kNarrowWindow) short_of_range.emplace_back(key_of(r), r.coverage);
  const std::string widened = listed_coverage({d.widened_window.begin(), d.widened_window.end()});
  const std::string narrow = listed_coverage(short_of_range);
  const std::string why = " (its gauge stops short in the simulation, and a gauge that hardly moves matches over what it reaches)";
  std::string note;
  if (!widened.empty())
    note += " The campaign's window compared the base fit with part of the measured range only: " + widened + why +
            "; the diagnosis refined the base fit again comparing every channel over its measured range, and compared "
            "so from there on, as \"objective\": {\"window\": \"measured\"} does.";
  if (!narrow.empty())
    note += " The base fit is compared with part of the measured range only: " + narrow + why +
            ". Set \"objective\": {\"window\": \"measured\"} to compare every channel over its measured range.";
  return note;
}

std::string sparse_measurement_note(const Diagnosis& d) {
  std::string sparse;
  for (std::size_t i = 0; i < d.base_residuals.size(); ++i) {
    const ChannelResidual& r = d.base_residuals[i];
    if (!(r.gap_share() > kSparseGap)) continue;
    std::string fits;  // the fits recorded more densely, whose simulated curve has shape inside the gap
    int most = 0;
    std::size_t rows = 0;
    const auto add = [&](const std::string& name, const std::vector<ChannelResidual>& residuals) {
      if (i >= residuals.size() || residuals[i].simulated_in_gap < kShapeInGap ||
          !(static_cast<double>(residuals[i].simulated_rows) > kDenserRecord * static_cast<double>(r.measured_rows)))
        return;
      fits += (fits.empty() ? "" : ", ") + name;
      most = std::max(most, residuals[i].simulated_in_gap);
      rows = std::max(rows, residuals[i].simulated_rows);
    };
    add("the base fit", d.base_residuals);
    for (const auto& c : d.candidates) add("the " + c.effect + " fit", c.residuals);
    if (fits.empty()) continue;
    sparse += (sparse.empty() ? "" : "; ") + r.case_name + "/" + r.channel + " between " +
              format_number(r.gap_lower * 1e3, 3) + " and " + format_number(r.gap_upper * 1e3, 3) + " mm (" +
              format_number(100 * r.gap_share(), 2) + " % of its compared range), where " + fits + " simulated up to " +
              std::to_string(most) + " points (" + std::to_string(rows) + " rows recorded against the measurement's " +
              std::to_string(r.measured_rows) + ")";
  }
  if (sparse.empty()) return "";
  return " The measurement has no point on " + sparse +
         ": there the simulated curve is compared with a straight line between two measured points, and a fast "
         "event (a slip, a snap) leaves an error that no parameter removes. Record the simulation at the "
         "measurement's rate (the scene's loading.record_interval, or the generator option record_interval) so "
         "that both curves are read at the same instants.";
}

std::string unfitted_data_note(const Diagnosis& d) {
  std::string missed;
  for (const auto& [key, rms] : d.held_out_rms) {
    if (std::find(d.held_out_checked.begin(), d.held_out_checked.end(), key) != d.held_out_checked.end()) continue;
    const auto noise = d.held_out_noise.find(key);
    missed += (missed.empty() ? "" : ", ") + key + " (RMS " + format_number(rms, 3) + " N";
    if (noise != d.held_out_noise.end() && std::isfinite(noise->second) && noise->second > 0)
      missed += ", " + format_number(rms / noise->second, 2) + " x its noise";
    missed += ")";
  }
  if (missed.empty()) return "";
  return " But the base fit misses data it was not fitted to: " + missed +
         ". An effect may show only there; to let the diagnosis use that data, fit it (a channel weight above 0, "
         "or the case left out of --held-out).";
}

std::string ContinuedSearch::describe(const std::string& effect) const {
  const std::string head = effect + "'s fit stayed above the noise and scatter, so it was searched " +
                           std::to_string(simulations) + " simulations further";
  if (kept) return head + ", which lowered its error from " + format_number(error_before, 3) + " to " + format_number(error_found, 3) + " N.";
  if (!std::isfinite(error_found)) return head + "; that search failed, and the first fit stands.";
  return head + " without a closer fit (" + format_number(error_found, 3) + " N against " + format_number(error_before, 3) +
         " N); the first fit stands.";
}

std::string UnionSearch::describe(const std::string& effect) const {
  const std::string head = "The union search proposed " + std::to_string(rounds) + " points for " + effect +
                           " from an emulator of " + std::to_string(training_rows) + " runs of every model";
  if (kept) return head + "; the best lowered its error from " + format_number(error_before, 3) + " to " + format_number(error_found, 3) + " N.";
  if (!std::isfinite(error_found)) return head + "; none fitted better than its calibration, whose fit stands.";
  return head + "; the best, re-run, fitted to " + format_number(error_found, 3) + " N against " + format_number(error_before, 3) +
         " N, so the calibration's fit stands.";
}

namespace {

// A value in the unit a structural engineer reads: millimetres for "m", degrees for "deg", and a
// power-of-1000 prefix for the others (1.83e6 N/m -> "1.83 MN/m").
std::string with_unit(double v, const std::string& unit) {
  if (unit == "deg") return format_number(v, 3) + "°";
  if (unit == "m") return format_number(v * 1e3, 3) + " mm";
  if (unit == "1" || unit.empty()) return format_number(v, 3);
  constexpr const char* kPrefixes[] = {"", "k", "M", "G", "T"};
  int k = 0;
  while (std::abs(v) >= 1000 && k < 4) {
    v /= 1000;
    ++k;
  }
  return format_number(v, 3) + " " + kPrefixes[k] + unit;
}

// "name ≈ value (lower – upper)" for each of the chosen fit's own parameters, its range from the
// bounds check where it ran (lower and upper: the nearest values the data rule out).
}  // namespace

std::string detail::fitted_effect_parameters(const EffectCandidate& c, const Diagnosis& d) {
  const dem::Effect& effect = dem::find_effect(c.effect);
  std::map<std::string, int> uses;  // of each field: named by its field alone unless two groups set it
  for (const auto& [name, value] : c.params)
    if (!d.base_params.count(name)) ++uses[dem::parameter_field(name)];
  std::string pinned, loose;  // the parameters the bounds' check pins on a side, and those it does not
  for (const auto& [name, value] : c.params) {
    if (d.base_params.count(name)) continue;
    const dem::EffectParameter* p = effect.parameter(dem::parameter_field(name));
    if (!p) continue;
    const std::string field = uses[dem::parameter_field(name)] > 1 ? name : dem::parameter_field(name);
    const auto b = std::find_if(c.bounds.begin(), c.bounds.end(), [&name = name](const ParameterBound& x) { return x.name == name; });
    if (b != c.bounds.end() && !std::isfinite(b->lower) && !std::isfinite(b->upper)) {
      loose += (loose.empty() ? "" : ", ") + field;
      continue;
    }
    std::string text = field + " ≈ " + with_unit(value, p->unit);
    if (b != c.bounds.end()) {
      if (b->bounded()) text += " (" + with_unit(b->lower, p->unit) + " – " + with_unit(b->upper, p->unit) + ")";
      else if (std::isfinite(b->upper)) text += " (below " + with_unit(b->upper, p->unit) + ")";
      else text += " (above " + with_unit(b->lower, p->unit) + ")";
    }
    pinned += (pinned.empty() ? "" : ", ") + text;
  }
  if (!loose.empty()) pinned += (pinned.empty() ? "" : "; ") + loose + " not pinned by the data";
  return pinned;
}

// How often the resamples reach the verdict's choice, for the headline: "; chosen in 97 % of 200
// resamples", or for an undecided verdict every choice's share ("; across 200 resamples: joint-gap
// 23.5 %, ..."); "" when not measured.
std::string frequency_text(const Diagnosis& d) {
  const auto& f = d.frequency;
  if (f.resamples == 0) return "";
  const std::string resamples = std::to_string(f.resamples) + " resamples";
  if (d.outcome != DiagnosisOutcome::undecided) return "; chosen in " + percent(f.verdict) + " of " + resamples;
  std::string listed;
  for (const auto& [name, share] : f.effects)
    if (share > 0) listed += (listed.empty() ? "" : ", ") + name + " " + percent(share);
  if (f.none > 0) listed += (listed.empty() ? "" : ", ") + std::string("no effect ") + percent(f.none);
  if (f.undecided > 0) listed += (listed.empty() ? "" : ", ") + std::string("a tie ") + percent(f.undecided);
  return "; across " + resamples + ": " + listed;
}

std::string verdict_headline(const Diagnosis& d, double noise, double scatter) {
  const std::string against = " N against " + format_number(noise, 3) + " N of noise";
  const std::string shares = frequency_text(d) + ".";  // every sentence ends with the resamples' share
  switch (d.outcome) {
    case DiagnosisOutcome::missing_effect:
      if (const EffectCandidate* c = chosen_candidate(d))
        return "Missing: " + effect_at(c->effect, c->target) + ": " +
               fitted_effect_parameters(*c, d) + "; force error " + format_number(d.error_before, 3) + " → " +
               format_number(c->error, 3) + against + shares;
      break;
    case DiagnosisOutcome::undecided: {
      std::string names;
      for (const auto& c : d.candidates)
        if (c.verdict == CandidateVerdict::tied) names += (names.empty() ? "" : " or ") + c.effect;
      return "Undecided" + (names.empty() ? "" : ": " + names) + ", the data do not settle it; force error " +
             format_number(d.error_before, 3) + against + shares;
    }
    case DiagnosisOutcome::unexplained: {
      const auto fitted =
          std::count_if(d.candidates.begin(), d.candidates.end(), [](const auto& c) { return c.tried && std::isfinite(c.error); });
      return "No effect found: force error " + format_number(d.error_before, 3) + against + "; " +
             (fitted == 0 ? std::string("no candidate effect could be fitted")
                          : "none of the " + std::to_string(fitted) + " effects calibrated explains it") +
             shares;
    }
    case DiagnosisOutcome::no_effect_needed: break;
  }
  return "No effect needed: force error " + format_number(d.error_before, 3) + against +
         (std::isfinite(scatter) ? " and " + format_number(scatter, 3) + " N of simulation scatter" : "") + shares;
}

void detail::add_note(Diagnosis& d, const std::string& note) {
  if (note.empty()) return;
  if (d.notes.empty() && d.conclusion.empty()) d.conclusion = d.verdict;
  d.verdict += note;
  d.notes.push_back(note.substr(note.find_first_not_of(' ')));
}

void detail::add_verdict_notes(DiagnosisRun& run) {
  Diagnosis& d = run.d;
  if (!run.at_noise) {
    d.advised_candidate_simulations = advised_candidate_simulations(d, run.options, run.per_candidate);
    add_note(d, more_search_note(d.advised_candidate_simulations, run.per_candidate));
  }
  for (const std::string& note : {split_response_note(d, run.options), base_at_bound_note(d, run.config.space),
                                  narrow_window_note(d), sparse_measurement_note(d)})
    add_note(d, note);
  if (d.conclusion.empty()) d.conclusion = d.verdict;
  d.headline = verdict_headline(d, run.noise, run.scatter);
}

}  // namespace demcal::pipelines
