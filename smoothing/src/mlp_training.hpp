// Private to the smoothing module: what the two training backends of the neural smoother share.
// The batch is prepared (discretised, normalised) once; a backend trains one network per curve from
// the same initial parameters and returns the network's outputs at the training abscissae.
#pragma once

#include "demcal/smoothing/regression_ensemble.hpp"
#include "demcal/smoothing/smoother.hpp"

#include <cstdint>
#include <cstring>
#include <functional>
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
// The step at `epoch` (from 0) of `epochs`: `first` decayed to `last` by a cosine.
double cosine_learning_rate(double first, double last, int epochs, int epoch);
double learning_rate_at(const SmootherOptions& options, int epoch);

// Rational approximation of tanh (the coefficients of Eigen's generic_fast_tanh_float), accurate to
// a few float ulps, branch-free so that loops over it vectorise.
[[gnu::always_inline]] inline float fast_tanh(float v) {
  constexpr float kClamp = 7.90531110763549805f;
  const float low = v < -kClamp ? -kClamp : v;  // ternaries map onto vector min/max
  const float x = low > kClamp ? kClamp : low;
  const float x2 = x * x;
  float p = x2 * -2.76076847742355e-16f + 2.00018790482477e-13f;
  p = x2 * p + -8.60467152213735e-11f;
  p = x2 * p + 5.12229709037114e-08f;
  p = x2 * p + 1.48572235717979e-05f;
  p = x2 * p + 6.37261928875436e-04f;
  p = x2 * p + 4.89352455891786e-03f;
  p = x * p;
  float q = x2 * 1.19825839466702e-06f + 1.18534705686654e-04f;
  q = x2 * q + 2.26843463243900e-03f;
  q = x2 * q + 4.89352518554385e-03f;
  return p / q;
}

// Eight floats; the default clone lowers each operation to two SSE ones. Moved in and out with
// memcpy (no alignment asked).
using Vec = float __attribute__((vector_size(32)));

// C[rows][n] += A[rows][k] B[k][n] (row-major; leading dimensions lda, ldb, ldc) for `Rows` rows at
// once, in blocks of 16 columns whose sums stay in registers. Each C value sums over k in order,
// whatever the blocking, so results do not depend on it.
template <int Rows>
[[gnu::always_inline]] inline void multiply_add_rows(const float* A, std::int64_t lda, const float* B, std::int64_t ldb, float* C,
                              std::int64_t ldc, std::int64_t k, std::int64_t n) {
  std::int64_t j = 0;
  for (; j + 16 <= n; j += 16) {
    Vec sum[Rows][2];
    for (int r = 0; r < Rows; ++r) std::memcpy(sum[r], C + r * ldc + j, sizeof sum[r]);
    for (std::int64_t i = 0; i < k; ++i) {
      Vec b0, b1;
      std::memcpy(&b0, B + i * ldb + j, sizeof b0);
      std::memcpy(&b1, B + i * ldb + j + 8, sizeof b1);
      for (int r = 0; r < Rows; ++r) {
        const float a = A[r * lda + i];
        sum[r][0] += a * b0;
        sum[r][1] += a * b1;
      }
    }
    for (int r = 0; r < Rows; ++r) std::memcpy(C + r * ldc + j, sum[r], sizeof sum[r]);
  }
  for (; j + 8 <= n; j += 8) {
    Vec sum[Rows];
    for (int r = 0; r < Rows; ++r) std::memcpy(&sum[r], C + r * ldc + j, sizeof sum[r]);
    for (std::int64_t i = 0; i < k; ++i) {
      Vec b0;
      std::memcpy(&b0, B + i * ldb + j, sizeof b0);
      for (int r = 0; r < Rows; ++r) sum[r] += A[r * lda + i] * b0;
    }
    for (int r = 0; r < Rows; ++r) std::memcpy(C + r * ldc + j, &sum[r], sizeof sum[r]);
  }
  for (int r = 0; r < Rows; ++r)
    for (std::int64_t i = 0; i < k; ++i) {
      const float a = A[r * lda + i];
      for (std::int64_t c = j; c < n; ++c) C[r * ldc + c] += a * B[i * ldb + c];
    }
}

// C[m][n] += A[m][k] B[k][n], every matrix row-major and contiguous: the products of both native
// backends. Each C value starts from its own and adds A[r][0] B[0][c], A[r][1] B[1][c], ... in
// that order, the operations of the plain loop in its order (contracted alike, into FMA in the
// AVX2 clone), so the results are the plain loop's to the bit. Always inlined, as everything
// called in a loop of a function with target clones: an out-of-line callee is compiled for the
// default target alone.
[[gnu::always_inline]] inline void multiply_add(const float* A, const float* B, float* C, std::int64_t m, std::int64_t k, std::int64_t n) {
  std::int64_t r = 0;
  for (; r + 4 <= m; r += 4) multiply_add_rows<4>(A + r * k, k, B, n, C + r * n, n, k, n);
  for (; r < m; ++r) multiply_add_rows<1>(A + r * k, k, B, n, C + r * n, n, k, n);
}

// out[cols][rows] = in[rows][cols]
[[gnu::always_inline]] inline void transpose(const float* in, float* out, std::int64_t rows, std::int64_t cols) {
  for (std::int64_t r = 0; r < rows; ++r)
    for (std::int64_t c = 0; c < cols; ++c) out[c * rows + r] = in[r * cols + c];
}

// Calls task(0 .. tasks-1), each once, on up to `threads` threads (the caller's among them); the
// first exception a task throws is rethrown after every thread has finished.
void run_tasks(std::int64_t tasks, std::int64_t threads, const std::function<void(std::int64_t)>& task);

TrainingOutput train_native(const TrainingBatch& batch, const SmootherOptions& options);
// The regression ensemble's native backend (native_regression.cpp); the batch already checked.
std::vector<float> train_regression_native(const RegressionBatch& batch);
TrainingOutput train_libtorch(const TrainingBatch& batch, const SmootherOptions& options);

}  // namespace demcal::smoothing::detail
