// `demcal fitness --experiment E.csv --simulation S.csv [--objective 1|2]`: prints the fitness and
// its channel values as JSON.
#include "command_registry.hpp"

#include "demcal/smoothing/smoothing.hpp"

#include <nlohmann/json.hpp>

#include <iostream>
#include <stdexcept>

namespace demcal::cli::fitness_command {

struct FitnessArgs {
  std::string experiment, simulation, force_column = "force";
  std::vector<std::string> ignored = {"time"};
  std::vector<std::string> weights;  // name=value
  int objective = 1;
  int points = 200;
  std::string window = "common";
  std::uint64_t seed = 1;
};

void run_fitness(const FitnessArgs& a) {
  using namespace demcal::smoothing;
  ObjectiveOptions options;
  options.points = a.points;
  options.window = parse_objective_window(a.window);  // checked by CLI11 already
  options.force_column = a.force_column;
  options.ignored_columns = a.ignored;
  for (const auto& w : a.weights) {
    const auto eq = w.find('=');
    if (eq == std::string::npos || eq == 0)
      throw std::runtime_error("--weight '" + w + "': expected COLUMN=VALUE");
    double value = 0;
    try {
      std::size_t used = 0;
      value = std::stod(w.substr(eq + 1), &used);
      if (used != w.size() - eq - 1) throw std::invalid_argument("trailing characters");
    } catch (const std::exception&) {
      throw std::runtime_error("--weight '" + w + "': the value is not a number");
    }
    options.channel_weights[w.substr(0, eq)] = value;
  }
  options.Validate();
  const Curve experiment = read_curve(a.experiment);
  const Curve simulation = read_curve(a.simulation);
  FitnessResult result;
  if (a.objective == 1) {
    result = objective1(experiment, simulation, options);
  } else {
    SmootherOptions smoother;
    smoother.seed = a.seed;
    common_channels(experiment, simulation, options);  // fail fast, before any training
    result = Objective2(experiment, options, smoother).evaluate(simulation);
  }
  nlohmann::json out;
  out["fitness"] = result.fitness;
  out["channels"] = nlohmann::json::object();
  for (const auto& [name, value] : result.channels) out["channels"][name] = value;
  std::cout << out.dump(2) << "\n";
}

void setup(CLI::App& app) {
  auto args = std::make_shared<FitnessArgs>();
  auto* sub = app.add_subcommand("fitness", "Objective 1 or 2 between a measured and a simulated curve (JSON)");
  sub->add_option("--experiment,-e", args->experiment, "Measured curve (CSV)")->required();
  sub->add_option("--simulation,-s", args->simulation, "Simulated curve (CSV)")->required();
  sub->add_option("--objective", args->objective, "1 (raw curves) or 2 (neural-smoothed curves)")
      ->check(CLI::IsMember({1, 2}));
  sub->add_option("--force-column", args->force_column, "Name of the force column in both files");
  sub->add_option("--ignore", args->ignored, "Columns that are neither force nor displacement (default: time)");
  sub->add_option("--weight", args->weights, "Channel weight COLUMN=VALUE (default 1 each)");
  sub->add_option("--points", args->points, "Evaluation points per channel")->check(CLI::Range(2, 1000000));
  sub->add_option("--window", args->window,
                  "Displacement window per channel: common (the paper's, both curves' shared range) or measured "
                  "(the experiment's range; the simulation held at its end values beyond its own)")
      ->check(CLI::IsMember({"common", "measured"}));
  sub->add_option("--seed", args->seed, "Seed of the smoothing networks (objective 2)");
  sub->callback([args] { run_fitness(*args); });
}

DEMCAL_REGISTER_COMMAND("fitness", setup);

}  // namespace demcal::cli::fitness_command
