// The native backend of the regression ensemble (regression_ensemble.hpp): the LibTorch backend's
// network, loss, Adam schedule and weight decay in plain loops over float arrays, one member per
// task. Every product is one register-blocked kernel over row-major arrays (multiply_add).
#include "demcal/smoothing/regression_ensemble.hpp"
#include "mlp_training.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::smoothing::detail {

namespace {

// One member: `parameters` (its slice of the result, holding its initial parameters on entry) is
// trained in place.
__attribute__((target_clones("arch=x86-64-v3", "default")))
void train_member(const RegressionBatch& rb, const std::vector<LayerShape>& shape, std::int64_t member, float* parameters) {
  const std::int64_t n = rb.rows, total = shape.back().bias_offset + shape.back().out;
  const std::size_t layers = shape.size();
  float* p = parameters;
  std::vector<float> g(static_cast<std::size_t>(total)), m(g.size(), 0.0f), v(g.size(), 0.0f);
  std::vector<std::vector<float>> activation(layers + 1);  // input of layer l; activation[layers] = output
  activation[0] = rb.x;
  std::int64_t widest = 1, largest = 1;
  for (std::size_t l = 0; l < layers; ++l) {
    widest = std::max(widest, std::max(shape[l].in, shape[l].out));
    largest = std::max(largest, shape[l].in * shape[l].out);
    activation[l + 1].resize(static_cast<std::size_t>(n * shape[l].out));
  }
  std::vector<float> delta(static_cast<std::size_t>(n * widest)), previous_delta(delta.size());
  std::vector<float> transposed(static_cast<std::size_t>(std::max(n * widest, largest)));
  // d(loss)/d(output) = 2 w (f − y) / (Σ w × outputs)
  const float* weight = rb.row_weight.data() + member * n;
  double weight_sum = 0;
  for (std::int64_t k = 0; k < n; ++k) weight_sum += weight[k];
  std::vector<float> row_scale(static_cast<std::size_t>(n));
  const float denominator = std::max(static_cast<float>(weight_sum), 1e-12f) * static_cast<float>(rb.outputs);
  for (std::int64_t k = 0; k < n; ++k) row_scale[static_cast<std::size_t>(k)] = weight[k] * 2.0f / denominator;

  for (int epoch = 0; epoch < rb.epochs; ++epoch) {
    for (std::size_t l = 0; l < layers; ++l) {
      const LayerShape& s = shape[l];
      float* z = activation[l + 1].data();
      for (std::int64_t k = 0; k < n; ++k)
        for (std::int64_t j = 0; j < s.out; ++j) z[k * s.out + j] = p[s.bias_offset + j];
      multiply_add(activation[l].data(), p + s.weight_offset, z, n, s.in, s.out);
      if (l + 1 < layers)
        for (std::int64_t q = 0; q < n * s.out; ++q) z[q] = fast_tanh(z[q]);
    }
    const float* output = activation[layers].data();
    const float* target = rb.y.data();
    for (std::int64_t k = 0; k < n; ++k)
      for (std::int64_t j = 0; j < rb.outputs; ++j)
        delta[static_cast<std::size_t>(k * rb.outputs + j)] =
            (output[k * rb.outputs + j] - target[k * rb.outputs + j]) * row_scale[static_cast<std::size_t>(k)];
    for (std::size_t l = layers; l-- > 0;) {
      const LayerShape& s = shape[l];
      float* gW = g.data() + s.weight_offset;
      float* gb = g.data() + s.bias_offset;
      const float* h = activation[l].data();
      for (std::int64_t j = 0; j < s.out; ++j) gb[j] = 0.0f;
      for (std::int64_t k = 0; k < n; ++k)
        for (std::int64_t j = 0; j < s.out; ++j) gb[j] += delta[static_cast<std::size_t>(k * s.out + j)];
      // gW[in][out] = hᵀ delta
      transpose(h, transposed.data(), n, s.in);
      for (std::int64_t q = 0; q < s.in * s.out; ++q) gW[q] = 0.0f;
      multiply_add(transposed.data(), delta.data(), gW, s.in, n, s.out);
      if (l == 0) break;
      // previous_delta[n][in] = (delta Wᵀ) × (1 − h²)
      transpose(p + s.weight_offset, transposed.data(), s.in, s.out);
      for (std::int64_t q = 0; q < n * s.in; ++q) previous_delta[static_cast<std::size_t>(q)] = 0.0f;
      multiply_add(delta.data(), transposed.data(), previous_delta.data(), n, s.out, s.in);
      for (std::int64_t q = 0; q < n * s.in; ++q) previous_delta[static_cast<std::size_t>(q)] *= 1.0f - h[q] * h[q];
      std::swap(delta, previous_delta);
    }
    const double lr = cosine_learning_rate(rb.learning_rate, rb.final_learning_rate, rb.epochs, epoch);
    const double t = epoch + 1;
    const float decay = static_cast<float>(1 - lr * rb.weight_decay);
    const float step = static_cast<float>(lr / (1 - std::pow(kAdamBeta1, t)));
    const float inv_c2 = static_cast<float>(1 / (1 - std::pow(kAdamBeta2, t)));
    const float b1 = static_cast<float>(kAdamBeta1), b2 = static_cast<float>(kAdamBeta2);
    const float eps = static_cast<float>(kAdamEpsilon);
    for (std::int64_t q = 0; q < total; ++q) {
      const std::size_t u = static_cast<std::size_t>(q);
      m[u] = b1 * m[u] + (1 - b1) * g[u];
      v[u] = b2 * v[u] + (1 - b2) * g[u] * g[u];
      p[q] = p[q] * decay - step * m[u] / (std::sqrt(v[u] * inv_c2) + eps);
    }
  }
}

}  // namespace

std::vector<float> train_regression_native(const RegressionBatch& rb) {
  std::vector<LayerShape> shape;
  std::int64_t offset = 0, in = rb.inputs;
  for (int l = 0; l <= rb.hidden_layers; ++l) {
    const std::int64_t out = l < rb.hidden_layers ? rb.hidden_width : rb.outputs;
    shape.push_back({in, out, offset, offset + in * out});
    offset += in * out + out;
    in = out;
  }
  std::vector<float> trained = rb.initial_parameters;
  run_tasks(rb.members, rb.threads,
            [&](std::int64_t member) { train_member(rb, shape, member, trained.data() + member * offset); });
  return trained;
}

}  // namespace demcal::smoothing::detail
