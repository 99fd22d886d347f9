// Training of an ensemble of small regression MLPs. The surrogate module's curve model
// (surrogate/curve_ensemble.hpp) is its user: inputs are points of the optimiser's unit cube,
// outputs a run's resampled curves. Two backends train the same networks with the same loss and
// schedule (float arithmetic, so they agree to round-off, not bit for bit):
// - native (default): loops over float arrays, every product one register-blocked kernel (an
//   AVX2+FMA clone chosen at run time where the CPU has it), each member on its own thread up to
//   `threads`. A member's training reads only its own inputs, so the result is the same for any
//   thread count.
// - libtorch: in the plugin libdemcal_torch.so (opened on first use, like the smoother's libtorch
//   backend), every member batched into one product per layer, on one thread (`threads` is its
//   intra-op count; Debian's OpenBLAS is not safe to call from two threads at once).
//
// Network of every member: `inputs` -> hidden_layers x hidden_width (tanh) -> `outputs` (linear).
// Flat parameter layout per member, as the smoother's: W0 (row-major [in][out]), b0, W1, b1, ...
// Loss per member m: Σ_i w_mi |f_m(x_i) − y_i|² / (Σ_i w_mi × outputs), minimised by full-batch
// Adam with the learning rate decaying from learning_rate to final_learning_rate (cosine) and
// decoupled weight decay (p ← p (1 − lr × weight_decay)). Every member trains from the initial
// parameters it is given: the caller owns the random draws, so a result depends on its inputs and
// the backend only (bit-identical repeats).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace demcal::smoothing {

enum class RegressionBackend { native, libtorch };
std::string to_string(RegressionBackend backend);
RegressionBackend parse_regression_backend(const std::string& name);  // "native" | "libtorch"

struct RegressionBatch {
  std::int64_t members = 0;
  std::int64_t rows = 0;
  std::int64_t inputs = 0;
  std::int64_t outputs = 0;
  int hidden_layers = 2;
  int hidden_width = 32;
  std::vector<float> x;                   // [rows][inputs]
  std::vector<float> y;                   // [rows][outputs]
  std::vector<float> row_weight;          // [members][rows], >= 0 (bootstrap counts)
  std::vector<float> initial_parameters;  // [members][regression_parameter_count(...)]
  int epochs = 1500;
  double learning_rate = 0.01;
  double final_learning_rate = 0.001;
  double weight_decay = 1e-4;
  RegressionBackend backend = RegressionBackend::native;
  int threads = 1;                        // native: members trained side by side; libtorch: intra-op threads
};

// Parameters of one member's network.
std::int64_t regression_parameter_count(std::int64_t inputs, std::int64_t outputs, int hidden_layers, int hidden_width);

// Trains every member; returns their parameters, [members][parameter count]. Throws
// std::runtime_error when the plugin cannot be loaded (naming the paths searched) or training fails,
// std::invalid_argument when the batch's sizes disagree or threads < 1.
std::vector<float> train_regression_ensemble(const RegressionBatch& batch);

}  // namespace demcal::smoothing
