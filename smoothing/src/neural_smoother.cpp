// The neural smoother's front: options, discretisation and normalisation of the batch, initial
// weights and the results. Training itself is in native_training.cpp and, loaded on first use,
// the LibTorch plugin (plugin/libtorch_training.cpp); what both share is in training_common.cpp.
#include "mlp_training.hpp"

#include "demcal/common/format.hpp"
#include "demcal/common/random.hpp"
#include "demcal/limits/limits.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace demcal::smoothing {

namespace {

using detail::LayerShape;

void set_architecture(const SmootherOptions& o, detail::TrainingBatch* tb) {
  std::int64_t offset = 0, in = 1;
  for (int l = 0; l <= o.hidden_layers; ++l) {
    const std::int64_t out = l < o.hidden_layers ? o.hidden_width : 1;
    tb->layers.push_back({in, out, offset, offset + in * out});
    offset += in * out + out;
    in = out;
  }
  tb->parameter_count = offset;
  // Glorot-uniform weights (suited to tanh; the first layer widened), zero biases.
  tb->initial_parameters.assign(static_cast<std::size_t>(offset), 0.0f);
  SplitMix64 rng(o.seed);
  for (std::size_t l = 0; l < tb->layers.size(); ++l) {
    const auto& s = tb->layers[l];
    const double a = (l == 0 ? o.first_layer_gain : 1.0) * std::sqrt(6.0 / static_cast<double>(s.in + s.out));
    for (std::int64_t i = 0; i < s.in * s.out; ++i)
      tb->initial_parameters[static_cast<std::size_t>(s.weight_offset + i)] =
          static_cast<float>((2 * uniform01(rng) - 1) * a);
  }
}

}  // namespace

std::string to_string(SmoothStatus status) {
  switch (status) {
    case SmoothStatus::ok: return "ok";
    case SmoothStatus::too_few_points: return "too_few_points";
    case SmoothStatus::non_finite: return "non_finite";
  }
  return "unknown";
}

std::string to_string(SmootherBackend backend) {
  return backend == SmootherBackend::libtorch ? "libtorch" : "native";
}

std::string to_string(StoppingRule rule) {
  return rule == StoppingRule::fixed_budget ? "fixed-budget" : "trend-spectrum";
}

StoppingRule parse_stopping_rule(const std::string& name) {
  if (name == "trend-spectrum") return StoppingRule::trend_spectrum;
  if (name == "fixed-budget") return StoppingRule::fixed_budget;
  throw std::invalid_argument("stopping rule '" + name + "': expected trend-spectrum or fixed-budget");
}

SmootherBackend parse_smoother_backend(const std::string& name) {
  if (name == "native") return SmootherBackend::native;
  if (name == "libtorch") return SmootherBackend::libtorch;
  throw std::invalid_argument("smoother backend '" + name + "': expected native or libtorch");
}

void SmootherOptions::Validate() const {
  auto fail = [](const std::string& field, double value, const std::string& rule) {
    throw std::invalid_argument("SmootherOptions." + field + " = " + format_number(value, 6) + ": " + rule);
  };
  if (points < 4) fail("points", points, "must be >= 4");
  if (hidden_layers < 1) fail("hidden_layers", hidden_layers, "must be >= 1");
  if (hidden_width < 1) fail("hidden_width", hidden_width, "must be >= 1");
  if (epochs < 1) fail("epochs", epochs, "must be >= 1");
  if (!(learning_rate > 0) || !std::isfinite(learning_rate)) fail("learning_rate", learning_rate, "must be > 0");
  if (!(final_learning_rate > 0) || final_learning_rate > learning_rate)
    fail("final_learning_rate", final_learning_rate, "must be in (0, learning_rate]");
  if (threads < 1) fail("threads", threads, "must be >= 1");
  if (curve_threads < 1) fail("curve_threads", curve_threads, "must be >= 1");
  if (check_interval < 1) fail("check_interval", check_interval, "must be >= 1");
  if (trend_cutoff < 1 || trend_cutoff > points - 2)
    fail("trend_cutoff", trend_cutoff, "must be in [1, points - 2]");
  if (!(first_layer_gain > 0) || !std::isfinite(first_layer_gain))
    fail("first_layer_gain", first_layer_gain, "must be finite and > 0");
  limits::require_within(limits::Limit::curve_points, points, "SmootherOptions.points");
  limits::require_within(limits::Limit::epochs, epochs, "SmootherOptions.epochs");
  limits::require_within(limits::Limit::workers, threads, "SmootherOptions.threads");
  limits::require_within(limits::Limit::workers, curve_threads, "SmootherOptions.curve_threads");
  limits::require_within(limits::Limit::network_weights, 1.0 * hidden_width * hidden_width * hidden_layers,
                         "SmootherOptions.hidden_layers x hidden_width^2");
}

std::vector<SmoothResult> smooth_batch(const std::vector<XYSeries>& inputs, const SmootherOptions& options) {
  options.Validate();
  std::vector<SmoothResult> results(inputs.size());
  detail::TrainingBatch tb;
  tb.points = options.points;
  const std::size_t n = static_cast<std::size_t>(options.points);

  std::vector<std::size_t> trained;  // indices into inputs
  std::vector<double> y_mean, y_scale;
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    try {
      results[i].training = discretise(inputs[i], options.points);
    } catch (const CurveError& e) {
      results[i].status = SmoothStatus::too_few_points;
      results[i].message = e.what();
      continue;
    }
    const auto& t = results[i].training;
    const double x0 = t.x.front(), x1 = t.x.back();
    const double mean = std::accumulate(t.y.begin(), t.y.end(), 0.0) / static_cast<double>(n);
    double var = 0;
    for (double v : t.y) var += (v - mean) * (v - mean);
    double scale = std::sqrt(var / static_cast<double>(n));
    if (!(scale > 0) || !std::isfinite(scale)) scale = std::max(1.0, std::abs(mean));
    for (std::size_t k = 0; k < n; ++k) {
      tb.x.push_back(static_cast<float>(2 * (t.x[k] - x0) / (x1 - x0) - 1));
      tb.y.push_back(static_cast<float>((t.y[k] - mean) / scale));
    }
    y_mean.push_back(mean);
    y_scale.push_back(scale);
    trained.push_back(i);
  }
  if (trained.empty()) return results;
  tb.curves = static_cast<std::int64_t>(trained.size());
  set_architecture(options, &tb);

  const detail::TrainingOutput out = options.backend == SmootherBackend::libtorch
                                         ? detail::train_libtorch(tb, options)
                                         : detail::train_native(tb, options);
  for (std::size_t b = 0; b < trained.size(); ++b) {
    auto& r = results[trained[b]];
    r.smoothed.x = r.training.x;
    r.smoothed.y.resize(n);
    bool finite = true;
    for (std::size_t k = 0; k < n; ++k) {
      const double v = y_mean[b] + y_scale[b] * static_cast<double>(out.prediction[b * n + k]);
      finite = finite && std::isfinite(v);
      r.smoothed.y[k] = v;
    }
    r.final_loss = static_cast<double>(out.loss[b]) * y_scale[b];
    r.epochs_trained = out.epoch[b];
    r.estimated_error = static_cast<double>(out.estimate[b]) * y_scale[b];
    if (!finite) {
      r.status = SmoothStatus::non_finite;
      r.message = "the network produced a non-finite value";
    }
  }
  return results;
}

XYSeries smooth_dnn(const XYSeries& input, const SmootherOptions& options) {
  auto results = smooth_batch({input}, options);
  if (results[0].status != SmoothStatus::ok)
    throw CurveError("cannot smooth the curve (" + to_string(results[0].status) + "): " + results[0].message);
  return results[0].smoothed;
}

}  // namespace demcal::smoothing
