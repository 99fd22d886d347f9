// `demcal optimise`: runs one optimiser on an analytic test function and prints the result as JSON.
// It is how users (and the optimiser benchmark) compare algorithms without running simulations.
#include "command_registry.hpp"

#include <demcal/optimise/optimise.hpp>

#include <nlohmann/json.hpp>

#include <iostream>
#include <memory>
#include <stdexcept>
#include <string>

namespace {

struct OptimiseCommandOptions {
  std::string function = "sphere";
  int dimension = 3;
  long evaluations = 200;
  std::string algorithm = "tbpso";
  std::uint64_t seed = 1;
  int batch = 10;
  std::string trust_direction = "paper";
  bool constriction = false;
  bool unshifted = false;
  std::string bounds = "clamp";
  std::string ga_mutation = "reset";
  int elitism = 0;
  long polish_evaluations = 0;
  std::string polish_algorithm = "LN_BOBYQA";
};

nlohmann::json vector_json(const Eigen::VectorXd& v) {
  nlohmann::json out = nlohmann::json::array();
  for (Eigen::Index k = 0; k < v.size(); ++k) out.push_back(v[k]);
  return out;
}

void run(const OptimiseCommandOptions& o) {
  using namespace demcal::optimise;
  if (o.evaluations <= 0) throw std::runtime_error("--evals " + std::to_string(o.evaluations) + " must be > 0");
  if (o.polish_evaluations < 0 || (o.polish_evaluations > 0 && o.polish_evaluations >= o.evaluations))
    throw std::runtime_error("--polish " + std::to_string(o.polish_evaluations) + " must lie in [0, --evals " +
                             std::to_string(o.evaluations) + "): the polish takes its evaluations out of --evals");
  const TestFunction function = make_test_function(o.function, o.dimension, !o.unshifted);
  ParameterSpace space;
  for (int k = 0; k < o.dimension; ++k) space.add(std::string("x").append(std::to_string(k)), function.lower[k], function.upper[k]);

  OptimiserOptions options;
  options.algorithm = o.algorithm;
  options.population = o.batch;
  options.max_evaluations = o.evaluations;
  options.seed = o.seed;
  options.trust_direction = o.trust_direction;
  options.constriction = o.constriction;
  options.bounds = parse_bound_handling(o.bounds);
  options.ga_mutation = parse_ga_mutation(o.ga_mutation);
  options.elitism = o.elitism;
  options.polish_evaluations = o.polish_evaluations;
  options.polish_algorithm = o.polish_algorithm;
  auto optimiser = make_optimiser(space, options);
  const MinimiseSummary summary = minimise(*optimiser, function.evaluate);

  nlohmann::json out;
  out["function"] = o.function;
  out["dimension"] = o.dimension;
  out["shifted"] = !o.unshifted;
  out["algorithm"] = optimiser->name();
  out["seed"] = o.seed;
  out["batch"] = o.batch;
  out["status"] = to_string(summary.status);
  if (!summary.message.empty()) out["message"] = summary.message;
  out["iterations"] = summary.iterations;

  if (const auto polish = optimiser->polish_report()) {
    out["before_polish"] = {{"best_value", polish->main_best_value},
                            {"best_x", vector_json(polish->main_best_x)},
                            {"evaluations", polish->main_evaluations}};
    out["polish"] = {{"evaluations", polish->polish_evaluations}, {"status", polish->polish_status}};
  }
  out["best_value"] = summary.best_value;
  out["best_x"] = vector_json(summary.best_x);
  out["evaluations"] = summary.evaluations;
  std::cout << out.dump(2) << "\n";
}

void setup(CLI::App& app) {
  auto options = std::make_shared<OptimiseCommandOptions>();
  auto* sub = app.add_subcommand("optimise", "Run an optimiser on an analytic test function; prints JSON");
  sub->add_option("--function", options->function, "sphere | rosenbrock | rastrigin | ackley")->capture_default_str();
  sub->add_option("--dim", options->dimension, "Number of dimensions")->capture_default_str();
  sub->add_option("--evals", options->evaluations, "Evaluation budget")->capture_default_str();
  sub->add_option("--algorithm", options->algorithm, "pso | tbpso | ga | nlopt:<NAME> (e.g. nlopt:LN_BOBYQA)")
      ->capture_default_str();
  sub->add_option("--seed", options->seed, "Random seed")->capture_default_str();
  sub->add_option("--batch", options->batch,
                  "Candidates per batch: swarm/population size of pso, tbpso, ga (NLopt always asks one point)")
      ->capture_default_str();
  sub->add_option("--trust-direction", options->trust_direction, "TBPSO reading of dx: toward (x_j - x_i) | paper (x_i - x_j)")
      ->capture_default_str();
  sub->add_flag("--constriction", options->constriction, "PSO/TBPSO: multiply by the constriction factor K (eq. 8)");
  sub->add_option("--bounds", options->bounds, "PSO/TBPSO bound handling: clamp | reflect")->capture_default_str();
  sub->add_option("--ga-mutation", options->ga_mutation, "GA mutation: reset (paper) | gaussian")->capture_default_str();
  sub->add_option("--elitism", options->elitism, "GA: individuals kept unchanged per generation")->capture_default_str();
  sub->add_flag("--unshifted", options->unshifted, "Put the optimum at the textbook location (box centre for most)");
  sub->add_option("--polish", options->polish_evaluations,
                  "Evaluations (out of --evals) for a local NLopt run from the main algorithm's best point")
      ->capture_default_str();
  sub->add_option("--polish-algorithm", options->polish_algorithm, "NLopt algorithm of the polish step")->capture_default_str();
  sub->callback([options] { run(*options); });
}

}  // namespace

DEMCAL_REGISTER_COMMAND("optimise", setup);
