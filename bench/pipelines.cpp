// Pipelines benchmarks on data/arch/campaign.json: the campaign (TBPSO, 20 iterations x 10
// particles, objective 2, the reference arch against the bundled synthetic measurement, threads
// backend on every core; goal <= 60 s on 2 cores; each repetition uses a fresh archive, so every
// run is simulated), and the fitness of one predicted curve (curve_fitness).
#include "demcal/pipelines/campaign.hpp"
#include "demcal/pipelines/surrogate_data.hpp"
#include "demcal/smoothing/objective.hpp"

#include <benchmark/benchmark.h>

#include <filesystem>

namespace fs = std::filesystem;

static void BM_ReferenceArchCampaign(benchmark::State& state) {
  auto config = demcal::pipelines::load_campaign(std::string(DEMCAL_SOURCE_DIR) + "/data/arch/campaign.json");
  config.optimiser.iterations = static_cast<int>(state.range(0));
  config.report = false;
  const fs::path out = fs::temp_directory_path() / "demcal-bench-pipelines";
  demcal::pipelines::RunOptions options;
  options.progress = false;
  double simulations = 0, best = 0;
  for (auto _ : state) {
    state.PauseTiming();
    fs::remove_all(out);
    config.output = out.string();
    state.ResumeTiming();
    const auto result = demcal::pipelines::run_campaign(config, options);
    simulations = static_cast<double>(result.simulations);
    best = result.best.fitness;
  }
  state.counters["simulations"] = simulations;
  state.counters["best_fitness"] = best;
  state.counters["s_per_simulation"] =
      benchmark::Counter(simulations, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_ReferenceArchCampaign)->Arg(20)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

// The fitness of a predicted curve (curve_fitness): what a surrogate's acquisition computes for each
// point it scores, per ensemble member. The grid and the measured curve of data/arch/campaign.json
// (objective 2: compared with the smoothed measurement, 200 points per channel); the curve scored
// is the measurement's own outputs on the grid.
static void BM_PredictedCurveFitness(benchmark::State& state) {
  const auto config = demcal::pipelines::load_campaign(std::string(DEMCAL_SOURCE_DIR) + "/data/arch/campaign.json");
  const auto measured = demcal::pipelines::load_measured(config.cases.front().measured);
  const demcal::smoothing::Objective2 objective(measured, config.objective_options);
  const auto grid = std::make_shared<const demcal::pipelines::CurveGrid>(
      demcal::pipelines::make_curve_grid(measured, config.objective_options, &objective, 1.0));
  const Eigen::VectorXd outputs = demcal::pipelines::curve_outputs(measured, *grid);
  double fitness = 0;
  for (auto _ : state) benchmark::DoNotOptimize(fitness = demcal::pipelines::curve_fitness(outputs, {grid}));
  state.counters["fitness"] = fitness;
}
BENCHMARK(BM_PredictedCurveFitness)->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
