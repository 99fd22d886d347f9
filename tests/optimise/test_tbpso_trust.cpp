// TBPSO's trust arithmetic (eqs. 11-14) on a hand-made three-particle example, step by step.
#include <demcal/optimise/optimise.hpp>

#include <gtest/gtest.h>

#include <cmath>

using namespace demcal::optimise;

namespace {

// Particles (unit cube): x1 = (0.1, 0.1), x2 = (0.4, 0.5), x3 = (0.1, 0.5).
// d12 = 0.5, d13 = 0.4, d23 = 0.3.
Eigen::MatrixXd positions() {
  Eigen::MatrixXd x(3, 2);
  x << 0.1, 0.1, 0.4, 0.5, 0.1, 0.5;
  return x;
}

Eigen::Matrix3d trust(std::initializer_list<double> values) {
  Eigen::Matrix3d m;
  auto it = values.begin();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m(i, j) = *it++;
  return m;
}

// The sequence of told values and, computed by hand, the personal bests and trust after each step.
//   step 1: f(x) = (3, 1, 2)      -> f(p) = (3, 1, 2), everyone improved (p0 = x0)
//           C = [[0,1,1],[0,0,0],[0,1,0]]
//   step 2: f(x) = (2.5, 1.5, 0.5) -> f(p) = (2.5, 1, 0.5); 1 and 3 improved, 2 did not
//           C12 = 1-1 = 0, C13 = 1+1 = 2, C21 = 0 (1 <= 2.5), C23 = 0+1 = 1, C3j = 0 (best)
//   step 3: f(x) = (4, 0.9, 0.7)   -> f(p) = (2.5, 0.9, 0.5); only 2 improved
//           C12 = 0+1 = 1, C13 = 2-1 = 1, C23 = 1-1 = 0
//   step 4: f(x) = (5, 0.95, 0.8)  -> f(p) unchanged; nobody improved
//           C12 = 1-1 = 0, C13 = 1-1 = 0, C23 = 0-1 = -1
struct Step {
  Eigen::Vector3d current, personal_best;
  Eigen::Matrix3d trust;
};
std::vector<Step> hand_steps() {
  return {
      {Eigen::Vector3d(3, 1, 2), Eigen::Vector3d(3, 1, 2), trust({0, 1, 1, 0, 0, 0, 0, 1, 0})},
      {Eigen::Vector3d(2.5, 1.5, 0.5), Eigen::Vector3d(2.5, 1, 0.5), trust({0, 0, 2, 0, 0, 1, 0, 0, 0})},
      {Eigen::Vector3d(4, 0.9, 0.7), Eigen::Vector3d(2.5, 0.9, 0.5), trust({0, 1, 1, 0, 0, 0, 0, 0, 0})},
      {Eigen::Vector3d(5, 0.95, 0.8), Eigen::Vector3d(2.5, 0.9, 0.5), trust({0, 0, 0, 0, 0, -1, 0, 0, 0})},
  };
}

}  // namespace

TEST(TbpsoTrust, RelativeDistancesByHand) {
  const Eigen::MatrixXd d = tbpso_relative_distances(positions());
  // Row sums: 0.9, 0.8, 0.7.
  EXPECT_NEAR(d(0, 1), 5.0 / 9.0, 1e-15);
  EXPECT_NEAR(d(0, 2), 4.0 / 9.0, 1e-15);
  EXPECT_NEAR(d(1, 0), 0.625, 1e-15);
  EXPECT_NEAR(d(1, 2), 0.375, 1e-15);
  EXPECT_NEAR(d(2, 0), 4.0 / 7.0, 1e-15);
  EXPECT_NEAR(d(2, 1), 3.0 / 7.0, 1e-15);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(d(i, i), 0.0);
}

TEST(TbpsoTrust, TrustUpdateStepByStep) {
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(3, 3);
  int step = 1;
  for (const auto& s : hand_steps()) {
    c = tbpso_trust_update(c, s.personal_best, s.current);
    EXPECT_EQ(c, Eigen::MatrixXd(s.trust)) << "step " << step << "\n" << c;
    ++step;
  }
}

TEST(TbpsoTrust, TrustPullByHandBothReadings) {
  const Eigen::MatrixXd x = positions();
  // After step 1, C = [[0,1,1],[0,0,0],[0,1,0]]:
  //   T1 = 5/9 (x2 - x1) + 4/9 (x3 - x1) = (0.3*5/9, 0.4*5/9 + 0.4*4/9) = (1/6, 0.4)
  //   T2 = 0,  T3 = 3/7 (x2 - x3) = (0.9/7, 0)
  const Eigen::MatrixXd toward = tbpso_trust_pull(x, hand_steps()[0].trust, TrustDirection::toward);
  EXPECT_NEAR(toward(0, 0), 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(toward(0, 1), 0.4, 1e-15);
  EXPECT_EQ(toward.row(1).norm(), 0.0);
  EXPECT_NEAR(toward(2, 0), 0.9 / 7.0, 1e-15);
  EXPECT_NEAR(toward(2, 1), 0.0, 1e-15);
  const Eigen::MatrixXd paper = tbpso_trust_pull(x, hand_steps()[0].trust, TrustDirection::paper);
  EXPECT_TRUE(paper.isApprox(-toward, 1e-15));
  // After step 2, C = [[0,0,2],[0,0,1],[0,0,0]]: T1 = 4/9*2*(x3 - x1) = (0, 0.32/0.9), T2 = 0.375 (x3 - x2).
  const Eigen::MatrixXd t2 = tbpso_trust_pull(x, hand_steps()[1].trust, TrustDirection::toward);
  EXPECT_NEAR(t2(0, 0), 0.0, 1e-15);
  EXPECT_NEAR(t2(0, 1), 0.32 / 0.9, 1e-15);
  EXPECT_NEAR(t2(1, 0), -0.1125, 1e-15);
  EXPECT_NEAR(t2(1, 1), 0.0, 1e-15);
  EXPECT_EQ(t2.row(2).norm(), 0.0);
}

TEST(TbpsoTrust, OptimiserCarriesTheSameTrustMatrix) {
  // The same told values through the real optimiser: its saved state holds the hand-computed C.
  ParameterSpace space;
  space.add("a", 0.0, 1.0).add("b", 0.0, 1.0);
  OptimiserOptions options;
  options.algorithm = "tbpso";
  options.population = 3;
  options.iterations = 10;
  auto opt = make_optimiser(space, options);
  int step = 1;
  for (const auto& s : hand_steps()) {
    ASSERT_EQ(opt->ask().size(), 3u);
    opt->tell({s.current[0], s.current[1], s.current[2]});
    const auto state = opt->save_state();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        EXPECT_EQ(state["trust"][i][j].get<double>(), s.trust(i, j)) << "step " << step << " C" << i + 1 << j + 1;
    for (int i = 0; i < 3; ++i) EXPECT_EQ(state["fp"][i].get<double>(), s.personal_best[i]) << "step " << step;
    ++step;
  }
}

TEST(TbpsoTrust, ConstrictionFactor) {
  EXPECT_DOUBLE_EQ(constriction_factor(4.0), 1.0);
  EXPECT_NEAR(constriction_factor(4.1), 0.729843788, 1e-9);
  EXPECT_THROW(constriction_factor(3.9), std::invalid_argument);
}

TEST(TbpsoTrust, VelocityClampAppliesToTheTrustTerm) {
  // Only the trust term moves the particles (ω = φ1 = φ2 = 0); with a huge trust C the term is
  // ~1e12 unit-cube lengths, and the clamp must still hold every component to max_velocity.
  ParameterSpace space;
  space.add("a", 0.0, 1.0).add("b", 0.0, 1.0);
  OptimiserOptions options;
  options.algorithm = "tbpso";
  options.population = 3;
  options.iterations = 10;
  options.inertia_start = options.inertia_end = 0.0;
  options.tbpso_cognitive = options.tbpso_social = 0.0;
  options.max_velocity = 0.1;
  options.bounds = BoundHandling::reflect;  // keeps |v| when a move leaves the cube
  for (const char* direction : {"paper", "toward"}) {
    options.trust_direction = direction;
    auto first = make_optimiser(space, options);
    first->ask();
    first->tell({3.0, 2.0, 1.0});
    auto state = first->save_state();
    state["trust"] = {{0.0, 1e12, 1e12}, {0.0, 0.0, 1e12}, {0.0, 0.0, 0.0}};
    auto opt = make_optimiser(space, options);
    opt->load_state(state);
    opt->ask();
    opt->tell({3.0, 2.0, 1.0});  // everyone ties its best ("improved"): C = 1e12 + 1 where i is worse
    const auto after = opt->save_state();
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 2; ++k) {
        const double v = after["v"][i][k].get<double>();
        EXPECT_LE(std::abs(v), 0.1) << direction << " particle " << i;
        // Particles 1 and 2 trust someone: their trust term saturates the clamp in every coordinate
        // (positions differ in both coordinates). Particle 3 is the best: no trust term, no motion.
        if (i < 2) EXPECT_EQ(std::abs(v), 0.1) << direction << " particle " << i;
        else EXPECT_EQ(v, 0.0) << direction;
      }
  }
}
