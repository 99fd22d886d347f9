#include "demcal/optimise/optimiser.hpp"

#include "internal.hpp"

#include "demcal/common/format.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace demcal::optimise {

using detail::fail;

// ---- enums ----------------------------------------------------------------------------------

std::string to_string(BoundHandling handling) { return handling == BoundHandling::reflect ? "reflect" : "clamp"; }
BoundHandling parse_bound_handling(const std::string& text) {
  if (text == "clamp") return BoundHandling::clamp;
  if (text == "reflect") return BoundHandling::reflect;
  fail("unknown bound handling '" + text + "' (expected 'clamp' or 'reflect')");
}

std::string to_string(TrustDirection direction) { return direction == TrustDirection::paper ? "paper" : "toward"; }
TrustDirection parse_trust_direction(const std::string& text) {
  if (text == "toward") return TrustDirection::toward;
  if (text == "paper") return TrustDirection::paper;
  fail("unknown trust_direction '" + text + "' (expected 'toward' (x_j - x_i) or 'paper' (x_i - x_j))");
}

std::string to_string(GaMutation mutation) { return mutation == GaMutation::gaussian ? "gaussian" : "reset"; }
GaMutation parse_ga_mutation(const std::string& text) {
  if (text == "reset") return GaMutation::reset;
  if (text == "gaussian") return GaMutation::gaussian;
  fail("unknown GA mutation '" + text + "' (expected 'reset' or 'gaussian')");
}

std::string to_string(OptimiserStatus status) {
  switch (status) {
    case OptimiserStatus::running: return "running";
    case OptimiserStatus::budget_exhausted: return "budget_exhausted";
    case OptimiserStatus::target_reached: return "target_reached";
    case OptimiserStatus::converged: return "converged";
    case OptimiserStatus::failed: return "failed";
  }
  return "unknown";
}

// ---- options --------------------------------------------------------------------------------

long OptimiserOptions::evaluation_budget() const {
  return max_evaluations > 0 ? max_evaluations : static_cast<long>(population) * iterations;
}

void OptimiserOptions::Validate() const {
  const bool is_swarm = algorithm == "pso" || algorithm == "tbpso";
  const bool is_ga = algorithm == "ga";
  const std::string nlopt_name = detail::nlopt_name_from_algorithm(algorithm);
  if (!is_swarm && !is_ga && nlopt_name.empty()) {
    std::string known;
    for (const auto& n : nlopt_algorithms()) known += " nlopt:" + n;
    fail("unknown algorithm '" + algorithm + "' (expected pso, tbpso, ga or one of" + known + ")");
  }
  if (population < 2) fail("option population = " + std::to_string(population) + " must be >= 2");
  if (iterations < 1) fail("option iterations = " + std::to_string(iterations) + " must be >= 1");
  if (max_evaluations < 0) fail("option max_evaluations = " + std::to_string(max_evaluations) + " must be >= 0");
  limits::require_within(limits::Limit::population, population, "option population");
  limits::require_within(limits::Limit::population, nlopt_population, "option nlopt_population");
  limits::require_within(limits::Limit::iterations, iterations, "option iterations");
  if (max_evaluations > 0)
    limits::require_within(limits::Limit::evaluations, max_evaluations, "option max_evaluations");
  else
    limits::require_within(limits::Limit::evaluations, 1.0 * population * iterations, "option population x iterations");
  if (std::isnan(target_value)) fail("option target_value is NaN");
  auto finite_nonnegative = [](double v, const char* name) {
    if (!std::isfinite(v) || v < 0.0)
      fail(std::string("option ") + name + " = " + format_number(v, round_trip_digits) + " must be finite and >= 0");
  };
  auto probability = [](double v, const char* name) {
    if (!(v >= 0.0 && v <= 1.0))
      fail(std::string("option ") + name + " = " + format_number(v, round_trip_digits) + " must lie in [0, 1]");
  };
  finite_nonnegative(inertia_start, "inertia_start");
  finite_nonnegative(inertia_end, "inertia_end");
  finite_nonnegative(pso_cognitive, "pso_cognitive");
  finite_nonnegative(pso_social, "pso_social");
  finite_nonnegative(tbpso_cognitive, "tbpso_cognitive");
  finite_nonnegative(tbpso_social, "tbpso_social");
  finite_nonnegative(tbpso_trust, "tbpso_trust");
  finite_nonnegative(max_velocity, "max_velocity");
  finite_nonnegative(initial_velocity, "initial_velocity");
  finite_nonnegative(initial_step, "initial_step");
  finite_nonnegative(xtol_rel, "xtol_rel");
  finite_nonnegative(ftol_abs, "ftol_abs");
  parse_trust_direction(trust_direction);
  if (constriction) {
    const double phi = algorithm == "tbpso" ? tbpso_cognitive + tbpso_social + tbpso_trust : pso_cognitive + pso_social;
    if (phi < 4.0)
      fail("option constriction needs phi = sum of the acceleration weights >= 4, got " + format_number(phi, round_trip_digits) +
           " for " + algorithm);
  }
  probability(crossover_probability, "crossover_probability");
  probability(mutation_probability, "mutation_probability");
  if (!(ga_sigma_start > 0.0) || !std::isfinite(ga_sigma_start))
    fail("option ga_sigma_start = " + format_number(ga_sigma_start, round_trip_digits) + " must be finite and > 0");
  if (!(ga_sigma_end > 0.0) || !std::isfinite(ga_sigma_end))
    fail("option ga_sigma_end = " + format_number(ga_sigma_end, round_trip_digits) + " must be finite and > 0");
  if (elitism < 0 || elitism >= population)
    fail("option elitism = " + std::to_string(elitism) + " must lie in [0, population - 1 = " +
         std::to_string(population - 1) + "]");
  if (evaluations_per_iteration < 0 || evaluations_per_iteration > population)
    fail("option evaluations_per_iteration = " + std::to_string(evaluations_per_iteration) +
         " must lie in [0, population = " + std::to_string(population) + "]");
  if (nlopt_population < 0) fail("option nlopt_population = " + std::to_string(nlopt_population) + " must be >= 0");
  for (std::size_t k = 0; k < initial_point.size(); ++k)
    if (!std::isfinite(initial_point[k]))
      fail("option initial_point[" + std::to_string(k) + "] = " + format_number(initial_point[k], round_trip_digits) + " is not finite");
  for (std::size_t i = 0; i < further_starts.size(); ++i)
    for (std::size_t k = 0; k < further_starts[i].size(); ++k)
      if (!std::isfinite(further_starts[i][k]))
        fail("option further_starts[" + std::to_string(i) + "][" + std::to_string(k) + "] = " +
             format_number(further_starts[i][k], round_trip_digits) + " is not finite");
  if (polish_evaluations < 0)
    fail("option polish_evaluations = " + std::to_string(polish_evaluations) + " must be >= 0");
  if (polish_evaluations > 0) {
    if (polish_evaluations >= evaluation_budget())
      fail("option polish_evaluations = " + std::to_string(polish_evaluations) +
           " must be smaller than the evaluation budget " + std::to_string(evaluation_budget()) +
           " (the polish takes its evaluations out of the budget)");
    if (detail::nlopt_name_from_algorithm("nlopt:" + polish_algorithm).empty())
      fail("option polish_algorithm = '" + polish_algorithm + "' is not a known NLopt algorithm");
    if (!(polish_initial_step > 0.0) || !std::isfinite(polish_initial_step))
      fail("option polish_initial_step = " + format_number(polish_initial_step, round_trip_digits) + " must be finite and > 0");
  }
}

// ---- base class -----------------------------------------------------------------------------

Optimiser::Optimiser(ParameterSpace space, OptimiserOptions options, std::string name)
    : space_(std::move(space)), options_(std::move(options)), name_(std::move(name)) {}

Optimiser::~Optimiser() = default;

bool Optimiser::done() const { return status_ != OptimiserStatus::running; }

void Optimiser::substitute(std::size_t, const Eigen::VectorXd&) {
  throw std::logic_error(name_ + ": this optimiser cannot accept substituted candidates");
}

std::vector<Eigen::VectorXd> Optimiser::alternatives(std::size_t, int) const {
  throw std::logic_error(name_ + ": this optimiser cannot propose alternative candidates");
}

void Optimiser::withdraw(std::size_t) {
  throw std::logic_error(name_ + ": this optimiser cannot withdraw candidates");
}

Eigen::VectorXd Optimiser::best_x() const {
  if (best_unit_.size() == 0) return {};
  return space_.to_physical(best_unit_);
}

Eigen::VectorXd Optimiser::physical(const Eigen::VectorXd& unit) const { return space_.to_physical(unit); }

double Optimiser::record(const Eigen::VectorXd& unit_point, double value) {
  const double v = detail::sanitise(value);
  ++evaluations_;
  if (v < best_value_) {
    best_value_ = v;
    best_unit_ = unit_point;
  }
  return v;
}

void Optimiser::update_status_after_tell() {
  if (status_ != OptimiserStatus::running) return;
  if (best_value_ <= options_.target_value) {
    status_ = OptimiserStatus::target_reached;
  } else if (evaluations_ >= options_.evaluation_budget()) {
    status_ = OptimiserStatus::budget_exhausted;
  }
}

nlohmann::json Optimiser::save_common() const {
  nlohmann::json s;
  s["algorithm"] = name_;
  s["dimension"] = space_.dimension();
  s["best_unit"] = detail::vector_to_json(best_unit_);
  s["best_value"] = detail::number_to_json(best_value_);
  s["iteration"] = iteration_;
  s["evaluations"] = evaluations_;
  s["status"] = to_string(status_);
  s["message"] = message_;
  return s;
}

void Optimiser::load_common(const nlohmann::json& state) {
  if (!state.is_object()) fail(name_ + ": optimiser state must be a JSON object");
  const std::string algorithm = detail::state_field(state, "algorithm").get<std::string>();
  if (algorithm != name_) fail("optimiser state is for algorithm '" + algorithm + "', not '" + name_ + "'");
  const int dimension = detail::state_field(state, "dimension").get<int>();
  if (dimension != space_.dimension())
    fail(name_ + ": optimiser state has dimension " + std::to_string(dimension) + ", the space has " +
         std::to_string(space_.dimension()));
  best_unit_ = detail::vector_from_json(detail::state_field(state, "best_unit"), "best_unit");
  best_value_ = detail::number_from_json(detail::state_field(state, "best_value"), "best_value");
  iteration_ = detail::state_field(state, "iteration").get<int>();
  evaluations_ = detail::state_field(state, "evaluations").get<long>();
  const std::string status = detail::state_field(state, "status").get<std::string>();
  status_ = OptimiserStatus::running;
  for (auto s : {OptimiserStatus::running, OptimiserStatus::budget_exhausted, OptimiserStatus::target_reached,
                 OptimiserStatus::converged, OptimiserStatus::failed})
    if (to_string(s) == status) status_ = s;
  message_ = detail::state_field(state, "message").get<std::string>();
}

// ---- factory --------------------------------------------------------------------------------

std::unique_ptr<Optimiser> make_optimiser(const ParameterSpace& space, const OptimiserOptions& options) {
  space.Validate();
  options.Validate();
  if (!options.initial_point.empty() && static_cast<int>(options.initial_point.size()) != space.dimension())
    fail("option initial_point has " + std::to_string(options.initial_point.size()) + " values, the space has " +
         std::to_string(space.dimension()) + " free parameters");
  for (std::size_t i = 0; i < options.further_starts.size(); ++i)
    if (static_cast<int>(options.further_starts[i].size()) != space.dimension())
      fail("option further_starts[" + std::to_string(i) + "] has " + std::to_string(options.further_starts[i].size()) +
           " values, the space has " + std::to_string(space.dimension()) + " free parameters");
  if (options.polish_evaluations > 0) return detail::make_polished(space, options);
  if (options.algorithm == "pso") return detail::make_swarm(space, options, false);
  if (options.algorithm == "tbpso") return detail::make_swarm(space, options, true);
  if (options.algorithm == "ga") return detail::make_genetic(space, options);
  return detail::make_nlopt(space, options, detail::nlopt_name_from_algorithm(options.algorithm));
}

const std::vector<std::string>& nlopt_algorithms() {
  static const std::vector<std::string> names = {"GN_DIRECT_L", "GN_DIRECT",   "GN_CRS2_LM",    "GN_ISRES",
                                                 "GN_ESCH",     "LN_BOBYQA",   "LN_NELDERMEAD", "LN_SBPLX",
                                                 "LN_COBYLA",   "LN_NEWUOA_BOUND", "LN_PRAXIS"};
  return names;
}

// ---- conveniences ---------------------------------------------------------------------------

MinimiseSummary minimise(Optimiser& optimiser, const Objective& objective) {
  MinimiseSummary summary;
  while (!optimiser.done()) {
    const auto batch = optimiser.ask();
    if (batch.empty()) break;
    std::vector<double> values;
    values.reserve(batch.size());
    for (const auto& x : batch) values.push_back(objective(x));
    optimiser.tell(values);
    summary.best_value_history.push_back(optimiser.best_value());
  }
  summary.status = optimiser.status();
  summary.message = optimiser.message();
  summary.best_x = optimiser.best_x();
  summary.best_value = optimiser.best_value();
  summary.evaluations = optimiser.evaluations();
  summary.iterations = optimiser.iteration();
  return summary;
}

void PolishOptions::Validate() const {
  if (detail::nlopt_name_from_algorithm("nlopt:" + algorithm).empty())
    fail("polish algorithm '" + algorithm + "' is not a known NLopt algorithm");
  if (max_evaluations <= 0) fail("polish max_evaluations = " + std::to_string(max_evaluations) + " must be > 0");
  limits::require_within(limits::Limit::evaluations, max_evaluations, "polish max_evaluations");
  if (!(initial_step > 0.0) || !std::isfinite(initial_step))
    fail("polish initial_step = " + format_number(initial_step, round_trip_digits) + " must be finite and > 0");
  if (!(xtol_rel >= 0.0) || !std::isfinite(xtol_rel))
    fail("polish xtol_rel = " + format_number(xtol_rel, round_trip_digits) + " must be >= 0");
}

std::unique_ptr<Optimiser> make_polisher(const ParameterSpace& space, const Eigen::VectorXd& start_physical,
                                         const PolishOptions& options) {
  options.Validate();
  OptimiserOptions o;
  o.algorithm = "nlopt:" + options.algorithm;
  o.max_evaluations = options.max_evaluations;
  o.seed = options.seed;
  o.initial_step = options.initial_step;
  o.xtol_rel = options.xtol_rel;
  o.initial_point.assign(start_physical.data(), start_physical.data() + start_physical.size());
  return make_optimiser(space, o);
}

// ---- detail: JSON and RNG helpers -----------------------------------------------------------

namespace detail {

std::string rng_to_string(const std::mt19937_64& rng) {
  std::ostringstream out;
  out << rng;
  return out.str();
}

void rng_from_string(std::mt19937_64& rng, const std::string& text) {
  std::istringstream in(text);
  in >> rng;
  if (in.fail()) fail("optimiser state: malformed random generator state");
}

nlohmann::json number_to_json(double value) {
  if (std::isnan(value)) return "nan";
  if (std::isinf(value)) return value > 0 ? "inf" : "-inf";
  return value;
}

double number_from_json(const nlohmann::json& value, const std::string& key) {
  if (value.is_number()) return value.get<double>();
  if (value.is_string()) {
    const auto s = value.get<std::string>();
    if (s == "inf") return HUGE_VAL;
    if (s == "-inf") return -HUGE_VAL;
    if (s == "nan") return std::nan("");
  }
  fail("optimiser state: key '" + key + "' holds " + value.dump() + ", not a number");
}

nlohmann::json vector_to_json(const Eigen::VectorXd& v) {
  nlohmann::json out = nlohmann::json::array();
  for (Eigen::Index k = 0; k < v.size(); ++k) out.push_back(number_to_json(v[k]));
  return out;
}

Eigen::VectorXd vector_from_json(const nlohmann::json& value, const std::string& key) {
  if (!value.is_array()) fail("optimiser state: key '" + key + "' is not an array");
  Eigen::VectorXd v(static_cast<Eigen::Index>(value.size()));
  for (std::size_t k = 0; k < value.size(); ++k) v[static_cast<Eigen::Index>(k)] = number_from_json(value[k], key);
  return v;
}

nlohmann::json matrix_to_json(const Eigen::MatrixXd& m) {
  nlohmann::json out = nlohmann::json::array();
  for (Eigen::Index r = 0; r < m.rows(); ++r) out.push_back(vector_to_json(m.row(r).transpose()));
  return out;
}

Eigen::MatrixXd matrix_from_json(const nlohmann::json& value, const std::string& key) {
  if (!value.is_array()) fail("optimiser state: key '" + key + "' is not an array of rows");
  if (value.empty()) return {};
  const auto cols = vector_from_json(value[0], key).size();
  Eigen::MatrixXd m(static_cast<Eigen::Index>(value.size()), cols);
  for (std::size_t r = 0; r < value.size(); ++r) {
    const auto row = vector_from_json(value[r], key);
    if (row.size() != cols) fail("optimiser state: key '" + key + "' has rows of different lengths");
    m.row(static_cast<Eigen::Index>(r)) = row.transpose();
  }
  return m;
}

const nlohmann::json& state_field(const nlohmann::json& state, const std::string& key) {
  if (!state.is_object() || !state.contains(key)) fail("optimiser state: missing key '" + key + "'");
  return state.at(key);
}

std::string nlopt_name_from_algorithm(const std::string& algorithm) {
  const std::string prefix = "nlopt:";
  if (algorithm.rfind(prefix, 0) != 0) return {};
  std::string name = algorithm.substr(prefix.size());
  std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return std::toupper(c); });
  if (name.rfind("NLOPT_", 0) == 0) name = name.substr(6);
  for (const auto& known : nlopt_algorithms())
    if (known == name) return name;
  return {};
}

}  // namespace detail

}  // namespace demcal::optimise
