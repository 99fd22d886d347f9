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
#include <thread>
#include <vector>

namespace demcal::smoothing::detail {

namespace {

// Rational approximation of tanh (the coefficients of Eigen's generic_fast_tanh_float), accurate to
// a few float ulps, branch-free so that loops over it vectorise.
inline float fast_tanh(float v) {
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

  auto forward = [&]() {
    for (std::size_t l = 0; l < layers; ++l) {
      const auto& s = tb.layers[l];
      const float* W = p.data() + s.weight_offset;
      const float* b = p.data() + s.bias_offset;
      const float* h = activation[l].data();
      float* z = activation[l + 1].data();
      for (std::int64_t j = 0; j < s.out; ++j) {
        float* zj = z + j * n;
        for (std::int64_t k = 0; k < n; ++k) zj[k] = b[j];
        for (std::int64_t i = 0; i < s.in; ++i) {
          const float wij = W[i * s.out + j];
          const float* hi = h + i * n;
          for (std::int64_t k = 0; k < n; ++k) zj[k] += wij * hi[k];
        }
      }
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
      // delta_prev[i] = (sum_j W[i][j] delta[j]) * (1 - h[i]^2)
      const float* W = p.data() + s.weight_offset;
      for (std::int64_t i = 0; i < s.in; ++i) {
        float* ndi = next_delta.data() + i * n;
        for (std::int64_t k = 0; k < n; ++k) ndi[k] = 0.0f;
        for (std::int64_t j = 0; j < s.out; ++j) {
          const float wij = W[i * s.out + j];
          const float* dj = delta.data() + j * n;
          for (std::int64_t k = 0; k < n; ++k) ndi[k] += wij * dj[k];
        }
        const float* hi = h + i * n;
        for (std::int64_t k = 0; k < n; ++k) ndi[k] *= 1.0f - hi[k] * hi[k];
      }
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

TrainingOutput train_native(const TrainingBatch& tb, const SmootherOptions& options) {
  CheckpointSelector selector(tb, options);  // writes only curve c's slots for curve c
  const std::int64_t threads = std::max<std::int64_t>(1, std::min<std::int64_t>(options.curve_threads, tb.curves));
  std::atomic<std::int64_t> next{0};
  std::vector<std::exception_ptr> errors(static_cast<std::size_t>(threads));  // one thread: the caller's alone
  const auto work = [&](std::size_t worker) {
    try {
      for (std::int64_t c; (c = next++) < tb.curves;) train_curve(tb, options, c, &selector);
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
  return selector.result();
}

}  // namespace demcal::smoothing::detail
