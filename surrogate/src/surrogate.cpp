#include "demcal/surrogate/surrogate.hpp"
#include "internal.hpp"

#include "demcal/common/format.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace demcal::surrogate {

namespace {

using detail::vector_from;
using detail::vector_json;

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

// ---- failure classifier ------------------------------------------------------------------------

void FailureClassifier::fit(const std::vector<TrainingRow>& rows) {
  const auto n = static_cast<Eigen::Index>(rows.size());
  const Eigen::Index d = rows.empty() ? 0 : rows.front().unit.size();
  X_.resize(n, d);
  failed_.resize(n);
  failures_ = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    X_.row(i) = rows[static_cast<size_t>(i)].unit.transpose();
    failed_[i] = std::isfinite(rows[static_cast<size_t>(i)].fitness) ? 0.0 : 1.0;
    failures_ += failed_[i] > 0 ? 1 : 0;
  }
  rate_ = n > 0 ? static_cast<double>(failures_) / static_cast<double>(n) : 0.0;
  if (failures_ == 0 || failures_ == n) return;
  Eigen::MatrixXd sq(n, n);
  for (Eigen::Index a = 0; a < n; ++a)
    for (Eigen::Index b = 0; b < n; ++b) sq(a, b) = (X_.row(a) - X_.row(b)).squaredNorm();
  double best_ll = -HUGE_VAL;
  for (double h : {0.03, 0.05, 0.08, 0.12, 0.2, 0.3, 0.5}) {
    double ll = 0;
    for (Eigen::Index i = 0; i < n; ++i) {
      double num = prior_weight_ * rate_, den = prior_weight_;
      for (Eigen::Index j = 0; j < n; ++j) {
        if (j == i) continue;
        const double w = std::exp(-sq(i, j) / (2 * h * h));
        num += w * failed_[j];
        den += w;
      }
      const double p = std::clamp(num / den, 1e-6, 1 - 1e-6);
      ll += failed_[i] > 0 ? std::log(p) : std::log(1 - p);
    }
    if (ll > best_ll) {
      best_ll = ll;
      bandwidth_ = h;
    }
  }
}

double FailureClassifier::probability(const Eigen::VectorXd& x) const {
  if (failures_ == 0) return 0.0;
  double num = prior_weight_ * rate_, den = prior_weight_;
  for (Eigen::Index j = 0; j < X_.rows(); ++j) {
    const double w = std::exp(-(X_.row(j).transpose() - x).squaredNorm() / (2 * bandwidth_ * bandwidth_));
    num += w * failed_[j];
    den += w;
  }
  return num / den;
}

nlohmann::json FailureClassifier::to_json() const {
  nlohmann::json X = nlohmann::json::array();
  for (Eigen::Index i = 0; i < X_.rows(); ++i) X.push_back(vector_json(X_.row(i).transpose()));
  return {{"bandwidth", bandwidth_}, {"prior_weight", prior_weight_}, {"X", X}, {"failed", vector_json(failed_)}};
}

FailureClassifier FailureClassifier::from_json(const nlohmann::json& j, const std::string& where) {
  try {
    FailureClassifier c;
    std::vector<TrainingRow> rows;
    const auto failed = j.at("failed").get<std::vector<double>>();
    const auto& X = j.at("X");
    if (X.size() != failed.size()) throw std::invalid_argument("X and failed have different lengths");
    for (size_t i = 0; i < failed.size(); ++i)
      rows.push_back({vector_from(X[i]), failed[i] > 0 ? std::numeric_limits<double>::quiet_NaN() : 0.0, {}});
    c.fit(rows);
    c.bandwidth_ = j.at("bandwidth").get<double>();
    if (!(c.bandwidth_ > 0)) throw std::invalid_argument("bandwidth must be > 0");
    return c;
  } catch (const std::exception& e) {
    throw std::invalid_argument(where + ": " + e.what());
  }
}

// ---- options ---------------------------------------------------------------------------------------

std::string to_string(Acquisition a) { return a == Acquisition::expected_improvement ? "ei" : "lcb"; }

Acquisition parse_acquisition(const std::string& text) {
  if (text == "ei") return Acquisition::expected_improvement;
  if (text == "lcb") return Acquisition::lower_confidence_bound;
  throw std::invalid_argument("acquisition = '" + text + "' (expected ei or lcb)");
}

void SurrogateOptions::Validate() const {
  if (kind != "gp" && kind != "mlp") throw std::invalid_argument("surrogate kind = '" + kind + "' (expected gp or mlp)");
  if (pool_factor < 1) throw std::invalid_argument("surrogate pool_factor = " + std::to_string(pool_factor) + " must be >= 1");
  if (k < 0) throw std::invalid_argument("surrogate k = " + std::to_string(k) + " must be >= 0 (0 = the whole batch)");
  if (!(lcb_kappa >= 0) || !std::isfinite(lcb_kappa))
    throw std::invalid_argument("surrogate lcb_kappa = " + format_number(lcb_kappa, round_trip_digits) + " must be finite and >= 0");
  if (min_runs < 3) throw std::invalid_argument("surrogate min_runs = " + std::to_string(min_runs) + " must be >= 3");
  if (max_training_runs < 10)
    throw std::invalid_argument("surrogate max_training_runs = " + std::to_string(max_training_runs) + " must be >= 10");
  if (batch < 0) throw std::invalid_argument("surrogate batch = " + std::to_string(batch) + " must be >= 0 (0 = the backend's workers)");
  if (!(refit_growth >= 1) || !std::isfinite(refit_growth))
    throw std::invalid_argument("surrogate refit_growth = " + format_number(refit_growth, round_trip_digits) +
                                " must be finite and >= 1");
  if (threads < 1) throw std::invalid_argument("surrogate threads = " + std::to_string(threads) + " must be >= 1");
  if (!(cost_ratio > 0))
    throw std::invalid_argument("surrogate cost_ratio = " + format_number(cost_ratio, round_trip_digits) +
                                " must be > 0 (infinity: never adapt)");
  limits::require_within(limits::Limit::training_rows, max_training_runs, "surrogate max_training_runs");
  limits::require_within(limits::Limit::population, batch, "surrogate batch");
  limits::require_within(limits::Limit::training_rows, min_runs, "surrogate min_runs");
  limits::require_within(limits::Limit::population, pool_factor, "surrogate pool_factor (candidates ranked per simulated one)");
  limits::require_within(limits::Limit::population, k, "surrogate k");
  gp.Validate();
  mlp.Validate();
}

namespace {

// "cost_ratio": a number, or "inf" (never adapt).
const FieldTable<SurrogateOptions>& surrogate_fields() {
  static const FieldTable<SurrogateOptions> table{
      field("kind", &SurrogateOptions::kind),
      field("pool_factor", &SurrogateOptions::pool_factor),
      field("k", &SurrogateOptions::k),
      named_field("acquisition", &SurrogateOptions::acquisition, parse_acquisition,
                  [](Acquisition a) { return to_string(a); }),
      field("lcb_kappa", &SurrogateOptions::lcb_kappa),
      field("min_runs", &SurrogateOptions::min_runs),
      field("max_training_runs", &SurrogateOptions::max_training_runs),
      field("batch", &SurrogateOptions::batch),
      field("refit_growth", &SurrogateOptions::refit_growth),
      custom_field<SurrogateOptions>(
          "cost_ratio",
          [](SurrogateOptions& o, const nlohmann::json& value, const std::string&) {
            o.cost_ratio = value == "inf" ? HUGE_VAL : value.get<double>();
          },
          [](const SurrogateOptions& o) -> std::optional<nlohmann::json> {
            return std::isfinite(o.cost_ratio) ? nlohmann::json(o.cost_ratio) : nlohmann::json("inf");
          }),
      custom_field<SurrogateOptions>(
          "gp",
          [](SurrogateOptions& o, const nlohmann::json& value, const std::string& where) {
            o.gp = GpOptions::from_json(value, where + ".gp");
          },
          [](const SurrogateOptions& o) -> std::optional<nlohmann::json> { return o.gp.to_json(); }),
      custom_field<SurrogateOptions>(
          "mlp",
          [](SurrogateOptions& o, const nlohmann::json& value, const std::string& where) {
            o.mlp = MlpOptions::from_json(value, where + ".mlp");
          },
          [](const SurrogateOptions& o) -> std::optional<nlohmann::json> { return o.mlp.to_json(); }),
  };
  return table;
}

}  // namespace

// threads is left out: results do not depend on it.
nlohmann::json SurrogateOptions::to_json() const { return surrogate_fields().to_json(*this); }

SurrogateOptions SurrogateOptions::from_json(const nlohmann::json& j, const std::string& where) {
  return detail::options_from_json(j, where, surrogate_fields());
}

std::vector<TrainingRow> select_training_rows(const std::vector<TrainingRow>& rows, int max_rows) {
  if (static_cast<long>(rows.size()) <= max_rows) return rows;
  std::vector<size_t> order(rows.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    const double fa = std::isfinite(rows[a].fitness) ? rows[a].fitness : HUGE_VAL;
    const double fb = std::isfinite(rows[b].fitness) ? rows[b].fitness : HUGE_VAL;
    return fa < fb;
  });
  const size_t best = static_cast<size_t>(max_rows / 2);
  std::vector<bool> take(rows.size(), false);
  for (size_t i = 0; i < best; ++i) take[order[i]] = true;
  std::vector<size_t> rest;
  for (size_t i = 0; i < rows.size(); ++i)
    if (!take[i]) rest.push_back(i);
  const size_t wanted = static_cast<size_t>(max_rows) - best;
  for (size_t j = 0; j < wanted; ++j) take[rest[j * rest.size() / wanted]] = true;
  std::vector<TrainingRow> out;
  for (size_t i = 0; i < rows.size(); ++i)
    if (take[i]) out.push_back(rows[i]);
  return out;
}

// ---- model -----------------------------------------------------------------------------------

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
    ensemble_.fit(X, Y, options_.mlp);
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
  if (!ensemble_.refine(X, Y, options_.mlp)) return false;
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

// ---- pre-screening -----------------------------------------------------------------------------

nlohmann::json ScreenReport::to_json() const {
  nlohmann::json list = nlohmann::json::array();
  for (const auto& c : candidates)
    list.push_back({{"slot", c.slot},
                    {"x", vector_json(c.physical)},
                    {"pool", c.pool},
                    {"replaced", c.replaced},
                    {"simulated", c.simulated},
                    {"predicted_fitness", c.prediction.fitness},
                    {"predicted_mean", c.prediction.mean},
                    {"predicted_sd", c.prediction.sd},
                    {"failure_probability", c.prediction.failure_probability},
                    {"score", c.score}});
  return {{"pool", pool}, {"simulated", simulated}, {"candidates", list}};
}

ScreenReport prescreen(optimise::Optimiser& optimiser, const SurrogateModel& model, const SurrogateOptions& options) {
  if (!optimiser.can_substitute()) throw std::logic_error(optimiser.name() + ": cannot be pre-screened");
  if (!model.usable()) throw std::logic_error("prescreen: the surrogate model is not fitted");
  const auto batch = optimiser.ask();
  const auto& space = optimiser.space();
  ScreenReport report;
  for (size_t i = 0; i < batch.size(); ++i) {
    std::vector<Eigen::VectorXd> pool = {batch[i]};
    if (options.pool_factor > 1) {
      auto alternatives = optimiser.alternatives(i, options.pool_factor - 1);
      pool.insert(pool.end(), alternatives.begin(), alternatives.end());
    }
    ScreenedCandidate best;
    best.slot = static_cast<int>(i);
    best.pool = static_cast<int>(pool.size());
    best.score = -HUGE_VAL;
    for (size_t j = 0; j < pool.size(); ++j) {
      const Prediction p = model.predict(space.to_unit(pool[j]));
      const double s = model.score(p);
      if (s > best.score) {  // ties keep the optimiser's own proposal
        best.score = s;
        best.prediction = p;
        best.physical = pool[j];
        best.replaced = j > 0;
      }
    }
    if (best.replaced) optimiser.substitute(i, best.physical);
    report.pool += best.pool;
    report.candidates.push_back(best);
  }
  const size_t keep = options.k > 0 ? std::min(batch.size(), static_cast<size_t>(options.k)) : batch.size();
  std::vector<size_t> order(batch.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return report.candidates[a].score > report.candidates[b].score; });
  for (size_t r = 0; r < order.size(); ++r) {
    auto& c = report.candidates[order[r]];
    c.simulated = r < keep;
    if (!c.simulated) optimiser.withdraw(order[r]);
  }
  report.simulated = static_cast<int>(keep);
  return report;
}

// ---- cross-validation ----------------------------------------------------------------------------

nlohmann::json CrossValidation::to_json() const {
  return {{"rows", rows},
          {"finite_rows", finite_rows},
          {"failed_rows", failed_rows},
          {"folds", folds},
          {"mean_absolute_error", mean_absolute_error},
          {"relative_error", relative_error},
          {"median_relative_error", median_relative_error},
          {"coverage90", coverage90},
          {"failure_brier", failure_brier}};
}

CrossValidation cross_validate(const std::vector<TrainingRow>& rows, const SurrogateOptions& options, int folds,
                               const CurveHooks& hooks) {
  if (folds < 2) throw std::invalid_argument("cross_validate: folds = " + std::to_string(folds) + " must be >= 2");
  CrossValidation cv;
  cv.rows = static_cast<long>(rows.size());
  cv.folds = folds;
  std::vector<double> abs_errors, rel_errors, ys;
  long covered = 0;
  double brier = 0;
  for (int f = 0; f < folds; ++f) {
    std::vector<TrainingRow> train, test;
    for (size_t i = 0; i < rows.size(); ++i) (static_cast<int>(i % static_cast<size_t>(folds)) == f ? test : train).push_back(rows[i]);
    SurrogateModel model(options, hooks);
    if (test.empty() || !model.fit(train)) continue;
    for (const auto& r : test) {
      if (options.kind == "mlp" && std::isfinite(r.fitness) && r.outputs.size() == 0) continue;
      const Prediction p = model.predict(r.unit);
      const bool failed = !std::isfinite(r.fitness);
      brier += (p.failure_probability - (failed ? 1.0 : 0.0)) * (p.failure_probability - (failed ? 1.0 : 0.0));
      if (failed) {
        ++cv.failed_rows;
        continue;
      }
      ++cv.finite_rows;
      abs_errors.push_back(std::abs(p.fitness - r.fitness));
      if (r.fitness != 0) rel_errors.push_back(std::abs(p.fitness - r.fitness) / std::abs(r.fitness));
      ys.push_back(r.fitness);
      const auto [lo, hi] = model.interval(r.unit, 0.9);
      if (r.fitness >= lo && r.fitness <= hi) ++covered;
    }
  }
  if (cv.finite_rows == 0) return cv;
  cv.mean_absolute_error = std::accumulate(abs_errors.begin(), abs_errors.end(), 0.0) / static_cast<double>(abs_errors.size());
  cv.relative_error = detail::relative_error(abs_errors, ys);
  if (!rel_errors.empty()) {
    std::nth_element(rel_errors.begin(), rel_errors.begin() + static_cast<long>(rel_errors.size() / 2), rel_errors.end());
    cv.median_relative_error = rel_errors[rel_errors.size() / 2];
  }
  cv.coverage90 = static_cast<double>(covered) / static_cast<double>(cv.finite_rows);
  cv.failure_brier = brier / static_cast<double>(cv.finite_rows + cv.failed_rows);
  return cv;
}

}  // namespace demcal::surrogate
