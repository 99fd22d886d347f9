// Optimiser overhead (Google Benchmark): what the ask/tell machinery itself costs per iteration, and
// what a checkpoint (save_state) and a resume (load_state + the next ask) cost. The objective is
// the Sphere function, so the figures are the optimisers' own work; a DEM run costs seconds.
//
//   bench_optimise [--benchmark_filter=AskTell]
//
// Setting: 3 free parameters, population 10 (the paper's swarm). AskTell: one benchmark iteration
// is one optimiser iteration, i.e. one ask()/tell() round of the population for PSO/TBPSO/GA, and
// ten single-point rounds for NLopt (which runs on its own thread and hands over each point). The state benchmarks use an optimiser after
// 200 evaluations (a campaign: 20 iterations x 10 particles).
#include <demcal/optimise/optimise.hpp>

#include <benchmark/benchmark.h>

#include <memory>
#include <string>
#include <vector>

using namespace demcal::optimise;

namespace {

constexpr int kDimension = 3;
constexpr int kPopulation = 10;

const TestFunction& sphere() {
  static const TestFunction f = make_test_function("sphere", kDimension);
  return f;
}

ParameterSpace space() {
  ParameterSpace s;
  for (int k = 0; k < kDimension; ++k) s.add(std::string("x").append(std::to_string(k)), sphere().lower[k], sphere().upper[k]);
  return s;
}

// "tbpso:toward" and "ga:gaussian-elitist" are the non-default variants.
OptimiserOptions options_for(const std::string& label, long budget) {
  OptimiserOptions o;
  o.population = kPopulation;
  o.max_evaluations = budget;
  o.seed = 1;
  o.algorithm = label;
  if (label == "tbpso:toward") {
    o.algorithm = "tbpso";
    o.trust_direction = "toward";
  }
  if (label == "ga:gaussian-elitist") {
    o.algorithm = "ga";
    o.ga_mutation = GaMutation::gaussian;
    o.elitism = 1;
  }
  return o;
}

const std::vector<std::string>& labels() {
  static const std::vector<std::string> l = {"pso",
                                             "tbpso",
                                             "tbpso:toward",
                                             "ga",
                                             "ga:gaussian-elitist",
                                             "nlopt:GN_DIRECT_L",
                                             "nlopt:GN_CRS2_LM",
                                             "nlopt:GN_ISRES",
                                             "nlopt:GN_ESCH",
                                             "nlopt:LN_BOBYQA",
                                             "nlopt:LN_NELDERMEAD",
                                             "nlopt:LN_SBPLX"};
  return l;
}

// One ask/tell round; returns the number of evaluations (0 when the optimiser is done).
long round(Optimiser& opt) {
  const auto batch = opt.ask();
  if (batch.empty()) return 0;
  std::vector<double> values;
  values.reserve(batch.size());
  for (const auto& x : batch) values.push_back(sphere().evaluate(x));
  opt.tell(values);
  return static_cast<long>(batch.size());
}

// One benchmark iteration = one iteration of the optimiser: one ask/tell round of the whole
// population for PSO/TBPSO/GA (9 new candidates with one elite), ten single-point rounds for NLopt.
// A large budget keeps the optimiser running; when one stops anyway (a local NLopt method
// converging), a fresh one is made and started (its NLopt thread has computed its first point)
// outside the timed region.
void ask_tell(benchmark::State& state, const std::string& label) {
  const ParameterSpace s = space();
  const OptimiserOptions o = options_for(label, 1000000000L);
  const int rounds_per_iteration = label.rfind("nlopt:", 0) == 0 ? kPopulation : 1;
  auto opt = make_optimiser(s, o);
  long evaluations = 0;
  for (auto _ : state) {
    for (int r = 0; r < rounds_per_iteration;) {
      const long n = round(*opt);
      if (n == 0) {
        state.PauseTiming();
        opt = make_optimiser(s, o);
        opt->done();
        state.ResumeTiming();
        continue;
      }
      evaluations += n;
      ++r;
    }
  }
  state.SetItemsProcessed(evaluations);
  state.counters["evaluations_per_iteration"] =
      benchmark::Counter(static_cast<double>(evaluations) / static_cast<double>(state.iterations()));
}

std::unique_ptr<Optimiser> after_campaign(const std::string& label) {
  auto opt = make_optimiser(space(), options_for(label, 2000));
  long evaluations = 0;
  while (evaluations < 200) {
    const long n = round(*opt);
    if (n == 0) break;
    evaluations += n;
  }
  return opt;
}

// Checkpoint: save_state() and its text form, as pipelines write it after each iteration.
void save_state(benchmark::State& state, const std::string& label) {
  const auto opt = after_campaign(label);
  std::size_t bytes = 0;
  for (auto _ : state) {
    const std::string text = opt->save_state().dump();
    bytes = text.size();
    benchmark::DoNotOptimize(text.data());
  }
  state.counters["state_bytes"] = benchmark::Counter(static_cast<double>(bytes));
}

// Resume: parse the text, make a fresh optimiser, load_state(), ask() the next batch. For NLopt the
// ask() replays the recorded evaluations through a new NLopt run, so this is the real restart cost.
void load_state(benchmark::State& state, const std::string& label) {
  const auto opt = after_campaign(label);
  const std::string text = opt->save_state().dump();
  const ParameterSpace s = space();
  const OptimiserOptions o = options_for(label, 2000);
  for (auto _ : state) {
    auto resumed = make_optimiser(s, o);
    resumed->load_state(nlohmann::json::parse(text));
    const auto batch = resumed->ask();
    benchmark::DoNotOptimize(batch.data());
  }
}

const bool registered = [] {
  for (const auto& label : labels()) {
    benchmark::RegisterBenchmark(("AskTell/" + label).c_str(), ask_tell, label)->Unit(benchmark::kMicrosecond);
    benchmark::RegisterBenchmark(("SaveState/" + label).c_str(), save_state, label)->Unit(benchmark::kMicrosecond);
    benchmark::RegisterBenchmark(("LoadState/" + label).c_str(), load_state, label)->Unit(benchmark::kMicrosecond);
  }
  return true;
}();

}  // namespace

BENCHMARK_MAIN();
