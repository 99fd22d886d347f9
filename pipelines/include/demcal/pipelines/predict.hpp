// Prediction: simulate the cases of a campaign file with one given parameter set (for example the
// best set of another campaign's result.json) and measure how far each simulated curve lies from
// its measured one. This is the "worth" test of a calibration: calibrate on some experiments, then
// predict others the calibration never saw.
//
//   auto config = load_campaign("data/walls/predict-SW200-SW250.json");
//   auto params = read_result_parameters("demo-out/walls/worth/result.json");
//   auto report = predict_cases(config, params);   // one CasePrediction per case
//
// The campaign's `parameters` bounds and `optimiser` are not used; its cases (scene + measured
// curve + column mapping), objective points and channel weights are, and its backend when that is
// an external command (the engine otherwise). Fixed parameters of the
// campaign fill names the given set lacks, and a tied parameter is derived from its source when
// absent. Errors are measured in the force unit of the engine (N) and displacements in m.
#pragma once

#include "demcal/pipelines/campaign.hpp"
#include "demcal/smoothing/curve.hpp"
#include "demcal/smoothing/objective.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <vector>

namespace demcal::pipelines {

struct PredictionOptions {
  int threads = 0;  // simulations at once; <= 0 = the campaign backend's own count (every hardware
                    // thread for the engine, backend.parallel for an external command)
  // A campaign whose backend is an external command (`"backend": {"type": "command"}`) predicts
  // through that command, one run per case: the folder its per-run folders are made under ("" = a
  // temporary folder, removed afterwards). Other campaigns run the built-in engine.
  std::string work_folder;
};

// One case simulated with the given parameters, against its measured curve.
struct CasePrediction {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  std::string name;                // the case's name in the campaign
  std::string status = "failed";   // engine status (completed, collapsed, step_limit, ...) or "failed"
  std::string message;             // engine message, or why the comparison failed
  smoothing::Curve simulated;      // time (s), force (N), gauges (m)
  double fitness = kNaN;           // objective 1 (paper eqs. 16-20) on the raw curves, N
  std::map<std::string, double> channels;  // objective 1 per displacement channel (unweighted), N
  // Root-mean-square force error over the objective's evaluation points, N: for each channel
  // f_c / sqrt(points); with several channels, sqrt of the mean of the squared per-channel values.
  double rms_error = kNaN;
  // Peak force of each curve inside the displacement window both curves share (the objective's
  // window on the first channel), N, and the displacement (m) where it occurs.
  double measured_peak = kNaN;
  double measured_peak_displacement = kNaN;
  double simulated_peak = kNaN;
  double simulated_peak_displacement = kNaN;
  double peak_error = kNaN;        // (simulated - measured) / measured, dimensionless
  // The displacement (m) where each curve first reaches kRise of its peak inside the window: how
  // early the stiffness carries the load, apart from how high the peak is.
  static constexpr double kRise = 0.8;
  double measured_rise_displacement = kNaN;
  double simulated_rise_displacement = kNaN;
  double window_lower = kNaN;      // m, the shared displacement window of the first channel
  double window_upper = kNaN;
  double wall_time_s = 0;          // the simulation's wall time
  nlohmann::json details = nlohmann::json::object();  // the engine summary (peak_force, hinges, ...)

  bool ok() const { return status != "failed" && std::isfinite(fitness); }
  nlohmann::json to_json() const;  // everything but the curve, NaN as null
};

// The best parameter set of a result.json written by `demcal calibrate` (`best.params`: SI units,
// friction in degrees). Throws CampaignError naming the file and key when it is missing or malformed.
std::map<std::string, double> read_result_parameters(const std::string& result_json_path);

// The parameter set each case is simulated with: `params`, completed by the campaign's fixed
// parameters and its tied parameter (when absent from `params`). Throws CampaignError when a
// name is unknown to a case's scene or a value is not finite.
std::map<std::string, double> complete_parameters(const CampaignConfig& config,
                                                  const std::map<std::string, double>& params);

// The curve a run is scored with: a collapsed run's continued at zero force to the end of the
// measured curve (smoothing::continued_after_collapse: it carries nothing after its collapse), any
// other run's as it is. Campaign fitness, predictions and diagnoses all score through it.
smoothing::Curve scored_curve(const std::string& status, const smoothing::Curve& simulated,
                              const smoothing::Curve& measured, const smoothing::ObjectiveOptions& options);

// Simulates every case of `config` with `params` (completed as above) and compares each with its
// measured curve. A run that fails is a CasePrediction with status "failed" and a message; bad
// input (unreadable measured file, unknown parameter) throws CampaignError before any simulation.
std::vector<CasePrediction> predict_cases(const CampaignConfig& config, const std::map<std::string, double>& params,
                                          const PredictionOptions& options = {});

// The compact JSON of a prediction: {"params": {...}, "cases": [CasePrediction::to_json()...]}.
nlohmann::json prediction_json(const std::map<std::string, double>& params,
                               const std::vector<CasePrediction>& cases);

}  // namespace demcal::pipelines
