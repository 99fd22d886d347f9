// The Gaussian process and the failure classifier on synthetic problems with a known answer.
#include "demcal/surrogate/gaussian_process.hpp"
#include "demcal/surrogate/surrogate.hpp"

#include "../test_random.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace demcal::surrogate;

namespace {

using demcal::test_random::uniform;
using demcal::test_random::normal;

double known(const Eigen::VectorXd& x) { return std::sin(6 * x[0]) + 0.5 * x[1] * x[1] + 0.3 * x[0] * x[1]; }

Eigen::MatrixXd random_points(int n, int d, std::mt19937_64& rng) {
  Eigen::MatrixXd X(n, d);
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < d; ++k) X(i, k) = uniform(rng);
  return X;
}

GpOptions linear_scale() {
  GpOptions o;
  o.log_transform = LogTransform::never;
  return o;
}

}  // namespace

TEST(GaussianProcess, ReproducesAKnownFunction) {
  std::mt19937_64 rng(11);
  const Eigen::MatrixXd X = random_points(40, 2, rng);
  Eigen::VectorXd y(X.rows());
  for (Eigen::Index i = 0; i < X.rows(); ++i) y[i] = known(X.row(i).transpose());
  GaussianProcess gp(linear_scale());
  ASSERT_EQ(gp.fit(X, y), GpStatus::fitted);
  double sq = 0, within = 0;
  const int tests = 300;
  for (int t = 0; t < tests; ++t) {
    Eigen::VectorXd x(2);
    x << uniform(rng), uniform(rng);
    const GpPrediction p = gp.predict(x);
    const double e = p.mean - known(x);
    sq += e * e;
    if (std::abs(e) <= 3 * p.observation_sd() + 1e-6) ++within;
  }
  // The function spans about 2.3 units: an RMS error below 2 % of that is a reproduction.
  EXPECT_LT(std::sqrt(sq / tests), 0.045);
  EXPECT_GE(within / tests, 0.95) << "the predicted sd must cover the actual error";
  EXPECT_LT(gp.noise_sd(), 0.01) << "no noise in the data";
  // Interpolation at a training point.
  EXPECT_NEAR(gp.predict(X.row(3).transpose()).mean, y[3], 1e-2);
}

TEST(GaussianProcess, RecoversAKnownNoiseLevel) {
  for (double sigma : {0.05, 0.2}) {
    std::mt19937_64 rng(5);
    const Eigen::MatrixXd X = random_points(200, 2, rng);
    Eigen::VectorXd y(X.rows());
    for (Eigen::Index i = 0; i < X.rows(); ++i) y[i] = known(X.row(i).transpose()) + sigma * normal(rng);
    GaussianProcess gp(linear_scale());
    ASSERT_EQ(gp.fit(X, y), GpStatus::fitted);
    EXPECT_NEAR(gp.noise_sd(), sigma, 0.2 * sigma) << "sigma " << sigma;
  }
}

TEST(GaussianProcess, NinetyPercentIntervalsCoverHeldOutPoints) {
  std::mt19937_64 rng(7);
  const double sigma = 0.1;
  const Eigen::MatrixXd X = random_points(120, 3, rng);
  auto f = [](const Eigen::VectorXd& x) { return std::cos(4 * x[0]) * (1 + x[1]) + x[2] * x[2]; };
  Eigen::VectorXd y(X.rows());
  for (Eigen::Index i = 0; i < X.rows(); ++i) y[i] = f(X.row(i).transpose()) + sigma * normal(rng);
  GaussianProcess gp(linear_scale());
  ASSERT_EQ(gp.fit(X, y), GpStatus::fitted);
  int covered = 0;
  const int tests = 1000;
  for (int t = 0; t < tests; ++t) {
    Eigen::VectorXd x(3);
    x << uniform(rng), uniform(rng), uniform(rng);
    const double observed = f(x) + sigma * normal(rng);
    const auto [lo, hi] = gp.interval(x, 0.9);
    if (observed >= lo && observed <= hi) ++covered;
  }
  const double coverage = static_cast<double>(covered) / tests;
  EXPECT_GT(coverage, 0.85);
  EXPECT_LT(coverage, 0.96);
  const LooSummary loo = gp.leave_one_out();
  EXPECT_GT(loo.coverage90, 0.82);
  EXPECT_LT(loo.coverage90, 0.97);
}

TEST(GaussianProcess, ChoosesTheLogTransformWhenItPredictsBetter) {
  std::mt19937_64 rng(3);
  const Eigen::MatrixXd X = random_points(40, 2, rng);
  Eigen::VectorXd y(X.rows()), z(X.rows());
  for (Eigen::Index i = 0; i < X.rows(); ++i) {
    y[i] = std::exp(8 * X(i, 0) + 2 * X(i, 1));   // spans four decades: smooth only in log
    z[i] = known(X.row(i).transpose());            // takes negative values: no log possible
  }
  GaussianProcess a;
  a.fit(X, y);
  EXPECT_TRUE(a.log_transformed());
  GaussianProcess b;
  b.fit(X, z);
  EXPECT_FALSE(b.log_transformed());
  // Deterministic, and the JSON form predicts the same.
  GaussianProcess again;
  again.fit(X, y);
  Eigen::VectorXd x(2);
  x << 0.4, 0.6;
  EXPECT_EQ(a.predict(x).mean, again.predict(x).mean);
  const GaussianProcess copy = GaussianProcess::from_json(nlohmann::json::parse(a.to_json().dump()), "model");
  EXPECT_NEAR(copy.predict(x).mean, a.predict(x).mean, 1e-9 * std::abs(a.predict(x).mean));
  EXPECT_THROW(GaussianProcess::from_json(nlohmann::json{{"options", 1}}, "m.json"), std::invalid_argument);
}

TEST(FailureClassifier, LearnsTheFailureRegion) {
  std::mt19937_64 rng(9);
  std::vector<TrainingRow> rows;
  for (int i = 0; i < 150; ++i) {
    Eigen::VectorXd u(2);
    u << uniform(rng), uniform(rng);
    rows.push_back({u, u[0] > 0.7 ? std::numeric_limits<double>::quiet_NaN() : 1.0 + u[1]});
  }
  FailureClassifier c;
  c.fit(rows);
  Eigen::VectorXd inside(2), outside(2);
  inside << 0.9, 0.5;
  outside << 0.2, 0.5;
  EXPECT_GT(c.probability(inside), 0.8);
  EXPECT_LT(c.probability(outside), 0.1);
  // Expected improvement is discounted by the failure probability.
  SurrogateOptions gp;
  gp.kind = "gp";
  SurrogateModel model(gp);
  ASSERT_TRUE(model.fit(rows));
  EXPECT_LT(model.score(inside), model.score(outside) + 1e-12);
}
