// Shared by the diagnosis's sources. run_diagnosis (diagnose.cpp) is a list of stages, one file each:
//   base_fit.cpp       1. the base calibration and its refinement
//   base_residual.cpp  2. the base best set's residual, noise and simulation scatter
//   signatures.cpp     3. each effect probed: how much of the residual it can explain
//   extension.cpp      4. the extended calibrations, best signature first
//   union_search.cpp   4b. the union search: one emulator over the base and every candidate
//   selection.cpp      5. the verdict, with further searches where no fit explains the curves
//   resampling.cpp     5c. how often the verdict holds over resamples of the data and round-off
//   ranges.cpp         6. how tightly the data pin an accepted effect's parameters
//   notes.cpp          7. the verdict's notes; diagnose_report.cpp: report.md
// The stages share a DiagnosisRun; case_runner.cpp simulates parameter sets for them, residual.cpp
// holds the curve arithmetic (pure functions, declared in diagnose.hpp).
#pragma once

#include "demcal/common/format.hpp"
#include "demcal/dem/effects.hpp"
#include "demcal/pipelines/diagnose.hpp"
#include "demcal/pipelines/predict.hpp"

#include <atomic>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace demcal::pipelines::detail {

// A residual's simulated_rows and simulated_in_gap from its simulated series and that series's
// loading envelope (its measured gap already set).
void note_simulated_sampling(ChannelResidual& residual, const smoothing::XYSeries& simulated,
                             const smoothing::XYSeries& simulated_envelope);

// A share in [0, 1] as a percentage of three significant digits: "97 %", "33.5 %".
std::string percent(double share);

// `s` usable as a file or folder name: every character but letters, digits, '-' and '_' -> '_'.
std::string file_safe(std::string s);
// "<effect> at <target>", or the effect alone where it has no target: a fit as the verdict names it.
inline std::string effect_at(const std::string& effect, const std::string& target) {
  return target.empty() ? effect : effect + " at " + target;
}

// report.md and its figures (diagnose_report.cpp).
void write_diagnosis_report(const Diagnosis& diagnosis, const DiagnoseOptions& options);

// ---- runs of parameter sets (case_runner.cpp) ---------------------------------------------------

std::string key_of(const ChannelResidual& c);  // "<case>/<channel>"
// Root mean square of per-channel values ("<case>/<channel>" -> N), NaN ones left out; 0 when none.
double overall(const std::map<std::string, double>& per_channel);
double overall_noise(const std::vector<ChannelResidual>& residuals);  // RMS of the channels' noise, N
// RMS force error over every channel: sqrt of the mean of the per-channel mean squares (NaN: none).
double overall_error(const std::vector<ChannelResidual>& residuals);
void progress(const DiagnoseOptions& o, const std::string& line);     // a progress line on stderr
bool is_held_out(const std::string& case_name, const std::vector<std::string>& held_out_cases);

// What one parameter set does to every case: the simulated curves and their residuals.
struct Evaluation {
  bool ok = false;
  std::string message;
  std::vector<CasePrediction> cases;
  std::vector<ChannelResidual> residuals;  // per case and channel, on the base grid when one is given
  std::vector<ChannelResidual> held_out;   // channels of weight 0 and of held-out cases, not fitted
  double error = Diagnosis::kNaN;
  double held_out_error = Diagnosis::kNaN;
};

// One parameter set to simulate: on `config` (the base or an extended model), its residuals on
// `grid` (the base residuals: fits compare point by point) or, when null, on its own grid.
struct RunRequest {
  const CampaignConfig* config = nullptr;
  std::map<std::string, double> params;
  const std::vector<ChannelResidual>* grid = nullptr;
};

// Simulates parameter sets on the campaign's cases and counts the runs.
class CaseRunner {
 public:
  CaseRunner(const CampaignConfig& config, const std::vector<std::string>& held_out_cases);

  // Simulates `params` on `config` (RunRequest).
  Evaluation evaluate(const CampaignConfig& config, const std::map<std::string, double>& params,
                      const std::vector<ChannelResidual>* grid = nullptr);
  // Every request at once, one set per worker (the campaign's threads backend: backend.threads, or
  // every hardware thread), a lone set's cases side by side; the evaluations in the order asked,
  // the same as evaluating the sets one by one. Throws the first (in that order) that throws.
  std::vector<Evaluation> evaluate_all(const std::vector<RunRequest>& requests);
  // The sets evaluate_all simulates at once.
  int workers() const { return workers_; }
  // The two halves of evaluate_all: the simulations, and the residuals of one set's simulated cases.
  std::vector<std::vector<CasePrediction>> simulate_all(const std::vector<RunRequest>& requests);
  Evaluation score(const CampaignConfig& config, std::vector<CasePrediction> cases,
                   const std::vector<ChannelResidual>* grid) const;

  // Every run the diagnosis has evaluated, its calibrations' archived ones included, so that the
  // budget and the count of a resumed diagnosis are those of an uninterrupted one.
  long simulations() const { return simulations_; }
  long simulated_this_session() const { return simulated_this_session_; }
  void add_campaign(const CampaignResult& r);
  void add_runs_of(const CaseRunner& other);  // another runner's counts and times (a further step's)

  // Runs `tasks` side by side, all at once up to kTasksPerWorker per worker (together), or one
  // after another in their order (not together: a total simulation budget, which each task reads
  // at its start, then holds as in a diagnosis without side-by-side stages). Tasks may call this
  // runner and run campaigns; each writes only its own results, which the caller merges in task
  // order, so the results are those of the tasks run one by one. One task's waits (its round's
  // slowest run, its model's fits) are filled by the others' runs, and no task is left to run
  // alone at the end while the others' cores idle. Side by side, the stage's wall time counts
  // once, shared between simulations and models in the proportion the tasks spent in each.
  // Rethrows the first exception in task order once every task has ended.
  void side_by_side(const std::vector<std::function<void()>>& tasks, bool together);
  // Whether side_by_side runs `tasks` tasks at once (more than one, together, more than one worker,
  // not inside another task): its tasks then print no line per round of their searches.
  bool runs_together(std::size_t tasks, bool together) const;
  // Tasks at once per worker, at most: each task's rounds already use every worker, so more would
  // only add threads.
  static constexpr int kTasksPerWorker = 4;
  // Model seconds spent outside the calibrations (the union search's emulator).
  void add_model_seconds(double seconds) { add_times(0, seconds); }
  // This session's seconds waiting for simulations (direct runs and the calibrations') and in the
  // calibrations' models (surrogate fits and search).
  double simulation_seconds() const { return simulation_s_; }
  double model_seconds() const { return model_s_; }

 private:
  std::map<std::string, smoothing::Curve> measured_;  // by case name
  std::vector<std::string> held_out_cases_;
  int workers_ = 1;
  // Side by side (side_by_side): counts under the lock, times summed per task until the stage ends.
  std::mutex mutex_;
  std::atomic<bool> shared_{false};
  double shared_simulation_s_ = 0, shared_model_s_ = 0;
  void add_times(double simulation_s, double model_s);
  long simulations_ = 0;
  long simulated_this_session_ = 0;  // direct runs and the calibrations' runs not read from the archive
  double simulation_s_ = 0, model_s_ = 0;
};

// Concatenated residual (or curve difference) over channels, each channel divided by its noise so
// that channels of different precision weigh alike.
std::vector<double> stacked(const std::vector<ChannelResidual>& base, const std::vector<ChannelResidual>* other);

// A parameter set's run and its re-runs with every free parameter of `nudge_space` moved by k x 1e-7
// of itself (k = 1..reruns), each on `grid` (none: the first run's own grid), in that order, all
// simulated at once; failed re-runs are left out, and a failed first run is returned alone.
std::vector<Evaluation> runs_with_reruns(const CampaignConfig& config, const CampaignConfig& nudge_space,
                                         const std::map<std::string, double>& params,
                                         const std::vector<ChannelResidual>* grid, int reruns, CaseRunner& runner);
// The run of median error (of an even count, the worse middle one): a search keeps the luckiest run
// it meets, so a fit is judged on the middle of its run and re-runs.
const Evaluation& median_run(const std::vector<Evaluation>& runs);
// The simulation's own scatter per channel (into `per_channel`, "<case>/<channel>" -> N) and over
// all channels (returned; NaN with fewer than two runs).
double simulation_scatter(const std::vector<Evaluation>& runs, std::map<std::string, double>& per_channel);

// Every calibration of a diagnosis shares one archive, so that the refinement's surrogate starts
// from the base calibration's runs (same scene hash and objective); the extended models have scene
// hashes of their own.
std::string diagnosis_archive(const DiagnoseOptions& options);
// The campaign without its held-out cases: what every calibration of the diagnosis fits.
CampaignConfig fitted_cases(CampaignConfig config, const DiagnoseOptions& options);

// ---- extended models (extension.cpp) -----------------------------------------------------------

// Every search of a diagnosis ("bo"): rounds of one point per worker, never grown by the cost rule,
// each round's model fitted while the round before it is simulated, whatever the machine's speed.
// A search here is short (tens of simulations in up to six dimensions), where fewer rounds cost
// accuracy (measured: the compliant-support loop test missed the soft support with rounds grown
// to 4 points, found it with 2), and a verdict must not depend on how busy the machine was
// (docs/diagnose.md, step 4).
void fix_search_rounds(CampaignConfig& c);

struct ExtendedModel {
  CampaignConfig config;
  std::vector<std::string> parameter_names;                   // set_parameter names of the effect
  std::vector<dem::EffectParameter> parameters;              // registry entry of each name, range resolved
  std::string target;
};

// The base model with `effect` switched on for `targets` in every case's scene (written to folder).
ExtendedModel extend(const CampaignConfig& config, const dem::Effect& effect, const std::vector<std::string>& targets,
                     const dem::ResponseScales& scales, const std::filesystem::path& folder);

// The highest value an effect parameter may take over a base set: the base parameter its registry
// entry names as its cap (dem::EffectParameter::capped_by), of the same group where the name has
// one, else of every group; +infinity when it has none.
double parameter_cap(const std::string& name, const dem::EffectParameter& p, const std::map<std::string, double>& base);

// The space of base + effect (`m`): the base parameters in the campaign's bounds (narrowed around
// `best` where the options say so), the effect's in its search ranges, each capped parameter below
// the lowest value of its cap searched.
optimise::ParameterSpace extended_space(const ExtendedModel& m, const CampaignConfig& config,
                                        const std::map<std::string, double>& best, const DiagnoseOptions& options);
// The campaign that calibrates base + effect (`m`; none: the base alone) from `best`, into `folder`,
// at most `evaluations` simulations, warm-started at `warm`; for "bo", its design starts also at
// each of `further_base` (other base sets, further_start_sets) with the effect as in `warm`.
CampaignConfig extended_campaign(const ExtendedModel& m, const CampaignConfig& config,
                                 const std::map<std::string, double>& best, const DiagnoseOptions& options,
                                 long evaluations, const std::filesystem::path& folder,
                                 const std::map<std::string, double>& warm,
                                 const std::vector<std::map<std::string, double>>& further_base = {});

// The extended calibration of one candidate: base + its effect into `folder`, at most `budget`
// simulations, warm-started at `warm` (and at `further_base`, as extended_campaign), every set it
// evaluated appended to `searched` (when given); its best set (into `best_set`, on every case) re-run and the
// fit judged on the run of median error, since the best of many runs of a model that slips or snaps
// may be a lucky one. Sets the fit's fields of `c` (its simulations added); false, with `c.reason`,
// when the best set cannot be re-simulated. Throws what run_campaign throws.
bool calibrate_candidate(EffectCandidate& c, std::map<std::string, double>& best_set, const ExtendedModel& m,
                         const CampaignConfig& config, const std::map<std::string, double>& base_params,
                         const DiagnoseOptions& options, long budget, const std::filesystem::path& folder,
                         const std::map<std::string, double>& warm, const std::vector<ChannelResidual>& base_residuals,
                         CaseRunner& runner, const std::vector<std::map<std::string, double>>& further_base = {},
                         std::vector<ParameterSet>* searched = nullptr);

// A fit's search continued once (DiagnoseOptions::continued_simulations): `model` with its seed + 1,
// `budget` simulations from `set` in `folder`, on the base model `config` at `base_params`. The
// lower of `fit` and the new fit is kept in `fit` and `set`, `fit.simulations` counting both;
// `label` names the fit in the line of a failed search. Returns the further search's record.
ContinuedSearch continue_search(EffectCandidate& fit, std::map<std::string, double>& set, ExtendedModel model,
                                const CampaignConfig& config, const std::map<std::string, double>& base_params,
                                const DiagnoseOptions& options, long budget, const std::filesystem::path& folder,
                                const std::vector<ChannelResidual>& base_residuals, CaseRunner& runner,
                                const std::string& label, std::vector<ParameterSet>* searched = nullptr);

// A fit's fields of `c` (rerun_errors, residuals, error, rms, held-out errors) from a set's run and
// re-runs (runs_with_reruns), judged on the run of median error; false, with `c.reason`, when the
// first run failed.
bool judge_fit(EffectCandidate& c, const std::vector<Evaluation>& runs);

// Whether a signature share comes within `share` of a positive reference share: a signature is a
// linearisation from a few single runs, so shares that close do not order two targets or effects.
bool signature_comes_close(double score, double reference, double share);

// ---- selection (selection.cpp) -----------------------------------------------------------------

// Every calibrated candidate's criterion change against the base, all counted with the effective
// points of common_effective_points over the base and those candidates (kept in the diagnosis);
// returns them in the order of the base residuals.
std::vector<double> score_candidates(Diagnosis& d);
// The candidate of the first effect chosen (Diagnosis::chosen.front()); null when none is.
const EffectCandidate* chosen_candidate(const Diagnosis& d);
// The tried candidate of lowest criterion among those whose criterion falls and whose fit lowers the
// error without spoiling the held-out data (the lead of an unexplained residual: the tentative
// effect, the first of the pair search's pairs with effects not calibrated); null when none does.
const EffectCandidate* unexplained_lead(const Diagnosis& d, const DiagnoseOptions& options);
// The diagnosis's error floor (error_floor of its base noise and scatter), N.
double floor_of(const Diagnosis& d, const DiagnoseOptions& options);
// "RMS force error E N, noise about N N, simulation scatter about S N" of the base fit.
std::string base_errors_text(const Diagnosis& d);
// The chosen effect when its fit misses the curves by more than the explained level; else null.
const EffectCandidate* unexplained_chosen(const Diagnosis& d, const DiagnoseOptions& options);

// ---- the stages --------------------------------------------------------------------------------

// A target probed for its signature: the candidate's signature fields, its model, its warm start.
struct ProbedTarget {
  EffectCandidate candidate;
  ExtendedModel model;
  std::map<std::string, double> warm;
  double warm_error = std::numeric_limits<double>::infinity();  // the force error of warm's run, N
};

// What the stages of one diagnosis share: run_diagnosis makes it, each stage reads what the stages
// before it left and adds its own part.
struct DiagnosisRun {
  DiagnosisRun(CampaignConfig config, DiagnoseOptions options);

  // The base model: the campaign's, or one with effects added; stage 1 may widen its objective's
  // window to the measured one (Diagnosis::widened_window), no stage after it changes it.
  CampaignConfig config;
  const DiagnoseOptions options;
  CaseRunner runner;
  Diagnosis d;
  std::vector<const dem::Effect*> effects;  // the effects considered (DiagnoseOptions::effects)
  long per_candidate = 0;                   // simulations per candidate calibration
  // The archives of the steps before this one (step 8; the first step's first): their calibrations
  // ran this step's base model, whose runs the union search learns from.
  std::vector<std::string> earlier_archives;

  // 2. the base residual
  std::map<std::string, double> base_params;  // the base best set, every parameter
  std::vector<Evaluation> base_runs;          // its run and re-runs (runs_with_reruns)
  Evaluation base;                            // its run of median error among them
  double noise = 0;                           // N, over every fitted channel
  double scatter = 0;                         // N, the simulation's own (NaN: no re-runs)
  bool at_noise = false;                      // the base fit is within the noise: nothing to explain

  // 3. signatures
  std::map<std::string, ExtendedModel> models;                      // effect -> its best-signature extension
  std::map<std::string, std::map<std::string, double>> warm_starts;  // effect -> its best probe's set
  std::map<std::string, std::vector<ProbedTarget>> close_targets;    // effect -> other targets calibrated too
  // effect -> every target of a targeted effect whose probes ran, the best included: the pair
  // search's other targets (search_pairs)
  std::map<std::string, std::vector<ProbedTarget>> probed_targets;

  // 4-6. calibrations and selection
  std::map<std::string, std::map<std::string, double>> best_sets;  // effect -> its fit's complete set
  std::map<std::string, std::vector<ParameterSet>> searched;       // effect -> every set its calibrations evaluated
  std::vector<double> effective_points;                            // score_candidates' last count

  // `wanted` simulations, within a total budget: room is left for a best set's run and re-runs.
  long within_budget(long wanted) const;
  // A continued search's simulations (DiagnoseOptions::continued_simulations; -1: a candidate's).
  long continued_budget() const { return options.continued_simulations < 0 ? per_candidate : options.continued_simulations; }
};

void fit_base(DiagnosisRun& run);                      // 1. base_fit.cpp
void measure_base_residual(DiagnosisRun& run);         // 2. base_residual.cpp
void probe_signatures(DiagnosisRun& run);              // 3. signatures.cpp
void calibrate_candidates(DiagnosisRun& run);          // 4. extension.cpp
// 4b. The union search (DiagnoseOptions::union_rounds; union_search.cpp): one emulator of
// the curves over UnionLayout's space of the base and every calibrated candidate's model, trained
// on every archived run of these models and on its own proposals; each round searches it for each
// candidate from many starts and simulates the best point of each, one per worker. A candidate's
// best proposal, judged on the median of its re-runs, replaces the calibration's fit when its error
// is lower (EffectCandidate::union_search).
void search_union(DiagnosisRun& run);
// 8a. The pair search (DiagnoseOptions::pair_rounds; union_search.cpp), where no effect passes
// alone: every pair of calibrated candidates, and the lead (unexplained_lead) with every effect
// probed but not calibrated; with the other targets of each effect (DiagnosisRun::probed_targets,
// the kOtherTargets whose best probes came closest) paired with the lead, and the lead's effect at
// its other targets paired with every effect at its own; the union search's emulator searched with
// both switched on within a trust region around each pair's best run, its best point simulated per
// round (into run.d.pair_search); the pairs whose best run beats their calibrated effects' fits (at
// most three, lowest first) judged on the median of their runs, the closest after a candidate's
// calibration from its best run.
struct PairFit {
  std::size_t pair = 0;                    // its entry of PairSearch::pairs
  const EffectCandidate* first = nullptr;  // the candidates of its two effects, in the candidates' order
  const EffectCandidate* second = nullptr;
  const ExtendedModel* first_model = nullptr;   // each effect alone at its target
  const ExtendedModel* second_model = nullptr;
  ExtendedModel model;                     // the base model with both effects
  std::map<std::string, double> set;       // its best set, complete
  EffectCandidate fit;                     // judge_fit's fields; effect and target the second's,
                                           // effect_parameters both effects'
};
std::vector<PairFit> search_pairs(DiagnosisRun& run);
void select_and_search_further(DiagnosisRun& run);     // 5. selection.cpp
void resample_verdict(DiagnosisRun& run);              // 5c. resampling.cpp
void bound_accepted_parameters(DiagnosisRun& run);     // 6. ranges.cpp
// The bounds of each parameter of m.parameter_names into c.bounds (profile_bound: c's fit, `best`,
// re-simulated on the fitted cases of m.config with one parameter moved, the others re-fitted where
// that one run rules the value out; the criterion change against c.residuals on `grid`), within the
// diagnosis's simulation budget. m.config may hold further effects' parameters: they are re-fitted
// with the base's.
void bound_effect_parameters(EffectCandidate& c, const ExtendedModel& m, const std::map<std::string, double>& best,
                             const std::vector<ChannelResidual>& grid, const std::vector<double>& effective_points,
                             CaseRunner& runner, const DiagnoseOptions& options);
void add_verdict_notes(DiagnosisRun& run);             // 7. notes.cpp
// "<case>/<channel> over N %, ..." of channels and the share of their measured range a window
// covers, in the order given (notes.cpp).
std::string listed_coverage(const std::vector<std::pair<std::string, double>>& shares);
void add_further_effects(DiagnosisRun& run);           // 8. further_effects.cpp
// 8b. An undecided verdict (effects tied, or no choice reached by --verdict-share of the resamples)
// gets the removal check of its closest fit: the base model alone re-fitted from the best-fitting
// candidate's set. Where the effect is no longer needed (removal_criteria), the candidates' searches
// only found a better base than the base calibration did, and the diagnosis says so: no effect
// needed (or none found, above twice the floor). The verdict no longer hangs on where the base
// calibration happened to stop.
void check_undecided_leader(DiagnosisRun& run);       // further_effects.cpp
// The counts and times of `run` into its diagnosis, then diagnosis.json and report.md in its folder.
void finish_diagnosis(DiagnosisRun& run, double wall_time_s);
// Stages 2 to 7 on the base model of `run`, whose base fit is set (stage 1, or a previous step).
void diagnose_from_base(DiagnosisRun& run);
// The chosen fit's own parameters, "field ≈ value (lower – upper)" in engineering units, the range
// from its bounds check where that ran; those the check pins on neither side only named ("support_ky,
// support_kr not pinned by the data"). A field two groups set is named in full ("<group>.<field>").
std::string fitted_effect_parameters(const EffectCandidate& c, const Diagnosis& d);

// `note` (a sentence with its leading space, "" = none) appended to the verdict and to its notes;
// the verdict before the first note is its conclusion.
void add_note(Diagnosis& d, const std::string& note);


}  // namespace demcal::pipelines::detail
