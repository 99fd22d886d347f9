#include <demcal/common/random.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

using demcal::mix_seed;
using demcal::normal;
using demcal::seeded_rng;
using demcal::SplitMix64;
using demcal::uniform01;

namespace {

// Returns the given values in turn: a generator whose draws a test chooses.
struct ScriptedGenerator {
  using result_type = std::uint64_t;
  static constexpr result_type min() { return 0; }
  static constexpr result_type max() { return std::numeric_limits<result_type>::max(); }
  result_type operator()() { return values.at(next++); }
  std::vector<result_type> values;
  std::size_t next = 0;
};

}  // namespace

TEST(Random, MixSeedIsSplitMix64) {
  // The first outputs of splitmix64 seeded with 0 and with 1234567 (the reference splitmix64.c).
  EXPECT_EQ(mix_seed(0), 0xe220a8397b1dcdafULL);
  SplitMix64 rng(1234567);
  EXPECT_EQ(rng(), 6457827717110365317ULL);
  EXPECT_EQ(rng(), 3203168211198807973ULL);
  EXPECT_EQ(rng(), 9817491932198370423ULL);
}

TEST(Random, SplitMix64StepsByTheGoldenRatio) {
  SplitMix64 rng(42);
  EXPECT_EQ(rng(), mix_seed(42));
  EXPECT_EQ(rng(), mix_seed(42 + 0x9e3779b97f4a7c15ULL));
}

TEST(Random, Uniform01IsTheTop53BitsOfOneDraw) {
  std::mt19937_64 rng(5), raw(5);
  for (int i = 0; i < 1000; ++i) {
    const double u = uniform01(rng);
    EXPECT_EQ(u, static_cast<double>(raw() >> 11) * 0x1.0p-53);
    EXPECT_GE(u, 0.0);
    EXPECT_LT(u, 1.0);
  }
  ScriptedGenerator extremes{{0, std::numeric_limits<std::uint64_t>::max()}};
  EXPECT_EQ(uniform01(extremes), 0.0);
  EXPECT_EQ(uniform01(extremes), 1.0 - 0x1.0p-53);
}

TEST(Random, SeededRngFoldsTheStreamsIntoTheSeed) {
  EXPECT_EQ(seeded_rng(9)(), std::mt19937_64(mix_seed(9))());
  EXPECT_EQ(seeded_rng(9, 4, std::size_t{7})(), std::mt19937_64(mix_seed(mix_seed(mix_seed(9) ^ 4) ^ 7))());
  // A negative stream index wraps as a conversion to std::uint64_t does.
  EXPECT_EQ(seeded_rng(9, -1)(), std::mt19937_64(mix_seed(mix_seed(9) ^ ~std::uint64_t{0}))());
  EXPECT_NE(seeded_rng(9, 4, 7)(), seeded_rng(9, 7, 4)());
}

TEST(Random, NormalIsBoxMullerMultipliedLeftToRight) {
  std::mt19937_64 rng(11), raw(11);
  for (int i = 0; i < 1000; ++i) {
    const double standard_deviation = i % 2 ? 1.0 : 0.05;
    const double u1 = static_cast<double>(raw() >> 11) * 0x1.0p-53, u2 = static_cast<double>(raw() >> 11) * 0x1.0p-53;
    const double expected = standard_deviation * std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
    EXPECT_EQ(normal(rng, standard_deviation), expected);
  }
  // u1 = 0 counts as 2^-53, so the draw stays finite.
  ScriptedGenerator zero{{0, 0}};
  EXPECT_EQ(normal(zero), std::sqrt(-2.0 * std::log(0x1.0p-53)));
}

TEST(Random, NormalHasMeanZeroAndTheGivenSpread) {
  std::mt19937_64 rng = seeded_rng(3);
  double sum = 0, sum_of_squares = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    const double x = normal(rng, 2.0);
    sum += x;
    sum_of_squares += x * x;
  }
  EXPECT_NEAR(sum / n, 0.0, 0.02);
  EXPECT_NEAR(std::sqrt(sum_of_squares / n), 2.0, 0.02);
}
