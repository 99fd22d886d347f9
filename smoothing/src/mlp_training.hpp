// Private to the smoothing module: what the two training backends of the neural smoother share.
// The batch is prepared (discretised, normalised) once; a backend trains one network per curve from
// the same initial parameters and returns the network's outputs at the training abscissae.
#pragma once

#include "demcal/smoothing/smoother.hpp"

#include <cstdint>
#include <vector>

namespace demcal::smoothing::detail {

// Layer l maps `in` to `out` values; its weights (row-major [in][out]) start at weight_offset of the
// flat parameter vector, its biases at bias_offset. Layout: W0, b0, W1, b1, ...
struct LayerShape {
  std::int64_t in, out, weight_offset, bias_offset;
};

struct TrainingBatch {
  std::int64_t curves = 0;  // networks to train
  std::int64_t points = 0;  // training points per curve
  std::vector<float> x;     // [curves][points], scaled to [-1, 1]
  std::vector<float> y;     // [curves][points], zero mean and unit standard deviation
  std::vector<LayerShape> layers;
  std::int64_t parameter_count = 0;
  std::vector<float> initial_parameters;  // one network, the same for every curve
};

struct TrainingOutput {
  std::vector<float> prediction;  // [curves][points], normalised units (the chosen checkpoint)
  std::vector<float> loss;        // [curves], mean absolute error there, normalised units
  std::vector<int> epoch;         // [curves], Adam steps behind the chosen checkpoint
  std::vector<float> estimate;    // [curves], the stopping rule's error estimate there, normalised
};

// The stopping rule, shared by both backends: scores the fit of every curve at checkpoints and
// keeps the best (StoppingRule::trend_spectrum) or the latest (fixed_budget). Backends call
// offer() with the network outputs of all curves after `epoch` Adam steps; at epoch 0, every
// check_interval epochs and after the last epoch.
class CheckpointSelector {
 public:
  CheckpointSelector(const TrainingBatch& batch, const SmootherOptions& options);
  bool due(int epoch) const { return epoch % check_interval_ == 0; }
  // `fit`: the `points` outputs of curve `curve`.
  void offer(int epoch, const float* fit, std::int64_t curve);
  TrainingOutput result() const { return best_; }

 private:
  const TrainingBatch& batch_;
  bool keep_best_;
  int check_interval_;
  int cutoff_;
  std::vector<double> basis_;  // [cutoff][points]: orthonormal DCT-II rows 1..cutoff
  TrainingOutput best_;
};

// Adam constants and the cosine schedule shared by both backends.
inline constexpr double kAdamBeta1 = 0.9;
inline constexpr double kAdamBeta2 = 0.999;
inline constexpr double kAdamEpsilon = 1e-8;
double learning_rate_at(const SmootherOptions& options, int epoch);

TrainingOutput train_native(const TrainingBatch& batch, const SmootherOptions& options);
TrainingOutput train_libtorch(const TrainingBatch& batch, const SmootherOptions& options);

}  // namespace demcal::smoothing::detail
