// The failure classifier: how likely a parameter set is to make a failed run (kernel density of
// the failed rows against all rows).
#include "demcal/surrogate/surrogate.hpp"
#include "internal.hpp"

#include <cmath>
#include <limits>

namespace demcal::surrogate {

using detail::vector_from;
using detail::vector_json;

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

}  // namespace demcal::surrogate
