// SurrogateModel: the fitness model of either kind (gp, mlp) with the failure classifier beside
// it; fitting, updates, predictions, scores and its JSON.
#include "demcal/surrogate/surrogate.hpp"
#include "internal.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

namespace demcal::surrogate {

using detail::vector_from;

namespace {

void split_rows(const std::vector<TrainingRow>& rows, Eigen::MatrixXd& X, Eigen::VectorXd& y) {
  long finite = 0;
  for (const auto& r : rows) finite += std::isfinite(r.fitness) ? 1 : 0;
  const Eigen::Index d = rows.empty() ? 0 : rows.front().unit.size();
  X.resize(finite, d);
  y.resize(finite);
  Eigen::Index i = 0;
  for (const auto& r : rows)
    if (std::isfinite(r.fitness)) {
      X.row(i) = r.unit.transpose();
      y[i++] = r.fitness;
    }
}

}  // namespace

namespace {

// The rows an "mlp" model trains on: finite fitness and outputs, all of one length.
void split_curve_rows(const std::vector<TrainingRow>& rows, Eigen::MatrixXd& X, Eigen::MatrixXd& Y, Eigen::VectorXd& y) {
  std::vector<const TrainingRow*> usable;
  for (const auto& r : rows)
    if (std::isfinite(r.fitness) && r.outputs.size() > 0) {
      if (!usable.empty() && r.outputs.size() != usable.front()->outputs.size())
        throw std::invalid_argument("surrogate mlp: training rows have outputs of " + std::to_string(usable.front()->outputs.size()) +
                                    " and " + std::to_string(r.outputs.size()) + " values");
      usable.push_back(&r);
    }
  const Eigen::Index n = static_cast<Eigen::Index>(usable.size());
  X.resize(n, n > 0 ? usable.front()->unit.size() : 0);
  Y.resize(n, n > 0 ? usable.front()->outputs.size() : 0);
  y.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    X.row(i) = usable[static_cast<size_t>(i)]->unit.transpose();
    Y.row(i) = usable[static_cast<size_t>(i)]->outputs.transpose();
    y[i] = usable[static_cast<size_t>(i)]->fitness;
  }
}

}  // namespace

MlpOptions SurrogateModel::mlp_options() const {
  MlpOptions mlp = options_.mlp;
  mlp.threads = options_.threads;
  return mlp;
}

bool SurrogateModel::fit(const std::vector<TrainingRow>& all_rows) {
  options_.Validate();
  const auto rows = select_training_rows(all_rows, options_.max_training_runs);
  rows_ = static_cast<long>(rows.size());
  if (options_.kind == "mlp") {
    if (!hooks_.fitness) throw std::invalid_argument("surrogate mlp: no fitness function for predicted curves");
    Eigen::MatrixXd X, Y;
    Eigen::VectorXd y;
    split_curve_rows(rows, X, Y, y);
    ensemble_ = CurveEnsemble();
    if (y.size() < 3) return false;
    mlp_log_ = options_.gp.log_transform != LogTransform::never && (y.array() > 0).all();
    if (options_.gp.log_transform == LogTransform::always && !mlp_log_)
      throw std::invalid_argument("surrogate mlp: log_transform 'always' with a fitness <= 0");
    ensemble_.fit(X, Y, mlp_options());
    classifier_.fit(rows);
    const Eigen::ArrayXd targets = mlp_log_ ? Eigen::ArrayXd(y.array().log()) : Eigen::ArrayXd(y.array());
    mlp_prior_sd_ = std::sqrt((targets - targets.mean()).square().mean());
    if (!(mlp_prior_sd_ > 0)) mlp_prior_sd_ = 1.0;  // equal targets: no scale to cap at
    mlp_noise_sd_ = set_incumbent(rows);
    return true;
  }
  Eigen::MatrixXd X;
  Eigen::VectorXd y;
  split_rows(rows, X, y);
  gp_ = GaussianProcess(options_.gp);
  if (y.size() < 3 || gp_.fit(X, y) != GpStatus::fitted) return false;
  classifier_.fit(rows);
  return condition(all_rows);
}

bool SurrogateModel::update(const std::vector<TrainingRow>& all_rows) {
  if (options_.kind != "mlp") return condition(all_rows);
  if (!usable()) return false;
  const auto rows = select_training_rows(all_rows, options_.max_training_runs);
  Eigen::MatrixXd X, Y;
  Eigen::VectorXd y;
  split_curve_rows(rows, X, Y, y);
  if (mlp_log_ && !(y.array() > 0).all()) return false;  // the model space no longer fits the rows
  if (!ensemble_.refine(X, Y, mlp_options())) return false;
  rows_ = static_cast<long>(rows.size());
  classifier_.fit(rows);
  const Eigen::ArrayXd targets = mlp_log_ ? Eigen::ArrayXd(y.array().log()) : Eigen::ArrayXd(y.array());
  mlp_prior_sd_ = std::sqrt((targets - targets.mean()).square().mean());
  if (!(mlp_prior_sd_ > 0)) mlp_prior_sd_ = 1.0;
  mlp_noise_sd_ = set_incumbent(rows);
  return true;
}

bool SurrogateModel::condition(const std::vector<TrainingRow>& all_rows) {
  if (options_.kind == "mlp") return fit(all_rows);
  if (gp_.length_scales().size() == 0) return false;
  const auto rows = select_training_rows(all_rows, options_.max_training_runs);
  Eigen::MatrixXd X;
  Eigen::VectorXd y;
  split_rows(rows, X, y);
  if (y.size() < 1) return false;
  if (X.cols() != gp_.length_scales().size())
    throw std::invalid_argument("surrogate model: rows have " + std::to_string(X.cols()) + " coordinates, the model " +
                                std::to_string(gp_.length_scales().size()));
  gp_.condition(X, y);
  classifier_.fit(rows);
  rows_ = static_cast<long>(rows.size());
  set_incumbent(rows);
  return gp_.fitted();
}

// Incumbent of EI: the smallest predicted mean at a training point (robust to the noise); spread:
// the range of the model-space targets (LCB's failure penalty). Returns the RMS of the residuals
// of the predicted mean at those points (model space).
double SurrogateModel::set_incumbent(const std::vector<TrainingRow>& rows) {
  incumbent_ = HUGE_VAL;
  double lo = HUGE_VAL, hi = -HUGE_VAL, squares = 0;
  long points = 0;
  const bool log = log_transformed();
  for (const auto& r : rows) {
    if (!std::isfinite(r.fitness) || (options_.kind == "mlp" && r.outputs.size() == 0)) continue;
    const double mean = predict(r.unit).mean;
    const double v = log ? std::log(r.fitness) : r.fitness;
    incumbent_ = std::min(incumbent_, mean);
    lo = std::min(lo, v);
    hi = std::max(hi, v);
    squares += (mean - v) * (mean - v);
    ++points;
  }
  spread_ = hi > lo ? hi - lo : 1.0;
  return points > 0 ? std::sqrt(squares / static_cast<double>(points)) : 0.0;
}

int SurrogateModel::dimension() const {
  return options_.kind == "mlp" ? ensemble_.dimension() : static_cast<int>(gp_.length_scales().size());
}

bool SurrogateModel::log_transformed() const { return options_.kind == "mlp" ? mlp_log_ : gp_.log_transformed(); }

Prediction SurrogateModel::predict(const Eigen::VectorXd& unit) const {
  Prediction p;
  p.failure_probability = classifier_.probability(unit);
  if (options_.kind == "mlp") {
    if (!hooks_.fitness) throw std::logic_error("surrogate mlp: no fitness function for predicted curves");
    const int members = ensemble_.members();
    double sum = 0, squares = 0;
    for (int m = 0; m < members; ++m) {
      const double f = hooks_.fitness(ensemble_.predict(m, unit));
      const double v = mlp_log_ ? std::log(std::max(f, 1e-300)) : f;
      sum += v;
      squares += v * v;
    }
    p.mean = sum / members;
    // Where no run succeeded the members can disagree without bound; like a GP's posterior under
    // its prior, the spread is capped at the spread of the training targets.
    p.sd = std::min(std::sqrt(std::max(0.0, (squares - members * p.mean * p.mean) / (members - 1))), mlp_prior_sd_);
    p.fitness = mlp_log_ ? std::exp(p.mean) : p.mean;
    p.noise_sd = mlp_noise_sd_;
    return p;
  }
  const GpPrediction g = gp_.predict(unit);
  p.mean = g.mean;
  p.sd = g.sd;
  p.noise_sd = g.noise_sd;
  p.fitness = gp_.from_model(g.mean);
  return p;
}

std::pair<double, double> SurrogateModel::interval(const Eigen::VectorXd& unit, double level) const {
  if (options_.kind != "mlp") return gp_.interval(unit, level);
  const Prediction p = predict(unit);
  const double half = normal_quantile(0.5 + level / 2) * std::sqrt(p.sd * p.sd + p.noise_sd * p.noise_sd);
  return mlp_log_ ? std::pair{std::exp(p.mean - half), std::exp(p.mean + half)} : std::pair{p.mean - half, p.mean + half};
}

double SurrogateModel::score(const Prediction& p) const {
  if (options_.acquisition == Acquisition::lower_confidence_bound)
    return -(p.mean - options_.lcb_kappa * p.sd) - p.failure_probability * spread_;
  const double gain = incumbent_ - p.mean;
  double ei = std::max(gain, 0.0);
  if (p.sd > 1e-12) {
    const double u = gain / p.sd;
    ei = gain * normal_cdf(u) + p.sd * normal_pdf(u);
  }
  return ei * (1.0 - p.failure_probability);
}

nlohmann::json SurrogateModel::to_json() const {
  nlohmann::json j = {{"format", "demcal-surrogate"}, {"version", 1}, {"kind", options_.kind},
                      {"options", options_.to_json()}, {"classifier", classifier_.to_json()}};
  if (options_.kind == "mlp") {
    j["ensemble"] = ensemble_.to_json();
    j["log_transform"] = mlp_log_;
    j["noise_sd"] = mlp_noise_sd_;
    j["prior_sd"] = mlp_prior_sd_;
    j["incumbent"] = incumbent_;
    j["spread"] = spread_;
    j["training_rows"] = rows_;
  } else {
    j["gp"] = gp_.to_json();
  }
  return j;
}

SurrogateModel SurrogateModel::from_json(const nlohmann::json& j, const std::string& where) {
  try {
    if (j.at("format") != "demcal-surrogate") throw std::invalid_argument("not a demcal surrogate model file");
    SurrogateModel m(SurrogateOptions::from_json(j.at("options"), where + ": options"));
    if (m.options_.kind == "mlp") {
      m.ensemble_ = CurveEnsemble::from_json(j.at("ensemble"), where + ": ensemble");
      m.mlp_log_ = j.at("log_transform").get<bool>();
      m.mlp_noise_sd_ = j.at("noise_sd").get<double>();
      m.mlp_prior_sd_ = j.at("prior_sd").get<double>();
      m.incumbent_ = j.at("incumbent").get<double>();
      m.spread_ = j.at("spread").get<double>();
      m.rows_ = j.at("training_rows").get<long>();
    } else {
      m.gp_ = GaussianProcess::from_json(j.at("gp"), where + ": gp");
      std::vector<TrainingRow> rows;
      const auto& X = j.at("gp").at("X");
      const auto y = j.at("gp").at("y").get<std::vector<double>>();
      for (size_t i = 0; i < y.size(); ++i) rows.push_back({vector_from(X[i]), y[i], {}});
      m.condition(rows);
    }
    m.classifier_ = FailureClassifier::from_json(j.at("classifier"), where + ": classifier");
    return m;
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(where + ": " + e.what());
  }
}

}  // namespace demcal::surrogate
