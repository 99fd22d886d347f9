// Curve smoothers: the neural smoother of objective 2 (LibTorch, behind this plain header) and two
// baselines (moving average, Savitzky–Golay).
//
// Every smoother takes an x–y series (displacement, force) and returns `points` (default 200) points
// at evenly spaced x over [min x, max x] of its input. Before fitting, the series is reduced to its
// loading envelope (loading_envelope in objective.hpp: only points where x reaches a new maximum,
// the last force kept at a repeated x) and discretised onto the 200 evenly spaced abscissae: the
// ordinate at an interior x_k is the mean of the envelope's piecewise-linear interpolant over one
// spacing centred on x_k; the two end ordinates are the envelope's end points. (Dense simulated
// recordings are so averaged rather than aliased; sparse lab curves are in effect interpolated, and
// a straight line is reproduced exactly.)
//
// The neural smoother (paper section 3.4.2): input displacement, output force, five hidden dense
// layers of 20 tanh neurons, linear output, mean absolute error loss, Adam, full batch, all points
// used for training. Inputs are scaled to [-1, 1] and outputs to zero mean and unit standard
// deviation. Adam runs a budget of `epochs` steps with the learning rate decayed from
// learning_rate to final_learning_rate (cosine). Stopping rule (StoppingRule::trend_spectrum, the
// default): every `check_interval` epochs the fit is scored by an estimate of its error to the
// unknown smooth truth, made from the data alone with the orthonormal DCT-II of the 200 points:
//   estimate^2 = (low-band power of the residual raw - fit) + (high-band power of the fit),
// low band = DCT indices 1..trend_cutoff (index k is k/2 cycles over the range), high band above.
// The residual's low band is trend the fit still misses; the fit's high band is oscillation it has
// learned. The checkpoint with the lowest estimate is returned (so training past the point where
// the network starts to follow the oscillations costs nothing but time). StoppingRule::fixed_budget
// returns the network after the whole budget. Settings chosen with the synthetic benchmark
// (synthetic.hpp, docs/smoothing.md); the tests check both sides of the rule.
// Many curves train in one call (smooth_batch): with the libtorch backend as one batched model (the
// weights of all networks stacked along a leading "curve" dimension, every layer one batched matrix
// product), with the native backend one network after another in the same call. Each curve has its
// own independent network, so its result does not depend on the other curves in the batch.
// Deterministic: the initial weights come from `seed` alone (the same for every curve).
#pragma once

#include "demcal/smoothing/curve.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace demcal::smoothing {

// Who trains the networks. Both train the same networks from the same initial weights with the
// same schedule (they agree to float rounding; tested):
//   native   - plain vectorised loops (AVX2+FMA where the CPU has it); the default, since the Debian
//              LibTorch has no optimised BLAS and is several times slower for these small products;
//   libtorch - LibTorch tensors, all curves stacked in one batched model (bmm over a curve dimension).
enum class SmootherBackend { native, libtorch };
std::string to_string(SmootherBackend backend);
SmootherBackend parse_smoother_backend(const std::string& name);  // "native" | "libtorch"

// The libtorch backend lives in a plugin, libdemcal_torch.so, opened on its first use, so that a
// program that trains no network never loads LibTorch (whose start-up costs most of a second).
// Searched: only the file named by $DEMCAL_TORCH_PLUGIN when it is set; else, in order, the running
// program's folder, <program folder>/../lib/demcal, and the build tree the module was compiled in. Returns the path of
// the loaded plugin; throws std::runtime_error naming every place searched when none loads.
std::string libtorch_plugin_path();

// How the returned network is chosen among the training epochs (see the header comment).
enum class StoppingRule { trend_spectrum, fixed_budget };
std::string to_string(StoppingRule rule);
StoppingRule parse_stopping_rule(const std::string& name);  // "trend-spectrum" | "fixed-budget"

struct SmootherOptions {
  int points = 200;                     // output (and training) points per curve, >= 4
  int hidden_layers = 5;                // dense tanh layers
  int hidden_width = 20;                // neurons per hidden layer
  int epochs = 400;                     // Adam budget (epochs), >= 1
  double learning_rate = 0.01;          // Adam step at the start, > 0
  double final_learning_rate = 0.001;   // step at the last epoch (cosine decay), in (0, learning_rate]
  // Scale of the first layer's initial weights relative to Glorot-uniform: > 1 starts the tanh
  // units in their nonlinear range, so a peaked curve is reached in fewer epochs. > 0.
  double first_layer_gain = 3.0;
  StoppingRule stopping = StoppingRule::trend_spectrum;
  int check_interval = 10;              // epochs between scored checkpoints (trend_spectrum), >= 1
  // Highest DCT index counted as trend (trend_spectrum): 24 = 12 cycles over the curve's range.
  // In [1, points - 2].
  int trend_cutoff = 24;
  std::uint64_t seed = 1;              // initial weights
  SmootherBackend backend = SmootherBackend::native;
  int threads = 1;                     // LibTorch intra-op threads (libtorch backend; calling thread)
  // Native backend: the curves of one batch trained side by side on up to this many threads. Each
  // curve has its own network from the same initial weights, so the values are the same for any
  // count; what changes is the wall time of a batch of few curves (a run's two channels) while
  // cores are idle. >= 1.
  int curve_threads = 1;
  // Throws std::invalid_argument naming the bad field and value.
  void Validate() const;
};

// Per-curve outcome of the neural smoother.
enum class SmoothStatus { ok, too_few_points, non_finite };
std::string to_string(SmoothStatus status);

struct SmoothResult {
  SmoothStatus status = SmoothStatus::ok;
  std::string message;     // empty when ok
  XYSeries smoothed;       // `points` points, x evenly spaced over the input's range
  XYSeries training;       // the discretised input the network was trained on (same x)
  double final_loss = 0;   // mean absolute error on `training`, in the input's force unit
  int epochs_trained = 0;  // Adam steps behind the returned network (the chosen checkpoint)
  // The stopping rule's estimate of the RMS error to the smooth truth at that checkpoint (force
  // unit; computed for either rule).
  double estimated_error = 0;
};

// Smooths every input with its own network, all trained together in one batched model.
// A series with fewer than 2 distinct finite x values gets status too_few_points (others still
// train). Throws std::invalid_argument on invalid options.
std::vector<SmoothResult> smooth_batch(const std::vector<XYSeries>& inputs,
                                       const SmootherOptions& options = {});
// One curve; throws CurveError if it cannot be smoothed (status not ok).
XYSeries smooth_dnn(const XYSeries& input, const SmootherOptions& options = {});

// The envelope discretised onto `points` evenly spaced x (the training set described above).
// Throws CurveError with fewer than 2 distinct finite x values.
XYSeries discretise(const XYSeries& input, int points);

// Baselines, on the same discretised series, returning `points` points.
// Moving average: centred window of `window` points (odd, >= 1), shrunk symmetrically at the ends.
XYSeries moving_average(const XYSeries& input, int window, int points = 200);
// Savitzky–Golay: least-squares polynomial of `order` over a centred window of `window` points (odd,
// > order); at the ends the window is shifted inside the series and its polynomial evaluated there.
XYSeries savitzky_golay(const XYSeries& input, int window, int order, int points = 200);

// Window defaults used by `demcal smooth` and the comparison (chosen on the synthetic benchmark).
inline constexpr int kDefaultMovingAverageWindow = 15;
inline constexpr int kDefaultSavitzkyGolayWindow = 31;
inline constexpr int kDefaultSavitzkyGolayOrder = 3;

// Root-mean-square difference of two series at the same x (sizes must match).
double rms_difference(const std::vector<double>& a, const std::vector<double>& b);

}  // namespace demcal::smoothing
