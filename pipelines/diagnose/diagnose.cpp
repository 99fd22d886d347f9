// run_diagnosis (diagnose.hpp): the stages in order, each in a file of its own (diagnose_internal.hpp
// lists them); the options' checks and diagnosis.json.
#include "demcal/pipelines/diagnose.hpp"
#include "diagnose_internal.hpp"

#include "demcal/dem/effects.hpp"
#include "demcal/limits/limits.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using nlohmann::json;
using namespace detail;

void DiagnoseOptions::Validate() const {
  // An option with a flag is named as its flag, the others (set from code) as their field.
  auto fail = [](const std::string& name, const std::string& value, const std::string& rule) {
    throw CampaignError("diagnose option " + name + " " + value + ": " + rule);
  };
  const auto text = [](double v) { return format_number(v, 6); };
  const auto at_least = [&](const std::string& name, double value, double least, const std::string& note = "") {
    if (!(value >= least)) fail(name, text(value), "must be >= " + text(least) + note);
  };
  const auto share = [&](const std::string& name, double value) {
    if (!(value > 0 && value <= 1)) fail(name, text(value), "must be in (0, 1]");
  };
  const auto budget = [&](const std::string& name, long value, long least, const std::string& note = "") {
    at_least(name, static_cast<double>(value), static_cast<double>(least), note);
    if (auto m = limits::check(limits::Limit::evaluations, static_cast<double>(value))) fail(name, std::to_string(value), *m);
  };
  if (out.empty()) fail("--out", "\"\"", "must name a folder");
  budget("--max-simulations", max_simulations, 0);
  at_least("--candidates", candidates, 1);
  at_least("--candidates-at-split", candidates_at_split, 0, " (0: every effect)");
  budget("--candidate-simulations", candidate_simulations, 0);
  if (!(evidence > 0)) fail("--evidence", text(evidence), "must be > 0");
  at_least("--tie-margin", tie_margin, 0);
  share("--close-target-share", close_target_share);
  share("--close-candidate-share", close_candidate_share);
  budget("--profile-simulations", profile_simulations, 0);
  budget("--continued-simulations", continued_simulations, -1, " (-1: a candidate's budget)");
  budget("--scatter-runs", scatter_runs, 0);
  at_least("--union-rounds", union_rounds, 0, " (0: none)");
  if (auto m = limits::check(limits::Limit::evaluations, static_cast<double>(union_rounds)))
    fail("--union-rounds", std::to_string(union_rounds), *m);
  at_least("--pair-rounds", pair_rounds, 0, " (0: none)");
  if (auto m = limits::check(limits::Limit::evaluations, static_cast<double>(pair_rounds)))
    fail("--pair-rounds", std::to_string(pair_rounds), *m);
  at_least("--max-effects", max_effects, 0, " (0: no limit)");
  at_least("--resamples", resamples, 0);
  if (resamples > kMaxResamples) fail("--resamples", std::to_string(resamples), "must be <= " + std::to_string(kMaxResamples));
  share("--verdict-share", verdict_share);
  if (!(scatter_floor_ratio > 0)) fail("--scatter-floor-ratio", text(scatter_floor_ratio), "must be > 0");
  at_least("noise_level_ratio", noise_level_ratio, 1);
  at_least("held_out_tolerance", held_out_tolerance, 0);
  at_least("--held-out-ratio", held_out_ratio, 1);
  if (candidate_algorithm.empty()) fail("--candidate-algorithm", "\"\"", "must name an optimiser");
  if (surrogate_kind != "gp" && surrogate_kind != "mlp") fail("--surrogate-kind", "\"" + surrogate_kind + "\"", "must be gp or mlp");
  if (surrogate_backend != "native" && surrogate_backend != "libtorch")
    fail("--surrogate-backend", "\"" + surrogate_backend + "\"", "must be native or libtorch");
  at_least("--candidate-starts", candidate_starts, 1);
  share("start_separation", start_separation);
  if (!(candidate_initial_step > 0 && candidate_initial_step <= 0.5))
    fail("candidate_initial_step", text(candidate_initial_step), "must be in (0, 0.5]");
  const bool wide = narrow_log_factor == 0 && narrow_linear_share == 0;
  if (!wide && !(narrow_log_factor > 1)) fail("narrow_log_factor", text(narrow_log_factor), "must be > 1 (or 0 with narrow_linear_share 0)");
  if (!wide && !(narrow_linear_share > 0 && narrow_linear_share <= 1))
    fail("narrow_linear_share", text(narrow_linear_share), "must be in (0, 1] (or 0 with narrow_log_factor 0)");
  for (auto name = effects.begin(); name != effects.end(); ++name) {
    try {
      dem::find_effect(*name);
    } catch (const dem::SceneError& e) {
      fail("--effects", *name, e.what());
    }
    if (std::find(effects.begin(), name, *name) != name) fail("--effects", *name, "named twice");
  }
}

namespace {

// Each bound by its parameter's name (ParameterBound::to_json).
json bounds_json(const std::vector<ParameterBound>& bounds) {
  json j = json::object();
  for (const auto& b : bounds) j[b.name] = b.to_json();
  return j;
}

json params_json(const std::map<std::string, double>& params) {
  json j = json::object();
  for (const auto& [k, v] : params) j[k] = finite_or_null(v);
  return j;
}

// What the diagnosis cannot run on, named before anything is simulated.
void check_diagnosable(const CampaignConfig& config, const DiagnoseOptions& options) {
  config.Validate();
  options.Validate();
  // The effects are switched on in each case's scene and calibrated with their parameters, which
  // only the engine's backends set; an external command receives the campaign's own placeholders.
  if (config.backend.type == "command")
    throw CampaignError(config.source + ": backend.type is \"command\": the diagnosis switches effects on in demcal's "
                        "engine and calibrates their parameters, which an external command never receives; diagnose "
                        "with the \"threads\" backend (the scene and parameters of this campaign in demcal)");
  if (config.backend.type == "mpi")
    throw CampaignError(config.source + ": backend.type is \"mpi\": the diagnosis runs on this machine's threads (the "
                        "MPI backend gives the same results); set backend.type to \"threads\"");
  for (const auto& name : options.held_out)
    if (std::none_of(config.cases.begin(), config.cases.end(), [&](const CaseSpec& c) { return c.name == name; }))
      throw CampaignError("--held-out: the campaign has no case named '" + name + "'");
  if (fitted_cases(config, options).cases.empty())
    throw CampaignError("--held-out: every case of the campaign is held out, nothing is left to fit");
  // The base calibration gets at most half of a total budget, and a search needs two populations.
  if (const long least = 4L * config.optimiser.population;
      options.max_simulations > 0 && options.result.empty() && options.max_simulations < least)
    throw CampaignError("--max-simulations " + std::to_string(options.max_simulations) +
                        ": the base calibration gets at most half of it, and needs two populations of " +
                        std::to_string(config.optimiser.population) + "; give at least " + std::to_string(least) +
                        " (or --result with a finished base calibration)");
}

void write_diagnosis_json(const Diagnosis& d, const DiagnoseOptions& options) {
  std::ofstream out(fs::path(options.out) / "diagnosis.json");
  out << d.to_json().dump(2) << "\n";
  if (!out) throw CampaignError("cannot write " + (fs::path(options.out) / "diagnosis.json").string());
}

}  // namespace

DiagnosisRun::DiagnosisRun(CampaignConfig config_in, DiagnoseOptions options_in)
    : config(std::move(config_in)), options(std::move(options_in)), runner(config, options.held_out) {
  if (options.effects.empty()) {
    for (const auto& e : dem::effect_registry()) effects.push_back(&e);
  } else {
    for (const auto& n : options.effects) effects.push_back(&dem::find_effect(n));
  }
}

long DiagnosisRun::within_budget(long wanted) const {
  if (options.max_simulations <= 0) return wanted;
  return std::min(wanted, options.max_simulations - runner.simulations() - (1 + options.scatter_runs));
}

void detail::finish_diagnosis(DiagnosisRun& run, double wall_time_s) {
  Diagnosis& d = run.d;
  d.simulations = run.runner.simulations();
  d.simulated_this_session = run.runner.simulated_this_session();
  d.wall_time_s = wall_time_s;
  d.simulation_time_s = run.runner.simulation_seconds();
  d.model_time_s = run.runner.model_seconds();
  write_diagnosis_json(d, run.options);
  if (run.options.report) write_diagnosis_report(d, run.options);
}

void detail::diagnose_from_base(DiagnosisRun& run) {
  measure_base_residual(run);
  if (!run.at_noise) {
    probe_signatures(run);
    calibrate_candidates(run);
    if (run.options.union_rounds > 0) search_union(run);
  }
  select_and_search_further(run);
  resample_verdict(run);
  if (!run.at_noise) bound_accepted_parameters(run);
  add_verdict_notes(run);
}

Diagnosis run_diagnosis(const CampaignConfig& config, const DiagnoseOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  check_diagnosable(config, options);
  fs::create_directories(options.out);
  CampaignConfig pinned = config;  // every calibration of the diagnosis derives from this one
  pinned.surrogate.options.mlp.backend = smoothing::parse_regression_backend(options.surrogate_backend);
  DiagnosisRun run(pinned, options);
  fit_base(run);
  diagnose_from_base(run);
  add_further_effects(run);
  check_undecided_leader(run);
  finish_diagnosis(run, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  progress(options, run.d.headline);
  return std::move(run.d);
}

std::string to_string(DiagnosisOutcome outcome) {
  switch (outcome) {
    case DiagnosisOutcome::missing_effect: return "missing_effect";
    case DiagnosisOutcome::undecided: return "undecided";
    case DiagnosisOutcome::unexplained: return "unexplained";
    case DiagnosisOutcome::no_effect_needed: break;
  }
  return "no_effect_needed";
}

std::string to_string(CandidateVerdict verdict) {
  switch (verdict) {
    case CandidateVerdict::accepted: return "accepted";
    case CandidateVerdict::rejected: return "rejected";
    case CandidateVerdict::tied: return "tied";
    case CandidateVerdict::not_tried: break;
  }
  return "not tried";
}

json ContinuedSearch::to_json() const {
  return {{"simulations", simulations}, {"error_before", finite_or_null(error_before)},
          {"error_found", finite_or_null(error_found)}, {"kept", kept}};
}

json UnionSearch::to_json() const {
  return {{"rounds", rounds}, {"simulations", simulations}, {"training_rows", training_rows},
          {"error_before", finite_or_null(error_before)}, {"error_found", finite_or_null(error_found)}, {"kept", kept}};
}

json PairSearch::to_json() const {
  json tried = json::array();
  for (const auto& p : pairs)
    tried.push_back({{"effects", p.effects}, {"targets", p.targets}, {"best_run_error", finite_or_null(p.best_run_error)},
                     {"calibrated", p.calibrated}, {"continued", p.continued}, {"error", finite_or_null(p.error)},
                     {"criterion", finite_or_null(p.criterion)}});
  return {{"rounds", rounds}, {"simulations", simulations}, {"pairs", tried}, {"effects", effects},
          {"params", params_json(params)}, {"rerun_errors", rerun_errors}, {"error", finite_or_null(error)},
          {"criterion", finite_or_null(criterion)}, {"frequency", finite_or_null(frequency)}, {"accepted", accepted}};
}

json Diagnosis::to_json() const {
  json base = {{"params", params_json(base_params)}, {"fitness", finite_or_null(base_fitness)}, {"rms", params_json(base_rms)},
               {"rerun_errors", base_rerun_errors}};
  base["widened_window"] = params_json(widened_window);
  base["further_starts"] = json::array();
  for (const auto& s : further_starts) base["further_starts"].push_back(params_json(s));
  json residuals = json::array();
  for (const auto& r : base_residuals) residuals.push_back(r.to_json());
  base["residual"] = residuals;
  json cands = json::array();
  for (const auto& c : candidates) {
    json rj = json::array();
    for (const auto& r : c.residuals) rj.push_back(r.to_json());
    cands.push_back({{"effect", c.effect},
                     {"target", c.target},
                     {"signature_score", c.signature_score},
                     {"tried", c.tried},
                     {"params", params_json(c.params)},
                     {"fitness", finite_or_null(c.fitness)},
                     {"rms", params_json(c.rms)},
                     {"score", finite_or_null(c.score)},
                     {"verdict", to_string(c.verdict)},
                     {"reason", c.reason},
                     {"simulations", c.simulations},
                     {"rerun_errors", c.rerun_errors},
                     {"residual", rj},
                     {"held_out_rms", params_json(c.held_out_rms)}});
    cands.back()["error"] = finite_or_null(c.error);
    cands.back()["held_out_error"] = finite_or_null(c.held_out_error);
    json ranges = json::object();
    for (const auto& [name, range] : c.search_ranges) ranges[name] = {range[0], range[1]};
    cands.back()["search_ranges"] = ranges;
    if (c.continued.simulations > 0) cands.back()["continued"] = c.continued.to_json();
    if (c.union_search.rounds > 0) cands.back()["union_search"] = c.union_search.to_json();
    if (!c.other_targets.empty()) {
      json others = json::array();
      for (const auto& o : c.other_targets)
        others.push_back({{"target", o.target}, {"signature_score", o.signature_score}, {"error", finite_or_null(o.error)},
                          {"simulations", o.simulations}});
      cands.back()["other_targets"] = others;
    }
    if (!c.bounds.empty()) cands.back()["bounds"] = bounds_json(c.bounds);
  }
  json added_json = json::array();
  for (const auto& a : added)
    added_json.push_back({{"effect", a.effect}, {"target", a.target}, {"parameters", a.parameters},
                          {"bounds", bounds_json(a.bounds)}, {"error_before", finite_or_null(a.error_before)},
                          {"error_after", finite_or_null(a.error_after)}, {"frequency", finite_or_null(a.frequency)},
                          {"tentative", a.tentative}, {"folder", a.folder}});
  json removals = json::array();
  for (const auto& r : removal_checks)
    removals.push_back({{"effect", r.effect}, {"criterion", finite_or_null(r.criterion)},
                        {"error_without", finite_or_null(r.error_without)},
                        {"explained_level", finite_or_null(r.explained_level)}, {"folder", r.folder},
                        {"dropped", r.dropped}});
  json points = json::object();
  for (const auto& [key, n] : effective_points)
    points[key] = {{"points", n}, {"from", effective_points_from.at(key)}};
  return {{"status", status == CampaignStatus::completed ? "completed" : "failed"},
          {"message", message},
          {"base", base},
          {"noise", params_json(noise)},
          {"effective_points", points},
          {"scatter", params_json(scatter)},
          {"candidates", cands},
          {"chosen", chosen},
          {"outcome", to_string(outcome)},
          {"added", added_json},
          {"removal_checks", removals},
          {"pair_search", pair_search.rounds > 0 ? pair_search.to_json() : json()},
          {"headline", headline},
          {"conclusion", conclusion},
          {"notes", notes},
          {"verdict", verdict},
          {"frequency", frequency.to_json()},
          {"advised_candidate_simulations", advised_candidate_simulations > 0 ? json(advised_candidate_simulations) : json()},
          {"error_before", finite_or_null(error_before)},
          {"error_after", finite_or_null(error_after)},
          {"peak_normal_stress", finite_or_null(peak_normal_stress)},
          {"start_normal_stress", finite_or_null(start_normal_stress)},
          {"held_out", {{"rms", params_json(held_out_rms)}, {"noise", params_json(held_out_noise)},
                        {"error", finite_or_null(held_out_error)}, {"checks", held_out_checked}}},
          {"simulations", simulations},
          {"session", {{"simulated", simulated_this_session}}},
          {"wall_time_s", wall_time_s},
          {"timing", {{"wall_s", wall_time_s}, {"simulations_s", simulation_time_s}, {"model_s", model_time_s}}}};
}

}  // namespace demcal::pipelines
