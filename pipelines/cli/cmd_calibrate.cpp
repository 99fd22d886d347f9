// `demcal calibrate`: run or resume a calibration campaign (campaign.hpp), from a campaign file,
// flags, or both (flags override the file).
#include "command_registry.hpp"

#include "demcal/common/format.hpp"
#include "demcal/pipelines/campaign.hpp"
#include "demcal/pipelines/mpi.hpp"

#include <cmath>
#include <iostream>
#include <memory>

namespace demcal::cli::calibrate_command {

struct CalibrateFlags {
  std::string campaign_file;
  std::string scene, generator, experiment, out, archive, name, algorithm, backend, command, surrogate;
  std::vector<std::string> params, mappings, generator_options;
  int iterations = 0, swarm = 0, objective = 0, threads = -1, fitness_threads = -1;
  long polish = -1;
  long max_simulations = 0;
  long long seed = -1;
  double timeout = 0;
  bool timeout_given = false;
  bool resume = false, no_report = false, quiet = false;
};

demcal::pipelines::CampaignConfig build_config(const CalibrateFlags& f) {
  using namespace demcal::pipelines;
  CampaignConfig c;
  if (!f.campaign_file.empty()) c = load_campaign(f.campaign_file);
  else c.source = "command line";
  if (f.campaign_file.empty() && f.scene.empty() && f.generator.empty() && f.experiment.empty())
    throw CampaignError("no campaign: give a campaign file (demcal calibrate campaign.json) or --scene/--generator, "
                        "--experiment and --param flags");
  if (!f.scene.empty() || !f.generator.empty() || !f.experiment.empty() || !f.mappings.empty()) {
    if (c.cases.size() > 1) throw CampaignError("--scene/--experiment/--map cannot change a campaign with several cases");
    if (c.cases.empty()) c.cases.emplace_back();
    auto& k = c.cases[0];
    if (!f.scene.empty()) k.scene = SceneSpec{f.scene, "", nlohmann::json::object()};
    if (!f.generator.empty()) {
      k.scene = SceneSpec{"", f.generator, nlohmann::json::object()};
      for (const auto& option : f.generator_options) {
        const auto eq = option.find('=');
        if (eq == std::string::npos) throw CampaignError("--scene-option " + option + ": expected KEY=VALUE");
        const std::string value = option.substr(eq + 1);
        try {
          k.scene.options[option.substr(0, eq)] = nlohmann::json::parse(value);
        } catch (const std::exception&) {
          k.scene.options[option.substr(0, eq)] = value;
        }
      }
    }
    if (!f.experiment.empty()) k.measured.file = f.experiment;
    if (!f.mappings.empty()) {
      k.measured.columns.clear();
      for (const auto& m : f.mappings) k.measured.columns.push_back(parse_mapping_flag(m));
    }
  }
  if (!f.params.empty()) {
    c.space = demcal::optimise::ParameterSpace();
    for (const auto& p : f.params) add_parameter_flag(c.space, p);
  }
  if (!f.name.empty()) c.name = f.name;
  if (!f.algorithm.empty()) c.optimiser.algorithm = f.algorithm;
  if (f.iterations > 0) c.optimiser.iterations = f.iterations;
  if (f.swarm > 0) c.optimiser.population = f.swarm;
  if (f.max_simulations > 0) c.optimiser.max_evaluations = f.max_simulations;
  if (f.seed >= 0) c.optimiser.seed = static_cast<std::uint64_t>(f.seed);
  if (f.objective > 0) c.objective = f.objective;
  if (!f.backend.empty()) {
    if (f.backend != "threads" && f.backend != "command" && f.backend != "mpi")
      throw CampaignError("--backend " + f.backend + ": unknown backend '" + f.backend + "' (known: threads, command, mpi)");
    c.backend.type = f.backend;
  }
  if (!f.command.empty()) {
    c.backend.command = f.command;
    if (f.backend.empty()) c.backend.type = "command";
  }
  if (f.timeout_given) {
    if (!(f.timeout >= 0) || !std::isfinite(f.timeout)) {
      throw CampaignError("--timeout " + demcal::format_number(f.timeout, 6) + ": must be a number of seconds >= 0 (0 = none)");
    }
    c.backend.timeout_s = f.timeout;
  }
  if (f.threads >= 0) c.backend.threads = c.backend.parallel = f.threads;
  if (f.fitness_threads >= 0) c.backend.fitness_threads = f.fitness_threads;
  if (f.polish == 0) c.polish.enabled = false;
  if (f.polish > 0) {
    c.polish.enabled = true;
    c.polish.options.max_evaluations = f.polish;
  }
  if (f.surrogate == "off") {
    c.surrogate.enabled = false;
  } else if (f.surrogate == "on") {
    c.surrogate.enabled = true;
  } else if (f.surrogate == "gp" || f.surrogate == "mlp") {
    c.surrogate.enabled = true;
    c.surrogate.options.kind = f.surrogate;
  } else if (!f.surrogate.empty()) {
    c.surrogate.enabled = true;
    c.surrogate.model_file = f.surrogate;
    if (const std::string kind = surrogate_model_kind(f.surrogate); !kind.empty()) c.surrogate.options.kind = kind;
  }
  if (!f.out.empty()) c.output = f.out;
  if (!f.archive.empty()) c.archive = f.archive;
  if (f.no_report) c.report = false;
  return c;
}

void run(const CalibrateFlags& flags) {
  using namespace demcal::pipelines;
  const CampaignConfig config = build_config(flags);
  RunOptions options;
  options.resume = flags.resume;
  options.progress = !flags.quiet;
  std::unique_ptr<MpiSession> mpi;
  if (config.backend.type == "mpi") {
    mpi = std::make_unique<MpiSession>(nullptr, nullptr);
    options.mpi_rank = mpi->rank();
    options.mpi_size = mpi->size();
    if (mpi->rank() > 0) {
      run_mpi_worker(config);
      return;
    }
  }
  try {
    const CampaignResult result = run_campaign(config, options);
    if (!flags.quiet) {
      std::cout << "best fitness " << result.best.fitness << " after " << result.simulations << " simulations ("
                << result.wall_time_s << " s)\n";
      for (const auto& [name, value] : result.best.params) std::cout << "  " << name << " = " << value << "\n";
      std::cout << "result: " << config.output << "/result.json\n";
    }
    if (result.status != CampaignStatus::completed) {
      std::cerr << "demcal: calibration failed: " << result.message << "\n";
      demcal::cli::exit_code() = 2;
    }
  } catch (const std::exception& e) {
    if (mpi && mpi->size() > 1) {
      std::cerr << "demcal: error: " << e.what() << "\n";
      mpi_abort(1);
    }
    throw;
  }
}

void setup(CLI::App& app) {
  auto flags = std::make_shared<CalibrateFlags>();
  auto* sub = app.add_subcommand("calibrate", "Calibrate scene parameters against measured curves (PSO, TBPSO, GA, NLopt)");
  sub->add_option("campaign", flags->campaign_file, "Campaign JSON file (flags below override it)")->check(CLI::ExistingFile);
  sub->add_option("--scene", flags->scene, "Scene JSON file");
  sub->add_option("--generator", flags->generator, "Scene generator instead of a file: arch | wall");
  sub->add_option("--scene-option", flags->generator_options, "Generator option KEY=VALUE (repeatable)");
  sub->add_option("--experiment", flags->experiment, "Measured curve CSV");
  sub->add_option("--map", flags->mappings, "Measured column mapping TARGET=COLUMN[:UNIT[:SCALE]] (repeatable)");
  sub->add_option("--param", flags->params, "NAME=LOWER:UPPER[:log] | NAME=fixed:VALUE | NAME=tied:SOURCE:RATIO (repeatable)");
  sub->add_option("--algorithm", flags->algorithm, "pso | tbpso | ga | nlopt:NAME | bo (Bayesian optimisation)");
  sub->add_option("--surrogate", flags->surrogate,
                  "Pre-screen candidates with a surrogate: on | off | gp | mlp (on, of that kind) | MODEL (a file from demcal surrogate train)");
  sub->add_option("--iterations", flags->iterations, "Iterations (generations)");
  sub->add_option("--swarm,--population", flags->swarm, "Candidates per iteration");
  sub->add_option("--max-simulations", flags->max_simulations, "Simulation budget (wins over --iterations; with --surrogate it counts simulations)");
  sub->add_option("--objective", flags->objective, "Objective function 1 or 2");
  sub->add_option("--seed", flags->seed, "Random seed");
  sub->add_option("--backend", flags->backend, "threads | command | mpi");
  sub->add_option("--command", flags->command, "External simulator template (implies --backend command)");
  sub->add_option("--timeout", flags->timeout, "External command timeout per run (s)")
      ->each([flags](const std::string&) { flags->timeout_given = true; });
  sub->add_option("--threads", flags->threads, "Simulations at once (0 = every core)");
  sub->add_option("--fitness-threads", flags->fitness_threads, "Threads computing objectives (0 = every core)");
  sub->add_option("--polish", flags->polish, "Local NLopt polish after the swarm: N simulations (0 = off)");
  sub->add_option("--out", flags->out, "Output folder");
  sub->add_option("--archive", flags->archive, "Archive file (default OUT/archive.sqlite)");
  sub->add_option("--name", flags->name, "Campaign name");
  sub->add_flag("--resume", flags->resume, "Continue the interrupted campaign in the archive");
  sub->add_flag("--no-report", flags->no_report, "Skip report.md and figures");
  sub->add_flag("--quiet", flags->quiet, "No progress lines");
  sub->callback([flags] { run(*flags); });
}

}  // namespace demcal::cli::calibrate_command

DEMCAL_REGISTER_COMMAND("calibrate", demcal::cli::calibrate_command::setup);
