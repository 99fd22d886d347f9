// Stage 5c of the diagnosis: the selection taken again on resamples of the data and of the fits'
// round-off (verdict_frequency), and a verdict that does not hold in most of them made undecided.
#include "diagnose_internal.hpp"

#include <algorithm>
#include <cmath>
#include <random>

namespace demcal::pipelines {

using nlohmann::json;
using namespace detail;

namespace {

constexpr const char* kNone = "none";
constexpr const char* kUndecided = "undecided";

// The choice a selection made: its one effect, "none" or "undecided".
std::string choice_of(const Diagnosis& d) {
  if (d.outcome == DiagnosisOutcome::undecided) return kUndecided;
  if (d.outcome == DiagnosisOutcome::missing_effect && !d.chosen.empty()) return d.chosen.front();
  return kNone;
}

// Grid points drawn by a moving-block bootstrap: blocks of `block` consecutive indices of [0, n),
// each starting anywhere a whole block fits, until n indices are drawn.
std::vector<std::size_t> block_resample(std::size_t n, std::size_t block, std::mt19937_64& random) {
  std::vector<std::size_t> indices;
  if (n == 0) return indices;
  block = std::clamp<std::size_t>(block, 1, std::max<std::size_t>(n, 1));
  std::uniform_int_distribution<std::size_t> start(0, n - block);
  while (indices.size() < n) {
    const std::size_t first = start(random);
    for (std::size_t i = first; i < first + block && indices.size() < n; ++i) indices.push_back(i);
  }
  return indices;
}

// `fit` with each channel's RMS error taken over `indices[c]` of its grid; false when the fit does
// not lie on the base grid (another channel count or grid size).
bool resampled(std::vector<ChannelResidual>& fit, const std::vector<std::vector<std::size_t>>& indices) {
  if (fit.size() != indices.size()) return false;
  for (std::size_t c = 0; c < fit.size(); ++c) {
    auto& ch = fit[c];
    if (ch.measured.size() != ch.simulated.size() || (!indices[c].empty() && indices[c].back() >= ch.measured.size()))
      return false;
    double sum = 0;
    for (std::size_t i : indices[c]) sum += (ch.measured[i] - ch.simulated[i]) * (ch.measured[i] - ch.simulated[i]);
    ch.rms = std::sqrt(sum / static_cast<double>(std::max<std::size_t>(1, indices[c].size())));
  }
  return true;
}

}  // namespace

std::string detail::percent(double share) { return format_number(100 * share, 3) + " %"; }

json Diagnosis::VerdictFrequency::to_json() const {
  json shares = json::object();
  for (const auto& [name, share] : effects) shares[name] = share;
  return {{"resamples", resamples}, {"verdict", finite_or_null(verdict)}, {"effects", shares},
          {"none", finite_or_null(none)}, {"undecided", finite_or_null(undecided)}};
}

Diagnosis::VerdictFrequency verdict_frequency(const Diagnosis& diagnosis, const FitRuns& base_runs,
                                              const std::vector<double>& effective_points,
                                              const DiagnoseOptions& options, std::uint64_t seed) {
  Diagnosis::VerdictFrequency f;
  const bool tried = std::any_of(diagnosis.candidates.begin(), diagnosis.candidates.end(),
                                 [](const EffectCandidate& c) { return c.tried && !c.run_residuals.empty(); });
  if (options.resamples <= 0 || !tried || base_runs.residuals.empty() ||
      effective_points.size() != diagnosis.base_residuals.size())
    return f;
  std::mt19937_64 random(seed);
  std::map<std::string, long> counts;
  const auto& grid = diagnosis.base_residuals;
  Diagnosis d = diagnosis;  // each resample sets every field the selection reads and writes
  for (int r = 0; r < options.resamples; ++r) {
    std::vector<std::vector<std::size_t>> indices;
    for (std::size_t c = 0; c < grid.size(); ++c) {
      const std::size_t n = grid[c].measured.size();
      const double points = std::max(1.0, effective_points[c]);
      indices.push_back(block_resample(n, static_cast<std::size_t>(std::lround(static_cast<double>(n) / points)), random));
    }
    const auto pick = [&](std::size_t runs) { return std::uniform_int_distribution<std::size_t>(0, runs - 1)(random); };
    const std::size_t b = pick(base_runs.residuals.size());
    d.base_residuals = base_runs.residuals[b];
    if (b < base_runs.held_out_rms.size()) d.held_out_rms = base_runs.held_out_rms[b];
    if (!resampled(d.base_residuals, indices)) return {};
    d.error_before = overall_error(d.base_residuals);
    for (auto& c : d.candidates) {
      if (!c.tried || c.run_residuals.empty()) continue;
      const std::size_t k = pick(c.run_residuals.size());
      c.residuals = c.run_residuals[k];
      if (k < c.run_held_out_rms.size()) c.held_out_rms = c.run_held_out_rms[k];
      if (resampled(c.residuals, indices)) {
        c.error = overall_error(c.residuals);
        c.score = information_criterion_change(d.base_residuals, c.residuals, c.effect_parameters, effective_points);
      } else {
        c.error = c.score = EffectCandidate::kNaN;
      }
    }
    select_effect(d, options);
    ++counts[choice_of(d)];
  }
  const auto share = [&](const std::string& key) {
    const auto found = counts.find(key);
    return found == counts.end() ? 0.0 : static_cast<double>(found->second) / options.resamples;
  };
  f.resamples = options.resamples;
  for (const auto& c : diagnosis.candidates)
    if (c.tried) f.effects[c.effect] = share(c.effect);
  f.none = share(kNone);
  f.undecided = share(kUndecided);
  f.verdict = share(choice_of(diagnosis));
  return f;
}

double pair_frequency(const std::vector<std::vector<ChannelResidual>>& base_runs,
                      const std::vector<std::vector<ChannelResidual>>& pair_runs, int parameters,
                      const std::vector<double>& effective_points, double evidence, int resamples,
                      std::uint64_t seed) {
  if (resamples <= 0 || base_runs.empty() || pair_runs.empty() || effective_points.size() != base_runs.front().size())
    return Diagnosis::kNaN;
  std::mt19937_64 random(seed);
  const auto pick = [&](std::size_t runs) { return std::uniform_int_distribution<std::size_t>(0, runs - 1)(random); };
  long passed = 0;
  for (int r = 0; r < resamples; ++r) {
    std::vector<std::vector<std::size_t>> indices;
    for (std::size_t c = 0; c < effective_points.size(); ++c) {
      const std::size_t n = base_runs.front()[c].measured.size();
      const double points = std::max(1.0, effective_points[c]);
      indices.push_back(block_resample(n, static_cast<std::size_t>(std::lround(static_cast<double>(n) / points)), random));
    }
    std::vector<ChannelResidual> base = base_runs[pick(base_runs.size())];
    std::vector<ChannelResidual> pair = pair_runs[pick(pair_runs.size())];
    if (!resampled(base, indices) || !resampled(pair, indices)) continue;
    const double change = information_criterion_change(base, pair, parameters, effective_points);
    if (change < -evidence && overall_error(pair) < overall_error(base)) ++passed;
  }
  return static_cast<double>(passed) / resamples;
}

bool settle_on_frequency(Diagnosis& d, const DiagnoseOptions& options) {
  const auto& f = d.frequency;
  if (f.resamples == 0 || d.outcome == DiagnosisOutcome::undecided || !(f.verdict < options.verdict_share)) return false;
  std::vector<std::pair<double, std::string>> shares;  // every choice some resamples reach, largest first
  for (const auto& [name, share] : f.effects)
    if (share > 0) shares.emplace_back(share, name);
  if (f.none > 0) shares.emplace_back(f.none, "no effect");
  if (f.undecided > 0) shares.emplace_back(f.undecided, "a tie");
  std::stable_sort(shares.begin(), shares.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  std::string listed;
  for (const auto& [share, name] : shares) listed += (listed.empty() ? "" : ", ") + name + " in " + percent(share);
  const std::string choice = choice_of(d) == kNone ? "that no effect is needed" : d.chosen.front();
  const std::string taken_again = "the selection taken again on " + std::to_string(f.resamples) +
                                  " resamples of the data and of the fits' round-off";
  if (f.none >= options.verdict_share) {  // most resamples settle on no effect: that is the verdict
    for (auto& c : d.candidates)
      if (c.verdict == CandidateVerdict::accepted || c.verdict == CandidateVerdict::tied) {
        c.verdict = CandidateVerdict::rejected;
        c.reason = "chosen in only " + percent(f.effects.count(c.effect) ? f.effects.at(c.effect) : 0.0) + " of " +
                   std::to_string(f.resamples) + " resamples of the data and the fits' round-off; " + c.reason;
      }
    d.chosen.clear();
    d.error_after = d.error_before;
    const bool unexplained = d.error_before > kUnexplainedRatio * floor_of(d, options);
    d.outcome = unexplained ? DiagnosisOutcome::unexplained : DiagnosisOutcome::no_effect_needed;
    d.verdict = std::string(unexplained ? "No effect found" : "No effect needed") + ": the fits' median runs point to " +
                choice + ", but " + taken_again + " finds no effect in " + percent(f.none) + " of them (" + listed +
                "); " + base_errors_text(d) +
                (unexplained ? ", so the model lacks something the effects tried do not supply." : ".");
    d.frequency.verdict = f.none;
    return true;
  }
  for (auto& c : d.candidates)
    if (c.tried && f.effects.count(c.effect) && f.effects.at(c.effect) > 0) {
      c.verdict = CandidateVerdict::tied;
      c.reason = "chosen in " + percent(f.effects.at(c.effect)) + " of " + std::to_string(f.resamples) +
                 " resamples of the data and the fits' round-off" + (c.reason.empty() ? "" : "; " + c.reason);
    }
  d.chosen.clear();
  d.error_after = d.error_before;
  d.outcome = DiagnosisOutcome::undecided;
  d.verdict = "The data do not settle it: the fits' median runs point to " + choice + ", but " + taken_again +
              " reaches it in only " + percent(f.verdict) + " of them (" + listed + "), fewer than the " +
              percent(options.verdict_share) + " a verdict needs; the model is not extended.";
  return true;
}

namespace detail {

void resample_verdict(DiagnosisRun& run) {
  if (run.at_noise) return;
  FitRuns base;
  for (const auto& e : run.base_runs) {
    base.residuals.push_back(e.residuals);
    std::map<std::string, double> held_out;
    for (const auto& ch : e.held_out) held_out[key_of(ch)] = ch.rms;
    base.held_out_rms.push_back(std::move(held_out));
  }
  run.d.frequency = verdict_frequency(run.d, base, run.effective_points, run.options,
                                      static_cast<std::uint64_t>(run.config.optimiser.seed));
  if (run.d.frequency.resamples > 0)
    progress(run.options, "the selection on " + std::to_string(run.d.frequency.resamples) +
                              " resamples reaches the verdict's choice in " + percent(run.d.frequency.verdict) + " of them");
  settle_on_frequency(run.d, run.options);
}

}  // namespace detail
}  // namespace demcal::pipelines
