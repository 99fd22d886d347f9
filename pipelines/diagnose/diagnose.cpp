// The diagnosis loop (diagnose.hpp): base fit, residual, signatures, extended calibrations,
// selection. Each stage is one function; run_diagnosis lists them.
#include "demcal/pipelines/diagnose.hpp"
#include "diagnose_internal.hpp"

#include "demcal/dem/effects.hpp"
#include "demcal/limits/limits.hpp"
#include "demcal/pipelines/predict.hpp"
#include "demcal/pipelines/surrogate_data.hpp"
#include "demcal/smoothing/objective.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <iterator>
#include <set>
#include <sstream>

namespace demcal::pipelines {

namespace fs = std::filesystem;
using nlohmann::json;

using detail::format_number;
using detail::file_safe;
using detail::parameter_field;
using detail::write_diagnosis_report;

void DiagnoseOptions::Validate() const {
  auto fail = [](const std::string& field, const std::string& value, const std::string& rule) {
    throw CampaignError("diagnose option " + field + " = " + value + ": " + rule);
  };
  if (output.empty()) fail("output", "\"\"", "must name a folder");
  if (max_simulations < 0) fail("max_simulations", std::to_string(max_simulations), "must be >= 0");
  if (max_candidates < 1) fail("max_candidates", std::to_string(max_candidates), "must be >= 1");
  if (candidates_at_split < 0)
    fail("candidates_at_split", std::to_string(candidates_at_split), "must be >= 0 (0: every effect)");
  if (candidate_evaluations < 0) fail("candidate_evaluations", std::to_string(candidate_evaluations), "must be >= 0");
  if (!(evidence_threshold > 0)) fail("evidence_threshold", std::to_string(evidence_threshold), "must be > 0");
  if (!(tie_margin >= 0)) fail("tie_margin", std::to_string(tie_margin), "must be >= 0");
  if (!(close_target_share > 0 && close_target_share <= 1))
    fail("close_target_share", std::to_string(close_target_share), "must be in (0, 1]");
  if (!(close_candidate_share > 0 && close_candidate_share <= 1))
    fail("close_candidate_share", std::to_string(close_candidate_share), "must be in (0, 1]");
  if (profile_evaluations < 0) fail("profile_evaluations", std::to_string(profile_evaluations), "must be >= 0");
  if (continued_evaluations < -1)
    fail("continued_evaluations", std::to_string(continued_evaluations), "must be >= 0 (-1: a candidate's budget)");
  if (scatter_runs < 0) fail("scatter_runs", std::to_string(scatter_runs), "must be >= 0");
  const auto bounded = [&](const std::string& field, long value) {
    if (auto m = limits::check(limits::Limit::evaluations, static_cast<double>(value)))
      fail(field, std::to_string(value), *m);
  };
  bounded("max_simulations", max_simulations);
  bounded("candidate_evaluations", candidate_evaluations);
  bounded("profile_evaluations", profile_evaluations);
  bounded("continued_evaluations", continued_evaluations);
  bounded("scatter_runs", scatter_runs);
  if (!(scatter_floor_ratio > 0)) fail("scatter_floor_ratio", std::to_string(scatter_floor_ratio), "must be > 0");
  if (!(noise_level_ratio >= 1)) fail("noise_level_ratio", std::to_string(noise_level_ratio), "must be >= 1");
  if (!(held_out_tolerance >= 0)) fail("held_out_tolerance", std::to_string(held_out_tolerance), "must be >= 0");
  if (!(held_out_reproduced_ratio >= 1))
    fail("held_out_reproduced_ratio", std::to_string(held_out_reproduced_ratio), "must be >= 1");
  if (candidate_algorithm.empty()) fail("candidate_algorithm", "\"\"", "must name an optimiser");
  if (surrogate_kind != "gp" && surrogate_kind != "mlp") fail("surrogate_kind", "\"" + surrogate_kind + "\"", "must be gp or mlp");
  if (!(candidate_initial_step > 0 && candidate_initial_step <= 0.5))
    fail("candidate_initial_step", std::to_string(candidate_initial_step), "must be in (0, 0.5]");
  const bool wide = narrow_log_factor == 0 && narrow_linear_share == 0;
  if (!wide && !(narrow_log_factor > 1)) fail("narrow_log_factor", std::to_string(narrow_log_factor), "must be > 1 (or 0 with narrow_linear_share 0)");
  if (!wide && !(narrow_linear_share > 0 && narrow_linear_share <= 1))
    fail("narrow_linear_share", std::to_string(narrow_linear_share), "must be in (0, 1] (or 0 with narrow_log_factor 0)");
  for (auto name = effects.begin(); name != effects.end(); ++name) {
    try {
      dem::find_effect(*name);
    } catch (const dem::SceneError& e) {
      fail("effects", *name, e.what());
    }
    if (std::find(effects.begin(), name, *name) != name) fail("effects", *name, "named twice");
  }
}

namespace {

json params_json(const std::map<std::string, double>& params) {
  json j = json::object();
  for (const auto& [k, v] : params) j[k] = finite_or_null(v);
  return j;
}

std::string key_of(const ChannelResidual& c) { return c.case_name + "/" + c.channel; }

// RMS force error over every channel: sqrt of the mean of the per-channel mean squares.
double overall_error(const std::vector<ChannelResidual>& residuals) {
  if (residuals.empty()) return Diagnosis::kNaN;
  double sum = 0;
  for (const auto& c : residuals) sum += c.rms * c.rms;
  return std::sqrt(sum / static_cast<double>(residuals.size()));
}

// Root mean square of per-channel values ("<case>/<channel>" -> N), NaN ones left out; 0 when none.
double overall(const std::map<std::string, double>& per_channel) {
  double sum = 0;
  int n = 0;
  for (const auto& [key, v] : per_channel)
    if (std::isfinite(v)) {
      sum += v * v;
      ++n;
    }
  return n ? std::sqrt(sum / n) : 0.0;
}

double overall_noise(const std::vector<ChannelResidual>& residuals) {
  double sum = 0;
  for (const auto& c : residuals) sum += c.noise * c.noise;
  return std::sqrt(sum / static_cast<double>(std::max<std::size_t>(1, residuals.size())));
}

void progress(const DiagnoseOptions& o, const std::string& line) {
  if (o.progress) std::cerr << "diagnose: " << line << std::endl;
}

// What one parameter set does to every case: the simulated curves and their residuals.
struct Evaluation {
  bool ok = false;
  std::string message;
  std::vector<CasePrediction> cases;
  std::vector<ChannelResidual> residuals;  // per case and channel, on the base grid when one is given
  std::vector<ChannelResidual> held_out;   // channels of weight 0 and of held-out cases, not fitted
  double error = Diagnosis::kNaN;
  double held_out_error = Diagnosis::kNaN;
};

bool is_held_out(const std::string& case_name, const std::vector<std::string>& held_out_cases) {
  return std::find(held_out_cases.begin(), held_out_cases.end(), case_name) != held_out_cases.end();
}

// Simulates parameter sets on the campaign's cases and counts the runs.
class CaseRunner {
 public:
  CaseRunner(const CampaignConfig& config, const std::vector<std::string>& held_out_cases)
      : held_out_cases_(held_out_cases) {
    for (const auto& c : config.cases) measured_.emplace(c.name, load_measured(c.measured));
  }

  // Simulates `params` on `config` (the base or an extended model). With `grid` (the base
  // residuals) the residuals are taken on the same displacements, so fits compare point by point.
  Evaluation evaluate(const CampaignConfig& config, const std::map<std::string, double>& params,
                      const std::vector<ChannelResidual>* grid = nullptr) {
    Evaluation e;
    const auto start = std::chrono::steady_clock::now();
    e.cases = predict_cases(config, params);
    simulation_s_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    simulations_ += static_cast<long>(e.cases.size());
    simulated_this_session_ += static_cast<long>(e.cases.size());
    std::size_t g = 0;
    for (std::size_t k = 0; k < e.cases.size(); ++k) {
      const auto& p = e.cases[k];
      if (!p.ok()) {
        e.message = "case " + p.name + ": " + p.status + (p.message.empty() ? "" : " (" + p.message + ")");
        return e;
      }
      const auto found = measured_.find(p.name);
      if (found == measured_.end()) {
        e.message = "case " + p.name + " is not a case of the campaign";
        return e;
      }
      const smoothing::Curve& measured = found->second;
      const smoothing::Curve simulated = scored_curve(p.status, p.simulated, measured, config.objective_options);
      const auto channels = smoothing::common_channels(measured, simulated, config.objective_options);
      const bool case_held_out = is_held_out(p.name, held_out_cases_);
      for (const auto& ch : channels) {
        const auto weight = config.objective_options.channel_weights.find(ch);
        const auto sim = smoothing::series(simulated, ch, config.objective_options.force_column);
        if (case_held_out || (weight != config.objective_options.channel_weights.end() && weight->second == 0)) {
          // not fitted: a check of the fit, on its own grid
          try {
            ChannelResidual r = analyse_channel(smoothing::series(measured, ch, config.objective_options.force_column),
                                                sim, config.objective_options.points, config.objective_options.window);
            r.case_name = p.name;
            r.channel = ch;
            e.held_out.push_back(std::move(r));
          } catch (const smoothing::CurveError&) {
            // a held-out channel the simulation does not reach is left out of the check
          }
          continue;
        }
        ChannelResidual r;
        if (grid) {
          if (g >= grid->size()) {
            e.message = "the model's channels differ from the base model's";
            return e;
          }
          r = resimulated((*grid)[g++], sim);
        } else {
          r = analyse_channel(smoothing::series(measured, ch, config.objective_options.force_column), sim,
                              config.objective_options.points, config.objective_options.window);
        }
        r.case_name = p.name;
        r.channel = ch;
        e.residuals.push_back(std::move(r));
      }
    }
    e.ok = true;
    e.error = overall_error(e.residuals);
    if (!e.held_out.empty()) e.held_out_error = overall_error(e.held_out);
    return e;
  }

  // Every run the diagnosis has evaluated, its calibrations' archived ones included, so that the
  // budget and the count of a resumed diagnosis are those of an uninterrupted one.
  long simulations() const { return simulations_; }
  long simulated_this_session() const { return simulated_this_session_; }
  void add_campaign(const CampaignResult& r) {
    simulations_ += r.simulations;
    simulated_this_session_ += r.simulated_this_session;
    simulation_s_ += r.simulation_time_s;
    model_s_ += r.model_time_s;
  }
  // This session's seconds waiting for simulations (direct runs and the calibrations') and in the
  // calibrations' models (surrogate fits and search).
  double simulation_seconds() const { return simulation_s_; }
  double model_seconds() const { return model_s_; }

 private:
  std::map<std::string, smoothing::Curve> measured_;  // by case name
  std::vector<std::string> held_out_cases_;
  long simulations_ = 0;
  long simulated_this_session_ = 0;  // direct runs and the calibrations' runs not read from the archive
  double simulation_s_ = 0, model_s_ = 0;
};

// Concatenated residual (or curve difference) over channels, each channel divided by its noise so
// that channels of different precision weigh alike.
std::vector<double> stacked(const std::vector<ChannelResidual>& base, const std::vector<ChannelResidual>* other) {
  std::vector<double> v;
  for (std::size_t c = 0; c < base.size(); ++c) {
    const double scale = std::isfinite(base[c].noise) && base[c].noise > 0 ? 1 / base[c].noise : 1.0;
    for (std::size_t i = 0; i < base[c].measured.size(); ++i)
      v.push_back(scale * (other ? (*other)[c].simulated[i] - base[c].simulated[i]
                                 : base[c].measured[i] - base[c].simulated[i]));
  }
  return v;
}

// ---- stage 1: the base fit ---------------------------------------------------------------------

// Every calibration of a diagnosis shares one archive, so that the refinement's surrogate starts
// from the base calibration's runs (same scene hash and objective); the extended models have scene
// hashes of their own.
std::string diagnosis_archive(const DiagnoseOptions& options) {
  return (fs::path(options.output) / "archive.sqlite").string();
}

// The campaign without its held-out cases: what every calibration of the diagnosis fits.
CampaignConfig fitted_cases(CampaignConfig config, const DiagnoseOptions& options) {
  std::erase_if(config.cases, [&](const CaseSpec& c) { return is_held_out(c.name, options.held_out_cases); });
  return config;
}

std::map<std::string, double> base_fit(const CampaignConfig& config, const DiagnoseOptions& options, CaseRunner& runner,
                                       double* fitness) {
  if (!options.base_result.empty()) {
    fs::path result = options.base_result;
    if (fs::is_directory(result)) result /= "result.json";
    progress(options, "base parameters from " + result.string());
    const auto params = read_result_parameters(result.string());
    // a calibration of this campaign's parameters, or the diagnosis would start from another model
    if (const std::string why = outside_space(config.space, params); !why.empty())
      throw CampaignError(result.string() + ": " + why + " (--result must be a calibration of this campaign's parameters)");
    std::ifstream in(result);
    const json j = json::parse(in, nullptr, false);
    *fitness = j.is_object() && j.contains("best") && j["best"].contains("fitness") && j["best"]["fitness"].is_number()
                   ? j["best"]["fitness"].get<double>()
                   : Diagnosis::kNaN;
    return params;
  }
  CampaignConfig base = fitted_cases(config, options);
  base.output = (fs::path(options.output) / "base").string();
  base.archive = diagnosis_archive(options);
  base.report = options.report;
  base.surrogate.options.cost_ratio = HUGE_VAL;  // as every search of the diagnosis (extended_campaign)
  if (options.max_simulations > 0)
    base.optimiser.max_evaluations = std::min(base.optimiser.evaluation_budget(), options.max_simulations / 2);
  progress(options, "base calibration (" + std::to_string(base.optimiser.evaluation_budget()) + " simulations) in " +
                        base.output);
  RunOptions run;
  run.resume = options.resume;
  run.progress = options.progress;
  const CampaignResult result = run_campaign(base, run);
  runner.add_campaign(result);
  if (result.status != CampaignStatus::completed || result.best.params.empty())
    throw CampaignError("the base calibration failed: " + result.message);
  *fitness = result.best.fitness;
  return result.best.params;
}

// ---- stage 3: signatures -----------------------------------------------------------------------

struct ExtendedModel {
  CampaignConfig config;
  std::vector<std::string> parameter_names;                   // set_parameter names of the effect
  std::vector<dem::EffectParameter> parameters;              // registry entry of each name, range resolved
  std::string target;
};

// The registry entry of an effect parameter's set_parameter name, its search range resolved for
// this structure (dem::scaled_search_range).
dem::EffectParameter registry_parameter(const dem::Effect& effect, const std::string& name,
                                        const dem::ResponseScales& scales) {
  for (const auto& p : effect.parameters)
    if (p.name == parameter_field(name)) return dem::scaled_search_range(p, scales);
  throw CampaignError("effect parameter " + name + " is not in the effect registry");
}

// What the base best run reached, for the structure-relative search ranges: the largest contact
// stress over the fitted cases, in the run and at its start (0 when a backend does not report them).
dem::ResponseScales response_scales(const Evaluation& base, const DiagnoseOptions& options) {
  dem::ResponseScales s;
  auto largest = [](const json& details, const char* key, double& into) {
    if (details.contains(key) && details[key].is_number()) into = std::max(into, details[key].get<double>());
  };
  for (const auto& c : base.cases)
    if (!is_held_out(c.name, options.held_out_cases)) {
      largest(c.details, "max_normal_stress", s.peak_normal_stress);
      largest(c.details, "start_normal_stress", s.start_normal_stress);
    }
  return s;
}

// The base model with `effect` switched on for `targets` in every case's scene (written to folder).
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
        if (std::find(fields.begin(), fields.end(), parameter_field(n)) == fields.end()) fields.push_back(parameter_field(n));
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

// Where in its search range each effect parameter is probed for the signature: from strong to mild.
constexpr double kProbeFractions[] = {0.2, 0.5, 0.8};
// Golden-section steps of the search of an effect's simplest form (search_simplest_form): from a
// bracket of half the range to about 3 % of it, within the reference arch's cap valley.
constexpr int kSimplestFormRefinements = 6;

// A parameter's value at fraction t of its search range (geometric for log-scaled ones).
double at_fraction(const dem::EffectParameter& p, double t) {
  if (p.log_scale && p.search_min > 0) return p.search_min * std::pow(p.search_max / p.search_min, t);
  return p.search_min + t * (p.search_max - p.search_min);
}

// Whether a signature share comes within `share` of a positive reference share: a signature is a
// linearisation from a few single runs, so shares that close do not order two targets or effects.
bool signature_comes_close(double score, double reference, double share) {
  return reference > 0 && score >= share * reference;
}

// Upper bound of a friction loss: never above the base friction angle of the same group.
double friction_cap(const std::string& name, const std::map<std::string, double>& base) {
  if (name.find("friction_loss_deg") == std::string::npos) return std::numeric_limits<double>::infinity();
  const auto dot = name.rfind('.');
  const std::string group_key = dot == std::string::npos ? "friction_deg" : name.substr(0, dot) + ".friction_deg";
  for (const auto& key : {group_key, std::string("friction_deg")})
    if (auto it = base.find(key); it != base.end()) return it->second;
  return std::numeric_limits<double>::infinity();
}

// The effect's parameters at fractions t[i] of their search ranges, over the base set.
std::map<std::string, double> effect_values(const ExtendedModel& m, const std::map<std::string, double>& base,
                                            const std::vector<double>& t) {
  std::map<std::string, double> values = base;
  for (std::size_t i = 0; i < m.parameter_names.size(); ++i)
    values[m.parameter_names[i]] = std::min(at_fraction(m.parameters[i], t[i]), friction_cap(m.parameter_names[i], base));
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

namespace {

// `best` with every free parameter of `config` moved by k x 1e-7 of itself: a set that differs from
// it by far less than anything physical (the scatter runs).
std::map<std::string, double> nudged(const std::map<std::string, double>& best, const CampaignConfig& config, int k) {
  auto moved = best;
  for (const auto& p : config.space.free_parameters()) moved[p.name] *= 1 + 1e-7 * k;
  return moved;
}

// A parameter set's run and its re-runs with every free parameter of `nudge_space` moved by k x 1e-7
// of itself (k = 1..reruns), each on `grid` (none: the first run's own grid), in that order; failed
// re-runs are left out, and a failed first run is returned alone.
std::vector<Evaluation> runs_with_reruns(const CampaignConfig& config, const CampaignConfig& nudge_space,
                                         const std::map<std::string, double>& params,
                                         const std::vector<ChannelResidual>* grid, int reruns, CaseRunner& runner) {
  std::vector<Evaluation> runs = {runner.evaluate(config, params, grid)};
  if (!runs.front().ok) return runs;
  const std::vector<ChannelResidual> on = grid ? *grid : runs.front().residuals;
  for (int k = 1; k <= reruns; ++k) {
    Evaluation again = runner.evaluate(config, nudged(params, nudge_space, k), &on);
    if (again.ok) runs.push_back(std::move(again));
  }
  return runs;
}

// The run of median error (of an even count, the worse middle one): a search keeps the luckiest run
// it meets, so a fit is judged on the middle of its run and re-runs.
const Evaluation& median_run(const std::vector<Evaluation>& runs) {
  std::vector<const Evaluation*> by_error;
  for (const auto& run : runs) by_error.push_back(&run);
  std::stable_sort(by_error.begin(), by_error.end(), [](const auto* a, const auto* b) { return a->error < b->error; });
  return *by_error[by_error.size() / 2];
}

// The simulation's own scatter per channel (into `per_channel`, "<case>/<channel>" -> N) and over
// all channels (returned; NaN with fewer than two runs): half the mean square difference of each
// pair of the runs' simulated curves (one set, re-run with its parameters moved by far less than
// anything physical, on one grid) estimates the variance of one curve.
double simulation_scatter(const std::vector<Evaluation>& runs, std::map<std::string, double>& per_channel) {
  if (runs.size() < 2) return Diagnosis::kNaN;
  const auto& first = runs.front().residuals;
  double total = 0;
  for (std::size_t c = 0; c < first.size(); ++c) {
    double sum = 0;
    int pairs = 0;
    for (std::size_t i = 0; i < runs.size(); ++i)
      for (std::size_t j = i + 1; j < runs.size(); ++j, ++pairs) {
        const auto& a = runs[i].residuals[c].simulated;
        const auto& b = runs[j].residuals[c].simulated;
        double sq = 0;
        for (std::size_t k = 0; k < a.size(); ++k) sq += (a[k] - b[k]) * (a[k] - b[k]);
        sum += sq / static_cast<double>(std::max<std::size_t>(1, a.size())) / 2;
      }
    const double variance = sum / pairs;
    per_channel[key_of(first[c])] = std::sqrt(variance);
    total += variance;
  }
  return std::sqrt(total / static_cast<double>(std::max<std::size_t>(1, first.size())));
}

// Sensitivity of the stacked curves to each free base parameter: one forward difference of 5 % of
// the unit cube (backwards at the upper bound).
std::vector<std::vector<double>> base_sensitivities(const CampaignConfig& config, const std::map<std::string, double>& best,
                                                    const std::vector<ChannelResidual>& base, CaseRunner& runner) {
  std::vector<std::vector<double>> columns;
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
    const Evaluation e = runner.evaluate(config, complete_parameters(config, params), &base);
    if (e.ok) columns.push_back(stacked(base, &e.residuals));
  }
  return columns;
}

// Candidate targets of an effect in this scene: each fixed block for support springs; joints for
// a gap (the base fit's hinges first, then its sliding joints); else the effect's default.
std::vector<std::vector<std::string>> targets_for(const dem::Effect& effect, const Evaluation& base,
                                                  const dem::Scene& scene) {
  std::vector<std::vector<std::string>> out;
  if (effect.target == dem::EffectTarget::support_blocks) {
    for (const auto& b : scene.blocks)
      if (b.fixed) out.push_back({b.name});
    return out;
  }
  if (effect.target != dem::EffectTarget::joint) return {{}};
  for (const char* key : {"hinges", "sliding_joints"})
    for (const auto& c : base.cases)
      if (c.details.contains(key) && c.details[key].is_array())
        for (const auto& joint : c.details[key]) {
          const std::vector<std::string> t{joint.get<std::string>()};
          if (std::find(out.begin(), out.end(), t) == out.end() && out.size() < 4) out.push_back(t);
        }
  return out;
}

// ---- stage 4: extended calibration ------------------------------------------------------------

CampaignConfig extended_campaign(const ExtendedModel& m, const CampaignConfig& config,
                                 const std::map<std::string, double>& best, const DiagnoseOptions& options,
                                 long evaluations, const fs::path& folder, const std::map<std::string, double>& warm) {
  CampaignConfig c = fitted_cases(m.config, options);
  std::map<std::string, double> narrowed_lower;  // a friction loss stays below the lowest friction searched
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
    narrowed_lower[s.name] = s.lower;
    space.add(s);
  }
  for (std::size_t i = 0; i < m.parameter_names.size(); ++i) {
    const dem::EffectParameter& p = m.parameters[i];
    optimise::ParameterSpec s;
    s.name = m.parameter_names[i];
    s.lower = p.search_min;
    std::map<std::string, double> caps = best;
    for (const auto& [name, lower] : narrowed_lower) caps[name] = lower;
    s.upper = std::min(p.search_max, friction_cap(s.name, caps));
    s.scale = p.log_scale ? optimise::ParameterSpec::Scale::log10 : optimise::ParameterSpec::Scale::linear;
    if (!(s.upper > s.lower)) s.lower = s.upper - 0.5 * (p.search_max - p.search_min);
    space.add(s);
  }
  for (const auto& [name, value] : config.space.fixed_parameters()) space.fix(name, value);
  if (const auto& tied = config.space.tied_parameter()) space.tie(tied->name, tied->source, tied->ratio);
  c.space = space;
  c.name = config.name + "+" + folder.filename().string();
  c.output = folder.string();
  c.archive = diagnosis_archive(options);
  c.report = options.report;
  c.optimiser.max_evaluations = evaluations;
  c.optimiser.algorithm = options.candidate_algorithm;
  c.surrogate.options.kind = options.surrogate_kind;
  // Rounds of one point per worker, never grown by the cost rule: a candidate's search is short
  // (tens of simulations in up to six dimensions), where fewer rounds cost accuracy (measured: the
  // compliant-support loop test missed the soft support with rounds grown to 4 points, found it
  // with 2), and a verdict must not depend on how busy the machine was.
  c.surrogate.options.cost_ratio = HUGE_VAL;
  const bool local = options.candidate_algorithm.rfind("nlopt:", 0) == 0;
  if (local || options.candidate_algorithm == "bo") {
    // Warm start: the base best with the effect at its best-explaining probe, clipped to the box
    // (the local search's start; the first point of the Bayesian search's design).
    const auto names = space.free_names();
    const Eigen::VectorXd lower = space.lower_bounds(), upper = space.upper_bounds();
    c.optimiser.initial_point.clear();
    for (std::size_t i = 0; i < names.size(); ++i) {
      const auto it = warm.find(names[i]);
      const double v = it != warm.end() ? it->second : best.at(names[i]);
      c.optimiser.initial_point.push_back(std::clamp(v, lower(static_cast<Eigen::Index>(i)), upper(static_cast<Eigen::Index>(i))));
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

// The chosen effect's finding in a structural engineer's words, from its fitted parameters.
std::string finding(const EffectCandidate& c, const std::map<std::string, double>& base) {
  auto value = [&](const std::string& field, double* out) {
    for (const auto& [k, v] : c.params) {
      if (parameter_field(k) == field && base.find(k) == base.end()) {
        *out = v;
        return true;
      }
    }
    return false;
  };
  double a = 0, b = 0, d = 0;
  std::ostringstream s;
  if (c.effect == "joint-closure" && value("closure_max", &a)) {
    s << "the joints are rough and close nonlinearly: they stiffen as they close, up to a maximum closure of about "
      << format_number(a * 1e3) << " mm";
  } else if (c.effect == "friction-softening" && value("friction_loss_deg", &a) && value("slip_softening", &b)) {
    s << "friction is lost with sliding: its angle falls by about " << format_number(a) << "°";
    for (const auto& [k, v] : c.params)
      if (parameter_field(k) == "friction_deg") {
        s << " (from " << format_number(v) << "° to " << format_number(v - a) << "°)";
        break;
      }
    s << " over " << format_number(b * 1e3) << " mm of slip";
  } else if (c.effect == "cohesion" && value("cohesion", &a)) {
    s << "the joints are bonded: a cohesion of about " << format_number(a / 1e3) << " kPa";
    if (value("tensile_strength", &b)) s << " and a tensile strength of about " << format_number(b / 1e3) << " kPa";
    s << " hold until the first failure of each joint";
  } else if (c.effect == "crushing-cap" && value("compressive_strength", &a)) {
    s << "the masonry crushes where the thrust concentrates (a hinge or the toe) at about " << format_number(a / 1e6)
      << " MPa";
    if (value("crushing_softening", &b)) s << ", losing its strength over " << format_number(b * 1e3) << " mm";
  } else if (c.effect == "support-compliance") {
    s << "the supports yield elastically instead of being rigid";
    if (value("support_kx", &a)) s << ": horizontal stiffness about " << format_number(a / 1e6) << " MN/m (a 10 kN thrust moves it by about " << format_number(1e4 / a * 1e3) << " mm)";
    if (value("support_ky", &b)) s << ", vertical about " << format_number(b / 1e6) << " MN/m";
    if (value("support_kr", &d)) s << ", rotational about " << format_number(d / 1e3) << " kN·m/rad";
  } else if (c.effect == "joint-gap" && value("gap_opening", &a) && value("gap_taper", &b)) {
    const dem::JointGap gap{c.target, a, b};
    s << "joint " << c.target << " was already open before loading: about " << format_number(gap.intrados() * 1e3)
      << " mm at the intrados and " << format_number(gap.extrados() * 1e3) << " mm at the extrados (imperfect fit or lost mortar)";
  } else if (c.effect == "boundary-restraint" && value("beam_kr", &a)) {
    s << "the loading beam is neither fixed nor free in rotation: a rotational restraint of about "
      << format_number(a / 1e3) << " kN·m/rad";
  } else {
    s << "effect " << c.effect;
  }
  return s.str();
}

// ---- stage 5: selection ------------------------------------------------------------------------

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

// The bounds of every parameter of candidate c's effect (profile_bound: its fit re-simulated on the
// fitted cases with one parameter moved, the others re-fitted where that one run rules the value
// out), within the diagnosis's simulation budget.
void bound_effect_parameters(EffectCandidate& c, const ExtendedModel& m, const std::map<std::string, double>& best,
                             const std::vector<ChannelResidual>& grid, const std::vector<double>& effective_points,
                             CaseRunner& runner, const DiagnoseOptions& options) {
  const CampaignConfig fitted = fitted_cases(m.config, options);
  const long runs_per_trial = static_cast<long>(fitted.cases.size());
  const auto within_budget = [&](long runs) {
    return options.max_simulations <= 0 || runner.simulations() + runs_per_trial * runs <= options.max_simulations;
  };
  const ChangeAt change_at = [&](const std::map<std::string, double>& params) {
    const Evaluation e = runner.evaluate(fitted, params, &grid);
    return e.ok ? information_criterion_change(c.residuals, e.residuals, 0, effective_points) : Diagnosis::kNaN;
  };
  for (std::size_t i = 0; i < m.parameter_names.size(); ++i) {
    const std::string& name = m.parameter_names[i];
    if (!best.count(name)) continue;
    const auto values = bound_trial_values(m.parameters[i], best.at(name), friction_cap(name, best));
    if (!within_budget(static_cast<long>(values.size()))) return;  // over the budget: the rest stay unchecked
    const auto conditional = [&](double v) {
      std::map<std::string, double> params = best;
      params[name] = v;
      return change_at(params);
    };
    const auto refitted = [&](double v) {
      if (options.profile_evaluations == 0 || !within_budget(options.profile_evaluations)) return Diagnosis::kNaN;
      return refitted_change(m, best, name, v, change_at, options.profile_evaluations);
    };
    c.bounds.push_back(profile_bound(name, best.at(name), values, conditional, refitted, options.evidence_threshold));
  }
}

// Every calibrated candidate's criterion change against the base, all counted with the effective
// points of common_effective_points over the base and those candidates (kept in the diagnosis);
// returns them in the order of the base residuals.
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

// The extended calibration of one candidate: base + its effect into `folder`, at most `budget`
// simulations, warm-started at `warm`; its best set (into `best_set`, on every case) re-run and the
// fit judged on the run of median error, since the best of many runs of a model that slips or snaps
// may be a lucky one. Sets the fit's fields of `c` (its simulations added); false, with `c.reason`,
// when the best set cannot be re-simulated. Throws what run_campaign throws.
bool calibrate_candidate(EffectCandidate& c, std::map<std::string, double>& best_set, const ExtendedModel& m,
                         const CampaignConfig& config, const std::map<std::string, double>& base_params,
                         const DiagnoseOptions& options, long budget, const fs::path& folder,
                         const std::map<std::string, double>& warm, const std::vector<ChannelResidual>& base_residuals,
                         CaseRunner& runner) {
  const CampaignConfig ext = extended_campaign(m, config, base_params, options, budget, folder, warm);
  for (const auto& p : ext.space.free_parameters())  // the calibration's own box (its residual friction capped lower)
    if (c.search_ranges.count(p.name)) c.search_ranges[p.name] = {p.lower, p.upper};
  RunOptions run;
  run.resume = options.resume;
  run.progress = options.progress;
  const CampaignResult r = run_campaign(ext, run);
  runner.add_campaign(r);
  c.simulations += r.simulations;
  c.params = r.best.params;
  c.fitness = r.best.fitness;
  best_set = complete_parameters(ext, r.best.params);
  const std::vector<Evaluation> runs = runs_with_reruns(m.config, ext, best_set, &base_residuals, options.scatter_runs, runner);
  if (!runs.front().ok) {
    c.reason = "its best set cannot be re-simulated: " + runs.front().message;
    return false;
  }
  c.rerun_errors.clear();
  for (const auto& one : runs) c.rerun_errors.push_back(one.error);
  const Evaluation& e = median_run(runs);
  c.residuals = e.residuals;
  c.error = e.error;
  c.rms.clear();
  for (const auto& ch : e.residuals) c.rms[key_of(ch)] = ch.rms;
  c.held_out_rms.clear();
  for (const auto& ch : e.held_out) c.held_out_rms[key_of(ch)] = ch.rms;
  c.held_out_error = e.held_out_error;
  c.effect_parameters = static_cast<int>(m.parameter_names.size());
  return true;
}

}  // namespace

void select_effect(Diagnosis& d, const DiagnoseOptions& options) {
  std::vector<EffectCandidate*> accepted, short_of_criterion;
  for (auto& c : d.candidates) {
    if (!c.tried) continue;
    if (!std::isfinite(c.score)) {
      c.verdict = "rejected";
      if (c.reason.empty()) c.reason = "no usable fit";
    } else if (c.score < -options.evidence_threshold && c.error < d.error_before) {
      if (const HeldOutCheck check = check_held_out(c, d, options); check.spoils) {
        c.verdict = "rejected";
        c.reason = "fits the calibrated curves (criterion change " + format_number(c.score) +
                   ") but spoils the data it was not fitted to, which the base fit reproduces: error there " +
                   format_number(check.base_error) + " -> " + format_number(check.candidate_error) + " N";
      } else {
        accepted.push_back(&c);
      }
    } else {
      c.verdict = "rejected";
      c.reason = c.score < -options.evidence_threshold
                     ? "the criterion falls (" + format_number(c.score) + ") but the RMS error does not (" +
                           format_number(d.error_before) + " -> " + format_number(c.error) + " N)"
                     : "the fit does not improve enough for its extra parameters (criterion change " +
                           format_number(c.score) + ", needs < -" + format_number(options.evidence_threshold) + ")";
      short_of_criterion.push_back(&c);
    }
  }
  std::sort(accepted.begin(), accepted.end(), [](auto* a, auto* b) { return a->score < b->score; });
  // A curve fit better by less than the noise does not dispute the criterion, here as for the
  // candidates short of it below.
  const double noise = overall_noise(d.base_residuals);
  std::vector<EffectCandidate*> tied;
  std::map<const EffectCandidate*, std::string> tie_reasons;
  for (auto* c : accepted) {
    const auto* front = accepted.front();
    if (c->score - front->score < options.tie_margin) {
      tied.push_back(c);
      tie_reasons[c] = "explains the data as well as the other tied effects (criteria within " +
                       format_number(options.tie_margin) + ")";
    } else if (c->error < front->error - noise) {
      // Both pass, the criterion prefers the front and the curves prefer this one by more than the
      // noise (a channel the front fits better outweighs the others, or the front adds fewer
      // parameters): the two measures disagree.
      tied.push_back(c);
      tie_reasons[c] = "passes the criterion less clearly than " + front->effect + " (" + format_number(c->score) +
                       " against " + format_number(front->score) + ") but fits the curves better (error " +
                       format_number(c->error) + " against " + format_number(front->error) + " N)";
    } else {
      c->verdict = "rejected";
      c->reason = "explains the data clearly less well than " + front->effect + " (criterion " +
                  format_number(c->score) + " against " + format_number(front->score) + ")";
      if (c->error < front->error)
        c->reason += "; its closer fit of the curves (error " + format_number(c->error) + " against " +
                     format_number(front->error) + " N) is within the noise (" + format_number(noise) + " N)";
    }
  }
  // One effect passes, and another that does not is as good by one of the two measures: it fits the
  // curves better by more than the noise (it adds more parameters, or its gain lies on a channel
  // with few independent points), or its criterion is within the tie margin of the passing one's
  // while it lowers the error too (the passing one is then preferred no more clearly than between
  // two that both pass). The data cannot tell them apart.
  if (tied.size() == 1) {
    auto* passing = tied.front();
    std::string rivals;  // each rival with its error, criterion and why it ties
    for (auto* c : short_of_criterion) {
      if (!std::isfinite(c->error)) continue;
      const bool fits_better = c->error < passing->error - noise;
      const bool as_likely = c->score - passing->score < options.tie_margin && c->error < d.error_before;
      if (!fits_better && !as_likely) continue;
      c->verdict = "tied";
      c->reason = fits_better ? "fits the curves better than " + passing->effect + " (error " + format_number(c->error) +
                                    " against " + format_number(passing->error) + " N) but does not pass the criterion (" +
                                    format_number(c->score) + ")"
                              : "does not pass the criterion (" + format_number(c->score) + ") but falls short of " +
                                    passing->effect + "'s (" + format_number(passing->score) + ") by less than " +
                                    format_number(options.tie_margin) + ", with the error lowered to " +
                                    format_number(c->error) + " N";
      rivals += (rivals.empty() ? "" : "; ") + c->effect + " (" + format_number(c->error) + " N, criterion " +
                format_number(c->score) + ") " +
                (fits_better ? "comes closer to the curves without passing the criterion"
                             : "falls short of its criterion by less than " + format_number(options.tie_margin));
    }
    if (!rivals.empty()) {
      passing->verdict = "tied";
      passing->reason = "passes the criterion (" + format_number(passing->score) + "), but " + rivals;
      d.chosen.clear();
      d.error_after = d.error_before;
      d.verdict = "The data cannot tell which effect is missing: " + passing->effect + " passes the criterion (error " +
                  format_number(d.error_before) + " -> " + format_number(passing->error) + " N, criterion " +
                  format_number(passing->score) + "), but " + rivals +
                  ". Each explains part of the residual, none clearly better (measurement noise about " +
                  format_number(noise) + " N); the model is not extended.";
      return;
    }
  }
  if (tied.size() == 1) {
    auto* c = tied.front();
    c->verdict = "accepted";
    c->reason = "criterion change " + format_number(c->score) + "; error " + format_number(d.error_before) + " -> " +
                format_number(c->error) + " N";
    if (std::isfinite(d.held_out_error))
      c->reason += "; on data not fitted " + format_number(d.held_out_error) + " -> " + format_number(c->held_out_error) + " N";
    d.chosen = {c->effect};
    d.error_after = c->error;
    d.verdict = "The base model misses one effect: " + finding(*c, d.base_params) + ". Adding " + c->effect +
                " lowers the RMS force error from " + format_number(d.error_before) + " N to " +
                format_number(c->error) + " N (measurement noise about " + format_number(noise) + " N).";
  } else if (tied.size() > 1) {
    std::string names;
    for (auto* c : tied) {
      c->verdict = "tied";
      c->reason = tie_reasons[c];
      names += (names.empty() ? "" : " or ") + c->effect;
    }
    d.chosen.clear();
    d.error_after = d.error_before;
    d.verdict = "The data cannot tell which effect is missing: " + names +
                " explain the residual equally well. Another test (a further channel, or a test of the same structure) "
                "is needed to choose; the model is not extended.";
  } else {
    d.chosen.clear();
    d.error_after = d.error_before;
    const double scatter = overall(d.scatter);
    const double floor = error_floor(noise, scatter, options);
    const std::string errors = "RMS force error " + format_number(d.error_before) + " N, noise about " +
                               format_number(noise) + " N, simulation scatter about " + format_number(scatter) + " N";
    const EffectCandidate* closest = nullptr;
    for (const auto* c : short_of_criterion)
      if (closest == nullptr || c->error < closest->error) closest = c;
    if (closest != nullptr && d.error_before > kUnexplainedRatio * floor) {
      // far above the noise: the model lacks something, which "no effect needed" would hide
      d.verdict = "No effect found: the base fit misses the curves by " + format_number(d.error_before / floor, 2) +
                  " x the noise and scatter combined (" + errors + "), so the model lacks something, but none of the "
                  "candidate effects explains enough of it for its extra parameters (closest: " + closest->effect +
                  ", " + format_number(d.error_before) + " -> " + format_number(closest->error) + " N, criterion " +
                  format_number(closest->score) + "). The missing effect is not among those tried, or their searches "
                  "did not reach its fit." + unfitted_data_note(d);
    } else {
      d.verdict = "No effect needed: none of the candidate effects explains the residual better than its extra "
                  "parameters cost (" + errors + ")." + unfitted_data_note(d);
    }
  }
}

namespace {
// The diagnosis's error floor (error_floor of its base noise and scatter), N.
double floor_of(const Diagnosis& d, const DiagnoseOptions& options) {
  return error_floor(overall_noise(d.base_residuals), overall(d.scatter), options);
}
}  // namespace

std::vector<std::string> candidates_to_search_further(const Diagnosis& d, const DiagnoseOptions& options) {
  const double floor = floor_of(d, options);
  const double explained = options.noise_level_ratio * floor;
  const auto open = [&](const EffectCandidate& c) { return c.tried && c.continued.simulations == 0 && c.error > explained; };
  // an accepted fit above the level: its own search first
  for (const auto& c : d.candidates)
    if (c.verdict == "accepted" && open(c)) return {c.effect};
  // an accepted fit at the level explains the residual; so does a base fit near it
  const bool explained_fit = std::any_of(d.candidates.begin(), d.candidates.end(), [&](const EffectCandidate& c) {
    return c.verdict == "accepted" && !(c.error > explained);
  });
  if (explained_fit) return {};
  const bool unexplained_base = d.error_before > kUnexplainedRatio * floor;
  std::vector<std::string> names;
  for (const auto& c : d.candidates) {
    if (!open(c) || c.verdict == "accepted") continue;
    const bool passes = c.score < -options.evidence_threshold && !check_held_out(c, d, options).spoils;
    if (c.verdict == "tied" || (unexplained_base && passes)) names.push_back(c.effect);
  }
  return names;
}

namespace {
// The chosen effect when its fit misses the curves by more than the explained level; else null.
const EffectCandidate* unexplained_chosen(const Diagnosis& d, const DiagnoseOptions& options) {
  if (d.chosen.size() != 1) return nullptr;
  const double explained = options.noise_level_ratio * floor_of(d, options);
  for (const auto& c : d.candidates)
    if (c.effect == d.chosen.front()) return c.error > explained ? &c : nullptr;
  return nullptr;
}
}  // namespace

std::string unexplained_fit_note(const Diagnosis& d, const DiagnoseOptions& options) {
  const EffectCandidate* chosen = unexplained_chosen(d, options);
  if (chosen == nullptr) return "";
  const double floor = floor_of(d, options);
  const double explained = options.noise_level_ratio * floor;
  const EffectCandidate* next = nullptr;  // the closest other fit
  for (const auto& c : d.candidates)
    if (&c != chosen && c.tried && std::isfinite(c.error) && (next == nullptr || c.error < next->error)) next = &c;
  std::string note = " Its fit still misses the curves by more than the noise and scatter allow (" +
                     format_number(chosen->error) + " N against " + format_number(explained) + " N, " +
                     format_number(options.noise_level_ratio, 3) + " x their combined " + format_number(floor) +
                     " N): " + chosen->effect + " explains part of the residual, not all of it; the rest is another "
                     "effect, or a form of this one its search did not reach";
  if (next != nullptr)
    note += " (the closest other fit: " + next->effect + ", " + format_number(next->error) + " N, criterion " +
            format_number(next->score) + ")";
  return note + ".";
}

long advised_candidate_simulations(const Diagnosis& d, const DiagnoseOptions& options, long per_candidate) {
  bool unresolved = unexplained_chosen(d, options) != nullptr;
  if (d.chosen.empty()) {
    const bool tie =
        std::any_of(d.candidates.begin(), d.candidates.end(), [](const EffectCandidate& c) { return c.verdict == "tied"; });
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

double error_floor(double noise, double scatter, const DiagnoseOptions& options) {
  if (!std::isfinite(scatter)) return noise;
  return std::hypot(noise, std::min(scatter, options.scatter_floor_ratio * noise));
}

ChannelResidual resimulated(const ChannelResidual& base, const smoothing::XYSeries& simulated) {
  ChannelResidual r = base;
  const auto envelope = smoothing::loading_envelope(simulated);
  // on the base's grid, held beyond its reach (a one-point envelope: a gauge that never passed its start)
  if (envelope.x.empty()) throw smoothing::CurveError("a simulated curve has no loading point");
  for (std::size_t i = 0; i < r.displacement.size(); ++i) r.simulated[i] = smoothing::interpolate(envelope, r.displacement[i]);
  complete_residual(r);
  detail::note_simulated_sampling(r, simulated, envelope);
  return r;
}

bool response_splits(double scatter, double noise, const DiagnoseOptions& options) {
  return scatter > options.scatter_floor_ratio * noise;
}

int candidates_to_calibrate(bool splits, const DiagnoseOptions& options) {
  if (!splits) return options.max_candidates;
  if (options.candidates_at_split == 0) return std::numeric_limits<int>::max();
  return std::max(options.max_candidates, options.candidates_at_split);
}

std::string split_response_note(const Diagnosis& d, const DiagnoseOptions& options) {
  const double noise = overall_noise(d.base_residuals), scatter = overall(d.scatter);
  if (!response_splits(scatter, noise, options)) return "";
  std::string rerun_errors;
  for (const double e : d.base_rerun_errors) rerun_errors += (rerun_errors.empty() ? "" : ", ") + format_number(e);
  std::string note = " The base fit sits where the model's response splits: its re-runs, parameters moved by 1e-7, score " +
                     rerun_errors + " N and scatter by " + format_number(scatter) + " N, " +
                     format_number(scatter / noise, 2) +
                     " x the noise; that scatter is the point's, not the model's, and the floor counts it up to " +
                     format_number(options.scatter_floor_ratio, 2) + " x the noise.";
  const auto tried = std::count_if(d.candidates.begin(), d.candidates.end(), [](const auto& c) { return c.tried; });
  if (tried > options.max_candidates)
    note += " The signatures, differences of single runs there, do not rank the effects: " + std::to_string(tried) +
            " were calibrated instead of the top " + std::to_string(options.max_candidates) + ".";
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
    listed += (listed.empty() ? "" : "; ") + free[j].name + " " + format_number(physical(static_cast<Eigen::Index>(j))) +
              " at the " + (u <= kAtBound ? "lower" : "upper") + " end of [" + format_number(free[j].lower) + ", " +
              format_number(free[j].upper) + "]";
  }
  if (listed.empty()) return "";
  return " The base fit presses against its calibration range (" + listed +
         "): the data ask for more than the range allows, because the range is too narrow or because the parameter "
         "stands in for something the base model lacks; a calibration over a wider range tells the two apart.";
}

std::string narrow_window_note(const Diagnosis& d) {
  std::string narrow;
  for (const auto& r : d.base_residuals) {
    if (!(r.coverage < kNarrowWindow)) continue;
    narrow += (narrow.empty() ? "" : ", ") + r.case_name + "/" + r.channel + " over " +
              format_number(100 * r.coverage, 2) + " %";
  }
  if (narrow.empty()) return "";
  return " The base fit is compared with part of the measured range only: " + narrow +
         " (its gauge stops short in the simulation, and a gauge that hardly moves matches over what it reaches). "
         "Set \"objective\": {\"window\": \"measured\"} to compare every channel over its measured range.";
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
    missed += (missed.empty() ? "" : ", ") + key + " (RMS " + format_number(rms) + " N";
    if (noise != d.held_out_noise.end() && std::isfinite(noise->second) && noise->second > 0)
      missed += ", " + format_number(rms / noise->second, 2) + " x its noise";
    missed += ")";
  }
  if (missed.empty()) return "";
  return " But the base fit misses data it was not fitted to: " + missed +
         ". An effect may show only there; to let the diagnosis use that data, fit it (a channel weight above 0, "
         "or the case left out of --held-out).";
}

std::vector<std::string> held_out_checks(const Diagnosis& d, const DiagnoseOptions& options) {
  std::vector<std::string> keys;
  for (const auto& [key, rms] : d.held_out_rms) {
    const auto noise = d.held_out_noise.find(key);
    if (noise != d.held_out_noise.end() && std::isfinite(noise->second) &&
        rms <= options.held_out_reproduced_ratio * noise->second)
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

Diagnosis run_diagnosis(const CampaignConfig& config, const DiagnoseOptions& options) {
  const auto start = std::chrono::steady_clock::now();
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
  for (const auto& name : options.held_out_cases)
    if (std::none_of(config.cases.begin(), config.cases.end(), [&](const CaseSpec& c) { return c.name == name; }))
      throw CampaignError("--held-out: the campaign has no case named '" + name + "'");
  if (fitted_cases(config, options).cases.empty())
    throw CampaignError("--held-out: every case of the campaign is held out, nothing is left to fit");
  // The base calibration gets at most half of a total budget, and a search needs two populations.
  if (const long least = 4L * config.optimiser.population;
      options.max_simulations > 0 && options.base_result.empty() && options.max_simulations < least)
    throw CampaignError("--max-simulations " + std::to_string(options.max_simulations) +
                        ": the base calibration gets at most half of it, and needs two populations of " +
                        std::to_string(config.optimiser.population) + "; give at least " + std::to_string(least) +
                        " (or --result with a finished base calibration)");
  fs::create_directories(options.output);
  CaseRunner runner(config, options.held_out_cases);
  Diagnosis d;

  // 1. base fit, then the same search the candidates get, on the base parameters alone: an
  // effect must beat the best the base model can do with that search, not a less refined fit.
  d.base_params = base_fit(config, options, runner, &d.base_fitness);
  const long per_candidate = options.candidate_evaluations > 0 ? options.candidate_evaluations
                                                                : config.optimiser.evaluation_budget();
  // Within a total budget the refinement takes at most a quarter of what the base fit left.
  const long refine_budget = options.max_simulations > 0
                                 ? std::min(per_candidate, (options.max_simulations - runner.simulations()) / 4)
                                 : per_candidate;
  if (refine_budget >= 2 * config.optimiser.population) {
    ExtendedModel plain;
    plain.config = config;
    const fs::path folder = fs::path(options.output) / "base-refined";
    const CampaignConfig refine = extended_campaign(plain, config, d.base_params, options, refine_budget, folder, d.base_params);
    progress(options, "refining the base fit (" + std::to_string(refine_budget) + " simulations) in " + folder.string());
    RunOptions run;
    run.resume = options.resume;
    run.progress = options.progress;
    const CampaignResult r = run_campaign(refine, run);
    runner.add_campaign(r);
    if (r.status == CampaignStatus::completed && std::isfinite(r.best.fitness) &&
        (!std::isfinite(d.base_fitness) || r.best.fitness < d.base_fitness)) {
      d.base_params = r.best.params;
      d.base_fitness = r.best.fitness;
    }
  }
  const auto base_params = complete_parameters(config, d.base_params);
  // A calibration's budget within a total one: room is left for its best set's run and re-runs.
  const auto within_budget = [&](long wanted) {
    if (options.max_simulations <= 0) return wanted;
    return std::min(wanted, options.max_simulations - runner.simulations() - (1 + options.scatter_runs));
  };

  // 2. residual, of the base best set judged like every candidate: on the run of median error among
  // it and its re-runs, which also measure the simulation's own scatter
  const std::vector<Evaluation> base_runs =
      runs_with_reruns(config, config, base_params, nullptr, options.scatter_runs, runner);
  if (!base_runs.front().ok) throw CampaignError("the base best set cannot be simulated: " + base_runs.front().message);
  for (const auto& run : base_runs) d.base_rerun_errors.push_back(run.error);
  const double scatter = simulation_scatter(base_runs, d.scatter);
  const Evaluation& base = median_run(base_runs);
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
  const double noise = overall_noise(base.residuals);
  // Sensitivities and signatures compare fitted curves only: held-out cases are not simulated for them.
  const CampaignConfig fitted = fitted_cases(config, options);
  progress(options, "base RMS force error " + format_number(d.error_before) + " N, noise " + format_number(noise) +
                        " N, simulation scatter " + format_number(scatter) + " N");

  std::vector<const dem::Effect*> effects;
  if (options.effects.empty()) {
    for (const auto& e : dem::effect_registry()) effects.push_back(&e);
  } else {
    for (const auto& n : options.effects) effects.push_back(&dem::find_effect(n));
  }

  const bool at_noise = d.error_before <= options.noise_level_ratio * error_floor(noise, scatter, options);
  std::map<std::string, ExtendedModel> models;                   // effect -> its best-signature extension
  std::map<std::string, std::map<std::string, double>> best_sets;  // effect -> its fit's complete parameter set
  if (at_noise) {
    for (const auto* e : effects) {
      EffectCandidate c;
      c.effect = e->name;
      c.reason = "the base fit is already within the noise and the simulation's scatter";
      d.candidates.push_back(c);
    }
  } else {
    // 3. signatures
    const auto residual = stacked(base.residuals, nullptr);
    const auto sensitivities = base_sensitivities(fitted, base_params, base.residuals, runner);
    std::map<std::string, std::map<std::string, double>> warm_starts;  // effect -> best probe's parameters
    // A target probed for its signature: the candidate's signature fields, its model, its warm start.
    struct ProbedTarget {
      EffectCandidate candidate;
      ExtendedModel model;
      std::map<std::string, double> warm;
    };
    std::map<std::string, std::vector<ProbedTarget>> close_targets;  // effect -> other targets calibrated too
    const dem::Scene first_scene = build_scene(config.cases.front().scene, config.source + ": cases[0].scene");
    const dem::ResponseScales scales = response_scales(base, options);
    if (scales.peak_normal_stress > 0) d.peak_normal_stress = scales.peak_normal_stress;
    if (scales.start_normal_stress > 0) d.start_normal_stress = scales.start_normal_stress;
    for (const auto* e : effects) {
      EffectCandidate best_target;
      best_target.effect = e->name;
      best_target.signature_score = -1;
      std::vector<ProbedTarget> probed_targets;
      for (const auto& targets : targets_for(*e, base, first_scene)) {
        EffectCandidate c;
        c.effect = e->name;
        c.target = targets.empty() ? "" : targets.front();
        ExtendedModel m;
        try {
          m = extend(config, *e, targets, scales, fs::path(options.output) / "candidates" / (e->name + (c.target.empty() ? "" : "@" + c.target)));
        } catch (const std::exception& ex) {
          c.reason = std::string("not applicable here: ") + ex.what();
          c.signature_score = -1;
          if (best_target.signature_score < 0 && best_target.reason.empty()) best_target = c;
          continue;
        }
        for (std::size_t i = 0; i < m.parameter_names.size(); ++i)
          c.search_ranges[m.parameter_names[i]] = {
              m.parameters[i].search_min,
              std::min(m.parameters[i].search_max, friction_cap(m.parameter_names[i], base_params))};
        std::vector<std::vector<double>> signatures;
        std::map<std::string, double> warm;  // the probe closest to the measurement starts the search
        double warm_error = std::numeric_limits<double>::infinity();
        const CampaignConfig probed = fitted_cases(m.config, options);
        const auto probe_at = [&](const std::vector<double>& t) {
          const auto values = effect_values(m, base_params, t);
          const Evaluation s = runner.evaluate(probed, values, &base.residuals);
          if (s.ok && s.error < warm_error) {
            warm_error = s.error;
            warm = values;
          }
          return s;
        };
        const auto points = probe_points(m.parameter_names.size());
        for (const auto& t : points) {
          const Evaluation s = probe_at(t);
          if (s.ok) signatures.push_back(stacked(base.residuals, &s.residuals));
        }
        // one more run where the probes, taken as linear, say the residual is explained: the
        // search's start when it fits better than every probe
        if (signatures.size() == points.size()) {
          const auto t = linearised_fractions(residual, sensitivities, signatures, m.parameter_names.size(),
                                              kProbeFractions[0], kProbeFractions[2]);
          if (!t.empty()) probe_at(t);
        }
        // starts only, not signatures: a form the range holds at its end is no small change
        const auto probe_error = [&](const std::vector<double>& t) {
          const Evaluation s = probe_at(t);
          return s.ok ? s.error : std::numeric_limits<double>::quiet_NaN();
        };
        search_simplest_form(m.parameters, probe_error, kSimplestFormRefinements);
        if (!signatures.empty()) c.signature_score = signature_score(residual, sensitivities, signatures);
        if (signatures.empty() && c.reason.empty()) c.reason = "every probe run of the effect failed";
        if (!c.target.empty())
          progress(options, "  " + e->name + " at " + c.target + ": signature " + format_number(100 * c.signature_score, 2) +
                                " %, best probe " + format_number(warm_error) + " N");
        if (!signatures.empty()) probed_targets.push_back({c, m, warm});
        if (c.signature_score > best_target.signature_score) {
          best_target = c;
          models[e->name] = m;
          warm_starts[e->name] = warm;
        }
      }
      for (auto& t : probed_targets)
        if (t.candidate.target != best_target.target &&
            signature_comes_close(t.candidate.signature_score, best_target.signature_score, options.close_target_share))
          close_targets[e->name].push_back(std::move(t));
      if (best_target.signature_score < 0) {
        best_target.signature_score = 0;
        if (best_target.reason.empty()) best_target.reason = "no target for this effect in the scene";
      }
      progress(options, e->name + (best_target.target.empty() ? "" : " at " + best_target.target) +
                            ": signature explains " + format_number(100 * best_target.signature_score, 2) +
                            " % of the residual the base parameters cannot remove");
      d.candidates.push_back(best_target);
    }
    std::stable_sort(d.candidates.begin(), d.candidates.end(),
                     [](const auto& a, const auto& b) { return a.signature_score > b.signature_score; });

    // 4. extended calibrations, best signature first, within the budget; where the base response
    // splits, more of them (the signatures rank by realisation there)
    const bool splits = response_splits(scatter, noise, options);
    const int limit = candidates_to_calibrate(splits, options);
    if (splits && limit > options.max_candidates)
      progress(options, "the base fit sits where the response splits (scatter " + format_number(scatter) + " N, noise " +
                            format_number(noise) + " N): more than the top " + std::to_string(options.max_candidates) +
                            " effects by signature are calibrated (--candidates-at-split)");
    // An effect's other targets whose signatures its best one does not clearly beat (close_targets):
    // each calibrated alike; `c` keeps the fit of lower error, c.other_targets the others.
    const auto calibrate_close_targets = [&](EffectCandidate& c) {
      for (auto& other : close_targets[c.effect]) {
        const long other_budget = within_budget(per_candidate);
        if (other_budget < 2 * config.optimiser.population) break;
        const fs::path other_folder =
            fs::path(options.output) / "candidates" / (c.effect + "-at-" + file_safe(other.candidate.target));
        progress(options, "calibrating base + " + c.effect + " at " + other.candidate.target + " too (signature " +
                              format_number(100 * other.candidate.signature_score, 2) + " % against " +
                              format_number(100 * c.signature_score, 2) + " % at " + c.target + ", " +
                              std::to_string(other_budget) + " simulations) in " + other_folder.string());
        EffectCandidate alt = other.candidate;
        alt.tried = true;
        std::map<std::string, double> alt_set;
        try {
          calibrate_candidate(alt, alt_set, other.model, config, d.base_params, options, other_budget, other_folder,
                              other.warm, base.residuals, runner);
        } catch (const std::exception& ex) {
          progress(options, "the calibration of " + c.effect + " at " + alt.target + " failed: " + ex.what());
        }
        const bool better = std::isfinite(alt.error) && !(alt.error >= c.error);
        EffectCandidate& loser = better ? c : alt;
        std::vector<EffectCandidate::OtherTarget> others = std::move(c.other_targets);
        others.push_back({loser.target, loser.signature_score, loser.error, loser.simulations});
        const long simulations = c.simulations + alt.simulations;
        if (better) {
          c = std::move(alt);
          models[c.effect] = other.model;
          best_sets[c.effect] = alt_set;
        }
        c.other_targets = std::move(others);
        c.simulations = simulations;
      }
    };
    int tried = 0;
    double last_tried_signature = 0;  // of the limit-th effect tried
    for (auto& c : d.candidates) {
      if (!models.count(c.effect)) continue;
      const bool below_cut = tried >= limit;
      if (below_cut && !signature_comes_close(c.signature_score, last_tried_signature, options.close_candidate_share)) {
        c.reason = "ranked below the " + std::to_string(limit) + " effects tried";
        continue;
      }
      const long budget = within_budget(per_candidate);
      if (budget < 2 * config.optimiser.population) {
        c.reason = "over the simulation budget";
        continue;
      }
      const fs::path folder = fs::path(options.output) / "candidates" / c.effect;
      const std::string why = below_cut ? ", its signature close to the last one tried" : "";
      progress(options, "calibrating base + " + c.effect + " (" + std::to_string(budget) + " simulations" + why + ") in " +
                            folder.string());
      if (++tried == limit) last_tried_signature = c.signature_score;
      c.tried = true;
      try {
        calibrate_candidate(c, best_sets[c.effect], models.at(c.effect), config, d.base_params, options, budget, folder,
                            warm_starts[c.effect], base.residuals, runner);
      } catch (const std::exception& ex) {
        c.reason = std::string("its calibration failed: ") + ex.what();
      }
      calibrate_close_targets(c);
    }
  }

  // 5. selection
  std::vector<double> effective_points = score_candidates(d);
  if (at_noise) {
    d.error_after = d.error_before;
    d.verdict = "No effect needed: the base fit is already within the measurement noise and the simulation's own "
                "scatter (RMS force error " + format_number(d.error_before) + " N; noise about " + format_number(noise) +
                " N, scatter of the simulated curve about " + format_number(scatter) + " N)." + unfitted_data_note(d);
  } else {
    select_effect(d, options);
    // 5b. a search continued while the selection leaves the residual above the floor: the search,
    // not the effect, may be what leaves the error there (a stiffness whose truth is a narrow valley)
    const double explained = options.noise_level_ratio * floor_of(d, options);
    const long continued_budget = options.continued_evaluations < 0 ? per_candidate : options.continued_evaluations;
    std::set<std::string> searched_further;
    while (continued_budget > 0) {
      std::vector<std::string> names = candidates_to_search_further(d, options);
      std::erase_if(names, [&](const std::string& n) { return searched_further.count(n) || !models.count(n); });
      if (names.empty()) break;
      // an accepted effect's own search takes what is left; contenders get the same search or none
      const bool accepted_alone =
          names.size() == 1 && std::any_of(d.candidates.begin(), d.candidates.end(), [&](const EffectCandidate& c) {
            return c.effect == names.front() && c.verdict == "accepted";
          });
      const long budget = accepted_alone ? within_budget(continued_budget) : continued_budget;
      const bool affordable = options.max_simulations <= 0 ||
                              runner.simulations() + static_cast<long>(names.size()) * (budget + 1 + options.scatter_runs) <=
                                  options.max_simulations;
      if (budget < 2 * config.optimiser.population || !affordable) {
        progress(options, "no further search of " + std::to_string(names.size()) + " effect(s): " +
                              std::to_string(continued_budget) + " simulations each are short of two populations or "
                              "over --max-simulations");
        break;
      }
      for (const auto& name : names) {
        searched_further.insert(name);
        auto& c = *std::find_if(d.candidates.begin(), d.candidates.end(), [&](const auto& x) { return x.effect == name; });
        const fs::path folder = fs::path(options.output) / "candidates" / (c.effect + "-continued");
        progress(options, c.effect + "'s fit stays above the noise and scatter (" + format_number(c.error) + " against " +
                              format_number(explained) + " N): its search continued (" + std::to_string(budget) +
                              " simulations) in " + folder.string());
        EffectCandidate next = c;
        next.simulations = 0;
        next.error = EffectCandidate::kNaN;  // stays NaN when the further search fails
        std::map<std::string, double> next_set;
        // another seed: a search of its own (and campaign of its own in the archive), whose surrogate
        // trains on the first search's runs
        ExtendedModel further = models.at(c.effect);
        further.config.optimiser.seed += 1;
        try {
          calibrate_candidate(next, next_set, further, config, d.base_params, options, budget, folder,
                              best_sets.at(c.effect), base.residuals, runner);
        } catch (const std::exception& ex) {
          progress(options, "the continued search of " + c.effect + " failed: " + ex.what());
        }
        ContinuedSearch continued{next.simulations, c.error, next.error, next.error < c.error};
        const long simulations = c.simulations + continued.simulations;
        if (continued.kept) {
          c = std::move(next);
          best_sets[c.effect] = next_set;
        }
        c.simulations = simulations;
        c.continued = continued;
      }
      effective_points = score_candidates(d);
      select_effect(d, options);
    }
    for (const auto& c : d.candidates)
      if (c.continued.simulations > 0) d.verdict += " " + c.continued.describe(c.effect);
    d.verdict += unexplained_fit_note(d, options);
    if (options.bound_parameters) {
      std::vector<std::string> bounds;  // of the chosen effect, for the verdict
      for (auto& c : d.candidates) {
        if (c.verdict != "accepted" && c.verdict != "tied") continue;
        progress(options, "checking how tightly the data pin the parameters of " + c.effect);
        bound_effect_parameters(c, models.at(c.effect), best_sets.at(c.effect), base.residuals, effective_points, runner,
                                options);
        if (c.verdict == "accepted")
          for (const auto& b : c.bounds) bounds.push_back(b.describe());
      }
      if (!bounds.empty()) {
        d.verdict += " How tightly the data pin it, each parameter moved with the others re-fitted:";
        for (std::size_t i = 0; i < bounds.size(); ++i) d.verdict += (i ? "; " : " ") + bounds[i];
        d.verdict += ".";
      }
    }
    d.advised_candidate_simulations = advised_candidate_simulations(d, options, per_candidate);
    d.verdict += more_search_note(d.advised_candidate_simulations, per_candidate);
  }
  d.verdict += split_response_note(d, options) + base_at_bound_note(d, config.space) + narrow_window_note(d) +
               sparse_measurement_note(d);
  d.simulations = runner.simulations();
  d.simulated_this_session = runner.simulated_this_session();
  d.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  d.simulation_time_s = runner.simulation_seconds();
  d.model_time_s = runner.model_seconds();
  {
    std::ofstream out(fs::path(options.output) / "diagnosis.json");
    out << d.to_json().dump(2) << "\n";
    if (!out) throw CampaignError("cannot write " + (fs::path(options.output) / "diagnosis.json").string());
  }
  if (options.report) write_diagnosis_report(d, options);
  progress(options, d.verdict);
  return d;
}

std::string ContinuedSearch::describe(const std::string& effect) const {
  const std::string head = effect + "'s fit stayed above the noise and scatter, so it was searched " +
                           std::to_string(simulations) + " simulations further";
  if (kept) return head + ", which lowered its error from " + format_number(error_before) + " to " + format_number(error_found) + " N.";
  if (!std::isfinite(error_found)) return head + "; that search failed, and the first fit stands.";
  return head + " without a closer fit (" + format_number(error_found) + " N against " + format_number(error_before) +
         " N); the first fit stands.";
}

json ContinuedSearch::to_json() const {
  return {{"simulations", simulations}, {"error_before", finite_or_null(error_before)},
          {"error_found", finite_or_null(error_found)}, {"kept", kept}};
}

json Diagnosis::to_json() const {
  json base = {{"params", params_json(base_params)}, {"fitness", finite_or_null(base_fitness)}, {"rms", params_json(base_rms)},
               {"rerun_errors", base_rerun_errors}};
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
                     {"verdict", c.verdict},
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
    if (!c.other_targets.empty()) {
      json others = json::array();
      for (const auto& o : c.other_targets)
        others.push_back({{"target", o.target}, {"signature_score", o.signature_score}, {"error", finite_or_null(o.error)},
                          {"simulations", o.simulations}});
      cands.back()["other_targets"] = others;
    }
    if (!c.bounds.empty()) {
      json bounds = json::object();
      for (const auto& b : c.bounds) bounds[b.name] = b.to_json();
      cands.back()["bounds"] = bounds;
    }
  }
  json points = json::object();
  for (const auto& [key, n] : effective_points)
    points[key] = {{"points", n}, {"from", effective_points_from.at(key)}};
  return {{"status", status},
          {"message", message},
          {"base", base},
          {"noise", params_json(noise)},
          {"effective_points", points},
          {"scatter", params_json(scatter)},
          {"candidates", cands},
          {"chosen", chosen},
          {"verdict", verdict},
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
