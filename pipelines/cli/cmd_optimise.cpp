// `demcal optimise`: runs one optimiser on an analytic test function and prints the result as JSON.
// It is how users (and the optimiser benchmark) compare algorithms without running simulations.
#include "command_registry.hpp"
#include "field_flags.hpp"

#include <demcal/optimise/optimise.hpp>
#include <demcal/pipelines/campaign.hpp>

#include <nlohmann/json.hpp>

#include <iostream>
#include <memory>
#include <stdexcept>
#include <string>

namespace demcal::cli::optimise_command {

using demcal::optimise::OptimiserOptions;

struct OptimiseCommandOptions {
  std::string function = "sphere";
  int dimension = 3;
  bool unshifted = false;
  OptimiserOptions optimiser;
  // --algorithm, --seed, --bounds, ...: the campaign file's optimiser keys (optimiser_fields()).
  std::unique_ptr<demcal::cli::FieldFlags<OptimiserOptions>> optimiser_flags;
};

nlohmann::json vector_json(const Eigen::VectorXd& v) {
  nlohmann::json out = nlohmann::json::array();
  for (Eigen::Index k = 0; k < v.size(); ++k) out.push_back(v[k]);
  return out;
}

void run(OptimiseCommandOptions& o) {
  using namespace demcal::optimise;
  OptimiserOptions& options = o.optimiser;
  if (options.max_evaluations <= 0)
    throw std::runtime_error("--evals " + std::to_string(options.max_evaluations) + " must be > 0");
  if (options.polish_evaluations < 0 ||
      (options.polish_evaluations > 0 && options.polish_evaluations >= options.max_evaluations))
    throw std::runtime_error("--polish " + std::to_string(options.polish_evaluations) + " must lie in [0, --evals " +
                             std::to_string(options.max_evaluations) + "): the polish takes its evaluations out of --evals");
  const TestFunction function = make_test_function(o.function, o.dimension, !o.unshifted);
  ParameterSpace space;
  for (int k = 0; k < o.dimension; ++k) space.add(std::string("x").append(std::to_string(k)), function.lower[k], function.upper[k]);

  o.optimiser_flags->apply();
  auto optimiser = make_optimiser(space, options);
  const MinimiseSummary summary = minimise(*optimiser, function.evaluate);

  nlohmann::json out;
  out["function"] = o.function;
  out["dimension"] = o.dimension;
  out["shifted"] = !o.unshifted;
  out["algorithm"] = optimiser->name();
  out["seed"] = options.seed;
  out["batch"] = options.population;
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
  OptimiserOptions& optimiser = options->optimiser;
  optimiser.max_evaluations = 200;
  sub->add_option("--evals", optimiser.max_evaluations, "Evaluation budget")->capture_default_str();
  sub->add_option("--batch", optimiser.population,
                  "Candidates per batch: swarm/population size of pso, tbpso, ga (NLopt always asks one point)")
      ->capture_default_str();
  options->optimiser_flags = std::make_unique<demcal::cli::FieldFlags<OptimiserOptions>>(
      *sub, demcal::pipelines::optimiser_fields(), optimiser);
  sub->add_flag("--unshifted", options->unshifted, "Put the optimum at the textbook location (box centre for most)");
  sub->add_option("--polish", optimiser.polish_evaluations,
                  "Evaluations (out of --evals) for a local NLopt run from the main algorithm's best point")
      ->capture_default_str();
  sub->add_option("--polish-algorithm", optimiser.polish_algorithm, "NLopt algorithm of the polish step")
      ->capture_default_str();
  sub->callback([options] { run(*options); });
}

}  // namespace demcal::cli::optimise_command

DEMCAL_REGISTER_COMMAND("optimise", demcal::cli::optimise_command::setup);
