// Campaign benchmark: TBPSO, 20 iterations x 10 particles, objective 2, on the reference arch
// against the bundled synthetic measurement (data/arch/campaign.json), threads backend on every
// core. Goal: <= 60 s on 2 cores. Each repetition uses a fresh archive, so every run is simulated.
#include "demcal/pipelines/campaign.hpp"

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

BENCHMARK_MAIN();
