// Surrogate pre-screening of optimiser candidates: a model of the fitness over the optimiser's unit
// cube, trained on archived runs, that ranks candidates before the expensive simulations.
//
// The module knows nothing of SQLite or the engine: it takes plain rows (a unit-cube point and the
// fitness, NaN for a failed run) and an optimise::Optimiser. pipelines/ reads the archive into rows
// (archive_training_rows) and runs the simulations.
//
// Pieces
// - SurrogateModel, of one of two kinds, plus a FailureClassifier trained on all rows (failed =
//   non-finite fitness: unstable runs, no common window with the measurement, a crashed external
//   program). Both are deterministic functions of the rows and the options.
//   - "gp": a GaussianProcess on the finite fitness values.
//   - "mlp" (default): a CurveEnsemble (curve_ensemble.hpp) on the rows' outputs, a run's resampled curves;
//     the owner's CurveHooks::fitness turns each member's predicted curves into a fitness, and the
//     prediction is the members' mean and spread (model space: log fitness when all are > 0, unless
//     gp.log_transform says "never"), the spread capped at that of the training targets, as a GP's
//     prior caps its posterior. One model serves any objective of the same scene.
// - Acquisition: expected improvement (EI, default) or a lower confidence bound (LCB), both in the
//   GP's model space (log fitness when the log transform was chosen), multiplied (EI) or penalised
//   (LCB) by the predicted probability of failure.
// - prescreen(): one iteration of pre-screening inside the ask/tell loop: for each candidate of the
//   pending batch, pool_factor - 1 alternatives (Optimiser::alternatives) join it in a pool; each
//   candidate slot is replaced (substitute) by the best of its pool under the acquisition; the k
//   slots with the best acquisition are kept and the others withdrawn (Optimiser::withdraw). The
//   optimiser is then told simulated values for the kept slots and NaN for the withdrawn ones: it
//   never receives a prediction.
// - BayesOptimiser ("bo", bayes_optimiser.cpp): a pure surrogate-driven search behind the same
//   ask/tell interface: an initial Latin-hypercube design, then rounds of a batch of candidates
//   (one per worker), the penalised acquisition's optima under the model refitted on every told
//   value (plus any warm rows from earlier campaigns).
// - cross_validate(): k-fold held-out error and the coverage of the 90 % predictive intervals.
#pragma once

#include "demcal/optimise/optimiser.hpp"
#include "demcal/surrogate/curve_ensemble.hpp"
#include "demcal/surrogate/gaussian_process.hpp"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace demcal::surrogate {

// One training row: a point of the unit cube of the campaign's parameter space and its fitness
// (NaN or inf = a failed run); for the "mlp" kind also the run's outputs (its resampled curves, a
// vector whose layout the owner defines; empty when unknown: such a row trains the classifier only).
struct TrainingRow {
  Eigen::VectorXd unit;
  double fitness = std::numeric_limits<double>::quiet_NaN();
  Eigen::VectorXd outputs = Eigen::VectorXd();
};

// What the "mlp" kind needs from its owner (pipelines/ sets both from the campaign's cases).
struct CurveHooks {
  // The fitness of predicted outputs: the campaign's objective applied to the curves they describe.
  // Must be finite. Required by the "mlp" kind.
  std::function<double(const Eigen::VectorXd& outputs)> fitness;
  // The outputs of a simulated point (its archived runs), for "bo", which is told fitness values
  // only; empty when unknown.
  std::function<Eigen::VectorXd(const Eigen::VectorXd& unit)> outputs_at;
  // "bo", any kind: the wall time a worker spends per simulation so far (its fitness included),
  // in seconds: a round of one simulation per worker takes that long (cost-aware batches,
  // SurrogateOptions::cost_ratio). Empty or <= 0 when unknown: the batch stays as set.
  std::function<double()> seconds_per_simulation;
};

// Probability that a run at a point fails: a Nadaraya-Watson kernel estimate with a Gaussian kernel
// in the unit cube and a prior of `prior_weight` pseudo-runs at the overall failure rate,
//   p(x) = (Σ w_i f_i + a p̄) / (Σ w_i + a),  w_i = exp(−|x − x_i|² / (2 h²)).
// The bandwidth h is chosen from a fixed grid by the leave-one-out log-likelihood of the labels.
// Without any failed run p(x) = 0 everywhere.
class FailureClassifier {
 public:
  void fit(const std::vector<TrainingRow>& rows);
  double probability(const Eigen::VectorXd& unit) const;
  double bandwidth() const { return bandwidth_; }
  long failures() const { return failures_; }
  long points() const { return static_cast<long>(X_.rows()); }
  nlohmann::json to_json() const;
  static FailureClassifier from_json(const nlohmann::json& json, const std::string& where);

 private:
  Eigen::MatrixXd X_;
  Eigen::VectorXd failed_;     // 1 = failed, 0 = finite fitness
  double bandwidth_ = 0.1;
  double prior_weight_ = 1.0;
  double rate_ = 0.0;
  long failures_ = 0;
};

enum class Acquisition { expected_improvement, lower_confidence_bound };
std::string to_string(Acquisition acquisition);
Acquisition parse_acquisition(const std::string& text);  // "ei" | "lcb"

// Campaign key "surrogate" (docs/surrogate.md).
struct SurrogateOptions {
  std::string kind = "mlp";          // the model kind: "mlp" or "gp" (docs/surrogate.md: chosen by
                                     // the benchmark of docs/benchmarks.md)
  int pool_factor = 5;               // pool = pool_factor x batch (the candidate and pool_factor - 1
                                     // alternatives per slot), >= 1
  int k = 0;                         // candidates simulated per iteration; 0 = the whole batch
  Acquisition acquisition = Acquisition::expected_improvement;
  double lcb_kappa = 2.0;            // LCB = mean − kappa sd (model space)
  int min_runs = 10;                 // finished runs needed before the screen switches on (and the
                                     // initial design of "bo"), >= 3
  int max_training_runs = 400;       // at most this many rows (select_training_rows), >= 10
  int batch = 0;                     // "bo": points proposed per round; 0 = the backend's workers
  // A full refit ("mlp": from fresh weights; "gp": hyperparameters) when the rows have grown by
  // this factor since the last one; in between, update(): "mlp" continues from its weights
  // (mlp.refit_epochs), "gp" keeps its hyperparameters. 1 = a full refit every round, >= 1.
  double refit_growth = 1.5;
  // "bo": when a round's model time exceeds cost_ratio x its simulations' wall time, the batch grows
  // (up to 2 x) so that fewer rounds share the simulations; infinity ("inf") = never. > 0.
  double cost_ratio = 1.0;
  // "bo": when the next round's model is fitted. "auto": the cost rule above decides (the model
  // fits while the simulations run where a round's model time is below cost_ratio x its
  // simulations'; it measures time, so the choice can differ with the machine's load). "always":
  // from the first model on, every round proposes with the model fitted while the round before it
  // was simulated, its points penalised as the round's own: the same choices on any machine.
  std::string overlap = "auto";
  // Threads that score the acquisition's candidate points ("bo") and train the "mlp" kind's members
  // side by side (its native backend; LibTorch's training stays on one thread: its matrix products
  // call a BLAS that may not be safe to call from two threads at once). Not part of the options'
  // JSON: results do not depend on it.
  int threads = 1;
  GpOptions gp;                      // "gp"; its log_transform also rules the "mlp" kind's
  MlpOptions mlp;                    // "mlp"
  // Throws std::invalid_argument naming the option and value.
  void Validate() const;
  nlohmann::json to_json() const;
  static SurrogateOptions from_json(const nlohmann::json& json, const std::string& where);
};

// The rows a model trains on: all of them when there are at most max_rows; else the max_rows / 2
// best finite rows plus an evenly spaced selection (in the given order) of the rest, so the model
// keeps both the basin and a global view. Deterministic.
std::vector<TrainingRow> select_training_rows(const std::vector<TrainingRow>& rows, int max_rows);

struct Prediction {
  double mean = 0;          // model space (fitness or log fitness)
  double sd = 0;            // latent sd, model space
  double fitness = 0;       // back-transformed mean (the median predicted fitness)
  double failure_probability = 0;
  double noise_sd = 0;      // sd of a new observation around the latent value, model space
};

class SurrogateModel {
 public:
  SurrogateModel() = default;
  explicit SurrogateModel(SurrogateOptions options, CurveHooks hooks = {})
      : options_(std::move(options)), hooks_(std::move(hooks)) {}
  // A model read from a file has no hooks: an "mlp" model needs them before it predicts.
  void set_hooks(CurveHooks hooks) { hooks_ = std::move(hooks); }

  // Trains the model (finite rows; "mlp": finite rows with outputs) and the classifier (all rows).
  // Returns false (and stays unusable) with fewer than 3 such rows. Throws std::invalid_argument for
  // an "mlp" model without CurveHooks::fitness or with rows whose outputs differ in length.
  bool fit(const std::vector<TrainingRow>& rows);
  // "gp": keeps the hyperparameters of a trained model and conditions on these rows instead.
  // "mlp" (no hyperparameters): trains anew on these rows.
  bool condition(const std::vector<TrainingRow>& rows);
  // The cheap refit of a fitted model on rows that grew: "mlp" continues training from the current
  // weights (CurveEnsemble::refine), "gp" conditions with the kept hyperparameters. Returns false,
  // leaving the model as it was, when the model is not fitted or cannot take the rows (then fit()).
  bool update(const std::vector<TrainingRow>& rows);
  bool usable() const { return options_.kind == "mlp" ? ensemble_.fitted() : gp_.fitted(); }
  int dimension() const;
  bool log_transformed() const;

  Prediction predict(const Eigen::VectorXd& unit) const;
  // Central interval of a new observation at `level` (e.g. 0.9), in fitness units.
  std::pair<double, double> interval(const Eigen::VectorXd& unit, double level) const;
  // The acquisition's score (larger = more worth simulating).
  double score(const Prediction& p) const;
  double score(const Eigen::VectorXd& unit) const { return score(predict(unit)); }

  const GaussianProcess& gp() const { return gp_; }
  const CurveEnsemble& ensemble() const { return ensemble_; }
  const FailureClassifier& classifier() const { return classifier_; }
  const SurrogateOptions& options() const { return options_; }
  long training_rows() const { return rows_; }

  nlohmann::json to_json() const;   // a model file (demcal surrogate train)
  static SurrogateModel from_json(const nlohmann::json& json, const std::string& where);

 private:
  double set_incumbent(const std::vector<TrainingRow>& rows);
  MlpOptions mlp_options() const;   // options_.mlp trained on options_.threads
  SurrogateOptions options_;
  CurveHooks hooks_;
  GaussianProcess gp_;
  CurveEnsemble ensemble_;
  bool mlp_log_ = false;            // "mlp": model space is log fitness
  double mlp_noise_sd_ = 0;         // "mlp": RMS of the training residuals of the mean, model space
  double mlp_prior_sd_ = 1;         // "mlp": sd of the training targets, model space (caps the spread)
  FailureClassifier classifier_;
  double incumbent_ = 0;            // best finite model-space target (EI)
  double spread_ = 1;               // range of model-space targets (LCB failure penalty)
  long rows_ = 0;
};

// One iteration of pre-screening: what was ranked and what was kept.
struct ScreenedCandidate {
  Eigen::VectorXd physical;         // the slot's chosen point (physical units)
  int slot = 0;                     // index in the optimiser's batch
  int pool = 0;                     // points ranked for this slot
  bool replaced = false;            // an alternative beat the optimiser's own proposal
  bool simulated = false;           // kept (true) or withdrawn (false)
  Prediction prediction;
  double score = 0;
};
struct ScreenReport {
  int pool = 0;                     // points ranked in total
  int simulated = 0;                // slots kept
  std::vector<ScreenedCandidate> candidates;  // one per slot of the batch
  nlohmann::json to_json() const;
};

// Screens the optimiser's pending batch (ask() must have been called, can_substitute() true).
ScreenReport prescreen(optimise::Optimiser& optimiser, const SurrogateModel& model, const SurrogateOptions& options);

// Held-out check of a model kind on rows: `folds`-fold cross-validation (rows assigned to folds
// round-robin in the given order), each fold predicted by a model fitted to the others.
struct CrossValidation {
  long rows = 0, finite_rows = 0, failed_rows = 0;
  int folds = 0;
  double mean_absolute_error = 0;   // fitness units, held-out finite rows
  double relative_error = 0;        // mean |ŷ − y| / mean |y − mean(y)|
  double median_relative_error = 0; // median of |ŷ − y| / |y|
  double coverage90 = 0;            // fraction of held-out finite rows inside the 90 % interval
  double failure_brier = 0;         // mean (p − failed)² over all held-out rows
  nlohmann::json to_json() const;
};
CrossValidation cross_validate(const std::vector<TrainingRow>& rows, const SurrogateOptions& options, int folds = 5,
                               const CurveHooks& hooks = {});

// "bo": Bayesian optimisation behind the ask/tell interface (see the header comment). The initial
// design is a Latin hypercube of max(options.min_runs, population, given starts) points, its first
// the given initial point and further starts (OptimiserOptions::further_starts), less every point with a warm row within half the design's spacing of it
// (0.5 n^(-1/d) in the unit cube): clustered warm rows replace the points beside them, spread ones
// the whole design; then rounds of `batch` points
// (SurrogateOptions::batch, at least 1): each point the maximum of the acquisition, locally
// penalised around the points already in the round, over 2000 random points and 20 alternatives
// around each of the 5 best training points, polished by NLopt LN_BOBYQA from the best 3. The model
// is refitted fully or updated per SurrogateOptions::refit_growth; with hooks.seconds_per_simulation
// the batch grows once per cost_ratio. Deterministic given the rows and that decision; save_state()
// holds the told history, the model's predictions of each proposed point, the refits and the batch,
// so load_state() replays the refits and continues exactly.
// What a "bo" optimiser's saved state says of its run: points per round and why (the cost-aware
// decision), points the model proposed, and the prequential check of their predictions, each made
// before the point was simulated: relative error (mean |ŷ − y| / mean |y − ȳ|) and 90 % interval
// coverage over those that ran (finite fitness; NaN with fewer than 2). Throws
// std::invalid_argument for a state that is not a "bo" state.
struct BayesSummary {
  int batch = 0;
  std::string batch_reason;
  long predicted = 0;
  double prequential_error = std::numeric_limits<double>::quiet_NaN();
  double prequential_coverage90 = std::numeric_limits<double>::quiet_NaN();
};
BayesSummary summarise_bayes_state(const nlohmann::json& state);

std::unique_ptr<optimise::Optimiser> make_bayes_optimiser(const optimise::ParameterSpace& space,
                                                          const optimise::OptimiserOptions& options,
                                                          const SurrogateOptions& surrogate,
                                                          std::vector<TrainingRow> warm_rows = {},
                                                          CurveHooks hooks = {});

}  // namespace demcal::surrogate
