#include "demcal/surrogate/gaussian_process.hpp"
#include "internal.hpp"

#include "demcal/common/format.hpp"
#include "demcal/common/random.hpp"

#include <Eigen/Cholesky>
#include <nlopt.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

namespace demcal::surrogate {

namespace {

constexpr double kSqrt5 = 2.23606797749978969641;
constexpr double kJitter = 1e-10;        // added to the diagonal on top of the nugget
constexpr double kMinSignal = 1e-2, kMaxSignal = 1e2;  // standardised signal variance bounds

// Correlation matrix of the rows of X and the per-pair scaled squared differences are recomputed
// per likelihood evaluation; n stays in the hundreds, so this is cheap next to one simulation.
struct LikelihoodProblem {
  const Eigen::MatrixXd* X;
  const Eigen::VectorXd* z;
  int evaluations = 0;
};

// Negative log marginal likelihood and its gradient in θ = (log l_1..d, log s², log σn²).
double negative_log_likelihood(const Eigen::MatrixXd& X, const Eigen::VectorXd& z, const double* theta,
                               double* grad) {
  const Eigen::Index n = X.rows(), d = X.cols();
  Eigen::VectorXd inv_l2(d);
  for (Eigen::Index k = 0; k < d; ++k) inv_l2[k] = std::exp(-2.0 * theta[k]);
  const double s2 = std::exp(theta[d]), noise = std::exp(theta[d + 1]);
  Eigen::MatrixXd K(n, n);
  for (Eigen::Index a = 0; a < n; ++a) {
    K(a, a) = s2 + noise + kJitter;
    for (Eigen::Index b = 0; b < a; ++b) {
      const double r = std::sqrt(((X.row(a) - X.row(b)).array().square() * inv_l2.transpose().array()).sum());
      K(a, b) = K(b, a) = s2 * (1.0 + kSqrt5 * r + 5.0 / 3.0 * r * r) * std::exp(-kSqrt5 * r);
    }
  }
  Eigen::LLT<Eigen::MatrixXd> llt(K);
  if (llt.info() != Eigen::Success) {
    if (grad)
      for (Eigen::Index j = 0; j < d + 2; ++j) grad[j] = 0.0;
    return 1e300;
  }
  const Eigen::VectorXd alpha = llt.solve(z);
  const Eigen::MatrixXd L = llt.matrixL();
  double nll = 0.5 * z.dot(alpha) + 0.5 * static_cast<double>(n) * std::log(2.0 * M_PI);
  for (Eigen::Index i = 0; i < n; ++i) nll += std::log(L(i, i));
  if (grad) {
    const Eigen::MatrixXd W = llt.solve(Eigen::MatrixXd::Identity(n, n)) - alpha * alpha.transpose();
    for (Eigen::Index j = 0; j < d + 2; ++j) grad[j] = 0.0;
    for (Eigen::Index a = 0; a < n; ++a) {
      grad[d] += 0.5 * W(a, a) * s2;
      grad[d + 1] += 0.5 * W(a, a) * noise;
      for (Eigen::Index b = 0; b < a; ++b) {
        const Eigen::ArrayXd scaled = (X.row(a) - X.row(b)).array().square().transpose() * inv_l2.array();
        const double r = std::sqrt(scaled.sum());
        const double e = std::exp(-kSqrt5 * r);
        const double w = W(a, b);  // the pair (a, b) and (b, a): factor 2 x 0.5
        grad[d] += w * s2 * (1.0 + kSqrt5 * r + 5.0 / 3.0 * r * r) * e;
        const double common = w * s2 * 5.0 / 3.0 * (1.0 + kSqrt5 * r) * e;
        for (Eigen::Index k = 0; k < d; ++k) grad[k] += common * scaled[k];
      }
    }
  }
  return nll;
}

double nlopt_objective(unsigned n, const double* x, double* grad, void* data) {
  auto* p = static_cast<LikelihoodProblem*>(data);
  ++p->evaluations;
  (void)n;
  return negative_log_likelihood(*p->X, *p->z, x, grad);
}

struct Hyper {
  Eigen::VectorXd theta;
  double nll = std::numeric_limits<double>::infinity();
};

Hyper maximise_likelihood(const Eigen::MatrixXd& X, const Eigen::VectorXd& z, const GpOptions& o) {
  const int d = static_cast<int>(X.cols());
  const int m = d + 2;
  std::vector<double> lower(m), upper(m);
  for (int k = 0; k < d; ++k) {
    lower[k] = std::log(o.min_length);
    upper[k] = std::log(o.max_length);
  }
  lower[d] = std::log(kMinSignal);
  upper[d] = std::log(kMaxSignal);
  lower[d + 1] = std::log(o.min_noise);
  upper[d + 1] = std::log(o.max_noise);
  std::mt19937_64 rng(o.seed);
  Hyper best;
  LikelihoodProblem problem{&X, &z};
  for (int start = 0; start < o.restarts; ++start) {
    std::vector<double> theta(m);
    if (start == 0) {
      for (int k = 0; k < d; ++k) theta[k] = std::log(0.3);
      theta[d] = 0.0;
      theta[d + 1] = std::log(0.05);
    } else {
      // Lengths log-uniform in [0.05, 2] (the useful range in a unit cube), signal in [0.3, 3],
      // nugget log-uniform across its bounds.
      for (int k = 0; k < d; ++k) theta[k] = std::log(0.05) + uniform01(rng) * (std::log(2.0) - std::log(0.05));
      theta[d] = std::log(0.3) + uniform01(rng) * (std::log(3.0) - std::log(0.3));
      theta[d + 1] = lower[d + 1] + uniform01(rng) * (upper[d + 1] - lower[d + 1]);
    }
    for (int j = 0; j < m; ++j) theta[j] = std::clamp(theta[j], lower[j], upper[j]);
    nlopt_opt opt = nlopt_create(NLOPT_LD_LBFGS, static_cast<unsigned>(m));
    nlopt_set_lower_bounds(opt, lower.data());
    nlopt_set_upper_bounds(opt, upper.data());
    nlopt_set_min_objective(opt, nlopt_objective, &problem);
    nlopt_set_maxeval(opt, o.max_iterations);
    nlopt_set_ftol_rel(opt, 1e-9);
    nlopt_set_xtol_rel(opt, 1e-7);
    double value = std::numeric_limits<double>::infinity();
    nlopt_optimize(opt, theta.data(), &value);  // roundoff-limited stops still leave the best point
    nlopt_destroy(opt);
    value = negative_log_likelihood(X, z, theta.data(), nullptr);
    if (value < best.nll) {
      best.nll = value;
      best.theta = Eigen::Map<Eigen::VectorXd>(theta.data(), m);
    }
  }
  return best;
}

}  // namespace

std::string to_string(LogTransform transform) {
  switch (transform) {
    case LogTransform::automatic: return "auto";
    case LogTransform::never: return "never";
    case LogTransform::always: return "always";
  }
  return "auto";
}

LogTransform parse_log_transform(const std::string& text) {
  if (text == "auto") return LogTransform::automatic;
  if (text == "never") return LogTransform::never;
  if (text == "always") return LogTransform::always;
  throw std::invalid_argument("log_transform = '" + text + "' (expected auto, never or always)");
}

void GpOptions::Validate() const {
  if (restarts < 1) throw std::invalid_argument("gp option restarts = " + std::to_string(restarts) + " must be >= 1");
  if (max_iterations < 10)
    throw std::invalid_argument("gp option max_iterations = " + std::to_string(max_iterations) + " must be >= 10");
  limits::require_within(limits::Limit::iterations, 1.0 * restarts * max_iterations, "gp options restarts x max_iterations");
  if (!(min_length > 0) || !(max_length > min_length) || !std::isfinite(max_length))
    throw std::invalid_argument("gp options min_length = " + format_number(min_length, round_trip_digits) +
                                ", max_length = " + format_number(max_length, round_trip_digits) +
                                " must satisfy 0 < min_length < max_length");
  if (!(min_noise > 0) || !(max_noise > min_noise) || !std::isfinite(max_noise))
    throw std::invalid_argument("gp options min_noise = " + format_number(min_noise, round_trip_digits) +
                                ", max_noise = " + format_number(max_noise, round_trip_digits) +
                                " must satisfy 0 < min_noise < max_noise");
}

namespace {

const FieldTable<GpOptions>& gp_fields() {
  static const FieldTable<GpOptions> table{
      field("restarts", &GpOptions::restarts),
      field("max_iterations", &GpOptions::max_iterations),
      field("seed", &GpOptions::seed),
      field("min_length", &GpOptions::min_length),
      field("max_length", &GpOptions::max_length),
      field("min_noise", &GpOptions::min_noise),
      field("max_noise", &GpOptions::max_noise),
      named_field("log_transform", &GpOptions::log_transform, parse_log_transform,
                  [](LogTransform t) { return to_string(t); }),
  };
  return table;
}

}  // namespace

nlohmann::json GpOptions::to_json() const { return gp_fields().to_json(*this); }

GpOptions GpOptions::from_json(const nlohmann::json& j, const std::string& where) {
  return detail::options_from_json(j, where, gp_fields());
}

double GpPrediction::observation_sd() const { return std::sqrt(sd * sd + noise_sd * noise_sd); }

GaussianProcess::GaussianProcess(GpOptions options) : options_(std::move(options)) { options_.Validate(); }

double GaussianProcess::to_model(double y) const { return log_ ? std::log(y) : y; }
double GaussianProcess::from_model(double z) const { return log_ ? std::exp(z) : z; }
double GaussianProcess::noise_sd() const { return z_sd_ * std::sqrt(noise_); }

void GaussianProcess::factorise() {
  const Eigen::Index n = X_.rows();
  Eigen::MatrixXd K(n, n);
  for (Eigen::Index a = 0; a < n; ++a) {
    K(a, a) = signal_ + noise_ + kJitter;
    for (Eigen::Index b = 0; b < a; ++b)
      K(a, b) = K(b, a) = signal_ * matern52(X_.row(a).transpose(), X_.row(b).transpose(), lengths_);
  }
  Eigen::LLT<Eigen::MatrixXd> llt(K);
  if (llt.info() != Eigen::Success) throw std::runtime_error("gaussian process: covariance matrix is not positive definite");
  L_ = llt.matrixL();
  alpha_ = llt.solve(z_);
}

GpStatus GaussianProcess::fit(const Eigen::MatrixXd& X, const Eigen::VectorXd& y) {
  options_.Validate();
  if (X.rows() != y.size()) throw std::invalid_argument("gaussian process: X has " + std::to_string(X.rows()) +
                                                        " rows, y has " + std::to_string(y.size()) + " values");
  for (Eigen::Index i = 0; i < y.size(); ++i)
    if (!std::isfinite(y[i]) || !X.row(i).allFinite())
      throw std::invalid_argument("gaussian process: training point " + std::to_string(i) + " is not finite");
  X_ = X;
  y_ = y;
  if (X.rows() < 3 || X.cols() < 1) {
    status_ = GpStatus::too_few_points;
    return status_;
  }
  const bool positive = (y.array() > 0).all();
  std::vector<bool> transforms;
  if (options_.log_transform != LogTransform::always || !positive) transforms.push_back(false);
  if (options_.log_transform != LogTransform::never && positive) transforms.push_back(true);
  if (options_.log_transform == LogTransform::always && !positive)
    throw std::invalid_argument("gaussian process: log_transform = always needs positive targets");

  double best_error = std::numeric_limits<double>::infinity();
  GaussianProcess best;
  for (bool log_transform : transforms) {
    GaussianProcess candidate(options_);
    candidate.X_ = X;
    candidate.y_ = y;
    candidate.log_ = log_transform;
    Eigen::VectorXd model = y;
    if (log_transform) model = y.array().log().matrix();
    candidate.z_mean_ = model.mean();
    const double var = (model.array() - candidate.z_mean_).square().sum() / static_cast<double>(model.size());
    candidate.z_sd_ = var > 0 ? std::sqrt(var) : 1.0;
    candidate.z_ = (model.array() - candidate.z_mean_) / candidate.z_sd_;
    const Hyper h = maximise_likelihood(X, candidate.z_, options_);
    const int d = static_cast<int>(X.cols());
    candidate.lengths_ = h.theta.head(d).array().exp();
    candidate.signal_ = std::exp(h.theta[d]);
    candidate.noise_ = std::exp(h.theta[d + 1]);
    candidate.nll_ = h.nll;
    candidate.factorise();
    candidate.status_ = GpStatus::fitted;
    const double error = candidate.leave_one_out().mean_absolute_error;
    if (error < best_error) {
      best_error = error;
      best = std::move(candidate);
    }
  }
  *this = std::move(best);
  return status_;
}

void GaussianProcess::condition(const Eigen::MatrixXd& X, const Eigen::VectorXd& y) {
  if (lengths_.size() == 0) throw std::logic_error("gaussian process: condition() needs fitted hyperparameters");
  if (X.cols() != lengths_.size())
    throw std::invalid_argument("gaussian process: data have " + std::to_string(X.cols()) + " coordinates, the model " +
                                std::to_string(lengths_.size()));
  if (X.rows() != y.size()) throw std::invalid_argument("gaussian process: X and y sizes differ");
  for (Eigen::Index i = 0; i < y.size(); ++i)
    if (!std::isfinite(y[i]) || (log_ && !(y[i] > 0)))
      throw std::invalid_argument("gaussian process: training value " + format_number(y[i], round_trip_digits) + " is not usable" +
                                  (log_ ? " by a log-transformed model" : ""));
  X_ = X;
  y_ = y;
  if (X.rows() == 0) {
    status_ = GpStatus::too_few_points;
    return;
  }
  Eigen::VectorXd model = y;
  if (log_) model = y.array().log().matrix();
  z_ = (model.array() - z_mean_) / z_sd_;  // the trained model's standardisation
  factorise();
  status_ = GpStatus::fitted;
}

GpPrediction GaussianProcess::predict(const Eigen::VectorXd& x) const {
  if (!fitted()) throw std::logic_error("gaussian process: predict() before a successful fit");
  if (x.size() != X_.cols()) throw std::invalid_argument("gaussian process: point has the wrong dimension");
  const Eigen::Index n = X_.rows();
  Eigen::VectorXd k(n);
  for (Eigen::Index i = 0; i < n; ++i) k[i] = signal_ * matern52(x, X_.row(i).transpose(), lengths_);
  const double mean = k.dot(alpha_);
  const Eigen::VectorXd v = L_.triangularView<Eigen::Lower>().solve(k);
  const double var = std::max(0.0, signal_ - v.squaredNorm());
  GpPrediction p;
  p.mean = z_mean_ + z_sd_ * mean;
  p.sd = z_sd_ * std::sqrt(var);
  p.noise_sd = z_sd_ * std::sqrt(noise_);
  return p;
}

double GaussianProcess::predict_mean(const Eigen::VectorXd& x) const {
  if (!fitted()) throw std::logic_error("gaussian process: predict_mean() before a successful fit");
  if (x.size() != X_.cols()) throw std::invalid_argument("gaussian process: point has the wrong dimension");
  const Eigen::Index d = X_.cols();
  double mean = 0;
  for (Eigen::Index i = 0; i < X_.rows(); ++i) {  // matern52() inlined: no temporaries in this hot loop
    double r2 = 0;
    for (Eigen::Index k = 0; k < d; ++k) {
      const double t = (x[k] - X_(i, k)) / lengths_[k];
      r2 += t * t;
    }
    const double r = std::sqrt(r2);
    mean += alpha_[i] * (1.0 + kSqrt5 * r + 5.0 / 3.0 * r2) * std::exp(-kSqrt5 * r);
  }
  return z_mean_ + z_sd_ * signal_ * mean;
}

std::pair<double, double> GaussianProcess::interval(const Eigen::VectorXd& x, double level) const {
  const GpPrediction p = predict(x);
  const double q = normal_quantile(0.5 + 0.5 * level);
  return {from_model(p.mean - q * p.observation_sd()), from_model(p.mean + q * p.observation_sd())};
}

double GaussianProcess::best_model_target() const {
  if (y_.size() == 0) return std::numeric_limits<double>::infinity();
  return to_model(y_.minCoeff());
}

LooSummary GaussianProcess::leave_one_out() const {
  LooSummary s;
  if (!fitted()) return s;
  const Eigen::Index n = X_.rows();
  const Eigen::MatrixXd Linv = L_.triangularView<Eigen::Lower>().solve(Eigen::MatrixXd::Identity(n, n));
  const Eigen::VectorXd kinv_diag = Linv.colwise().squaredNorm().transpose();  // diag of K^-1
  const double q = normal_quantile(0.95);
  const double y_mean = y_.mean();
  double abs_error = 0, spread = 0;
  long covered = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double mean = z_mean_ + z_sd_ * (z_[i] - alpha_[i] / kinv_diag[i]);
    const double sd = z_sd_ / std::sqrt(kinv_diag[i]);
    abs_error += std::abs(from_model(mean) - y_[i]);
    spread += std::abs(y_[i] - y_mean);
    if (y_[i] >= from_model(mean - q * sd) && y_[i] <= from_model(mean + q * sd)) ++covered;
  }
  s.mean_absolute_error = abs_error / static_cast<double>(n);
  s.relative_error = spread > 0 ? abs_error / spread : 0.0;
  s.coverage90 = static_cast<double>(covered) / static_cast<double>(n);
  return s;
}

using detail::matrix_json;

nlohmann::json GaussianProcess::to_json() const {
  nlohmann::json lengths = nlohmann::json::array();
  for (Eigen::Index k = 0; k < lengths_.size(); ++k) lengths.push_back(lengths_[k]);
  nlohmann::json y = nlohmann::json::array();
  for (Eigen::Index i = 0; i < y_.size(); ++i) y.push_back(y_[i]);
  return {{"kind", "gp"},
          {"options", options_.to_json()},
          {"fitted", fitted()},
          {"log_transform", log_},
          {"target_mean", z_mean_},
          {"target_sd", z_sd_},
          {"length_scales", lengths},
          {"signal_variance", signal_},
          {"noise_variance", noise_},
          {"negative_log_likelihood", nll_},
          {"dimension", X_.cols()},
          {"X", matrix_json(X_)},
          {"y", y}};
}

GaussianProcess GaussianProcess::from_json(const nlohmann::json& j, const std::string& where) {
  try {
    GaussianProcess gp(GpOptions::from_json(j.at("options"), where + ": options"));
    gp.log_ = j.at("log_transform").get<bool>();
    gp.z_mean_ = j.at("target_mean").get<double>();
    gp.z_sd_ = j.at("target_sd").get<double>();
    const auto lengths = j.at("length_scales").get<std::vector<double>>();
    gp.lengths_ = Eigen::Map<const Eigen::VectorXd>(lengths.data(), static_cast<Eigen::Index>(lengths.size()));
    gp.signal_ = j.at("signal_variance").get<double>();
    gp.noise_ = j.at("noise_variance").get<double>();
    gp.nll_ = j.at("negative_log_likelihood").get<double>();
    const auto rows = j.at("X").get<std::vector<std::vector<double>>>();
    const auto y = j.at("y").get<std::vector<double>>();
    const auto d = static_cast<Eigen::Index>(lengths.size());
    Eigen::MatrixXd X(static_cast<Eigen::Index>(rows.size()), d);
    for (size_t i = 0; i < rows.size(); ++i) {
      if (static_cast<Eigen::Index>(rows[i].size()) != d)
        throw std::invalid_argument("X[" + std::to_string(i) + "] has " + std::to_string(rows[i].size()) +
                                    " coordinates, length_scales " + std::to_string(d));
      for (Eigen::Index k = 0; k < d; ++k) X(static_cast<Eigen::Index>(i), k) = rows[i][static_cast<size_t>(k)];
    }
    if (!(gp.z_sd_ > 0) || !(gp.signal_ > 0) || !(gp.noise_ > 0))
      throw std::invalid_argument("target_sd, signal_variance and noise_variance must be > 0");
    for (Eigen::Index k = 0; k < d; ++k)
      if (!(gp.lengths_[k] > 0)) throw std::invalid_argument("length_scales must be > 0");
    gp.condition(X, Eigen::Map<const Eigen::VectorXd>(y.data(), static_cast<Eigen::Index>(y.size())));
    return gp;
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(where + ": " + e.what());
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(where + ": " + e.what());
  }
}

double matern52(const Eigen::VectorXd& a, const Eigen::VectorXd& b, const Eigen::VectorXd& lengths) {
  const double r = std::sqrt(((a - b).array() / lengths.array()).square().sum());
  return (1.0 + kSqrt5 * r + 5.0 / 3.0 * r * r) * std::exp(-kSqrt5 * r);
}

double normal_pdf(double u) { return std::exp(-0.5 * u * u) / std::sqrt(2.0 * M_PI); }
double normal_cdf(double u) { return 0.5 * std::erfc(-u / std::sqrt(2.0)); }
double normal_quantile(double p) {
  if (!(p > 0 && p < 1))
    throw std::invalid_argument("normal_quantile: p = " + format_number(p, round_trip_digits) + " must lie in (0, 1)");
  double lo = -40, hi = 40;
  for (int i = 0; i < 200 && hi - lo > 1e-14; ++i) {
    const double mid = 0.5 * (lo + hi);
    (normal_cdf(mid) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace demcal::surrogate
