// Gaussian-process regression of a noisy scalar (the calibration fitness) over the optimiser's unit
// cube [0,1]^d.
//
// Model: y = m + f(x) + e, f ~ GP(0, s² k(x, x')), e ~ N(0, σn²), with the ARD Matérn-5/2 kernel
//   k(r) = (1 + √5 r + 5/3 r²) exp(−√5 r),  r² = Σ_k (x_k − x'_k)² / l_k²
// on the standardised targets (y − mean) / sd. The hyperparameters (one length l_k per coordinate,
// signal variance s², nugget σn²) maximise the marginal likelihood: L-BFGS (NLopt LD_LBFGS with the
// analytic gradient) in log space from `restarts` starting points, the first at fixed central values
// and the rest drawn from a generator seeded by `seed`, so a fit is a deterministic function of the
// data and the options. The nugget is what makes the model honest on a noisy objective: the
// stick-slip jumps of objective 2 are fitted as noise rather than as structure.
//
// Log transform: with LogTransform::automatic and all targets > 0, the model is fitted both to y and
// to log y and keeps the one with the smaller leave-one-out mean absolute error in y units (the
// back-transformed prediction of the log model is exp(mean), its median). Leave-one-out predictions
// are the closed forms of Rasmussen & Williams eq. 5.12 at the fitted hyperparameters.
//
// Predictions are in "model space" (y, or log y): mean and the standard deviation of the latent f;
// predictive intervals for a new observation add the nugget. Everything stays in the unit cube: the
// caller maps physical parameters with optimise::ParameterSpace::to_unit.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>

namespace demcal::surrogate {

enum class LogTransform { automatic, never, always };
std::string to_string(LogTransform transform);
LogTransform parse_log_transform(const std::string& text);  // "auto" | "never" | "always"

struct GpOptions {
  int restarts = 6;                  // starting points of the likelihood maximisation, >= 1
  int max_iterations = 200;          // L-BFGS evaluations per start, >= 10
  std::uint64_t seed = 1;            // starting points 2.. (the first is fixed)
  double min_length = 0.02;          // bounds of each length scale l_k, unit-cube lengths
  double max_length = 20.0;
  double min_noise = 1e-6;           // bounds of the nugget σn² as a fraction of the variance of the
  double max_noise = 1.0;            // standardised targets (i.e. of the sample variance of y)
  LogTransform log_transform = LogTransform::automatic;
  // Throws std::invalid_argument naming the option and value.
  void Validate() const;
  nlohmann::json to_json() const;
  static GpOptions from_json(const nlohmann::json& json, const std::string& where);
};

struct GpPrediction {
  double mean = 0;        // model space (y or log y)
  double sd = 0;          // standard deviation of the latent function, model space
  double noise_sd = 0;    // the nugget's standard deviation, model space
  // Predictive standard deviation of a new observation: sqrt(sd² + noise_sd²).
  double observation_sd() const;
};

// Leave-one-out summary at the fitted hyperparameters (targets in y units).
struct LooSummary {
  double mean_absolute_error = 0;   // mean |ŷ_-i − y_i|, y units
  double relative_error = 0;        // mean |ŷ_-i − y_i| / mean |y_i − mean(y)| (0 = perfect, 1 = no
                                    // better than predicting the mean)
  double coverage90 = 0;            // fraction of y_i inside their 90 % predictive interval
};

enum class GpStatus { fitted, too_few_points };

class GaussianProcess {
 public:
  GaussianProcess() = default;
  explicit GaussianProcess(GpOptions options);

  // Fits hyperparameters and transform to the rows of X (n x d, unit cube) and finite y (n). At
  // least 3 points are needed (else status() is too_few_points and predict() throws). Throws
  // std::invalid_argument on non-finite data or mismatched sizes.
  GpStatus fit(const Eigen::MatrixXd& X, const Eigen::VectorXd& y);
  // Conditions on new data with the current hyperparameters and transform (no new maximisation):
  // for a model trained elsewhere (demcal surrogate train) applied to a campaign's runs.
  void condition(const Eigen::MatrixXd& X, const Eigen::VectorXd& y);

  GpStatus status() const { return status_; }
  bool fitted() const { return status_ == GpStatus::fitted; }
  int dimension() const { return static_cast<int>(X_.cols()); }
  long points() const { return static_cast<long>(X_.rows()); }
  bool log_transformed() const { return log_; }

  GpPrediction predict(const Eigen::VectorXd& unit_point) const;
  // The model-space mean alone: O(n d), without the O(n²) variance (for searches on the mean).
  double predict_mean(const Eigen::VectorXd& unit_point) const;
  // Model-space value of a fitness (log y or y) and back.
  double to_model(double y) const;
  double from_model(double z) const;
  // Predictive interval of a new observation at `unit_point` with probability `level` (e.g. 0.9),
  // in y units.
  std::pair<double, double> interval(const Eigen::VectorXd& unit_point, double level) const;
  // The smallest model-space target of the training data (the incumbent of expected improvement).
  double best_model_target() const;

  LooSummary leave_one_out() const;
  // Fitted hyperparameters: length scales (unit cube), signal variance and nugget (both in units of
  // the standardised targets), the negative log marginal likelihood.
  const Eigen::VectorXd& length_scales() const { return lengths_; }
  double signal_variance() const { return signal_; }
  double noise_variance() const { return noise_; }
  // The nugget as a standard deviation in model space (the noise level the fit recovered).
  double noise_sd() const;
  double negative_log_likelihood() const { return nll_; }
  const GpOptions& options() const { return options_; }

  // Everything needed to predict (options, hyperparameters, transform, training data) and back.
  nlohmann::json to_json() const;
  static GaussianProcess from_json(const nlohmann::json& json, const std::string& where);

 private:
  void factorise();  // Cholesky of K and alpha for the current hyperparameters and data
  GpOptions options_;
  GpStatus status_ = GpStatus::too_few_points;
  bool log_ = false;
  Eigen::MatrixXd X_;
  Eigen::VectorXd y_;          // targets as given (y units)
  Eigen::VectorXd z_;          // standardised model-space targets
  double z_mean_ = 0, z_sd_ = 1;
  Eigen::VectorXd lengths_;
  double signal_ = 1, noise_ = 1e-2, nll_ = 0;
  Eigen::MatrixXd L_;          // Cholesky factor of K (lower)
  Eigen::VectorXd alpha_;      // K^-1 z
};

// Matérn-5/2 correlation (without the signal variance) of two unit-cube points.
double matern52(const Eigen::VectorXd& a, const Eigen::VectorXd& b, const Eigen::VectorXd& lengths);

// Standard normal density and distribution function, and the quantile (for interval levels).
double normal_pdf(double u);
double normal_cdf(double u);
double normal_quantile(double p);

}  // namespace demcal::surrogate
