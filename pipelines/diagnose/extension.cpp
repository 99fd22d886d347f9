// Stage 4 of the diagnosis: base + effect calibrated for the effects of best signature, within the
// budget; where the base response splits, more of them (the signatures rank by realisation there).
#include "diagnose_internal.hpp"

#include "demcal/pipelines/surrogate_data.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using namespace detail;

namespace {

// The registry entry of an effect parameter's set_parameter name, its search range resolved for
// this structure (dem::scaled_search_range).
dem::EffectParameter registry_parameter(const dem::Effect& effect, const std::string& name,
                                        const dem::ResponseScales& scales) {
  if (const dem::EffectParameter* p = effect.parameter(dem::parameter_field(name))) return dem::scaled_search_range(*p, scales);
  throw CampaignError("effect parameter " + name + " is not in the effect registry");
}

}  // namespace

bool response_splits(double scatter, double noise, const DiagnoseOptions& options) {
  return scatter > options.scatter_floor_ratio * noise;
}

int candidates_to_calibrate(bool splits, const DiagnoseOptions& options) {
  if (!splits) return options.candidates;
  if (options.candidates_at_split == 0) return std::numeric_limits<int>::max();
  return std::max(options.candidates, options.candidates_at_split);
}

std::vector<double> candidate_start(const optimise::ParameterSpace& space, const std::map<std::string, double>& warm,
                                    const std::map<std::string, double>& best) {
  const auto names = space.free_names();
  const auto n = static_cast<Eigen::Index>(names.size());
  const Eigen::VectorXd centre = space.to_physical(Eigen::VectorXd::Constant(n, 0.5));
  const Eigen::VectorXd lower = space.lower_bounds(), upper = space.upper_bounds();
  std::vector<double> start;
  for (Eigen::Index k = 0; k < n; ++k) {
    const auto& name = names[static_cast<std::size_t>(k)];
    const auto from_warm = warm.find(name), from_best = best.find(name);
    const double v = from_warm != warm.end() ? from_warm->second : from_best != best.end() ? from_best->second : centre(k);
    start.push_back(std::clamp(v, lower(k), upper(k)));
  }
  return start;
}

std::vector<std::map<std::string, double>> further_start_sets(const std::map<std::string, double>& best,
                                                              const std::vector<ParameterSet>& runs,
                                                              const optimise::ParameterSpace& space, int count,
                                                              double separation) {
  const auto names = space.free_names();
  const auto n = static_cast<Eigen::Index>(names.size());
  const auto unit = [&](const std::map<std::string, double>& set) -> std::optional<Eigen::VectorXd> {
    Eigen::VectorXd x(n);
    for (Eigen::Index k = 0; k < n; ++k) {
      const auto it = set.find(names[static_cast<std::size_t>(k)]);
      if (it == set.end() || !std::isfinite(it->second)) return std::nullopt;
      x(k) = it->second;
    }
    return space.to_unit(x).cwiseMax(0.0).cwiseMin(1.0);
  };
  std::vector<std::pair<const ParameterSet*, Eigen::VectorXd>> ranked;  // each usable run and its unit point
  for (const auto& r : runs)
    if (const auto x = unit(r.params); x && std::isfinite(r.fitness)) ranked.emplace_back(&r, *x);
  std::stable_sort(ranked.begin(), ranked.end(), [](const auto& a, const auto& b) { return a.first->fitness < b.first->fitness; });
  std::vector<Eigen::VectorXd> taken;
  if (const auto b = unit(best)) taken.push_back(*b);
  std::vector<std::map<std::string, double>> starts;
  for (const auto& [r, x] : ranked) {
    if (static_cast<int>(starts.size()) >= count) break;
    if (std::all_of(taken.begin(), taken.end(), [&, &x = x](const Eigen::VectorXd& t) { return (x - t).norm() >= separation; })) {
      taken.push_back(x);
      starts.push_back(r->params);
    }
  }
  return starts;
}

namespace detail {

void fix_search_rounds(CampaignConfig& c) {
  c.surrogate.options.cost_ratio = HUGE_VAL;
  c.surrogate.options.overlap = "always";
}

ExtendedModel extend(const CampaignConfig& config, const dem::Effect& effect, const std::vector<std::string>& targets,
                     const dem::ResponseScales& scales, const fs::path& folder) {
  ExtendedModel m;
  m.config = config;
  m.target = targets.empty() ? "" : targets.front();
  fs::create_directories(folder);
  for (std::size_t k = 0; k < config.cases.size(); ++k) {
    auto& c = m.config.cases[k];
    dem::Scene scene = build_scene(c.scene, config.source + ": cases[" + std::to_string(k) + "].scene");
    auto names = dem::enable_effect(scene, effect.name, targets);
    // A joint-group effect switched on everywhere is calibrated with one value for every group
    // (the name without its group), so that the search gains as few dimensions as the effect has.
    if (effect.target == dem::EffectTarget::joint_groups) {
      std::vector<std::string> fields;
      for (const auto& n : names)
        if (std::find(fields.begin(), fields.end(), dem::parameter_field(n)) == fields.end()) fields.push_back(dem::parameter_field(n));
      names = fields;
    }
    if (k == 0) {
      m.parameter_names = names;
    } else if (names != m.parameter_names) {
      throw dem::SceneError(c.name, "effect " + effect.name + " has other parameters in this case than in the first");
    }
    const fs::path file = folder / ("scene-" + c.name + ".json");
    dem::save_scene(scene, file.string());
    c.scene = SceneSpec{};
    c.scene.file = fs::absolute(file).string();
  }
  for (const auto& n : m.parameter_names) m.parameters.push_back(registry_parameter(effect, n, scales));
  return m;
}

double parameter_cap(const std::string& name, const dem::EffectParameter& p, const std::map<std::string, double>& base) {
  if (p.capped_by.empty()) return std::numeric_limits<double>::infinity();
  const auto dot = name.rfind('.');
  const std::string group_key = dot == std::string::npos ? p.capped_by : name.substr(0, dot) + "." + p.capped_by;
  for (const auto& key : {group_key, p.capped_by})
    if (auto it = base.find(key); it != base.end()) return it->second;
  return std::numeric_limits<double>::infinity();
}

bool signature_comes_close(double score, double reference, double share) {
  return reference > 0 && score >= share * reference;
}

optimise::ParameterSpace extended_space(const ExtendedModel& m, const CampaignConfig& config,
                                        const std::map<std::string, double>& best, const DiagnoseOptions& options) {
  std::map<std::string, double> caps = best;  // a capped parameter stays below the lowest value of its cap searched
  optimise::ParameterSpace space;
  for (const auto& p : config.space.free_parameters()) {
    optimise::ParameterSpec s = p;
    const double b = best.at(p.name);
    if (options.narrow_log_factor == 0 && options.narrow_linear_share == 0) {
      // the campaign's own bounds
    } else if (p.scale == optimise::ParameterSpec::Scale::log10) {
      s.lower = std::max(p.lower, b / options.narrow_log_factor);
      s.upper = std::min(p.upper, b * options.narrow_log_factor);
    } else {
      const double half = options.narrow_linear_share * (p.upper - p.lower);
      s.lower = std::max(p.lower, b - half);
      s.upper = std::min(p.upper, b + half);
    }
    caps[s.name] = s.lower;
    space.add(s);
  }
  for (std::size_t i = 0; i < m.parameter_names.size(); ++i) {
    const dem::EffectParameter& p = m.parameters[i];
    optimise::ParameterSpec s;
    s.name = m.parameter_names[i];
    s.lower = p.search_min;
    s.upper = std::min(p.search_max, parameter_cap(s.name, p, caps));
    s.scale = p.log_scale ? optimise::ParameterSpec::Scale::log10 : optimise::ParameterSpec::Scale::linear;
    if (!(s.upper > s.lower)) s.lower = s.upper - 0.5 * (p.search_max - p.search_min);
    space.add(s);
  }
  for (const auto& [name, value] : config.space.fixed_parameters()) space.fix(name, value);
  if (const auto& tied = config.space.tied_parameter()) space.tie(tied->name, tied->source, tied->ratio);
  return space;
}

CampaignConfig extended_campaign(const ExtendedModel& m, const CampaignConfig& config,
                                 const std::map<std::string, double>& best, const DiagnoseOptions& options,
                                 long evaluations, const fs::path& folder, const std::map<std::string, double>& warm,
                                 const std::vector<std::map<std::string, double>>& further_base) {
  CampaignConfig c = fitted_cases(m.config, options);
  c.space = extended_space(m, config, best, options);
  const optimise::ParameterSpace& space = c.space;
  c.name = config.name + "+" + folder.filename().string();
  c.output = folder.string();
  c.archive = diagnosis_archive(options);
  c.report = options.report;
  c.optimiser.max_evaluations = evaluations;
  c.optimiser.algorithm = options.candidate_algorithm;
  c.surrogate.options.kind = options.surrogate_kind;
  fix_search_rounds(c);
  // The diagnosis bounds an effect's parameters itself (stage 6): no identifiability profile here.
  c.identifiability_profile.enabled = false;
  const bool local = options.candidate_algorithm.rfind("nlopt:", 0) == 0;
  if (local || options.candidate_algorithm == "bo") {
    // Warm start: the base best with the effect at its best-explaining probe (the local search's
    // start; the first point of the Bayesian search's design).
    c.optimiser.initial_point = candidate_start(space, warm, best);
    for (const auto& other : further_base) {
      std::map<std::string, double> start = warm;
      for (const auto& p : config.space.free_parameters()) start[p.name] = other.at(p.name);
      c.optimiser.further_starts.push_back(candidate_start(space, start, other));
    }
    if (local) {
      c.optimiser.initial_step = options.candidate_initial_step;
      c.polish.enabled = false;
    }
  }
  if (!local && c.polish.enabled) {
    c.polish.options.max_evaluations = std::min<long>(c.polish.options.max_evaluations, evaluations / 4);
  }
  return c;
}

bool calibrate_candidate(EffectCandidate& c, std::map<std::string, double>& best_set, const ExtendedModel& m,
                         const CampaignConfig& config, const std::map<std::string, double>& base_params,
                         const DiagnoseOptions& options, long budget, const fs::path& folder,
                         const std::map<std::string, double>& warm, const std::vector<ChannelResidual>& base_residuals,
                         CaseRunner& runner, const std::vector<std::map<std::string, double>>& further_base,
                         std::vector<ParameterSet>* searched) {
  const CampaignConfig ext = extended_campaign(m, config, base_params, options, budget, folder, warm, further_base);
  for (const auto& p : ext.space.free_parameters())  // the calibration's own box (its residual friction capped lower)
    if (c.search_ranges.count(p.name)) c.search_ranges[p.name] = {p.lower, p.upper};
  RunOptions run;
  run.resume = options.resume;
  run.progress = options.progress;
  const CampaignResult r = run_campaign(ext, run);
  runner.add_campaign(r);
  if (searched) searched->insert(searched->end(), r.all.begin(), r.all.end());
  c.simulations += r.simulations;
  c.params = r.best.params;
  c.fitness = r.best.fitness;
  best_set = complete_parameters(ext, r.best.params);
  const std::vector<Evaluation> runs = runs_with_reruns(m.config, ext, best_set, &base_residuals, options.scatter_runs, runner);
  if (!judge_fit(c, runs)) return false;
  c.effect_parameters = static_cast<int>(m.parameter_names.size());
  return true;
}

ContinuedSearch continue_search(EffectCandidate& fit, std::map<std::string, double>& set, ExtendedModel model,
                                const CampaignConfig& config, const std::map<std::string, double>& base_params,
                                const DiagnoseOptions& options, long budget, const fs::path& folder,
                                const std::vector<ChannelResidual>& base_residuals, CaseRunner& runner,
                                const std::string& label, std::vector<ParameterSet>* searched) {
  EffectCandidate next = fit;
  next.simulations = 0;
  next.error = EffectCandidate::kNaN;  // stays NaN when the further search fails
  std::map<std::string, double> next_set;
  model.config.optimiser.seed += 1;
  try {
    calibrate_candidate(next, next_set, model, config, base_params, options, budget, folder, set, base_residuals, runner,
                        {}, searched);
  } catch (const std::exception& ex) {
    progress(options, "the continued search of " + label + " failed: " + ex.what());
  }
  ContinuedSearch continued{next.simulations, fit.error, next.error, next.error < fit.error};
  const long simulations = fit.simulations + continued.simulations;
  if (continued.kept) {
    fit = std::move(next);
    set = std::move(next_set);
  }
  fit.simulations = simulations;
  return continued;
}

bool judge_fit(EffectCandidate& c, const std::vector<Evaluation>& runs) {
  if (!runs.front().ok) {
    c.reason = "its best set cannot be re-simulated: " + runs.front().message;
    return false;
  }
  c.rerun_errors.clear();
  c.run_residuals.clear();
  c.run_held_out_rms.clear();
  for (const auto& one : runs) {
    c.rerun_errors.push_back(one.error);
    c.run_residuals.push_back(one.residuals);
    c.run_held_out_rms.emplace_back();
    for (const auto& ch : one.held_out) c.run_held_out_rms.back()[key_of(ch)] = ch.rms;
  }
  const Evaluation& e = median_run(runs);
  c.residuals = e.residuals;
  c.error = e.error;
  c.rms.clear();
  for (const auto& ch : e.residuals) c.rms[key_of(ch)] = ch.rms;
  c.held_out_rms.clear();
  for (const auto& ch : e.held_out) c.held_out_rms[key_of(ch)] = ch.rms;
  c.held_out_error = e.held_out_error;
  return true;
}

namespace {

// One calibration of stage 4: a candidate at its best-signature target (other == nullptr) or at one
// of the targets whose signatures that one does not clearly beat (close_targets), calibrated alike.
// Each writes only its own fields, so that the calibrations can run side by side.
struct CandidateCalibration {
  EffectCandidate* candidate = nullptr;
  const ProbedTarget* other = nullptr;
  EffectCandidate fit;                  // the calibration's candidate fields
  std::map<std::string, double> set;    // its best set
  std::vector<ParameterSet> searched;   // every set it evaluated
  bool below_cut = false;               // tried below the top effects, its signature close to theirs
  bool ran = false;                     // false: over the budget when its turn came
};

// Where a candidate is calibrated: null for its best-signature target, then each close target.
std::vector<const ProbedTarget*> close_targets_of(DiagnosisRun& run, const std::string& effect) {
  std::vector<const ProbedTarget*> targets = {nullptr};
  for (const auto& other : run.close_targets[effect]) targets.push_back(&other);
  return targets;
}

// Runs one calibration: its budget taken when it starts (within the diagnosis's total budget).
void run_calibration(DiagnosisRun& run, CandidateCalibration& job, bool quiet) {
  const DiagnoseOptions& options = run.options;
  EffectCandidate& c = *job.candidate;
  const long budget = run.within_budget(run.per_candidate);
  if (budget < 2 * run.config.optimiser.population) {
    job.fit.reason = "over the simulation budget";
    return;
  }
  job.ran = true;
  job.fit = job.other ? job.other->candidate : c;
  job.fit.tried = true;
  const fs::path folder = fs::path(options.out) / "candidates" /
                          (job.other ? c.effect + "-at-" + file_safe(job.other->candidate.target) : c.effect);
  const std::string runs = std::to_string(budget) + " simulations";
  const std::string why =
      job.other ? " at " + job.other->candidate.target + " too (signature " +
                      format_number(100 * job.other->candidate.signature_score, 2) + " % against " +
                      format_number(100 * c.signature_score, 2) + " % at " + c.target + ", " + runs + ")"
                : " (" + runs + (job.below_cut ? ", its signature close to the last one tried" : "") + ")";
  progress(options, "calibrating base + " + c.effect + why + " in " + folder.string());
  DiagnoseOptions own = options;
  own.progress = options.progress && !quiet;  // side by side: a line when it ends, not each round
  try {
    calibrate_candidate(job.fit, job.set, job.other ? job.other->model : run.models.at(c.effect), run.config,
                        run.d.base_params, own, budget, folder, job.other ? job.other->warm : run.warm_starts.at(c.effect),
                        run.base.residuals, run.runner, run.d.further_starts, &job.searched);
  } catch (const std::exception& ex) {
    job.fit.reason = std::string("its calibration failed: ") + ex.what();
    if (job.other) progress(options, "the calibration of " + c.effect + " at " + job.fit.target + " failed: " + ex.what());
  }
  if (quiet)
    progress(options, "base + " + effect_at(c.effect, job.fit.target) + ": error " +
                          format_number(job.fit.error, 3) + " N after " + std::to_string(job.fit.simulations) +
                          " simulations");
}

// The calibrations' results into the diagnosis, in their order: a candidate's own fit, then each
// close target's, the one of lower error kept with the others listed (EffectCandidate::other_targets).
void merge_calibration(DiagnosisRun& run, CandidateCalibration& job) {
  EffectCandidate& c = *job.candidate;
  if (!job.ran) {
    if (!job.other) c.reason = job.fit.reason;
    return;
  }
  auto& searched = run.searched[c.effect];
  searched.insert(searched.end(), job.searched.begin(), job.searched.end());
  if (!job.other) {
    c = std::move(job.fit);
    run.best_sets[c.effect] = std::move(job.set);
    return;
  }
  EffectCandidate& alt = job.fit;
  const bool better = std::isfinite(alt.error) && !(alt.error >= c.error);
  EffectCandidate& loser = better ? c : alt;
  std::vector<EffectCandidate::OtherTarget> others = std::move(c.other_targets);
  others.push_back({loser.target, loser.signature_score, loser.error, loser.simulations});
  const long simulations = c.simulations + alt.simulations;
  if (better) {
    c = std::move(alt);
    run.models[c.effect] = job.other->model;
    run.best_sets[c.effect] = std::move(job.set);
  }
  c.other_targets = std::move(others);
  c.simulations = simulations;
}

}  // namespace

void calibrate_candidates(DiagnosisRun& run) {
  const DiagnoseOptions& options = run.options;
  const bool splits = response_splits(run.scatter, run.noise, options);
  const int limit = candidates_to_calibrate(splits, options);
  if (splits && limit > options.candidates)
    progress(options, "the base fit sits where the response splits (scatter " + format_number(run.scatter, 3) + " N, noise " +
                          format_number(run.noise, 3) + " N): more than the top " + std::to_string(options.candidates) +
                          " effects by signature are calibrated (--candidates-at-split)");
  for (const auto& start : run.d.further_starts) {
    std::string text;
    for (const auto& p : run.config.space.free_parameters())
      text += (text.empty() ? "" : ", ") + p.name + " " + format_number(start.at(p.name), 4);
    progress(options, "a further start of the candidates' searches: " + text);
  }
  // Which calibrations run follows from the signatures alone: the top `limit` effects, those whose
  // signature comes close to the last of them, and each one's close targets.
  std::vector<CandidateCalibration> jobs;
  int tried = 0;
  double last_tried_signature = 0;  // of the limit-th effect tried
  for (auto& c : run.d.candidates) {
    if (!run.models.count(c.effect)) continue;
    const bool below_cut = tried >= limit;
    if (below_cut && !signature_comes_close(c.signature_score, last_tried_signature, options.close_candidate_share)) {
      c.reason = "ranked below the " + std::to_string(limit) + " effects tried";
      continue;
    }
    if (++tried == limit) last_tried_signature = c.signature_score;
    for (const ProbedTarget* other : close_targets_of(run, c.effect)) {
      CandidateCalibration& job = jobs.emplace_back();
      job.candidate = &c;
      job.other = other;
      job.below_cut = below_cut && other == nullptr;
    }
  }
  // Without a total budget every calibration's budget is known before any runs: side by side.
  const bool together = options.max_simulations <= 0;
  const bool quiet = run.runner.runs_together(jobs.size(), together);
  std::vector<std::function<void()>> tasks;
  for (auto& job : jobs) tasks.push_back([&run, &job, quiet] { run_calibration(run, job, quiet); });
  run.runner.side_by_side(tasks, together);
  for (auto& job : jobs) merge_calibration(run, job);
}

}  // namespace detail
}  // namespace demcal::pipelines
