// Seeded random numbers that come out the same on every platform and standard library: only the
// generators' raw 64-bit output is used, mapped by the functions below (no std::*_distribution,
// whose algorithms differ between libraries). Every stream in demcal starts from an explicit seed.
//
//   std::mt19937_64 rng = seeded_rng(options.seed, iteration, index);  // one stream per (iteration, index)
//   double u = uniform01(rng);                                          // [0, 1)
//   double step = normal(rng, 0.05);                                    // mean 0, standard deviation 0.05
//   SplitMix64 weights(seed);                                           // cheap, one word of state
//   double w = uniform01(weights);
#pragma once

#include <algorithm>
#include <cmath>
#include <concepts>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>

namespace demcal {

// splitmix64's output function of z + 0x9e3779b97f4a7c15 (the golden-ratio increment): nearby
// seeds (1, 2, 3) become unrelated ones, and mix_seed(state) is the next value of a SplitMix64
// stream at `state`. Also a hash step: mix_seed(h ^ bits) folds 64 bits into h.
constexpr std::uint64_t mix_seed(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

// A generator for one stream of a seeded computation, independent of the other streams: seeded with
// mix_seed(... mix_seed(mix_seed(seed) ^ stream_1) ^ stream_2 ...), each stream index (an iteration,
// a candidate, a member) converted to std::uint64_t (a negative int wraps). seeded_rng(seed) is
// std::mt19937_64(mix_seed(seed)).
template <std::integral... Streams>
std::mt19937_64 seeded_rng(std::uint64_t seed, Streams... streams) {
  std::uint64_t z = mix_seed(seed);
  ((z = mix_seed(z ^ static_cast<std::uint64_t>(streams))), ...);
  return std::mt19937_64(z);
}

// The splitmix64 generator: each call returns mix_seed(state) and advances state by the
// golden-ratio increment. One 64-bit word of state, for many short streams (one per network
// member or per row); a UniformRandomBitGenerator, so uniform01() takes it as it takes
// std::mt19937_64.
class SplitMix64 {
 public:
  using result_type = std::uint64_t;
  explicit constexpr SplitMix64(std::uint64_t seed) : state_(seed) {}
  static constexpr result_type min() { return 0; }
  static constexpr result_type max() { return std::numeric_limits<result_type>::max(); }
  constexpr result_type operator()() {
    const result_type value = mix_seed(state_);
    state_ += 0x9e3779b97f4a7c15ULL;
    return value;
  }

 private:
  std::uint64_t state_;
};

// Uniform in [0, 1) from the top 53 bits of one draw: k * 2^-53 with k in [0, 2^53).
template <class Generator>
double uniform01(Generator& rng) {
  static_assert(Generator::min() == 0 && Generator::max() == std::numeric_limits<std::uint64_t>::max(),
                "uniform01 needs a generator of full 64-bit values");
  return static_cast<double>(rng() >> 11) * 0x1.0p-53;
}

// Normal with mean 0 by Box-Muller from two uniform01() draws, u1 first (the pair's second value
// is discarded): standard_deviation * sqrt(-2 ln u1) * cos(2 pi u2), multiplied left to right,
// with u1 = 0 taken as 2^-53. normal(rng) is the standard normal; note that
// normal(rng, s) and s * normal(rng) may differ in the last bit.
template <class Generator>
double normal(Generator& rng, double standard_deviation = 1.0) {
  const double u1 = std::max(uniform01(rng), 0x1.0p-53);
  const double u2 = uniform01(rng);
  return standard_deviation * std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

}  // namespace demcal
