// The curve model of the surrogate's "mlp" kind: an ensemble of small MLPs that map a point of the
// optimiser's unit cube to a run's resampled curves (a fixed-length output vector that the owner
// defines: pipelines/surrogate_data.hpp resamples each channel's force on a displacement grid).
// Because it predicts curves, not a fitness, one model serves objective 1 and 2 and any measurement
// of the same scene: the owner turns each member's predicted curves into a fitness, and the members'
// spread is the prediction's uncertainty (SurrogateModel, surrogate.hpp).
//
// Training (smoothing/regression_ensemble.hpp: the native loops by default, LibTorch's plugin with
// "backend": "libtorch"): inputs 2u − 1, outputs
// standardised per column over the training rows; each member starts from its own Glorot-uniform
// draw and, with `bootstrap`, weighs each row by a Poisson(1) count drawn from the row's point (a
// bootstrap that gives a row the same weight whatever rows join it), so the members disagree where
// the data are thin. refine() continues from the current weights on more rows, keeping the output
// standardisation: the cheap refit of a model whose rows grow a few at a time. Prediction is a
// plain forward pass here (Eigen, double). Both are deterministic functions of the rows, the
// options and (refine) the previous weights.
#pragma once

#include "demcal/smoothing/regression_ensemble.hpp"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace demcal::surrogate {

// Campaign key "surrogate": {"mlp": {...}} (docs/surrogate.md).
struct MlpOptions {
  int members = 5;                    // networks in the ensemble, >= 2
  int hidden_layers = 2;              // tanh layers, >= 1
  int hidden_width = 32;              // neurons per hidden layer, >= 1
  int epochs = 2000;                  // full-batch Adam steps, >= 1
  double learning_rate = 0.01;        // at the first step, > 0
  double final_learning_rate = 0.0005;  // at the last (cosine decay), in (0, learning_rate]
  double weight_decay = 0.1;          // decoupled, per step x learning rate, >= 0
  bool bootstrap = true;              // each member weighs the rows by a bootstrap resample
  std::uint64_t seed = 1;             // initial weights and resamples
  int refit_epochs = 300;             // Adam steps of refine(), >= 1
  double refit_learning_rate = 0.002; // refine()'s first learning rate (cosine to final_learning_rate),
                                      // in [final_learning_rate, learning_rate]
  // Training backend, "native" or "libtorch" (regression_ensemble.hpp): the same networks, equal to
  // round-off, so the choice is part of a campaign's result-defining key.
  smoothing::RegressionBackend backend = smoothing::RegressionBackend::native;
  // Members trained side by side ("native"; LibTorch trains on one thread). Not part of the options'
  // JSON: results do not depend on it. The owner sets it (SurrogateOptions::threads).
  int threads = 1;
  // Throws std::invalid_argument naming the option and value.
  void Validate() const;
  nlohmann::json to_json() const;
  static MlpOptions from_json(const nlohmann::json& json, const std::string& where);
};

class CurveEnsemble {
 public:
  // X: [rows][dimension] unit points; Y: [rows][outputs]. Returns false with fewer than 3 rows.
  // Throws std::runtime_error when the LibTorch plugin is asked for and cannot be loaded.
  bool fit(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, const MlpOptions& options);
  // Continues training from the current weights on these rows (options.refit_epochs steps from
  // options.refit_learning_rate). Returns false, changing nothing, when not fitted, with fewer than
  // 3 rows or with other dimensions or members than the fitted ensemble.
  bool refine(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, const MlpOptions& options);
  bool fitted() const { return !members_.empty(); }
  int members() const { return static_cast<int>(members_.size()); }
  int dimension() const { return dimension_; }
  int outputs() const { return static_cast<int>(mean_.size()); }

  // Member m's outputs at a unit point, in the rows' units.
  Eigen::VectorXd predict(int member, const Eigen::VectorXd& unit) const;

  nlohmann::json to_json() const;
  static CurveEnsemble from_json(const nlohmann::json& json, const std::string& where);

 private:
  struct Network {
    std::vector<Eigen::MatrixXd> weight;  // per layer, [out][in]
    std::vector<Eigen::VectorXd> bias;
  };
  smoothing::RegressionBatch training_batch(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y,
                                            const MlpOptions& options) const;
  void load_members(const std::vector<float>& trained, const MlpOptions& options);

  std::vector<Network> members_;
  int dimension_ = 0;
  Eigen::VectorXd mean_, scale_;          // output standardisation
};

}  // namespace demcal::surrogate
