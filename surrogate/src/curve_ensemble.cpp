#include "demcal/surrogate/curve_ensemble.hpp"
#include "internal.hpp"

#include "demcal/common/format.hpp"
#include "demcal/common/random.hpp"
#include "demcal/smoothing/regression_ensemble.hpp"

#include <cmath>
#include <cstring>
#include <stdexcept>

namespace demcal::surrogate {

namespace {

using detail::matrix_from;
using detail::matrix_json;
using detail::vector_from;

}  // namespace

void MlpOptions::Validate() const {
  auto fail = [](const std::string& what) { throw std::invalid_argument("surrogate mlp." + what); };
  if (members < 2) fail("members = " + std::to_string(members) + " must be >= 2 (their spread is the uncertainty)");
  if (hidden_layers < 1) fail("hidden_layers = " + std::to_string(hidden_layers) + " must be >= 1");
  if (hidden_width < 1) fail("hidden_width = " + std::to_string(hidden_width) + " must be >= 1");
  if (epochs < 1) fail("epochs = " + std::to_string(epochs) + " must be >= 1");
  if (!(learning_rate > 0) || !std::isfinite(learning_rate))
    fail("learning_rate = " + format_number(learning_rate, round_trip_digits) + " must be > 0");
  if (!(final_learning_rate > 0) || final_learning_rate > learning_rate)
    fail("final_learning_rate = " + format_number(final_learning_rate, round_trip_digits) + " must be in (0, learning_rate]");
  if (!(weight_decay >= 0) || !std::isfinite(weight_decay))
    fail("weight_decay = " + format_number(weight_decay, round_trip_digits) + " must be >= 0");
  if (refit_epochs < 1) fail("refit_epochs = " + std::to_string(refit_epochs) + " must be >= 1");
  if (!(refit_learning_rate >= final_learning_rate) || !(refit_learning_rate <= learning_rate))
    fail("refit_learning_rate = " + format_number(refit_learning_rate, round_trip_digits) +
         " must be in [final_learning_rate, learning_rate]");
  if (threads < 1) fail("threads = " + std::to_string(threads) + " must be >= 1");
  limits::require_within(limits::Limit::epochs, epochs, "surrogate mlp.epochs");
  limits::require_within(limits::Limit::epochs, refit_epochs, "surrogate mlp.refit_epochs");
  limits::require_within(limits::Limit::network_weights, 1.0 * members * hidden_layers * hidden_width * hidden_width,
                         "surrogate mlp.members x hidden_layers x hidden_width^2");
}

namespace {

const FieldTable<MlpOptions>& mlp_fields() {
  static const FieldTable<MlpOptions> table{
      field("members", &MlpOptions::members),
      field("hidden_layers", &MlpOptions::hidden_layers),
      field("hidden_width", &MlpOptions::hidden_width),
      field("epochs", &MlpOptions::epochs),
      field("learning_rate", &MlpOptions::learning_rate),
      field("final_learning_rate", &MlpOptions::final_learning_rate),
      field("weight_decay", &MlpOptions::weight_decay),
      field("bootstrap", &MlpOptions::bootstrap),
      field("seed", &MlpOptions::seed),
      field("refit_epochs", &MlpOptions::refit_epochs),
      field("refit_learning_rate", &MlpOptions::refit_learning_rate),
      named_field("backend", &MlpOptions::backend, smoothing::parse_regression_backend,
                  [](smoothing::RegressionBackend b) { return smoothing::to_string(b); }),
  };
  return table;
}

}  // namespace

nlohmann::json MlpOptions::to_json() const { return mlp_fields().to_json(*this); }

MlpOptions MlpOptions::from_json(const nlohmann::json& j, const std::string& where) {
  return detail::options_from_json(j, where, mlp_fields());
}

namespace {

// A bootstrap weight of one row for one member: a Poisson(1) count drawn from the row's point, so a
// row keeps its weight when rows are added (a refined model sees the rows it was trained on as
// before) and the weights do not depend on the rows' order.
float poisson_weight(std::uint64_t seed, int member, const Eigen::VectorXd& unit) {
  std::uint64_t state = seed * 0x2545f4914f6cdd1dULL + static_cast<std::uint64_t>(member);
  for (Eigen::Index k = 0; k < unit.size(); ++k) {
    std::uint64_t bits;
    const double v = unit[k];
    std::memcpy(&bits, &v, sizeof bits);
    state = mix_seed(state ^ bits);
  }
  SplitMix64 rng(state);
  const double u = uniform01(rng);
  double p = std::exp(-1.0), cumulative = p;
  int count = 0;
  while (u > cumulative && count < 20) cumulative += (p /= ++count);
  return static_cast<float>(count);
}

void check_training_data(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y) {
  if (X.rows() != Y.rows()) throw std::invalid_argument("CurveEnsemble: X and Y have different row counts");
  if (!X.allFinite() || !Y.allFinite()) throw std::invalid_argument("CurveEnsemble: non-finite training data");
}

}  // namespace

smoothing::RegressionBatch CurveEnsemble::training_batch(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y,
                                                          const MlpOptions& options) const {
  const Eigen::Index n = X.rows(), d = X.cols(), m = Y.cols();
  smoothing::RegressionBatch batch;
  batch.members = options.members;
  batch.rows = n;
  batch.inputs = d;
  batch.outputs = m;
  batch.hidden_layers = options.hidden_layers;
  batch.hidden_width = options.hidden_width;
  batch.epochs = options.epochs;
  batch.learning_rate = options.learning_rate;
  batch.final_learning_rate = options.final_learning_rate;
  batch.weight_decay = options.weight_decay;
  batch.backend = options.backend;
  // LibTorch keeps one intra-op thread: its repeats are bit-identical only so.
  batch.threads = options.backend == smoothing::RegressionBackend::native ? options.threads : 1;
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index k = 0; k < d; ++k) batch.x.push_back(static_cast<float>(2 * X(i, k) - 1));
    for (Eigen::Index k = 0; k < m; ++k) batch.y.push_back(static_cast<float>((Y(i, k) - mean_[k]) / scale_[k]));
  }
  for (int member = 0; member < options.members; ++member)
    for (Eigen::Index i = 0; i < n; ++i)
      batch.row_weight.push_back(options.bootstrap ? poisson_weight(options.seed, member, X.row(i).transpose()) : 1.0f);
  return batch;
}

void CurveEnsemble::load_members(const std::vector<float>& trained, const MlpOptions& options) {
  const std::int64_t d = dimension_, m = mean_.size();
  const std::int64_t count = smoothing::regression_parameter_count(d, m, options.hidden_layers, options.hidden_width);
  members_.clear();
  for (int member = 0; member < options.members; ++member) {
    const float* p = trained.data() + static_cast<std::int64_t>(member) * count;
    Network net;
    std::int64_t in = d;
    for (int l = 0; l <= options.hidden_layers; ++l) {
      const std::int64_t out = l < options.hidden_layers ? options.hidden_width : m;
      Eigen::MatrixXd w(out, in);
      for (std::int64_t a = 0; a < in; ++a)
        for (std::int64_t b = 0; b < out; ++b) w(b, a) = p[a * out + b];
      p += in * out;
      Eigen::VectorXd bias(out);
      for (std::int64_t b = 0; b < out; ++b) bias[b] = p[b];
      p += out;
      net.weight.push_back(std::move(w));
      net.bias.push_back(std::move(bias));
      in = out;
    }
    members_.push_back(std::move(net));
  }
}

bool CurveEnsemble::fit(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, const MlpOptions& options) {
  options.Validate();
  members_.clear();
  if (X.rows() != Y.rows()) throw std::invalid_argument("CurveEnsemble: X and Y have different row counts");
  if (X.rows() < 3 || Y.cols() < 1) return false;
  check_training_data(X, Y);
  const Eigen::Index n = X.rows(), d = X.cols(), m = Y.cols();
  dimension_ = static_cast<int>(d);
  mean_ = Y.colwise().mean().transpose();
  scale_.resize(m);
  for (Eigen::Index k = 0; k < m; ++k) {
    const double sd = std::sqrt((Y.col(k).array() - mean_[k]).square().sum() / static_cast<double>(n));
    scale_[k] = sd > 1e-12 * (1 + std::abs(mean_[k])) ? sd : 1.0;  // a constant column stays as it is
  }
  smoothing::RegressionBatch batch = training_batch(X, Y, options);
  for (int member = 0; member < options.members; ++member) {
    SplitMix64 rng(options.seed * 0x2545f4914f6cdd1dULL + static_cast<std::uint64_t>(member));
    // Glorot-uniform weights, zero biases, in the flat layout W0, b0, W1, b1, ...
    std::int64_t in = d;
    for (int l = 0; l <= options.hidden_layers; ++l) {
      const std::int64_t out = l < options.hidden_layers ? options.hidden_width : m;
      const double limit = std::sqrt(6.0 / static_cast<double>(in + out));
      for (std::int64_t w = 0; w < in * out; ++w) batch.initial_parameters.push_back(static_cast<float>(limit * (2 * uniform01(rng) - 1)));
      batch.initial_parameters.insert(batch.initial_parameters.end(), static_cast<size_t>(out), 0.0f);
      in = out;
    }
  }
  load_members(smoothing::train_regression_ensemble(batch), options);
  return true;
}

bool CurveEnsemble::refine(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, const MlpOptions& options) {
  options.Validate();
  if (!fitted() || X.rows() < 3 || X.cols() != dimension_ || Y.cols() != mean_.size() ||
      static_cast<int>(members_.size()) != options.members || options.refit_epochs < 1)
    return false;
  check_training_data(X, Y);
  smoothing::RegressionBatch batch = training_batch(X, Y, options);
  batch.epochs = options.refit_epochs;
  batch.learning_rate = options.refit_learning_rate;
  for (const Network& net : members_)
    for (size_t l = 0; l < net.weight.size(); ++l) {
      const Eigen::MatrixXd& w = net.weight[l];  // [out][in], flat layout [in][out]
      for (Eigen::Index a = 0; a < w.cols(); ++a)
        for (Eigen::Index b = 0; b < w.rows(); ++b) batch.initial_parameters.push_back(static_cast<float>(w(b, a)));
      for (Eigen::Index b = 0; b < net.bias[l].size(); ++b) batch.initial_parameters.push_back(static_cast<float>(net.bias[l][b]));
    }
  load_members(smoothing::train_regression_ensemble(batch), options);
  return true;
}

Eigen::VectorXd CurveEnsemble::predict(int member, const Eigen::VectorXd& unit) const {
  if (!fitted()) throw std::logic_error("CurveEnsemble: not fitted");
  if (unit.size() != dimension_)
    throw std::invalid_argument("CurveEnsemble: a point of " + std::to_string(unit.size()) + " coordinates, the model has " +
                                std::to_string(dimension_));
  const Network& net = members_.at(static_cast<size_t>(member));
  Eigen::VectorXd h = 2 * unit.array() - 1;
  for (size_t l = 0; l < net.weight.size(); ++l) {
    h = net.weight[l] * h + net.bias[l];
    if (l + 1 < net.weight.size()) h = h.array().tanh();
  }
  return mean_.array() + scale_.array() * h.array();
}

nlohmann::json CurveEnsemble::to_json() const {
  nlohmann::json members = nlohmann::json::array();
  for (const auto& net : members_) {
    nlohmann::json layers = nlohmann::json::array();
    for (size_t l = 0; l < net.weight.size(); ++l)
      layers.push_back({{"weight", matrix_json(net.weight[l])}, {"bias", detail::vector_json(net.bias[l])}});
    members.push_back(layers);
  }
  return {{"dimension", dimension_},
          {"output_mean", detail::vector_json(mean_)},
          {"output_scale", detail::vector_json(scale_)},
          {"members", members}};
}

CurveEnsemble CurveEnsemble::from_json(const nlohmann::json& j, const std::string& where) {
  try {
    CurveEnsemble e;
    e.dimension_ = j.at("dimension").get<int>();
    e.mean_ = vector_from(j.at("output_mean"));
    e.scale_ = vector_from(j.at("output_scale"));
    if (e.mean_.size() != e.scale_.size()) throw std::invalid_argument("output_mean and output_scale differ in length");
    for (const auto& layers : j.at("members")) {
      Network net;
      Eigen::Index in = e.dimension_;
      for (const auto& layer : layers) {
        net.weight.push_back(matrix_from(layer.at("weight")));
        net.bias.push_back(vector_from(layer.at("bias")));
        if (net.weight.back().cols() != in || net.bias.back().size() != net.weight.back().rows())
          throw std::invalid_argument("a layer's shape does not follow the previous one");
        in = net.weight.back().rows();
      }
      if (in != e.mean_.size()) throw std::invalid_argument("the last layer does not give the outputs");
      e.members_.push_back(std::move(net));
    }
    if (e.members_.size() < 2) throw std::invalid_argument("fewer than 2 members");
    return e;
  } catch (const std::exception& ex) {
    throw std::invalid_argument(where + ": " + ex.what());
  }
}

}  // namespace demcal::surrogate
