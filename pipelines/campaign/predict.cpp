#include "demcal/pipelines/predict.hpp"

#include "campaign_internal.hpp"

#include "demcal/limits/limits.hpp"
#include "demcal/pipelines/backend.hpp"
#include "demcal/smoothing/objective.hpp"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <tuple>

namespace demcal::pipelines {

using detail::usable_status;
using nlohmann::json;

namespace {

// Largest force among the rows whose displacement lies in [lower, upper]; NaN rows skipped.
std::pair<double, double> peak_in_window(const smoothing::XYSeries& s, double lower, double upper) {
  double peak = CasePrediction::kNaN, at = CasePrediction::kNaN;
  for (std::size_t i = 0; i < s.x.size(); ++i) {
    if (!(s.x[i] >= lower && s.x[i] <= upper) || !std::isfinite(s.y[i])) continue;
    if (!std::isfinite(peak) || s.y[i] > peak) {
      peak = s.y[i];
      at = s.x[i];
    }
  }
  return {peak, at};
}

// Displacement of the first row (in time) inside [lower, upper] whose force reaches `level`; NaN when none does.
double first_reaching(const smoothing::XYSeries& s, double level, double lower, double upper) {
  for (std::size_t i = 0; i < s.x.size(); ++i)
    if (s.x[i] >= lower && s.x[i] <= upper && s.y[i] >= level) return s.x[i];
  return CasePrediction::kNaN;
}

void compare(const smoothing::Curve& measured, CasePrediction& p, const smoothing::ObjectiveOptions& options) {
  const auto result = smoothing::objective1(measured, scored_curve(p.status, p.simulated, measured, options), options);
  p.fitness = result.fitness;
  p.channels = result.channels;
  double sum_squares = 0;
  for (const auto& [name, value] : result.channels) sum_squares += value * value / options.points;
  p.rms_error = std::sqrt(sum_squares / static_cast<double>(result.channels.size()));
  const std::string channel = smoothing::common_channels(measured, p.simulated, options).front();
  const auto exp = smoothing::series(measured, channel, options.force_column);
  const auto sim = smoothing::series(p.simulated, channel, options.force_column);
  const auto exp_env = smoothing::loading_envelope(exp);
  const auto sim_env = smoothing::loading_envelope(sim);
  std::tie(p.window_lower, p.window_upper) = smoothing::objective_window(exp_env, sim_env, options.window, channel);
  std::tie(p.measured_peak, p.measured_peak_displacement) = peak_in_window(exp, p.window_lower, p.window_upper);
  std::tie(p.simulated_peak, p.simulated_peak_displacement) = peak_in_window(sim, p.window_lower, p.window_upper);
  if (std::isfinite(p.measured_peak) && p.measured_peak != 0)
    p.peak_error = (p.simulated_peak - p.measured_peak) / p.measured_peak;
  p.measured_rise_displacement = first_reaching(exp, CasePrediction::kRise * p.measured_peak, p.window_lower, p.window_upper);
  p.simulated_rise_displacement = first_reaching(sim, CasePrediction::kRise * p.simulated_peak, p.window_lower, p.window_upper);
}

// One run per case of the campaign's external command (its template, timeout, parallelism and
// output limit) with the parameter set `values`, each reported to `done`. Its per-run folders go under
// options.work_folder, or under a temporary folder removed afterwards.
void predict_through_command(const CampaignConfig& config, const std::map<std::string, double>& values,
                             const PredictionOptions& options, const OutcomeCallback& done) {
  namespace fs = std::filesystem;
  // a placeholder the set does not give is a missing parameter here, not a bad template
  std::vector<std::string> names;
  try {
    names = command_parameter_placeholders(config.backend.command);
  } catch (const std::invalid_argument& e) {
    throw CampaignError(config.source + ": backend.command: " + e.what());
  }
  for (const auto& name : names)
    if (!values.count(name))
      throw CampaignError(config.source + ": backend.command takes {" + name + "}, which the parameter set does not give");
  struct RemovedAfter {  // the temporary folder, removed however the runs end
    fs::path path;
    ~RemovedAfter() {
      std::error_code ignored;
      if (!path.empty()) fs::remove_all(path, ignored);
    }
  } temporary;
  fs::path work_root = fs::path(options.work_folder) / "runs";
  if (options.work_folder.empty()) {
    // a folder of its own: the process id and a counter keep concurrent predictions apart
    static std::atomic<unsigned> counter{0};
    temporary.path = fs::temp_directory_path() /
                     ("demcal-predict-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    work_root = temporary.path;
  }
  std::vector<std::string> parameter_names;
  for (const auto& [name, value] : values) parameter_names.push_back(name);
  const auto backend = detail::make_command_backend(config, work_root.string(), parameter_names,
                                                    options.threads > 0 ? options.threads : config.backend.parallel);
  std::vector<SimulationTask> tasks;
  for (std::size_t i = 0; i < config.cases.size(); ++i) tasks.push_back({i, values});
  backend->run(tasks, done);
}

}  // namespace

json CasePrediction::to_json() const {
  json ch = json::object();
  for (const auto& [name, value] : channels) ch[name] = finite_or_null(value);
  return {{"name", name},
          {"status", status},
          {"message", message},
          {"fitness", finite_or_null(fitness)},
          {"channels", ch},
          {"rms_error", finite_or_null(rms_error)},
          {"measured_peak", finite_or_null(measured_peak)},
          {"measured_peak_displacement", finite_or_null(measured_peak_displacement)},
          {"simulated_peak", finite_or_null(simulated_peak)},
          {"simulated_peak_displacement", finite_or_null(simulated_peak_displacement)},
          {"peak_error", finite_or_null(peak_error)},
          {"measured_rise_displacement", finite_or_null(measured_rise_displacement)},
          {"simulated_rise_displacement", finite_or_null(simulated_rise_displacement)},
          {"window", {finite_or_null(window_lower), finite_or_null(window_upper)}},
          {"wall_time_s", wall_time_s},
          {"engine", details.contains("peak_force")
                         ? json{{"peak_force", details["peak_force"]},
                                {"steps", details.value("steps", json(nullptr))},
                                {"hinges", details.value("hinges", json::array())},
                                {"sliding_joints", details.value("sliding_joints", json::array())}}
                         : json(nullptr)}};
}

std::map<std::string, double> read_result_parameters(const std::string& path) {
  if (auto m = limits::check_file_size(path)) throw CampaignError(path + ": " + *m);
  std::ifstream in(path);
  if (!in) throw CampaignError(path + ": cannot read the result file");
  json j;
  try {
    j = json::parse(in);
  } catch (const std::exception& e) {
    throw CampaignError(path + ": not valid JSON (" + e.what() + ")");
  }
  if (!j.contains("best") || !j["best"].is_object() || !j["best"].contains("params") ||
      !j["best"]["params"].is_object())
    throw CampaignError(path + ": no object 'best.params' (is it a result.json of demcal calibrate?)");
  std::map<std::string, double> params;
  for (const auto& [name, value] : j["best"]["params"].items()) {
    if (!value.is_number())
      throw CampaignError(path + ": best.params." + name + ": not a number (" + value.dump() + ")");
    params[name] = value.get<double>();
  }
  if (params.empty()) throw CampaignError(path + ": best.params is empty");
  return params;
}

std::map<std::string, double> complete_parameters(const CampaignConfig& config,
                                                  const std::map<std::string, double>& params) {
  std::map<std::string, double> out = params;
  for (const auto& [name, value] : config.space.fixed_parameters()) out.emplace(name, value);
  if (const auto& tied = config.space.tied_parameter(); tied && !out.count(tied->name)) {
    const auto source = out.find(tied->source);
    if (source == out.end())
      throw CampaignError(config.source + ": tied parameter '" + tied->name + "' needs '" + tied->source +
                          "', which the parameter set lacks");
    out[tied->name] = source->second / tied->ratio;
  }
  for (const auto& [name, value] : out)
    if (!std::isfinite(value))
      throw CampaignError("parameter '" + name + "': value is not finite (" + std::to_string(value) + ")");
  return out;
}

std::vector<CasePrediction> predict_cases(const CampaignConfig& config, const std::map<std::string, double>& params,
                                          const PredictionOptions& options) {
  if (config.cases.empty()) throw CampaignError(config.source + ": no case to predict");
  const auto values = complete_parameters(config, params);
  std::vector<smoothing::Curve> measured;
  for (const auto& c : config.cases) measured.push_back(load_measured(c.measured));

  std::vector<CasePrediction> out(config.cases.size());
  const OutcomeCallback compare_case = [&](std::size_t i, SimulationOutcome&& outcome) {
    CasePrediction& p = out[i];
    p.name = config.cases[i].name;
    p.status = outcome.status;
    p.message = outcome.message;
    p.simulated = std::move(outcome.curves);
    p.wall_time_s = outcome.wall_time_s;
    p.details = std::move(outcome.details);
    if (!usable_status(p.status) || p.simulated.rows() < 2) return;
    try {
      compare(measured[i], p, config.objective_options);
    } catch (const std::exception& e) {
      p.status = "failed";
      p.message = std::string("comparison with the measured curve failed: ") + e.what();
    }
  };
  if (config.backend.type == "command") {
    predict_through_command(config, values, options, compare_case);
    return out;
  }
  std::vector<dem::Scene> scenes;
  for (std::size_t i = 0; i < config.cases.size(); ++i) {
    const auto& c = config.cases[i];
    const std::string where = config.source + ": cases[" + std::to_string(i) + "].scene";
    dem::Scene scene = build_scene(c.scene, where);
    dem::Scene probe = scene;
    for (const auto& [name, value] : values) {
      try {
        dem::set_parameter(probe, name, value);
      } catch (const std::exception& e) {
        throw CampaignError(config.source + ": case '" + c.name + "': " + e.what());
      }
    }
    scenes.push_back(std::move(scene));
  }
  run_pool(
      config.cases.size(), options.threads > 0 ? options.threads : hardware_threads(),
      [&](std::size_t i) { return simulate_with_parameters(scenes[i], values); }, compare_case);
  return out;
}

smoothing::Curve scored_curve(const std::string& status, const smoothing::Curve& simulated,
                              const smoothing::Curve& measured, const smoothing::ObjectiveOptions& options) {
  if (status != "collapsed") return simulated;
  return smoothing::continued_after_collapse(simulated, smoothing::envelope_ends(measured, options), options);
}

json prediction_json(const std::map<std::string, double>& params, const std::vector<CasePrediction>& cases) {
  json p = json::object();
  for (const auto& [name, value] : params) p[name] = value;
  json list = json::array();
  for (const auto& c : cases) list.push_back(c.to_json());
  return {{"params", p}, {"cases", list}};
}

}  // namespace demcal::pipelines
