// Smoothing benchmarks: the neural smoother (one curve, twenty curves batched; both backends), the
// surrogate's regression ensemble (both backends),
// objective 1 and 2 (ten runs batched; one run, its channels on one or two threads), reading a lab
// curve. `bench_smoothing --comparison` prints instead the table of smoothers against the synthetic
// truth (docs/smoothing.md).
#include "demcal/smoothing/smoothing.hpp"
#include "demcal/surrogate/curve_ensemble.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <utility>

using namespace demcal::smoothing;

namespace {

std::vector<XYSeries> noisy_curves(int count) {
  std::vector<XYSeries> out;
  for (const auto& c : synthetic_family(count, 1)) out.push_back(c.noisy);
  return out;
}

void BM_SmoothCurves(benchmark::State& state) {
  const auto curves = noisy_curves(static_cast<int>(state.range(0)));
  SmootherOptions options;
  options.backend = state.range(1) ? SmootherBackend::libtorch : SmootherBackend::native;
  for (auto _ : state) benchmark::DoNotOptimize(smooth_batch(curves, options));
  state.SetLabel(to_string(options.backend) + ", " + std::to_string(options.epochs) + " epochs");
  state.counters["curves"] = static_cast<double>(curves.size());
}
BENCHMARK(BM_SmoothCurves)->ArgsProduct({{1, 20}, {0, 1}})->ArgNames({"curves", "libtorch"})
    ->Unit(benchmark::kMillisecond)->MinTime(2.0);

Curve two_channel_curve(const SyntheticCurve& c, const std::string& name) {
  Curve curve;
  curve.source = name;
  std::vector<double> horizontal;
  for (double v : c.noisy.x) horizontal.push_back(0.3 * v);
  curve.columns = {{"force", "N", c.noisy.y}, {"dv", "m", c.noisy.x}, {"dh", "m", horizontal}};
  return curve;
}

void BM_Objective1(benchmark::State& state) {
  SyntheticCurveOptions o;
  o.samples = static_cast<int>(state.range(0));
  const Curve e = two_channel_curve(make_synthetic_curve(o), "e");
  o.seed = 2;
  const Curve s = two_channel_curve(make_synthetic_curve(o), "s");
  for (auto _ : state) benchmark::DoNotOptimize(objective1(e, s));
}
BENCHMARK(BM_Objective1)->Arg(200)->Arg(5000)->ArgName("rows")->Unit(benchmark::kMicrosecond);

// One optimiser iteration of objective 2: ten particles x two channels in one batched pass.
void BM_Objective2TenParticles(benchmark::State& state) {
  const auto family = synthetic_family(11, 7);
  const Objective2 objective(two_channel_curve(family[0], "e"));
  std::vector<Curve> sims;
  for (int i = 1; i <= 10; ++i) sims.push_back(two_channel_curve(family[static_cast<std::size_t>(i)], "s"));
  for (auto _ : state) benchmark::DoNotOptimize(objective.evaluate_batch(sims));
}
BENCHMARK(BM_Objective2TenParticles)->Unit(benchmark::kMillisecond)->MinTime(2.0);

// One run's objective 2 (two channels), its channels trained one after another (1) or side by side
// (2, the campaign's fitness workers on two cores): the latency of a round's last run.
void BM_Objective2OneRun(benchmark::State& state) {
  const auto family = synthetic_family(2, 7);
  SmootherOptions smoother;
  smoother.curve_threads = static_cast<int>(state.range(0));
  const Objective2 objective(two_channel_curve(family[0], "e"), {}, smoother);
  const Curve run = two_channel_curve(family[1], "s");
  for (auto _ : state) benchmark::DoNotOptimize(objective.evaluate(run));
}
BENCHMARK(BM_Objective2OneRun)->Arg(1)->Arg(2)->ArgName("curve_threads")->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

// The surrogate's curve ensemble (surrogate/curve_ensemble.hpp) at the `mlp` kind's defaults: a full
// fit of five members, 2 x 32 tanh, on `rows` runs of `inputs` parameters with 82 outputs (two
// channels of 41 grid points); each training backend, its members on one or two threads.
void BM_RegressionEnsemble(benchmark::State& state) {
  const Eigen::Index rows = state.range(0), inputs = state.range(1), outputs = 82;
  demcal::surrogate::MlpOptions options;
  options.backend = state.range(2) ? RegressionBackend::libtorch : RegressionBackend::native;
  options.threads = static_cast<int>(state.range(3));
  const Eigen::MatrixXd X = (Eigen::MatrixXd::Random(rows, inputs).array() + 1) / 2;  // Eigen's fixed-seed generator
  Eigen::MatrixXd Y(rows, outputs);
  for (Eigen::Index i = 0; i < rows; ++i)
    for (Eigen::Index k = 0; k < outputs; ++k) Y(i, k) = std::tanh(X.row(i).sum() * static_cast<double>(k + 1) / 40);
  for (auto _ : state) {
    demcal::surrogate::CurveEnsemble ensemble;
    benchmark::DoNotOptimize(ensemble.fit(X, Y, options));
  }
  state.SetLabel(to_string(options.backend));
}
// LibTorch trains on one thread whatever `threads` says: its rows are run once.
BENCHMARK(BM_RegressionEnsemble)
    ->Apply([](benchmark::internal::Benchmark* b) {
      for (const int rows : {40, 160})
        for (const int inputs : {3, 9})
          for (const auto& [libtorch, threads] : {std::pair{0, 1}, std::pair{0, 2}, std::pair{1, 1}}) b->Args({rows, inputs, libtorch, threads});
    })
    ->ArgNames({"rows", "inputs", "libtorch", "threads"})->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ReadLabCurve(benchmark::State& state) {
  const std::string path = std::string(DEMCAL_SOURCE_DIR) +
                           "/data/walls/FD_SW302_Lourenco2005.csv";
  for (auto _ : state) benchmark::DoNotOptimize(read_curve(path));
}
BENCHMARK(BM_ReadLabCurve)->Unit(benchmark::kMicrosecond);

// Mean RMS error to the truth over the synthetic family, per smoother, for three kinds of noise.
void print_comparison() {
  const int count = 27;
  struct Regime {
    const char* name;
    bool oscillation, drops;
  };
  std::printf("| noise | DNN (trend-spectrum rule, budget %d) | DNN (fixed budget) | moving average 5 | moving average 15 | moving average 31 | "
              "Savitzky-Golay 31/3 | raw | DNN / MA15 (mean, worst) | DNN / SG (mean, worst) |\n",
              SmootherOptions{}.epochs);
  std::printf("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (const Regime regime : {Regime{"oscillation + stick-slip drops", true, true},
                              Regime{"oscillation only", true, false}, Regime{"stick-slip drops only", false, true}}) {
    std::vector<SyntheticCurve> curves;
    for (auto c : synthetic_family(count, 1)) {
      if (!regime.oscillation) c.options.oscillation_amplitude = 0;
      if (!regime.drops) c.options.stick_slip_drops = 0;
      curves.push_back(make_synthetic_curve(c.options));
    }
    std::vector<XYSeries> inputs;
    for (const auto& c : curves) inputs.push_back(c.noisy);
    const auto dnn = smooth_batch(inputs);
    SmootherOptions fixed;
    fixed.stopping = StoppingRule::fixed_budget;
    const auto dnn_fixed = smooth_batch(inputs, fixed);
    double e_fixed = 0;
    double e_dnn = 0, e_ma5 = 0, e_ma15 = 0, e_ma31 = 0, e_sg = 0, e_raw = 0;
    double r_ma = 0, r_sg = 0, worst_ma = 0, worst_sg = 0;
    for (int i = 0; i < count; ++i) {
      const auto& c = curves[static_cast<std::size_t>(i)];
      std::vector<double> truth;
      for (double x : dnn[static_cast<std::size_t>(i)].smoothed.x) truth.push_back(synthetic_truth(c.options, x));
      const double d = rms_difference(dnn[static_cast<std::size_t>(i)].smoothed.y, truth);
      const double m15 = rms_difference(moving_average(c.noisy, 15).y, truth);
      const double sg = rms_difference(savitzky_golay(c.noisy, 31, 3).y, truth);
      e_dnn += d / count;
      e_fixed += rms_difference(dnn_fixed[static_cast<std::size_t>(i)].smoothed.y, truth) / count;
      e_ma5 += rms_difference(moving_average(c.noisy, 5).y, truth) / count;
      e_ma15 += m15 / count;
      e_ma31 += rms_difference(moving_average(c.noisy, 31).y, truth) / count;
      e_sg += sg / count;
      e_raw += rms_difference(discretise(c.noisy, 200).y, truth) / count;
      r_ma += d / m15 / count;
      r_sg += d / sg / count;
      worst_ma = std::max(worst_ma, d / m15);
      worst_sg = std::max(worst_sg, d / sg);
    }
    std::printf("| %s | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.2f, %.2f | %.2f, %.2f |\n", regime.name, e_dnn,
                e_fixed, e_ma5, e_ma15, e_ma31, e_sg, e_raw, r_ma, worst_ma, r_sg, worst_sg);
  }
}

// One synthetic curve with its truth and the three smoothers, as a PNG (docs/figures).
void write_figure(const std::string& png) {
  const SyntheticCurve c = synthetic_family(27, 1)[13];
  const XYSeries dnn = smooth_dnn(c.noisy);
  XYSeries truth;
  for (double x : dnn.x) {
    truth.x.push_back(x);
    truth.y.push_back(synthetic_truth(c.options, x));
  }
  PlotOptions o;
  o.title = "synthetic curve: truth + oscillation + stick-slip drops";
  o.x_label = "displacement [m]";
  o.y_label = "force [N]";
  plot_png({{c.noisy, "noisy", true},
            {truth, "truth", false},
            {moving_average(c.noisy, 15), "moving average 15", false},
            {savitzky_golay(c.noisy, 31, 3), "Savitzky-Golay 31/3", false},
            {dnn, "DNN", false}},
           png, o);
}

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--comparison") == 0) {
      print_comparison();
      return 0;
    }
    if (std::strcmp(argv[i], "--figure") == 0 && i + 1 < argc) {
      write_figure(argv[i + 1]);
      return 0;
    }
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
