// Stage 3 of the diagnosis: each effect switched on at each of its targets and probed at a few
// points of its range; its signature is the share of the base residual those runs, taken as
// linear, explain beyond what the base parameters can (signature_score). The best probe starts the
// effect's calibration.
#include "diagnose_internal.hpp"

#include "demcal/dem/joints.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <iterator>
#include <limits>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using nlohmann::json;
using namespace detail;

namespace {

// Where in its search range each effect parameter is probed for the signature: from strong to mild.
constexpr double kProbeFractions[] = {0.2, 0.5, 0.8};
// Joints probed for an effect at one joint: at most kMechanismJointTargets of the base fit's hinges
// and sliding joints, then the joints beside its hinges up to kJointTargets in all. An effect at a
// joint moves the mechanism, so the base fit, which lacks it, can hinge beside it (the wedge gap of
// the other code's records: journal/diagnose-studies.md, "The wedge gap: the joints beside the
// hinges, and the search's budget").
constexpr std::size_t kMechanismJointTargets = 4;
constexpr std::size_t kJointTargets = 8;

// Golden-section steps of the search of an effect's simplest form (search_simplest_form): from a
// bracket of half the range to about 3 % of it, within the reference arch's cap valley.
constexpr int kSimplestFormRefinements = 6;

// A parameter's value at fraction t of its search range (geometric for log-scaled ones).
double at_fraction(const dem::EffectParameter& p, double t) {
  if (p.log_scale && p.search_min > 0) return p.search_min * std::pow(p.search_max / p.search_min, t);
  return p.search_min + t * (p.search_max - p.search_min);
}

// The effect's parameters at fractions t[i] of their search ranges, over the base set.
std::map<std::string, double> effect_values(const ExtendedModel& m, const std::map<std::string, double>& base,
                                            const std::vector<double>& t) {
  std::map<std::string, double> values = base;
  for (std::size_t i = 0; i < m.parameter_names.size(); ++i)
    values[m.parameter_names[i]] = std::min(at_fraction(m.parameters[i], t[i]), parameter_cap(m.parameter_names[i], m.parameters[i], base));
  return values;
}

// Probe points of the signature: every parameter at mid-range, then each parameter alone at the
// strong and mild ends of the probe range with the others at mid-range (one parameter: three
// points along its range). 2P + 1 runs for P parameters.
std::vector<std::vector<double>> probe_points(std::size_t parameters) {
  std::vector<std::vector<double>> points{std::vector<double>(parameters, 0.5)};
  for (std::size_t i = 0; i < parameters; ++i)
    for (double t : {kProbeFractions[0], kProbeFractions[2]}) {
      std::vector<double> p(parameters, 0.5);
      p[i] = t;
      points.push_back(p);
    }
  return points;
}

}  // namespace

std::vector<std::vector<double>> search_simplest_form(const std::vector<dem::EffectParameter>& parameters,
                                                      const std::function<double(const std::vector<double>&)>& error,
                                                      int refinements) {
  std::vector<std::vector<double>> run;
  const auto run_at = [&](std::size_t end, std::size_t j, double t) {
    std::vector<double> point(parameters.size(), 0.5);
    point[end] = 1;
    point[j] = t;
    run.push_back(point);
    const double e = error(point);
    return std::isnan(e) ? std::numeric_limits<double>::infinity() : e;
  };
  constexpr double kGolden = 0.38196601125010515;  // (3 - sqrt(5)) / 2
  for (std::size_t end = 0; end < parameters.size(); ++end) {
    if (!parameters[end].simplest_form_at_max) continue;
    for (std::size_t j = 0; j < parameters.size(); ++j) {
      if (j == end) continue;
      // the bracket (a, b, c): b the best fraction run so far, a and c the fractions around it
      double a = 0, b = kProbeFractions[0], c = kProbeFractions[1];
      double best = run_at(end, j, kProbeFractions[0]);
      constexpr int probes = static_cast<int>(std::size(kProbeFractions));
      for (int k = 1; k < probes; ++k) {
        const double e = run_at(end, j, kProbeFractions[k]);
        if (e < best) {
          best = e;
          a = kProbeFractions[k - 1];
          b = kProbeFractions[k];
          c = k + 1 < probes ? kProbeFractions[k + 1] : 1.0;
        }
      }
      for (int step = 0; step < refinements && std::isfinite(best); ++step) {
        const bool right = c - b > b - a;  // the wider side
        const double x = right ? b + kGolden * (c - b) : b - kGolden * (b - a);
        const double e = run_at(end, j, x);
        if (e < best) {
          best = e;
          (right ? a : c) = b;
          b = x;
        } else {
          (right ? c : a) = x;
        }
      }
    }
  }
  return run;
}

namespace detail {
namespace {

// What the base best run reached, for the structure-relative search ranges: the largest contact
// stress over the fitted cases, in the run and at its start (0 when a backend does not report them).
dem::ResponseScales response_scales(const Evaluation& base, const DiagnoseOptions& options) {
  dem::ResponseScales s;
  auto largest = [](const json& details, const char* key, double& into) {
    if (details.contains(key) && details[key].is_number()) into = std::max(into, details[key].get<double>());
  };
  for (const auto& c : base.cases)
    if (!is_held_out(c.name, options.held_out)) {
      largest(c.details, "max_normal_stress", s.peak_normal_stress);
      largest(c.details, "start_normal_stress", s.start_normal_stress);
    }
  return s;
}

// The runs that measure the sensitivity of the stacked curves to each free base parameter: one
// forward difference of 5 % of the unit cube (backwards at the upper bound).
std::vector<RunRequest> sensitivity_runs(const CampaignConfig& config, const std::map<std::string, double>& best,
                                         const std::vector<ChannelResidual>& base) {
  std::vector<RunRequest> runs;
  const auto& space = config.space;
  const auto names = space.free_names();
  Eigen::VectorXd physical(static_cast<Eigen::Index>(names.size()));
  for (std::size_t j = 0; j < names.size(); ++j) physical(static_cast<Eigen::Index>(j)) = best.at(names[j]);
  const Eigen::VectorXd unit = space.to_unit(physical);
  for (std::size_t j = 0; j < names.size(); ++j) {
    Eigen::VectorXd u = unit;
    const auto jj = static_cast<Eigen::Index>(j);
    u(jj) += u(jj) + 0.05 <= 1 ? 0.05 : -0.05;
    std::map<std::string, double> params = best;
    params[names[j]] = space.to_physical(u)(jj);
    runs.push_back({&config, complete_parameters(config, params), &base});
  }
  return runs;
}

// Candidate targets of an effect in this scene: each fixed block for support springs; joints for
// a gap (the base fit's hinges first, then its sliding joints, then the joints beside its hinges);
// else the effect's default.
std::vector<std::vector<std::string>> targets_for(const dem::Effect& effect, const Evaluation& base,
                                                  const dem::Scene& scene) {
  std::vector<std::vector<std::string>> out;
  if (effect.target == dem::EffectTarget::support_blocks) {
    for (const auto& b : scene.blocks)
      if (b.fixed) out.push_back({b.name});
    return out;
  }
  if (effect.target != dem::EffectTarget::joint) return {{}};
  const auto add = [&](const std::string& joint, std::size_t most) {
    const std::vector<std::string> t{joint};
    if (std::find(out.begin(), out.end(), t) == out.end() && out.size() < most) out.push_back(t);
  };
  std::vector<std::string> hinges;
  for (const char* key : {"hinges", "sliding_joints"})
    for (const auto& c : base.cases)
      if (c.details.contains(key) && c.details[key].is_array())
        for (const auto& joint : c.details[key]) {
          add(joint.get<std::string>(), kMechanismJointTargets);
          if (std::string(key) == "hinges") hinges.push_back(joint.get<std::string>());
        }
  for (const auto& hinge : hinges)
    for (const auto& joint : dem::joints_beside(scene, hinge)) add(joint, kJointTargets);
  return out;
}

// What every probe of the stage is compared with: the base residual, stacked over the channels,
// and the base parameters' sensitivities.
struct SignatureBasis {
  std::vector<double> residual;
  std::vector<std::vector<double>> sensitivities;
  dem::Scene first_scene;  // the first case's scene, whose blocks and joints are the targets
  dem::ResponseScales scales;
};

// One target of an effect, probed: its candidate (signature and search ranges), model and best probe.
struct TargetProbe {
  ProbedTarget probed;
  bool applicable = true;  // the effect could be switched on there
  bool signed_ = false;    // at least one probe ran, so the signature means something
  CampaignConfig fitted;   // the model on the fitted cases, what the probes run
  std::vector<std::vector<double>> points;      // the probes' fractions of the search ranges
  std::vector<std::vector<double>> signatures;  // the probes' curve changes (stacked)

  // The effect's parameters at fractions `t` of their ranges, over the base set.
  std::map<std::string, double> values_at(const std::vector<double>& t, const DiagnosisRun& run) const {
    return effect_values(probed.model, run.base_params, t);
  }
  // A probe's run: the search's start when it comes closer to the measurement than every earlier one.
  void note_run(const Evaluation& s, const std::map<std::string, double>& values) {
    if (s.ok && s.error < probed.warm_error) {
      probed.warm_error = s.error;
      probed.warm = values;
    }
  }
};

// The effect switched on at `targets`: its candidate and model, or why it cannot be.
TargetProbe extend_at(DiagnosisRun& run, const dem::Effect& effect, const std::vector<std::string>& targets,
                      const SignatureBasis& basis) {
  TargetProbe out;
  EffectCandidate& c = out.probed.candidate;
  c.effect = effect.name;
  c.target = targets.empty() ? "" : targets.front();
  ExtendedModel& m = out.probed.model;
  try {
    m = extend(run.config, effect, targets, basis.scales,
               fs::path(run.options.out) / "candidates" / (effect.name + (c.target.empty() ? "" : "@" + c.target)));
  } catch (const std::exception& ex) {
    c.reason = std::string("not applicable here: ") + ex.what();
    c.signature_score = -1;
    out.applicable = false;
    return out;
  }
  for (std::size_t i = 0; i < m.parameter_names.size(); ++i)
    c.search_ranges[m.parameter_names[i]] = {
        m.parameters[i].search_min,
        std::min(m.parameters[i].search_max, parameter_cap(m.parameter_names[i], m.parameters[i], run.base_params))};
  out.fitted = fitted_cases(m.config, run.options);
  out.points = probe_points(m.parameter_names.size());
  return out;
}

// The target's probe runs noted (its signatures, its best probe); returns where the probes, taken as
// linear, say the residual is explained, for one more run that the caller makes with every
// target's at once (the search's start when it fits better than every probe); none when a probe failed.
std::vector<double> linearised_probe(TargetProbe& t, const std::vector<Evaluation>& probe_runs,
                                     const SignatureBasis& basis, DiagnosisRun& run) {
  for (std::size_t k = 0; k < t.points.size(); ++k) {
    t.note_run(probe_runs[k], t.values_at(t.points[k], run));
    if (probe_runs[k].ok) t.signatures.push_back(stacked(run.base.residuals, &probe_runs[k].residuals));
  }
  if (t.signatures.size() != t.points.size()) return {};
  return linearised_fractions(basis.residual, basis.sensitivities, t.signatures, t.probed.model.parameter_names.size(),
                              kProbeFractions[0], kProbeFractions[2]);
}

// After that run: the search of the effect's simplest form (starts only, not signatures: a form the
// range holds at its end is no small change), the signature's score and its progress line.
void finish_probe(TargetProbe& t, const SignatureBasis& basis, DiagnosisRun& run) {
  const auto probe_error = [&](const std::vector<double>& fractions) {
    const auto values = t.values_at(fractions, run);
    const Evaluation s = run.runner.evaluate(t.fitted, values, &run.base.residuals);
    t.note_run(s, values);
    return s.ok ? s.error : std::numeric_limits<double>::quiet_NaN();
  };
  search_simplest_form(t.probed.model.parameters, probe_error, kSimplestFormRefinements);
  EffectCandidate& c = t.probed.candidate;
  if (!t.signatures.empty()) c.signature_score = signature_score(basis.residual, basis.sensitivities, t.signatures);
  if (t.signatures.empty() && c.reason.empty()) c.reason = "every probe run of the effect failed";
  if (!c.target.empty())
    progress(run.options, "  " + c.effect + " at " + c.target + ": signature " + format_number(100 * c.signature_score, 2) +
                              " %, best probe " + format_number(t.probed.warm_error, 3) + " N");
  t.signed_ = !t.signatures.empty();
}

// The effect probed at every target (`probes`, in targets_for's order); its best target joins the
// candidates, other targets whose signatures come close are kept for calibration too
// (run.close_targets).
void choose_target(DiagnosisRun& run, const dem::Effect& effect, std::vector<TargetProbe>& probes) {
  EffectCandidate best_target;
  best_target.effect = effect.name;
  best_target.signature_score = -1;
  std::vector<ProbedTarget> probed_targets;  // the signed ones of a targeted effect
  for (auto& t : probes) {
    if (!t.applicable) {
      if (best_target.signature_score < 0 && best_target.reason.empty()) best_target = t.probed.candidate;
      continue;
    }
    if (t.signed_ && !t.probed.candidate.target.empty()) probed_targets.push_back(t.probed);
    if (t.probed.candidate.signature_score > best_target.signature_score) {
      best_target = t.probed.candidate;
      run.models[effect.name] = t.probed.model;
      run.warm_starts[effect.name] = t.probed.warm;
    }
  }
  for (const auto& t : probed_targets)
    if (t.candidate.target != best_target.target &&
        signature_comes_close(t.candidate.signature_score, best_target.signature_score, run.options.close_target_share))
      run.close_targets[effect.name].push_back(t);
  if (!probed_targets.empty()) run.probed_targets[effect.name] = std::move(probed_targets);
  if (best_target.signature_score < 0) {
    best_target.signature_score = 0;
    if (best_target.reason.empty()) best_target.reason = "no target for this effect in the scene";
  }
  progress(run.options, effect_at(effect.name, best_target.target) +
                            ": signature explains " + format_number(100 * best_target.signature_score, 2) +
                            " % of the residual the base parameters cannot remove");
  run.d.candidates.push_back(best_target);
}

}  // namespace

void probe_signatures(DiagnosisRun& run) {
  // Sensitivities and signatures compare fitted curves only: held-out cases are not simulated for them.
  const CampaignConfig fitted = fitted_cases(run.config, run.options);
  SignatureBasis basis;
  basis.residual = stacked(run.base.residuals, nullptr);
  basis.first_scene = build_scene(run.config.cases.front().scene, run.config.source + ": cases[0].scene");
  basis.scales = response_scales(run.base, run.options);
  if (basis.scales.peak_normal_stress > 0) run.d.peak_normal_stress = basis.scales.peak_normal_stress;
  if (basis.scales.start_normal_stress > 0) run.d.start_normal_stress = basis.scales.start_normal_stress;
  // Every effect at every target; the runs of all of them at once, in three rounds: the base
  // sensitivities and every probe, then every linearised probe, then the simplest forms' searches.
  std::vector<std::vector<TargetProbe>> probes;  // per effect of run.effects
  for (const auto* e : run.effects) {
    probes.emplace_back();
    for (const auto& targets : targets_for(*e, run.base, basis.first_scene))
      probes.back().push_back(extend_at(run, *e, targets, basis));
  }
  std::vector<RunRequest> first = sensitivity_runs(fitted, run.base_params, run.base.residuals);
  const std::size_t sensitivities = first.size();
  for (auto& effect : probes)
    for (auto& t : effect)
      if (t.applicable)
        for (const auto& point : t.points) first.push_back({&t.fitted, t.values_at(point, run), &run.base.residuals});
  const std::vector<Evaluation> first_runs = run.runner.evaluate_all(first);
  for (std::size_t k = 0; k < sensitivities; ++k)
    if (first_runs[k].ok) basis.sensitivities.push_back(stacked(run.base.residuals, &first_runs[k].residuals));
  std::vector<RunRequest> linearised;
  std::vector<TargetProbe*> linearised_of;
  std::size_t next = sensitivities;
  for (auto& effect : probes)
    for (auto& t : effect) {
      if (!t.applicable) continue;
      const std::vector<Evaluation> own(first_runs.begin() + static_cast<long>(next),
                                        first_runs.begin() + static_cast<long>(next + t.points.size()));
      next += t.points.size();
      const auto fractions = linearised_probe(t, own, basis, run);
      if (fractions.empty()) continue;
      linearised.push_back({&t.fitted, t.values_at(fractions, run), &run.base.residuals});
      linearised_of.push_back(&t);
    }
  const std::vector<Evaluation> linearised_runs = run.runner.evaluate_all(linearised);
  for (std::size_t k = 0; k < linearised.size(); ++k) linearised_of[k]->note_run(linearised_runs[k], linearised[k].params);
  for (std::size_t e = 0; e < probes.size(); ++e) {
    for (auto& t : probes[e])
      if (t.applicable) finish_probe(t, basis, run);
    choose_target(run, *run.effects[e], probes[e]);
  }
  std::stable_sort(run.d.candidates.begin(), run.d.candidates.end(),
                   [](const auto& a, const auto& b) { return a.signature_score > b.signature_score; });
}

}  // namespace detail
}  // namespace demcal::pipelines
