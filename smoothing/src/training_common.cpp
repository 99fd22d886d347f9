// What both training backends of the neural smoother share: the learning-rate schedule and the
// checkpoint selector of the stopping rule. Kept apart from the front (neural_smoother.cpp) so that
// the LibTorch plugin links only this object of the module.
#include "mlp_training.hpp"

#include "demcal/smoothing/regression_ensemble.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace demcal::smoothing {

std::int64_t regression_parameter_count(std::int64_t inputs, std::int64_t outputs, int hidden_layers, int hidden_width) {
  std::int64_t count = 0, in = inputs;
  for (int l = 0; l < hidden_layers; ++l) {
    count += in * hidden_width + hidden_width;
    in = hidden_width;
  }
  return count + in * outputs + outputs;
}

std::string to_string(RegressionBackend backend) { return backend == RegressionBackend::native ? "native" : "libtorch"; }

RegressionBackend parse_regression_backend(const std::string& name) {
  if (name == "native") return RegressionBackend::native;
  if (name == "libtorch") return RegressionBackend::libtorch;
  throw std::invalid_argument("'" + name + "': must be \"native\" or \"libtorch\"");
}

namespace detail {

double cosine_learning_rate(double first, double last, int epochs, int epoch) {
  const double progress = epochs > 1 ? static_cast<double>(epoch) / (epochs - 1) : 1.0;
  return last + 0.5 * (first - last) * (1 + std::cos(M_PI * progress));
}

double learning_rate_at(const SmootherOptions& o, int epoch) {
  return cosine_learning_rate(o.learning_rate, o.final_learning_rate, o.epochs, epoch);
}

CheckpointSelector::CheckpointSelector(const TrainingBatch& batch, const SmootherOptions& o)
    : batch_(batch),
      keep_best_(o.stopping == StoppingRule::trend_spectrum),
      check_interval_(o.check_interval),
      cutoff_(o.trend_cutoff) {
  const std::int64_t n = batch.points;
  basis_.resize(static_cast<std::size_t>(cutoff_ * n));
  for (int k = 1; k <= cutoff_; ++k)
    for (std::int64_t i = 0; i < n; ++i)
      basis_[static_cast<std::size_t>((k - 1) * n + i)] =
          std::sqrt(2.0 / static_cast<double>(n)) * std::cos(M_PI * k * (static_cast<double>(i) + 0.5) / static_cast<double>(n));
  best_.prediction.assign(static_cast<std::size_t>(batch.curves * n), 0.0f);
  best_.loss.assign(static_cast<std::size_t>(batch.curves), 0.0f);
  best_.epoch.assign(static_cast<std::size_t>(batch.curves), -1);
  best_.estimate.assign(static_cast<std::size_t>(batch.curves), 0.0f);
}

void CheckpointSelector::offer(int epoch, const float* fit, std::int64_t c) {
  const std::int64_t n = batch_.points;
  const float* target = batch_.y.data() + c * n;
  // Mean squares over the points: residual's DCT band 1..cutoff; fit's band above cutoff
  // (its total power less the mean and the band 1..cutoff).
  double residual_low = 0, fit_low = 0, fit_sum = 0, fit_power = 0, loss = 0;
  for (std::int64_t i = 0; i < n; ++i) {
    fit_sum += fit[i];
    fit_power += static_cast<double>(fit[i]) * fit[i];
    loss += std::abs(static_cast<double>(fit[i]) - target[i]);
  }
  for (int k = 0; k < cutoff_; ++k) {
    const double* row = basis_.data() + static_cast<std::size_t>(k) * static_cast<std::size_t>(n);
    double r = 0, f = 0;
    for (std::int64_t i = 0; i < n; ++i) {
      r += row[i] * (static_cast<double>(target[i]) - fit[i]);
      f += row[i] * fit[i];
    }
    residual_low += r * r;
    fit_low += f * f;
  }
  const double fit_high = std::max(0.0, fit_power - fit_sum * fit_sum / static_cast<double>(n) - fit_low);
  const double estimate = std::sqrt((residual_low + fit_high) / static_cast<double>(n));
  const auto cu = static_cast<std::size_t>(c);
  if (best_.epoch[cu] >= 0 && keep_best_ && !(estimate < best_.estimate[cu])) return;
  std::copy(fit, fit + n, best_.prediction.begin() + c * n);
  best_.loss[cu] = static_cast<float>(loss / static_cast<double>(n));
  best_.epoch[cu] = epoch;
  best_.estimate[cu] = static_cast<float>(estimate);
}

}  // namespace detail

}  // namespace demcal::smoothing
