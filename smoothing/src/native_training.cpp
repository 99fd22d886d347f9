// The native training backend: the same network, loss, initialisation and Adam schedule as the
// LibTorch backend, in plain loops over float arrays that the compiler vectorises (an AVX2+FMA clone
// is chosen at run time where the CPU has it). It exists because the Debian LibTorch is built without
// an optimised BLAS (BLAS_INFO=generic): its 200x20x20 products run at a few GFLOPS, too slow for
// the smoothing speed goals (figures in docs/benchmarks.md).
#include "mlp_training.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <functional>
#include <thread>
#include <vector>

namespace demcal::smoothing::detail {

namespace {

// Sum of a[k] * b[k] with eight partial sums, so the loop vectorises without reassociation flags.
inline float dot(const float* a, const float* b, std::int64_t n) {
  float partial[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  std::int64_t k = 0;
  for (; k + 8 <= n; k += 8)
    for (int u = 0; u < 8; ++u) partial[u] += a[k + u] * b[k + u];
  float sum = 0;
  for (; k < n; ++k) sum += a[k] * b[k];
  for (int u = 0; u < 8; ++u) sum += partial[u];
  return sum;
}

// Arrays are feature-major ([feature][point]) so that every inner loop runs over the 200 points.
__attribute__((target_clones("arch=x86-64-v3", "default")))
void train_curve(const TrainingBatch& tb, const SmootherOptions& options, std::int64_t curve,
                 CheckpointSelector* selector) {
  const float* x = tb.x.data() + curve * tb.points;
  const float* target = tb.y.data() + curve * tb.points;
  const std::int64_t n = tb.points;
  const std::size_t layers = tb.layers.size();
  std::vector<float> p = tb.initial_parameters, g(p.size()), m(p.size(), 0.0f), v(p.size(), 0.0f);
  std::vector<std::vector<float>> activation(layers + 1);  // input of layer l; activation[layers] = output
  activation[0].assign(x, x + n);
  std::int64_t widest = 1;
  for (std::size_t l = 0; l < layers; ++l) {
    widest = std::max(widest, tb.layers[l].out);
    activation[l + 1].resize(static_cast<std::size_t>(n * tb.layers[l].out));
  }
  std::vector<float> delta(static_cast<std::size_t>(n * widest)), next_delta(delta.size());
  std::vector<float> transposed(static_cast<std::size_t>(widest * widest));  // a layer's Wᵀ

  // Inlined into each target clone: out of line it would be compiled for the default target alone.
  auto forward = [&]() __attribute__((always_inline)) {
    for (std::size_t l = 0; l < layers; ++l) {
      const auto& s = tb.layers[l];
      const float* W = p.data() + s.weight_offset;
      const float* b = p.data() + s.bias_offset;
      const float* h = activation[l].data();
      float* z = activation[l + 1].data();
      // z[out][n] = b + Wᵀ h, summed over the inputs in order
      for (std::int64_t j = 0; j < s.out; ++j)
        for (std::int64_t k = 0; k < n; ++k) z[j * n + k] = b[j];
      transpose(W, transposed.data(), s.in, s.out);
      multiply_add(transposed.data(), h, z, s.out, s.in, n);
      if (l + 1 < layers)
        for (std::int64_t k = 0; k < n * s.out; ++k) z[k] = fast_tanh(z[k]);
    }
  };

  const float inv_n = 1.0f / static_cast<float>(n);
  for (int epoch = 0; epoch < options.epochs; ++epoch) {
    forward();
    const float* out = activation[layers].data();
    if (selector->due(epoch)) selector->offer(epoch, out, curve);
    for (std::int64_t k = 0; k < n; ++k) {
      const float d = out[k] - target[k];
      delta[static_cast<std::size_t>(k)] = static_cast<float>((d > 0) - (d < 0)) * inv_n;
    }
    for (std::size_t l = layers; l-- > 0;) {
      const auto& s = tb.layers[l];
      float* gW = g.data() + s.weight_offset;
      float* gb = g.data() + s.bias_offset;
      const float* h = activation[l].data();
      for (std::int64_t j = 0; j < s.out; ++j) {
        const float* dj = delta.data() + j * n;
        float sum = 0;
        for (std::int64_t k = 0; k < n; ++k) sum += dj[k];
        gb[j] = sum;
        for (std::int64_t i = 0; i < s.in; ++i) gW[i * s.out + j] = dot(h + i * n, dj, n);
      }
      if (l == 0) break;
      // delta_prev[i] = (sum_j W[i][j] delta[j]) * (1 - h[i]^2), summed over the outputs in order
      for (std::int64_t q = 0; q < s.in * n; ++q) next_delta[static_cast<std::size_t>(q)] = 0.0f;
      multiply_add(p.data() + s.weight_offset, delta.data(), next_delta.data(), s.in, s.out, n);
      for (std::int64_t q = 0; q < s.in * n; ++q) next_delta[static_cast<std::size_t>(q)] *= 1.0f - h[q] * h[q];
      std::swap(delta, next_delta);
    }
    const double t = epoch + 1;
    const float c1 = static_cast<float>(1 - std::pow(kAdamBeta1, t));
    const float inv_c2 = static_cast<float>(1 / (1 - std::pow(kAdamBeta2, t)));
    const float step = static_cast<float>(learning_rate_at(options, epoch)) / c1;
    const float b1 = static_cast<float>(kAdamBeta1), b2 = static_cast<float>(kAdamBeta2);
    const float eps = static_cast<float>(kAdamEpsilon);
    for (std::size_t q = 0; q < p.size(); ++q) {
      m[q] = b1 * m[q] + (1 - b1) * g[q];
      v[q] = b2 * v[q] + (1 - b2) * g[q] * g[q];
      p[q] -= step * m[q] / (std::sqrt(v[q] * inv_c2) + eps);
    }
  }
  forward();
  selector->offer(options.epochs, activation[layers].data(), curve);
}

}  // namespace

void run_tasks(std::int64_t tasks, std::int64_t threads, const std::function<void(std::int64_t)>& task) {
  threads = std::max<std::int64_t>(1, std::min(threads, tasks));
  std::atomic<std::int64_t> next{0};
  std::vector<std::exception_ptr> errors(static_cast<std::size_t>(threads));  // one thread: the caller's alone
  const auto work = [&](std::size_t worker) {
    try {
      for (std::int64_t t; (t = next++) < tasks;) task(t);
    } catch (...) {
      errors[worker] = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  for (std::size_t t = 1; t < errors.size(); ++t) pool.emplace_back(work, t);
  work(0);
  for (auto& t : pool) t.join();
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);
}

TrainingOutput train_native(const TrainingBatch& tb, const SmootherOptions& options) {
  CheckpointSelector selector(tb, options);  // writes only curve c's slots for curve c
  run_tasks(tb.curves, options.curve_threads, [&](std::int64_t c) { train_curve(tb, options, c, &selector); });
  return selector.result();
}

}  // namespace demcal::smoothing::detail
