// The boundary between the smoothing module and its LibTorch plugin (libdemcal_torch.so), private to
// the module. The plugin is built from this project's sources with the same compiler, so C++ types
// cross it by pointer; the ABI number changes whenever TrainingBatch, TrainingOutput,
// SmootherOptions or RegressionBatch change layout or an entry point is added, and a plugin of
// another number is refused.
#pragma once

#include "mlp_training.hpp"
#include "demcal/smoothing/regression_ensemble.hpp"

#include <string>

#define DEMCAL_PLUGIN_EXPORT __attribute__((visibility("default")))

namespace demcal::smoothing::detail {

inline constexpr int kTorchPluginAbi = 3;

// int demcal_torch_plugin_abi(): the plugin's kTorchPluginAbi.
using TorchPluginAbiFunction = int (*)();
// int demcal_torch_train(batch, options, output, error): 0 and *output filled, or non-zero and
// *error set.
using TorchTrainFunction = int (*)(const TrainingBatch*, const SmootherOptions*, TrainingOutput*, std::string*);
// int demcal_torch_train_regression(batch, parameters, error): 0 and *parameters filled
// ([members][parameter count]), or non-zero and *error set.
using TorchRegressionFunction = int (*)(const RegressionBatch*, std::vector<float>*, std::string*);

}  // namespace demcal::smoothing::detail
