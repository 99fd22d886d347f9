// Smoothers: discretisation, baselines on exact cases, the neural smoother's stopping rule,
// determinism, batching, and objective 2.
#include "demcal/smoothing/objective.hpp"
#include "demcal/smoothing/smoother.hpp"
#include "demcal/smoothing/synthetic.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace demcal::smoothing;

namespace {

XYSeries line(int n, double slope, double intercept, double x1 = 1.0) {
  XYSeries s;
  for (int i = 0; i < n; ++i) {
    s.x.push_back(x1 * i / (n - 1));
    s.y.push_back(intercept + slope * s.x.back());
  }
  return s;
}

std::vector<double> truth_at(const SyntheticCurve& c, const std::vector<double>& x) {
  std::vector<double> t;
  for (double v : x) t.push_back(synthetic_truth(c.options, v));
  return t;
}

}  // namespace

TEST(Discretise, ExactOnALineAndAveragesDenseData) {
  const XYSeries d = discretise(line(37, 2.0, 1.0, 3.0), 200);
  ASSERT_EQ(d.x.size(), 200u);
  EXPECT_DOUBLE_EQ(d.x.front(), 0.0);
  EXPECT_DOUBLE_EQ(d.x.back(), 3.0);
  for (std::size_t k = 0; k < d.x.size(); ++k) EXPECT_NEAR(d.y[k], 1.0 + 2.0 * d.x[k], 1e-12);
  // A zig-zag of +-1 at every sample (dense: 20 samples per output spacing) averages to ~0.
  XYSeries zig;
  for (int i = 0; i < 4001; ++i) {
    zig.x.push_back(i / 4000.0);
    zig.y.push_back(i % 2 ? 1.0 : -1.0);
  }
  const XYSeries z = discretise(zig, 200);
  for (std::size_t k = 1; k + 1 < z.y.size(); ++k) EXPECT_LT(std::abs(z.y[k]), 0.06) << k;
  EXPECT_THROW(discretise(XYSeries{{1, 1}, {2, 3}}, 200), CurveError);
}

TEST(Baselines, MovingAverageAndSavitzkyGolayAreExactOnPolynomials) {
  const XYSeries ma = moving_average(line(50, -3.0, 2.0), 15, 200);
  for (std::size_t k = 0; k < ma.x.size(); ++k) EXPECT_NEAR(ma.y[k], 2.0 - 3.0 * ma.x[k], 1e-12);
  XYSeries cubic;
  for (int i = 0; i < 200; ++i) {
    const double x = i / 199.0;
    cubic.x.push_back(x);
    cubic.y.push_back(1 - 2 * x + 3 * x * x - 4 * x * x * x);
  }
  // With 200 input points at the output abscissae, an interior discretised value is
  // y_k * 3/4 + (y_k-1 + y_k+1) / 8, a symmetric filter that keeps a cubic a cubic: Savitzky-Golay
  // of order 3 must return it unchanged wherever its window avoids the two end points.
  const XYSeries d = discretise(cubic, 200);
  const XYSeries sg = savitzky_golay(cubic, 31, 3, 200);
  for (std::size_t k = 16; k < 184; ++k) EXPECT_NEAR(sg.y[k], d.y[k], 1e-12) << k;
  EXPECT_THROW(moving_average(cubic, 4), std::invalid_argument);
  EXPECT_THROW(savitzky_golay(cubic, 5, 5), std::invalid_argument);
}

namespace {

struct FitQuality {
  double error_to_truth = 0;  // RMS(smoothed - truth) / RMS(raw - truth), mean over curves
  double distance_to_raw = 0;  // RMS(smoothed - raw) / RMS(raw - truth), mean over curves
  double worst_error_to_truth = 0;
  double least_distance_to_raw = 1e300;
};

FitQuality fit_quality(const std::vector<SyntheticCurve>& family, const SmootherOptions& o,
                       std::vector<SmoothResult>* out = nullptr) {
  std::vector<XYSeries> inputs;
  for (const auto& c : family) inputs.push_back(c.noisy);
  const auto results = smooth_batch(inputs, o);
  FitQuality q;
  for (std::size_t i = 0; i < family.size(); ++i) {
    EXPECT_EQ(results[i].status, SmoothStatus::ok);
    const auto& s = results[i].smoothed;
    EXPECT_EQ(s.x.size(), 200u);
    const auto truth = truth_at(family[i], s.x);
    const XYSeries raw = discretise(family[i].noisy, 200);
    const double noise = rms_difference(raw.y, truth);
    const double error = rms_difference(s.y, truth) / noise, distance = rms_difference(s.y, raw.y) / noise;
    q.error_to_truth += error / static_cast<double>(family.size());
    q.distance_to_raw += distance / static_cast<double>(family.size());
    q.worst_error_to_truth = std::max(q.worst_error_to_truth, error);
    q.least_distance_to_raw = std::min(q.least_distance_to_raw, distance);
    double mae = 0;
    for (std::size_t k = 0; k < s.y.size(); ++k) mae += std::abs(s.y[k] - raw.y[k]);
    EXPECT_NEAR(results[i].final_loss, mae / static_cast<double>(s.y.size()), 1e-4 * family[i].options.peak_force);
  }
  if (out) *out = results;
  return q;
}

}  // namespace

TEST(NeuralSmoother, StopsBeforeLearningTheOscillations) {
  // The stopping rule, both sides. With it, the fit removes most of the noise (error to the truth
  // well below the raw curve's) without following the oscillations and drops (it stays about a
  // noise RMS away from the raw curve). Training 3000 epochs to the end instead learns the noise:
  // closer to the raw curve, further from the truth. Given the same 3000 epochs, the trend-spectrum
  // rule picks a checkpoint before that happens.
  const auto family = synthetic_family(4, 11);
  std::vector<SmoothResult> results;
  const FitQuality stopped = fit_quality(family, SmootherOptions{}, &results);
  EXPECT_LT(stopped.worst_error_to_truth, 0.55);
  EXPECT_LT(stopped.error_to_truth, 0.45);
  EXPECT_GT(stopped.least_distance_to_raw, 0.85);
  for (const auto& r : results) {
    EXPECT_GE(r.epochs_trained, 0);
    EXPECT_LE(r.epochs_trained, SmootherOptions{}.epochs);
    EXPECT_EQ(r.epochs_trained % SmootherOptions{}.check_interval, 0);
    EXPECT_GT(r.estimated_error, 0.0);
  }
  SmootherOptions long_budget;
  long_budget.epochs = 3000;
  long_budget.stopping = StoppingRule::fixed_budget;
  const FitQuality overtrained = fit_quality(family, long_budget);
  EXPECT_GT(overtrained.error_to_truth, stopped.error_to_truth + 0.1);
  EXPECT_LT(overtrained.distance_to_raw, stopped.distance_to_raw - 0.1);
  long_budget.stopping = StoppingRule::trend_spectrum;
  const FitQuality ruled = fit_quality(family, long_budget);
  EXPECT_LT(ruled.error_to_truth, overtrained.error_to_truth - 0.1);
  EXPECT_GT(ruled.distance_to_raw, overtrained.distance_to_raw + 0.1);
}

TEST(NeuralSmoother, TrendSpectrumRuleBeatsTheFixedBudgetAndTheMovingAverage) {
  // The synthetic family with oscillation and stick-slip drops (as docs/smoothing.md): mean RMS
  // error to the truth. Measured: rule 27.6 N, fixed budget 28.7 N, moving average 15 31.6 N,
  // Savitzky-Golay 31/3 27.3 N. (The target of half the moving average's error is not met;
  // docs/smoothing.md says why.)
  const auto family = synthetic_family(27, 1);
  std::vector<XYSeries> inputs;
  for (const auto& c : family) inputs.push_back(c.noisy);
  SmootherOptions fixed;
  fixed.stopping = StoppingRule::fixed_budget;
  const auto ruled = smooth_batch(inputs), budget = smooth_batch(inputs, fixed);
  double e_rule = 0, e_fixed = 0, e_ma = 0, e_sg = 0;
  for (std::size_t i = 0; i < family.size(); ++i) {
    const auto truth = truth_at(family[i], ruled[i].smoothed.x);
    e_rule += rms_difference(ruled[i].smoothed.y, truth);
    e_fixed += rms_difference(budget[i].smoothed.y, truth);
    e_ma += rms_difference(moving_average(inputs[i], kDefaultMovingAverageWindow).y, truth);
    e_sg += rms_difference(savitzky_golay(inputs[i], kDefaultSavitzkyGolayWindow, kDefaultSavitzkyGolayOrder).y, truth);
  }
  EXPECT_LT(e_rule, e_fixed);
  EXPECT_LT(e_rule, 0.9 * e_ma);
  EXPECT_LT(e_rule, 1.03 * e_sg);
  EXPECT_EQ(parse_stopping_rule("fixed-budget"), StoppingRule::fixed_budget);
  EXPECT_EQ(to_string(StoppingRule::trend_spectrum), "trend-spectrum");
  EXPECT_THROW(parse_stopping_rule("never"), std::invalid_argument);
}

TEST(NeuralSmoother, NativeAndLibTorchBackendsAgree) {
  const auto family = synthetic_family(2, 3);
  SmootherOptions o;
  o.epochs = 40;
  const auto native = smooth_batch({family[0].noisy, family[1].noisy}, o);
  o.backend = SmootherBackend::libtorch;
  const auto torch = smooth_batch({family[0].noisy, family[1].noisy}, o);
  for (std::size_t i = 0; i < 2; ++i) {
    ASSERT_EQ(torch[i].status, SmoothStatus::ok);
    for (std::size_t k = 0; k < 200; ++k)
      EXPECT_NEAR(native[i].smoothed.y[k], torch[i].smoothed.y[k], 1e-3 * family[i].options.peak_force) << i << " " << k;
    EXPECT_NEAR(native[i].final_loss, torch[i].final_loss, 1e-3 * family[i].options.peak_force);
    EXPECT_EQ(native[i].epochs_trained, torch[i].epochs_trained);
    EXPECT_NEAR(native[i].estimated_error, torch[i].estimated_error, 1e-3 * family[i].options.peak_force);
  }
  EXPECT_EQ(parse_smoother_backend("libtorch"), SmootherBackend::libtorch);
  EXPECT_THROW(parse_smoother_backend("gpu"), std::invalid_argument);
}

TEST(NeuralSmoother, DeterministicAndIndependentOfTheBatch) {
  const auto family = synthetic_family(3, 5);
  for (const auto backend : {SmootherBackend::native, SmootherBackend::libtorch}) {
    SmootherOptions o;
    o.epochs = 60;
    o.seed = 42;
    o.backend = backend;
    const auto batch = smooth_batch({family[0].noisy, family[1].noisy, family[2].noisy}, o);
    const auto again = smooth_batch({family[0].noisy, family[1].noisy, family[2].noisy}, o);
    const auto alone = smooth_batch({family[1].noisy}, o);
    SmootherOptions side_by_side = o;  // native: the curves on two and on three threads
    side_by_side.curve_threads = 2;
    const auto on_two = smooth_batch({family[0].noisy, family[1].noisy, family[2].noisy}, side_by_side);
    side_by_side.curve_threads = 3;
    const auto on_three = smooth_batch({family[0].noisy, family[1].noisy, family[2].noisy}, side_by_side);
    for (std::size_t c = 0; c < 3; ++c) {
      EXPECT_EQ(on_two[c].smoothed.y, batch[c].smoothed.y) << to_string(backend) << " curve " << c;
      EXPECT_EQ(on_three[c].smoothed.y, batch[c].smoothed.y) << to_string(backend) << " curve " << c;
      EXPECT_EQ(on_three[c].epochs_trained, batch[c].epochs_trained);
    }
    for (std::size_t k = 0; k < 200; ++k) {
      EXPECT_EQ(batch[1].smoothed.y[k], again[1].smoothed.y[k]) << to_string(backend);
      if (backend == SmootherBackend::native)
        EXPECT_EQ(batch[1].smoothed.y[k], alone[0].smoothed.y[k]);
      else  // bmm may order its sums differently for another batch size
        EXPECT_NEAR(batch[1].smoothed.y[k], alone[0].smoothed.y[k], 1e-3);
    }
    o.seed = 43;
    const auto other_seed = smooth_batch({family[1].noisy}, o);
    EXPECT_GT(rms_difference(other_seed[0].smoothed.y, alone[0].smoothed.y), 0.0);
  }
}

TEST(NeuralSmoother, ReportsUnfittableCurvesAndBadOptions) {
  SmootherOptions o;
  o.epochs = 5;
  const auto r = smooth_batch({XYSeries{{1, 1, NAN}, {1, 2, 3}}, line(10, 1, 0)}, o);
  EXPECT_EQ(r[0].status, SmoothStatus::too_few_points);
  EXPECT_EQ(r[1].status, SmoothStatus::ok);
  o.epochs = 0;
  try {
    o.Validate();
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("epochs = 0"), std::string::npos);
  }
  o = {};
  o.trend_cutoff = 199;
  try {
    o.Validate();
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("trend_cutoff = 199"), std::string::npos);
  }
  o = {};
  o.check_interval = 0;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
  o = {};
  o.curve_threads = 0;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
  o = {};
  o.final_learning_rate = 1;
  EXPECT_THROW(smooth_batch({line(10, 1, 0)}, o), std::invalid_argument);
}

TEST(Objective2, CachesTheExperimentAndBatchesSimulations) {
  const auto family = synthetic_family(3, 21);
  auto to_curve = [](const XYSeries& s, const std::string& name) {
    Curve c;
    c.source = name;
    c.columns = {{"dv", "m", s.x}, {"force", "N", s.y}};
    return c;
  };
  SmootherOptions smoother;
  smoother.epochs = 150;
  const Objective2 objective(to_curve(family[0].noisy, "e.csv"), {}, smoother);
  ASSERT_EQ(objective.smoothed_experiment().size(), 1u);
  EXPECT_EQ(objective.smoothed_experiment().at("dv").x.size(), 200u);
  const Curve a = to_curve(family[1].noisy, "a.csv"), b = to_curve(family[2].noisy, "b.csv");
  const auto batch = objective.evaluate_batch({a, b});
  ASSERT_EQ(batch.size(), 2u);
  EXPECT_NEAR(objective.evaluate(b).fitness, batch[1].fitness, 1e-6 * batch[1].fitness);
  // Objective 2 equals objective 1 applied to the smoothed curves.
  const auto smoothed_b = objective.smooth_simulation(b).at("dv");
  EXPECT_NEAR(batch[1].channels.at("dv"),
              channel_misfit(objective.smoothed_experiment().at("dv"), smoothed_b, 200),
              1e-6 * batch[1].fitness);
  // The experiment against itself smoothed with the same seed: zero.
  EXPECT_NEAR(objective.evaluate(to_curve(family[0].noisy, "same.csv")).fitness, 0.0, 1e-9);
  Curve wrong = a;
  wrong.columns[0].name = "dh";
  EXPECT_THROW(objective.evaluate(wrong), CurveError);
}

TEST(Objective2, EitherWindowHoldsAGaugeThatOnlyMovedBackwards) {
  // As objective 1: a one-point simulated envelope has no curve to smooth and is held at its force.
  const auto family = synthetic_family(2, 21);
  Curve e;
  e.source = "e.csv";
  e.columns = {{"dv", "m", family[0].noisy.x}, {"force", "N", family[0].noisy.y}};
  Curve s = e;
  s.source = "s.csv";
  for (double& x : s.columns[0].values) x = -x;  // every reading after the first goes backwards
  ObjectiveOptions measured;
  measured.window = ObjectiveWindow::measured;
  SmootherOptions smoother;
  smoother.epochs = 150;
  const Objective2 objective(e, measured, smoother);
  const XYSeries held{{0.0}, {s.columns[1].values.front()}};
  const auto batch = objective.evaluate_batch({s, e});
  EXPECT_DOUBLE_EQ(batch[0].channels.at("dv"),
                   channel_misfit(objective.smoothed_experiment().at("dv"), held, 200, "dv", ObjectiveWindow::measured));
  EXPECT_GT(batch[0].fitness, 10 * batch[1].fitness);
  const Objective2 common(e, {}, smoother);
  EXPECT_DOUBLE_EQ(common.evaluate(s).channels.at("dv"), batch[0].channels.at("dv"));
}

TEST(Synthetic, TruthPeaksWhereAskedAndNoiseIsBounded) {
  SyntheticCurveOptions o;
  const auto c = make_synthetic_curve(o);
  ASSERT_EQ(c.noisy.x.size(), static_cast<std::size_t>(o.samples));
  EXPECT_DOUBLE_EQ(synthetic_truth(o, o.peak_displacement), o.peak_force);
  EXPECT_DOUBLE_EQ(synthetic_truth(o, o.max_displacement), o.residual_fraction * o.peak_force);
  double worst = 0;
  for (std::size_t i = 0; i < c.noisy.x.size(); ++i) worst = std::max(worst, std::abs(c.noisy.y[i] - c.truth.y[i]));
  EXPECT_GT(worst, o.oscillation_amplitude * o.peak_force * 0.9);
  EXPECT_LT(worst, (o.oscillation_amplitude + o.stick_slip_drops * o.drop_depth) * o.peak_force);
  EXPECT_EQ(make_synthetic_curve(o).noisy.y, c.noisy.y);
}
