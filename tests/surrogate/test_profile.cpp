// Profiles on the emulator (surrogate/profile.hpp) on analytic fitness functions whose
// indistinguishable region is known: a long valley the rows sample only at one end, and a
// coordinate the fitness pins.
#include "demcal/surrogate/profile.hpp"

#include "../test_random.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace demcal::surrogate;

namespace {

using demcal::test_random::uniform;

// The valley x = y: fitness 1 + 50 (x - y)^2 + 0.02 (x - 0.75)^2 (+ 5 (z - 0.4)^2 in 3-D). Along
// the floor the fitness stays below 1.0115, inside a 5 % band everywhere; across it the band is
// |x - y| < 0.03. z is pinned: within the band only for |z - 0.4| < 0.1.
double valley(const Eigen::VectorXd& u) {
  double f = 1 + 50 * (u[0] - u[1]) * (u[0] - u[1]) + 0.02 * (u[0] - 0.75) * (u[0] - 0.75);
  if (u.size() > 2) f += 5 * (u[2] - 0.4) * (u[2] - 0.4);
  return f;
}

// Rows as a swarm leaves them: a space-filling design, rows on the valley's flanks along its whole
// length (0.05 to 0.15 off the floor: fitness 1.1 to 2.1, outside the band), and a cluster at the
// valley's end x in [0.7, 0.8], the only rows in the band (design rows in it are rejected).
std::vector<TrainingRow> clustered_rows(int d, int spread, int flank, int cluster, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<TrainingRow> rows;
  while (static_cast<int>(rows.size()) < spread) {
    Eigen::VectorXd u(d);
    for (int k = 0; k < d; ++k) u[k] = uniform(rng);
    if (valley(u) <= 1.06) continue;
    rows.push_back({u, valley(u)});
  }
  while (static_cast<int>(rows.size()) < spread + flank) {
    Eigen::VectorXd u(d);
    for (int k = 0; k < d; ++k) u[k] = uniform(rng);
    u[1] = u[0] + (uniform(rng) < 0.5 ? -1 : 1) * (0.05 + 0.1 * uniform(rng));
    if (u[1] < 0 || u[1] > 1) continue;
    rows.push_back({u, valley(u)});
  }
  for (int i = 0; i < cluster; ++i) {
    Eigen::VectorXd u(d);
    u[0] = 0.7 + 0.1 * uniform(rng);
    u[1] = u[0] + 0.04 * (uniform(rng) - 0.5);
    if (d > 2) u[2] = 0.4 + 0.1 * (uniform(rng) - 0.5);
    rows.push_back({u, valley(u)});
  }
  rows.push_back({Eigen::VectorXd::Constant(d, 0.5), std::nan("")});  // a failed run: ignored
  return rows;
}

void expect_reported_contains_evaluated(const ProfileResult& r) {
  for (const auto& c : r.coordinates) {
    EXPECT_LE(c.min, c.evaluated_min);
    EXPECT_GE(c.max, c.evaluated_max);
    EXPECT_LE(c.min, c.best);
    EXPECT_GE(c.max, c.best);
  }
}

}  // namespace

// (a) The rows in the band cover x in [0.7, 0.8] only; the profile follows the valley's floor,
// which is in the band everywhere, and reports most of it.
TEST(Profile, FollowsAValleyTheRowsSampleAtOneEnd) {
  const auto rows = clustered_rows(2, 40, 20, 25, 5);
  const ProfileResult r = profile_fitness(rows, 0.05);
  ASSERT_EQ(r.status, ProfileStatus::profiled) << r.message;
  EXPECT_EQ(r.finite_rows, 85);
  EXPECT_EQ(r.training_rows, 85);
  EXPECT_TRUE(r.log_transformed);
  const auto& x = r.coordinates[0];
  // the premise: the evaluated range is the cluster's
  EXPECT_GE(x.evaluated_min, 0.7);
  EXPECT_LE(x.evaluated_max, 0.8);
  EXPECT_LE(x.min, 0.3) << "profile range of x: [" << x.profile_min << ", " << x.profile_max << "]";
  EXPECT_GE(x.max, 0.9);
  EXPECT_LE(r.coordinates[1].min, 0.3);
  EXPECT_GE(r.coordinates[1].max, 0.9);
  // at x = 0.5 the search found the floor (y = x, fitness 1.0013; 0.1 off it the fitness is 1.5),
  // and the emulator's value there is within 10 % of it
  ASSERT_EQ(x.grid.size(), 41u);
  ASSERT_EQ(x.fitness.size(), 41u);
  EXPECT_EQ(x.grid[20], 0.5);
  EXPECT_NEAR(x.argmin[20][1], 0.5, 0.05);
  EXPECT_NEAR(x.fitness[20], 1.0013, 0.1);
  EXPECT_GT(r.threshold, r.band_fitness * (1 - 1e-12));
  expect_reported_contains_evaluated(r);
}

// (b) z is pinned to [0.3, 0.5] by the fitness: its range stays narrow, while x still reaches well
// beyond its evaluated [0.7, 0.8]. 3-D, so the inner searches are 2-D (BOBYQA; the 2-D case above
// uses COBYLA). The emulator of 150 rows in 3-D is rougher along the valley's floor (up to 15 %
// above it), so less of the floor is in the band than in 2-D.
TEST(Profile, APinnedCoordinateGetsANarrowRange) {
  const auto rows = clustered_rows(3, 60, 60, 30, 9);
  const ProfileResult r = profile_fitness(rows, 0.05);
  ASSERT_EQ(r.status, ProfileStatus::profiled) << r.message;
  const auto& z = r.coordinates[2];
  EXPECT_LE(z.min, 0.4);
  EXPECT_GE(z.max, 0.4);
  EXPECT_GE(z.min, 0.2) << "z pinned to 0.4 +- 0.1 reported as [" << z.min << ", " << z.max << "]";
  EXPECT_LE(z.max, 0.6);
  EXPECT_LE(r.coordinates[0].min, 0.45);
  EXPECT_GE(r.coordinates[0].max, 0.85);
  expect_reported_contains_evaluated(r);
}

// (c) The reported range is the hull of the evaluated and the profile ranges, whatever the
// emulator says: here with a zero band and very few grid points and starts.
TEST(Profile, ReportedRangeAlwaysContainsTheEvaluatedRange) {
  for (std::uint64_t seed : {1, 2, 3}) {
    ProfileOptions o;
    o.grid_points = 3;
    o.projected_starts = 0;
    o.random_starts = 1;
    o.seed = seed;
    for (double band : {0.0, 0.05, 0.5}) {
      const ProfileResult r = profile_fitness(clustered_rows(2, 15, 5, 10, seed), band, o);
      ASSERT_EQ(r.status, ProfileStatus::profiled);
      expect_reported_contains_evaluated(r);
      for (const auto& c : r.coordinates)
        if (std::isfinite(c.profile_min)) {
          EXPECT_LE(c.min, c.profile_min);
          EXPECT_GE(c.max, c.profile_max);
        }
    }
  }
}

TEST(Profile, SameInputSameOutput) {
  const auto rows = clustered_rows(3, 30, 10, 10, 4);
  const ProfileResult a = profile_fitness(rows, 0.05), b = profile_fitness(rows, 0.05);
  ASSERT_EQ(a.status, ProfileStatus::profiled);
  EXPECT_EQ(a.threshold, b.threshold);
  EXPECT_EQ(a.emulator_evaluations, b.emulator_evaluations);
  for (size_t k = 0; k < a.coordinates.size(); ++k) {
    EXPECT_EQ(a.coordinates[k].fitness, b.coordinates[k].fitness);
    EXPECT_EQ(a.coordinates[k].min, b.coordinates[k].min);
    EXPECT_EQ(a.coordinates[k].max, b.coordinates[k].max);
  }
  ProfileOptions other_seed;
  other_seed.seed = 2;
  EXPECT_EQ(profile_fitness(rows, 0.05, other_seed).status, ProfileStatus::profiled);
}

TEST(Profile, FewRowsOrNoProfileGiveTheEvaluatedRange) {
  auto rows = clustered_rows(2, 3, 2, 4, 3);  // 9 finite rows, one failed, one repeated below
  rows.push_back(rows.front());
  ProfileResult r = profile_fitness(rows, 0.05);
  EXPECT_EQ(r.status, ProfileStatus::too_few_rows);
  EXPECT_EQ(r.finite_rows, 9);
  EXPECT_NE(r.message.find("10 needed"), std::string::npos) << r.message;
  for (const auto& c : r.coordinates) {
    EXPECT_EQ(c.min, c.evaluated_min);
    EXPECT_EQ(c.max, c.evaluated_max);
    EXPECT_TRUE(c.grid.empty());
  }
  ProfileOptions off;
  off.enabled = false;
  EXPECT_EQ(profile_fitness(clustered_rows(2, 15, 5, 10, 3), 0.05, off).status, ProfileStatus::disabled);
  EXPECT_EQ(profile_fitness({}, 0.05).status, ProfileStatus::no_finite_rows);
  EXPECT_THROW(profile_fitness(rows, -0.1), std::invalid_argument);
  ProfileOptions bad;
  bad.grid_points = 2;
  EXPECT_THROW(profile_fitness(rows, 0.05, bad), std::invalid_argument);
}

// One coordinate: the profile is the emulator itself (nothing to minimise over).
TEST(Profile, OneCoordinate) {
  std::vector<TrainingRow> rows;
  for (int i = 0; i <= 20; ++i) {
    Eigen::VectorXd u(1);
    u[0] = i / 20.0;
    rows.push_back({u, 1 + 10 * (u[0] - 0.6) * (u[0] - 0.6)});
  }
  const ProfileResult r = profile_fitness(rows, 0.05);
  ASSERT_EQ(r.status, ProfileStatus::profiled);
  // in the band where 10 (x - 0.6)^2 < 0.05: x in [0.529, 0.671]
  EXPECT_NEAR(r.coordinates[0].min, 0.6 - std::sqrt(0.005), 0.02);
  EXPECT_NEAR(r.coordinates[0].max, 0.6 + std::sqrt(0.005), 0.02);
}

TEST(Profile, OptionsRoundTripThroughJson) {
  ProfileOptions o;
  o.grid_points = 21;
  o.seed = 7;
  const ProfileOptions back = ProfileOptions::from_json(o.to_json(), "test");
  EXPECT_EQ(back.grid_points, 21);
  EXPECT_EQ(back.seed, 7u);
  EXPECT_EQ(back.gp.log_transform, LogTransform::always);
  const ProfileOptions partial = ProfileOptions::from_json({{"gp", {{"restarts", 2}}}}, "test");
  EXPECT_EQ(partial.gp.restarts, 2);
  EXPECT_EQ(partial.gp.log_transform, LogTransform::always);
  EXPECT_THROW(ProfileOptions::from_json({{"grid_point", 3}}, "test"), std::invalid_argument);
}
