// Random draws of the tests' synthetic data (the library's own are in demcal/common/random.hpp;
// these keep the streams the tests' data were drawn with).
#pragma once

#include <cmath>
#include <random>

namespace demcal::test_random {

// Uniform in (0, 1): the top 53 bits of one draw, at the middle of their interval.
inline double uniform(std::mt19937_64& rng) { return (static_cast<double>(rng() >> 11) + 0.5) * 0x1.0p-53; }

// Standard normal by Box-Muller from two uniform() draws.
inline double normal(std::mt19937_64& rng) {
  const double u1 = uniform(rng), u2 = uniform(rng);
  return std::sqrt(-2 * std::log(u1)) * std::cos(2 * M_PI * u2);
}

}  // namespace demcal::test_random
