// Private helpers of the optimise module (JSON of doubles and vectors, random streams, factories).
#pragma once

#include "demcal/common/random.hpp"
#include "demcal/limits/limits.hpp"
#include "demcal/optimise/optimiser.hpp"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>

namespace demcal::optimise::detail {

// Bad options or states are std::invalid_argument with the message naming the key and value.
[[noreturn]] inline void fail(const std::string& message) { throw std::invalid_argument(message); }

// Non-finite (NaN, ±inf) told values are the worst: +inf.
inline double sanitise(double value) { return std::isfinite(value) ? value : HUGE_VAL; }

std::string rng_to_string(const std::mt19937_64& rng);
void rng_from_string(std::mt19937_64& rng, const std::string& text);

nlohmann::json number_to_json(double value);    // non-finite -> "inf" / "-inf" / "nan"
double number_from_json(const nlohmann::json& value, const std::string& key);
nlohmann::json vector_to_json(const Eigen::VectorXd& v);
Eigen::VectorXd vector_from_json(const nlohmann::json& value, const std::string& key);
nlohmann::json matrix_to_json(const Eigen::MatrixXd& m);  // array of rows
Eigen::MatrixXd matrix_from_json(const nlohmann::json& value, const std::string& key);

// Looks up a key in a state object; throws std::invalid_argument naming it when missing.
const nlohmann::json& state_field(const nlohmann::json& state, const std::string& key);

std::unique_ptr<Optimiser> make_swarm(const ParameterSpace& space, const OptimiserOptions& options, bool trust_based);
std::unique_ptr<Optimiser> make_genetic(const ParameterSpace& space, const OptimiserOptions& options);
// options.polish_evaluations > 0: the main algorithm, then a local NLopt polish (polished.cpp).
std::unique_ptr<Optimiser> make_polished(const ParameterSpace& space, const OptimiserOptions& options);
std::unique_ptr<Optimiser> make_nlopt(const ParameterSpace& space, const OptimiserOptions& options,
                                      const std::string& algorithm_name);

// "LN_BOBYQA" from "nlopt:LN_BOBYQA", "nlopt:nlopt_ln_bobyqa", ...; empty if not an nlopt name.
std::string nlopt_name_from_algorithm(const std::string& algorithm);

// tell() must answer a pending ask() with one fitness per candidate of that batch.
inline void check_told_batch(const std::string& name, bool pending, int pending_count, std::size_t told) {
  if (!pending) throw std::logic_error(name + ": tell() without a pending ask()");
  if (static_cast<int>(told) != pending_count)
    throw std::invalid_argument(name + ": tell() got " + std::to_string(told) + " values for " +
                                std::to_string(pending_count) + " candidates");
}

// Checks a candidate substituted from outside (a surrogate's pick) for the pending batch and
// returns it in the unit cube, clamped against round-off at the bounds.
inline Eigen::VectorXd substitution_in_unit_cube(const std::string& name, const ParameterSpace& space, bool pending,
                                                 int pending_count, std::size_t index,
                                                 const Eigen::VectorXd& physical_point) {
  if (!pending) throw std::logic_error(name + ": substitute() needs a pending ask()");
  if (index >= static_cast<std::size_t>(pending_count))
    throw std::invalid_argument(name + ": substitute() index " + std::to_string(index) + " outside the batch of " +
                                std::to_string(pending_count));
  const Eigen::VectorXd unit = space.to_unit(physical_point);
  for (Eigen::Index k = 0; k < unit.size(); ++k)
    if (!(unit[k] >= -1e-12 && unit[k] <= 1.0 + 1e-12))
      throw std::invalid_argument(name + ": substituted value " + std::to_string(physical_point[k]) + " of parameter '" +
                                  space.free_parameters()[static_cast<std::size_t>(k)].name + "' is outside its bounds");
  return unit.cwiseMax(0.0).cwiseMin(1.0);
}

// Generator of the alternatives of candidate `index` at iteration `iteration` (optimiser.hpp):
// seeded from (seed, iteration, index), independent of the optimiser's stream.
inline std::mt19937_64 alternatives_rng(std::uint64_t seed, int iteration, std::size_t index) {
  return seeded_rng(seed, iteration, index);
}

// Candidates per iteration the planned schedule assumes (options.evaluations_per_iteration).
inline int planned_batch(const OptimiserOptions& options) {
  return options.evaluations_per_iteration > 0 ? options.evaluations_per_iteration : options.population;
}

// Checks the pending batch for alternatives() / withdraw().
inline void check_pending_index(const std::string& name, const char* what, bool pending, int pending_count,
                                std::size_t index) {
  if (!pending) throw std::logic_error(name + ": " + what + "() needs a pending ask()");
  if (index >= static_cast<std::size_t>(pending_count))
    throw std::invalid_argument(name + ": " + what + "() index " + std::to_string(index) + " outside the batch of " +
                                std::to_string(pending_count));
}

}  // namespace demcal::optimise::detail
