// The LibTorch training backend, built as the plugin libdemcal_torch.so: the only translation unit
// of the project that includes LibTorch. The smoothing module opens the plugin on first use
// (torch_plugin.cpp), so commands that train no network never load LibTorch.
//
// All networks of a batch are stacked along a leading "curve" dimension and every layer is one
// batched matrix product (bmm). Backpropagation is written out under NoGradGuard instead of using
// autograd, and one flat parameter tensor gets a fused Adam update: this keeps the number of LibTorch
// calls per epoch at about 60, whatever the batch size.
#include "mlp_training.hpp"
#include "torch_plugin_abi.hpp"

#include <torch/torch.h>

namespace demcal::smoothing::detail {

namespace {

// Sets LibTorch's intra-op threads for one training and restores the previous count after it.
class TrainingThreads {
 public:
  explicit TrainingThreads(int threads) : previous_(torch::get_num_threads()) { torch::set_num_threads(threads); }
  ~TrainingThreads() { torch::set_num_threads(previous_); }
  TrainingThreads(const TrainingThreads&) = delete;
  TrainingThreads& operator=(const TrainingThreads&) = delete;

 private:
  int previous_;
};

// Backpropagation through a batch of tanh networks: from delta = d(loss)/d(output), the input of
// every layer (`activation`) and the transposed weights, the gradient of each network in the flat
// layout W0, b0, W1, b1, ... (one row per network; `grads` is scratch of 2 x layers tensors).
torch::Tensor backpropagate(torch::Tensor delta, const std::vector<torch::Tensor>& activation,
                            const std::vector<torch::Tensor>& weight_t, std::vector<torch::Tensor>& grads,
                            std::int64_t networks) {
  for (std::size_t l = activation.size(); l-- > 0;) {
    grads[2 * l] = torch::bmm(activation[l].transpose(1, 2), delta).view({networks, -1});
    grads[2 * l + 1] = delta.sum(1);
    if (l > 0) {
      const torch::Tensor& h = activation[l];
      delta = torch::bmm(delta, weight_t[l]).mul_(1 - h * h);
    }
  }
  return torch::cat(grads, 1);
}

// Adam's moment update with gradient g at step t (from 1); returns the bias-corrected denominator
// sqrt(v / (1 - beta2^t)) + epsilon of the parameter update.
torch::Tensor adam_moments(torch::Tensor& m, torch::Tensor& v, const torch::Tensor& g, double t) {
  m.mul_(kAdamBeta1).add_(g, 1 - kAdamBeta1);
  v.mul_(kAdamBeta2).addcmul_(g, g, 1 - kAdamBeta2);
  return (v / (1 - std::pow(kAdamBeta2, t))).sqrt_().add_(kAdamEpsilon);
}

TrainingOutput train_batched(const TrainingBatch& tb, const SmootherOptions& options) {
  torch::NoGradGuard no_grad;
  TrainingThreads threads(options.threads);

  const std::int64_t batch = tb.curves, n = tb.points, total = tb.parameter_count;
  const auto f32 = torch::TensorOptions().dtype(torch::kFloat32);
  torch::Tensor x = torch::from_blob(const_cast<float*>(tb.x.data()), {batch, n, 1}, f32).clone();
  torch::Tensor target = torch::from_blob(const_cast<float*>(tb.y.data()), {batch, n, 1}, f32).clone();
  torch::Tensor params = torch::from_blob(const_cast<float*>(tb.initial_parameters.data()), {1, total}, f32)
                             .expand({batch, total}).contiguous();
  torch::Tensor adam_m = torch::zeros_like(params);
  torch::Tensor adam_v = torch::zeros_like(params);

  const std::size_t layers = tb.layers.size();
  std::vector<torch::Tensor> weight(layers), bias(layers), weight_t(layers);
  for (std::size_t l = 0; l < layers; ++l) {
    const auto& s = tb.layers[l];
    weight[l] = params.narrow(1, s.weight_offset, s.in * s.out).view({batch, s.in, s.out});
    bias[l] = params.narrow(1, s.bias_offset, s.out).view({batch, 1, s.out});
    weight_t[l] = weight[l].transpose(1, 2);
  }

  std::vector<torch::Tensor> activation(layers);  // input of layer l
  std::vector<torch::Tensor> grads(2 * layers);
  const float inv_n = 1.0f / static_cast<float>(n);
  auto forward = [&]() {
    activation[0] = x;
    torch::Tensor h = x;
    for (std::size_t l = 0; l < layers; ++l) {
      torch::Tensor z = torch::baddbmm(bias[l], h, weight[l]);
      if (l + 1 < layers) {
        h = z.tanh_();
        activation[l + 1] = h;
      } else {
        h = z;
      }
    }
    return h;
  };

  CheckpointSelector selector(tb, options);
  auto offer = [&](int epoch, const torch::Tensor& output) {
    const torch::Tensor values = output.contiguous();
    for (std::int64_t c = 0; c < batch; ++c) selector.offer(epoch, values.data_ptr<float>() + c * n, c);
  };
  for (int epoch = 0; epoch < options.epochs; ++epoch) {
    torch::Tensor output = forward();
    if (selector.due(epoch)) offer(epoch, output);
    // d(mean |y - t|)/dy per curve: the loss is summed over curves, so each network sees only its own.
    const torch::Tensor g = backpropagate((output - target).sign_().mul_(inv_n), activation, weight_t, grads, batch);
    const double t = epoch + 1;
    const torch::Tensor denom = adam_moments(adam_m, adam_v, g, t);
    params.addcdiv_(adam_m, denom, -learning_rate_at(options, epoch) / (1 - std::pow(kAdamBeta1, t)));
  }

  offer(options.epochs, forward());
  return selector.result();
}

// The regression ensemble (regression_ensemble.hpp): the same batched products and hand-written
// backpropagation, with every member seeing all rows through its own row weights.
std::vector<float> train_regression(const RegressionBatch& rb) {
  torch::NoGradGuard no_grad;
  TrainingThreads threads(rb.threads);

  const std::int64_t members = rb.members, n = rb.rows;
  const std::int64_t total = regression_parameter_count(rb.inputs, rb.outputs, rb.hidden_layers, rb.hidden_width);
  const auto f32 = torch::TensorOptions().dtype(torch::kFloat32);
  torch::Tensor x = torch::from_blob(const_cast<float*>(rb.x.data()), {1, n, rb.inputs}, f32)
                        .expand({members, n, rb.inputs}).contiguous();
  torch::Tensor target = torch::from_blob(const_cast<float*>(rb.y.data()), {1, n, rb.outputs}, f32)
                             .expand({members, n, rb.outputs}).contiguous();
  torch::Tensor weight_rows = torch::from_blob(const_cast<float*>(rb.row_weight.data()), {members, n, 1}, f32).clone();
  // d(loss)/d(output) = 2 w (f − y) / (Σ w × outputs), per member.
  torch::Tensor scale = weight_rows.mul(2.0).div_(weight_rows.sum(1, true).clamp_min(1e-12).mul_(static_cast<double>(rb.outputs)));
  torch::Tensor params = torch::from_blob(const_cast<float*>(rb.initial_parameters.data()), {members, total}, f32).clone();
  torch::Tensor adam_m = torch::zeros_like(params);
  torch::Tensor adam_v = torch::zeros_like(params);

  std::vector<torch::Tensor> weight, bias, weight_t;
  std::int64_t offset = 0, in = rb.inputs;
  for (int l = 0; l <= rb.hidden_layers; ++l) {
    const std::int64_t out = l < rb.hidden_layers ? rb.hidden_width : rb.outputs;
    weight.push_back(params.narrow(1, offset, in * out).view({members, in, out}));
    offset += in * out;
    bias.push_back(params.narrow(1, offset, out).view({members, 1, out}));
    offset += out;
    weight_t.push_back(weight.back().transpose(1, 2));
    in = out;
  }
  const std::size_t layers = weight.size();
  std::vector<torch::Tensor> activation(layers), grads(2 * layers);
  for (int epoch = 0; epoch < rb.epochs; ++epoch) {
    torch::Tensor h = x;
    for (std::size_t l = 0; l < layers; ++l) {
      activation[l] = h;
      torch::Tensor z = torch::baddbmm(bias[l], h, weight[l]);
      h = l + 1 < layers ? z.tanh_() : z;
    }
    const torch::Tensor g = backpropagate((h - target).mul_(scale), activation, weight_t, grads, members);
    const double lr = cosine_learning_rate(rb.learning_rate, rb.final_learning_rate, rb.epochs, epoch);
    const double t = epoch + 1;
    const torch::Tensor denom = adam_moments(adam_m, adam_v, g, t);
    params.mul_(1 - lr * rb.weight_decay).addcdiv_(adam_m, denom, -lr / (1 - std::pow(kAdamBeta1, t)));
  }
  const torch::Tensor result = params.contiguous();
  return std::vector<float>(result.data_ptr<float>(), result.data_ptr<float>() + members * total);
}

}  // namespace

}  // namespace demcal::smoothing::detail

namespace {

// Runs `work` for a C entry point: 0, or 1 with *error set. Exceptions do not cross the boundary.
template <class Work>
int guarded(std::string* error, Work work) {
  try {
    work();
    return 0;
  } catch (const std::exception& e) {
    *error = e.what();
  } catch (...) {
    *error = "unknown exception";
  }
  return 1;
}

}  // namespace

// The plugin's C entry points (torch_plugin_abi.hpp).
extern "C" DEMCAL_PLUGIN_EXPORT int demcal_torch_plugin_abi() { return demcal::smoothing::detail::kTorchPluginAbi; }

extern "C" DEMCAL_PLUGIN_EXPORT int demcal_torch_train(const demcal::smoothing::detail::TrainingBatch* batch,
                                                        const demcal::smoothing::SmootherOptions* options,
                                                        demcal::smoothing::detail::TrainingOutput* output,
                                                        std::string* error) {
  return guarded(error, [&] { *output = demcal::smoothing::detail::train_batched(*batch, *options); });
}

extern "C" DEMCAL_PLUGIN_EXPORT int demcal_torch_train_regression(const demcal::smoothing::RegressionBatch* batch,
                                                                   std::vector<float>* parameters, std::string* error) {
  return guarded(error, [&] { *parameters = demcal::smoothing::detail::train_regression(*batch); });
}
