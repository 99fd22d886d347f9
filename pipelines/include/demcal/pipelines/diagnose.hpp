// `demcal diagnose`: why a calibration fits badly, and which physical effect fixes it.
//
//   1. base fit      the campaign's own calibration (or a finished one, `--result`): best set B;
//   2. residual      per case and channel, measured - simulated force on the objective's grid:
//                    bias, trend, where along the curve it sits (initial branch, up to the peak,
//                    after the peak) and with which sign, lag-1 autocorrelation, the measurement
//                    noise estimated from the measured curve alone, and the simulation's own
//                    scatter (B re-run with its parameters moved by 1e-7 of themselves; the
//                    residual is that of the run of median error, as for every candidate);
//   3. signatures    for every candidate effect (dem::effect_registry), the change of the simulated
//                    curves when the effect is switched on at B (two magnitudes), and the base
//                    parameters' own sensitivities (one finite difference each). An effect scores
//                    by the share of the residual that the base parameters cannot remove and its
//                    signature, with a non-negative weight, can: the ranking decides which effects
//                    are calibrated at all when the budget is short, and in which order;
//   4. extension     each tried effect: a calibration of the base parameters (bounds narrowed
//                    around B, if asked) plus the effect's parameters through run_campaign
//                    (archive, backends, surrogate, report), in <out>/candidates/<effect>/: by
//                    Bayesian optimisation on the surrogate (default), or a local search started
//                    from B with the effect at its probe closest to the measurement (one probe
//                    more: where the probes, taken as linear, say the residual is explained);
//   5. selection     the change of an information criterion with the effective number of
//                    independent points (the residual is autocorrelated; one count per channel for
//                    every fit, common_effective_points): accepted when it falls
//                    by more than `evidence`; "no effect needed" when none is accepted or
//                    the base residual is already at the noise level; two accepted effects within
//                    `tie_margin` of each other are "tied", and then none is chosen;
//   6. bounds        for an accepted or tied effect, how tightly the data pin each of its
//                    parameters (ParameterBound: the fit re-run with that parameter moved, the
//                    others re-fitted where needed);
//   7. more effects  the model with the accepted effect is the next base (max_effects); then each
//                    effect added is re-fitted without (the base alone for one: removal_criteria)
//                    and dropped where no longer needed (its removal costs no evidence, or the
//                    fit without it is explained); an undecided verdict's closest fit is checked
//                    so too, and where the base alone re-fitted from it does as well, no effect
//                    is needed.
//
// Outputs: <out>/diagnosis.json (layout in docs/commands/diagnose.md) and <out>/report.md with residual
// plots before and after, the table of candidates and the verdict in words. Forces in N,
// displacements in m, friction in degrees (as in campaigns).
#pragma once

#include "demcal/dem/effects.hpp"
#include "demcal/pipelines/campaign.hpp"
#include "demcal/smoothing/curve.hpp"

#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <vector>

namespace demcal::pipelines {

// ---- residual analysis -------------------------------------------------------------------------

// One stretch of a channel's evaluation grid.
struct ResidualRegion {
  std::string name;   // "initial" (up to half the measured peak), "to_peak", "after_peak"
  double lower = 0;   // m
  double upper = 0;   // m
  int points = 0;     // grid points inside (0: the curve has no such stretch)
  double mean = 0;    // N, mean residual (measured - simulated): > 0 = the model is too weak there
  double rms = 0;     // N
};

// The residual of one channel (force against one displacement) on the objective's grid: `points`
// evenly spaced displacements over the window both loading envelopes share.
struct ChannelResidual {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  std::string case_name;
  std::string channel;                 // displacement column
  std::vector<double> displacement;    // m
  std::vector<double> measured;        // N, the raw measured envelope interpolated on the grid
  std::vector<double> simulated;       // N
  double noise = kNaN;                 // N, standard deviation of the measurement noise (estimate_noise)
  double bias = 0;                     // N, mean residual
  double trend = 0;                    // N/m, least-squares slope of the residual against displacement
  double rms = 0;                      // N
  double peak_displacement = 0;        // m, where the measured curve peaks on the grid
  std::vector<ResidualRegion> regions; // initial, to_peak, after_peak
  double autocorrelation = 0;          // lag-1 autocorrelation of the residual on the grid
  double effective_points = 0;         // n (1 - rho) / (1 + rho), clamped to [1, n]
  double coverage = 1;                 // the window's share of the measured envelope's displacement range
  // The widest stretch of the window with no measured envelope point inside (m), and the simulated
  // envelope points inside it: there the measurement is a straight line between its two ends.
  double gap_lower = 0, gap_upper = 0;
  int simulated_in_gap = 0;
  std::size_t measured_rows = 0, simulated_rows = 0;  // of the two curves as recorded (finite rows)
  double gap_share() const;            // the gap's share of the window, in [0, 1]

  std::vector<double> residual() const;  // measured - simulated
  nlohmann::json to_json() const;        // the numbers, not the arrays
};

// Residual of one channel on the objective's grid (`points` over its window); throws
// smoothing::CurveError when a series has fewer than two envelope points or the window is empty.
ChannelResidual analyse_channel(const smoothing::XYSeries& measured, const smoothing::XYSeries& simulated,
                                int points, smoothing::ObjectiveWindow window = smoothing::ObjectiveWindow::common);

// Recomputes a residual's statistics (bias, trend, rms, regions, autocorrelation, effective
// points) from its displacement, measured and simulated arrays; keeps its noise.
void complete_residual(ChannelResidual& residual);

// The grid, measured values, noise and measured gap of `base` with another simulated curve
// interpolated on it (clamped to its end values outside its range), so that two fits compare point
// by point; its simulated points in the gap are its own.
ChannelResidual resimulated(const ChannelResidual& base, const smoothing::XYSeries& simulated);

// Standard deviation of the noise on a measured curve, from the data alone: the loading envelope's
// local three-point pseudo-residuals (Gasser, Sroka and Jennen-Steinmetz 1986; exact for any
// locally linear trend, valid for uneven spacing), scaled by 1.4826 x their median absolute value so
// that isolated drops do not count. NaN when the envelope has fewer than three points.
double estimate_noise(const smoothing::XYSeries& measured);

// Lag-1 autocorrelation of a sequence about its mean (0 for fewer than 3 values or no variance).
double lag1_autocorrelation(const std::vector<double>& values);

// ---- evidence ---------------------------------------------------------------------------------

// Change of the Bayesian information criterion from a base fit to an extended one, both measured on
// the same channels: sum_c n_eff,c ln(RSS_ext,c / RSS_base,c) + extra_parameters ln(sum_c n_eff,c),
// with each RSS (mean square) floored at the channel's noise variance: a channel fitted within its
// noise counts as at the noise, so moving about inside it is neither evidence for nor against a
// model. n_eff,c: `effective_points` (one per channel, as common_effective_points gives them), or
// when that is empty the extended fit's own. Negative = evidence for the extension; below -10 is
// "very strong" on the usual scale (Kass and Raftery 1995).
double information_criterion_change(const std::vector<ChannelResidual>& base,
                                    const std::vector<ChannelResidual>& extended, int extra_parameters,
                                    const std::vector<double>& effective_points = {});

// The removal check of the effects added to a model: for each effect i, `without[i]` is the fit of
// the model with the other effects (none: the base), calibrated again without it (empty where that
// fit failed), and `parameters[i]` its parameter count. Returns each effect's criterion change from
// `without[i]` to `with_all` (information_criterion_change, every fit counted with the
// common_effective_points of them all; NaN for an empty fit, an effect that is then kept), and sets
// `drop` to the effect whose removal costs least among those no longer needed, else -1. An effect
// is no longer needed when its change does not fall by more than `evidence` (it no longer pays for
// its parameters), or when the fit without it is explained: its overall RMS error at most
// `explained` (N; the loop's level, noise_level_ratio x error_floor; 0 = the criterion alone). A
// base fit at that level in step 2 means "no effect needed"; the same fit found by a re-fit says the
// same, so the verdict does not hang on which search happened to find it.
std::vector<double> removal_criteria(const std::vector<ChannelResidual>& with_all,
                                     const std::vector<std::vector<ChannelResidual>>& without,
                                     const std::vector<int>& parameters, double evidence, int& drop,
                                     double explained = 0);

// The effective points per channel with which the criterion counts every fit of one diagnosis: on
// each channel, those of the fit with the lowest RMS error there among `fits` (each a set of
// residuals on the same channels; sets of another size are skipped). How many independent points
// the data hold is a property of the data, not of a model, so the models compared are counted
// alike: with each fit's own count, a fit that leaves a rougher residual would earn more points and
// could pass with a worse error. The closest fit's residual is the nearest to the noise process; the
// structure it keeps makes the count conservative. `from`, if given, gets each channel's fit index.
std::vector<double> common_effective_points(const std::vector<const std::vector<ChannelResidual>*>& fits,
                                            std::vector<int>* from = nullptr);

// Share of the residual r that the base parameters' sensitivities J cannot remove and the effect's
// signatures S (its curve changes at a few magnitudes) can, with non-negative weights on S (an
// effect acts in one direction): 1 - min_{w >= 0} |r' - S' w|^2 / |r'|^2, where r' and S' are r and
// S with J's span projected out. 0 when S pushes the curve only the wrong way. All vectors of one
// length; at most 12 signatures.
double signature_score(const std::vector<double>& residual, const std::vector<std::vector<double>>& base_sensitivities,
                       const std::vector<std::vector<double>>& signatures);

// Where the signature probes, taken as linear, say the residual is explained: the fractions of
// each effect parameter's search range (clipped to [0, 1]). `probes` are the curve changes of the
// probe runs in probe order (every parameter at mid-range, then parameter i at fraction `strong`
// and at `mild` with the others at mid-range, i = 0..parameters-1), stacked like `residual`; each
// parameter's change is the difference of its two probes over their fractions' distance, and the
// base parameters' sensitivities are free in the least-squares fit too. Empty when a probe is
// missing or a column differs in length. The diagnosis runs this point as one probe more, a start
// for the candidate's search when it fits better than every probe.
std::vector<double> linearised_fractions(const std::vector<double>& residual,
                                         const std::vector<std::vector<double>>& base_sensitivities,
                                         const std::vector<std::vector<double>>& probes, std::size_t parameters,
                                         double strong, double mild);

// A search of an effect's simplest form where its search range only comes close to it
// (dem::EffectParameter::simplest_form_at_max: a crushing cap's softening, whose top of range is
// the nearest to a perfectly plastic cap). That form has one parameter fewer, and its valley can be
// narrower than the signature probes' spacing (the reference arch's 0.5 MPa cap: met at 0.51-0.53
// MPa, in a 57-fold range probed 3.4-fold apart), so it is searched on its own: with such a
// parameter at fraction 1 of its range and the others mid-range, each other parameter in turn is
// run at the probe fractions 0.2, 0.5 and 0.8, then narrowed by `refinements` golden-section steps
// inside the bracket around the best of the three (within [0, 1]). `error` runs a point (fractions
// of each parameter's range) and returns its error (NaN or infinity: a failed run). The diagnosis
// runs it after the signature probes, as starts for the candidate's search, not as signatures.
// Returns every point run, in order; none for an effect without such a parameter.
std::vector<std::vector<double>> search_simplest_form(const std::vector<dem::EffectParameter>& parameters,
                                                      const std::function<double(const std::vector<double>&)>& error,
                                                      int refinements);

// How tightly the data pin one effect parameter of an accepted (or tied) fit. The parameter is
// moved from the best by factors 1/10, 1/3, 3 and 10 when log-scaled, by -0.3, -0.1, +0.1 and +0.3
// of its search range when linear, within the search range. A tried value is ruled out when the
// information criterion (as in information_criterion_change, no extra parameter) rises by more than
// `threshold` over the best, with every other free parameter re-fitted at that value (a profile):
// the diagnosis uses its evidence, so the data must prefer the best over a value by as
// much as they must prefer an effect over the base model. A value is first run with the others at
// the best (the conditional change); only one that this rules out is re-fitted, since a re-fit can
// only lower the change. Without the re-fit, parameters that trade off (a softer support against a
// lower friction) would rule out values that fit as well once the others follow.
struct ParameterBound {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  std::string name;                                // set_parameter name
  double best = kNaN;
  double lower = kNaN;   // the ruled-out tried value nearest below the best (NaN: none below is)
  double upper = kNaN;   // the ruled-out tried value nearest above the best (NaN: none above is)
  std::vector<std::pair<double, double>> trials;   // (value, criterion change against the best), by value
  std::vector<double> refitted;                    // tried values whose change is after re-fitting the others
  bool bounded() const { return std::isfinite(lower) && std::isfinite(upper); }
  std::string describe() const;                    // one phrase, e.g. "beam_kr 3.4e+07: not bounded above (...)"
  nlohmann::json to_json() const;  // {"best", "lower", "upper" (null: not bounded), "trials", "refitted"}
};

// The bound from trials (value, criterion change; a NaN change = a failed run, ignored).
ParameterBound bound_from_trials(const std::string& name, double best, std::vector<std::pair<double, double>> trials,
                                 double threshold);

// The profile bound from tried `values`: `conditional(v)` is the change with the others at the
// best, `refitted(v)` the change with them re-fitted (NaN: no re-fit, e.g. over the budget or a
// failed run; the conditional change then stands and the value is not listed as re-fitted). On
// each side the values the conditional change rules out are re-fitted from the nearest outward,
// until one stays ruled out; those farther out keep their conditional change.
ParameterBound profile_bound(const std::string& name, double best, const std::vector<double>& values,
                             const std::function<double(double)>& conditional,
                             const std::function<double(double)>& refitted, double threshold);

// ---- the loop ----------------------------------------------------------------------------------

// Options of run_diagnosis, each named as its flag of `demcal diagnose` (docs/commands/diagnose.md
// has the table; docs/diagnose.md says why each default is what it is). Counts are simulations.
constexpr int kMaxResamples = 100000;  // DiagnoseOptions::resamples at most: each takes the selection again

struct DiagnoseOptions {
  std::string out = "diagnosis";      // --out: folder of diagnosis.json, report.md, base/, candidates/
  std::vector<std::string> effects;   // --effects: names to consider; empty = every registered effect
  std::string result;                 // --result: a finished base calibration (folder or result.json); "" = run one
  // --max-simulations: budget of the whole diagnosis: the base (at most half, when it runs), the
  // refinement (at most a quarter of the rest) and the candidates, each cut to what is left; the
  // signature probes come on top. 0 = the campaign's budget for the base and
  // `candidate_simulations` for each of the others.
  long max_simulations = 0;
  int candidates = 3;                 // --candidates: effects calibrated at most, best signature first, >= 1
  // --candidates-at-split: effects calibrated at most where the base fit's re-runs scatter by more
  // than scatter_floor_ratio x the noise (response_splits): there a signature is a difference of
  // single runs and ranks effects by realisation as much as by shape. 0: every effect; else >= candidates.
  int candidates_at_split = 0;
  // --candidate-simulations: per candidate calibration (and the base refinement); 0 = the campaign's.
  // 80 whatever the campaign's budget: a candidate searches more parameters than the base, from a
  // base fit whose compensation for the missing effect can lie far from the extended model's
  // valley (measured: docs/diagnose.md, step 4).
  int candidate_simulations = 80;
  // --close-target-share: an effect with several targets (a gap at each hinge, springs at either
  // support) is calibrated at its best-signature target and at every other target whose signature
  // explains at least this share of the best one's; the lower error is kept. In (0, 1].
  double close_target_share = 0.9;
  // --close-candidate-share: an effect ranked below the `candidates` tried is calibrated too when
  // its signature explains at least this share of the last tried one's. In (0, 1].
  double close_candidate_share = 0.9;
  double evidence = 10;               // --evidence: accept when the criterion falls by more than this, > 0
  double tie_margin = 6;              // --tie-margin: effects whose criteria are closer are tied, >= 0
  double noise_level_ratio = 1.25;    // base RMS / error floor at or below this: nothing to explain, >= 1
  // --scatter-runs: re-runs of the base best (and of each candidate's best) with every free
  // parameter moved by k x 1e-7 of itself, k = 1..n: the simulation's own scatter, since stick-slip
  // events fall at other moments for sets that differ by far less than anything physical. Each fit
  // is judged on the run of median error. 0 = none.
  int scatter_runs = 2;
  // --scatter-floor-ratio: the scatter counts in the error floor (error_floor) up to this x the
  // noise, > 0 (infinity: all of it); counted in full, a base fit where the response splits would
  // excuse any misfit.
  double scatter_floor_ratio = 1;
  // Base parameters in each candidate calibration: log-scaled ones within best x/÷ narrow_log_factor
  // (> 1), linear ones within best ± narrow_linear_share (in (0, 1]) of their range. Both 0 (the
  // default): the campaign's own bounds, since base parameters that compensate for a missing
  // effect can lie far from where the extended model needs them.
  double narrow_log_factor = 0;
  double narrow_linear_share = 0;
  // --candidate-algorithm: optimiser of each candidate calibration and of the base refinement: "bo"
  // (Bayesian optimisation on the surrogate), "nlopt:NAME" (local, from the base best with the
  // effect at its best probe; first step `candidate_initial_step` in unit-cube lengths, in
  // (0, 0.5]) or a swarm ("tbpso", "pso", "ga") over the box.
  std::string candidate_algorithm = "bo";
  double candidate_initial_step = 0.1;
  // --candidate-starts: points of each candidate's search design ("bo") that start from a base
  // fit, >= 1: the base best, then the best base sets of other regions (further_start_sets, at
  // least `start_separation` apart in the unit cube of the base parameters, in (0, 1]). Where the
  // base objective is flat along a parameter, its best set is one of many the data allow, each
  // compensating for the missing effect differently; the extended model's valley may lie beside
  // another of them.
  int candidate_starts = 3;
  double start_separation = 0.25;
  // --surrogate-kind: "gp" | "mlp", whatever the campaign's. "mlp" models the curves, so its
  // searches find the narrow valley a change of mechanism makes in the objective.
  std::string surrogate_kind = "mlp";
  // --surrogate-backend: how the "mlp" kind's ensemble is trained in every calibration and search
  // of the diagnosis, whatever the campaign's: "libtorch" (the training every measured table of
  // docs/diagnose.md was made with, which the diagnosis keeps) or "native" (the campaign default;
  // smoothing/regression_ensemble.hpp). The two train the same networks to round-off, so each
  // search becomes another realisation of itself.
  std::string surrogate_backend = "libtorch";
  // --held-out: cases left out of every calibration (at least one must stay); channels of weight 0
  // are not fitted either. Those the base fit reproduces (RMS at most `held_out_ratio` x their
  // noise, --held-out-ratio) check the fits: an effect whose fit makes them worse by more than the
  // larger of their noise and `held_out_tolerance` x the base fit's error there is rejected. One
  // the base fit misses is reported, not judged.
  std::vector<std::string> held_out;
  double held_out_tolerance = 0.1;    // share of the base fit's held-out error, >= 0
  double held_out_ratio = 2;          // --held-out-ratio, >= 1
  // --no-parameter-bounds sets false: how tightly the data pin each parameter of an accepted or
  // tied effect (ParameterBound): four runs per parameter, and for each value they rule out a
  // re-fit of the others of at most `profile_simulations` runs (--profile-simulations; 0 = none).
  bool parameter_bounds = true;
  int profile_simulations = 20;
  // --no-removal-check sets false: once the loop stops, each effect added is calibrated again
  // without (the model with the others; the base alone for one, `candidate_simulations` runs each)
  // and dropped when no longer needed (removal_criteria; Diagnosis::removal_checks).
  bool removal_check = true;
  // --no-tentative-effect sets false: where no effect passes alone and the base fit misses the
  // curves (outcome "unexplained"), the candidate of lowest criterion that lowers the error is added
  // tentatively and its model diagnosed again (step 8). When a further effect passes there, both are
  // kept, and the removal check (which it needs: off with --no-removal-check) re-fits each without
  // the other; else the verdict stays "no effect found". Two effects that each explain part of the
  // residual may pass only together: each alone is searched from a base that compensates for both.
  bool tentative_effect = true;
  // --continued-simulations: a further search (ContinuedSearch) of each fit left above the floor
  // where the selection leaves the residual unexplained: the accepted effect, then, while no fit
  // explains the curves, the contenders; and the pair search's calibrated pair (PairSearch).
  // -1: a candidate's budget; 0: none.
  long continued_simulations = -1;
  // --union-rounds: rounds of the union search after the candidates' calibrations (UnionSearch;
  // docs/diagnose.md, step 4): one emulator of the curves over the base parameters and every
  // calibrated candidate's, each candidate's model switched on or off, trained on every run of the
  // diagnosis; each round searches it for every candidate from many starts and simulates the best
  // point of each, and where the workers outnumber the candidates each one's share of them with its
  // next best points (measured: docs/diagnose.md, step 4b). 0: none.
  int union_rounds = 6;
  // --pair-rounds: rounds of the pair search (PairSearch; docs/diagnose.md, step 8) where no effect
  // passes alone and the base fit misses the curves ("no effect found"): the union search's
  // emulator searched with both effects of a pair switched on, within a trust region around the
  // pair's best run, the best point of each pair simulated per round; the closest pair is then
  // calibrated. Needs the removal check (it re-fits each effect of a pair without the other) and
  // --max-effects other than 1. 0: none.
  int pair_rounds = 8;
  // --max-effects: effects added at most. After an effect is accepted the diagnosis starts again
  // from the model with it (its fit the new base, the other effects the candidates), until no
  // further effect passes; 0 = no limit, 1 = one effect per diagnosis.
  int max_effects = 0;
  // --resamples: the selection taken again on this many resamples of the data and of the fits'
  // round-off (verdict_frequency); 0 = none. --verdict-share: a choice (an effect, or none) that
  // fewer than this share of them reach is not the verdict: "undecided", with the shares. In (0, 1];
  // 0.8 within stability selection's usual 0.6-0.9, and between the shares measured for right
  // verdicts (99.5-100 %) and for a second effect fitted at its vanishing point (51.5 %) on the
  // records of another code (docs/diagnose.md).
  int resamples = 200;                // <= kMaxResamples
  double verdict_share = 0.8;
  bool resume = false;                // --resume: continue the calibrations from their archives
  bool progress = true;               // --quiet sets false: progress lines on stderr
  bool report = true;                 // --no-report sets false: report.md with figures
  void Validate() const;              // throws CampaignError naming the flag and value
};

// A further search of a candidate whose fit stayed above the error floor
// (DiagnoseOptions::continued_simulations, candidates_to_search_further).
struct ContinuedSearch {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  long simulations = 0;        // of the further calibration (0: none ran)
  double error_before = kNaN;  // the fit's RMS force error before it, N
  double error_found = kNaN;   // the further search's fit, on the median of its re-runs, N (NaN: it failed)
  bool kept = false;           // that fit replaced the first (a lower error)
  std::string describe(const std::string& effect) const;  // a sentence for the verdict
  nlohmann::json to_json() const;
};

// The union search of a candidate (DiagnoseOptions::union_rounds): the points its rounds proposed
// for the candidate's model, simulated, and the best of them judged as a calibration's fit is.
struct UnionSearch {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  int rounds = 0;              // rounds that proposed a point for this candidate (0: none ran)
  long simulations = 0;        // its proposals and the best one's re-runs
  long training_rows = 0;      // runs the emulator of its last round was trained on, every model's
  double error_before = kNaN;  // the candidate's fit before, N
  double error_found = kNaN;   // the best proposal, on the median of its re-runs, N (NaN: none ran)
  bool kept = false;           // that fit replaced the calibration's (a lower error)
  std::string describe(const std::string& effect) const;  // a sentence for the report
  nlohmann::json to_json() const;
};

// The pair search (DiagnoseOptions::pair_rounds): two effects that each explain part of the residual
// may pass only together, since each alone is searched from a base fit that compensates for both.
// Every pair of calibrated candidates (each effect at its kept target), and the lead of the
// residual (unexplained_lead) with every effect probed but not calibrated and with other targets
// of each effect (the two whose probes came closest; the lead's effect at those targets paired
// with every effect at its own: the lead's target was chosen on a compensating base), is searched on one
// emulator of the curves over the base parameters and the effects' (the union search's, its rows
// grown by the pairs' runs) with both switched on, within a trust region around the pair's best
// run; the pairs whose best run beats their calibrated effects' fits are judged on the median of
// their re-runs (the closest of them calibrated first, as a candidate is, from its best run), and
// the one of lowest criterion against the base (both effects' parameters counted) is added when
// that criterion passes and enough resamples agree.
struct PairSearch {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  struct Pair {
    std::vector<std::string> effects;  // the two, in the candidates' order
    std::vector<std::string> targets;  // each one's target ("" where the effect has none)
    double best_run_error = kNaN;      // the best of its proposals (a single run), N
    double error = kNaN;               // judged: the median of its best set's runs, N (NaN: not judged)
    double criterion = kNaN;           // judged: against the base, both effects' parameters counted
    bool calibrated = false;           // the closest pair: calibrated as a candidate is, from its best run
    bool continued = false;            // the calibrated pair's search continued, its fit above the floor
  };
  int rounds = 0;                        // rounds run (0: the search did not run)
  long simulations = 0;                  // every proposal and the judged sets' re-runs
  std::vector<Pair> pairs;
  // The pair of lowest criterion among the judged ones that lower the error without spoiling
  // held-out data (empty: none): its fit, and whether it was added.
  std::vector<std::string> effects;
  std::map<std::string, double> params;  // its best set, every parameter of the model with both
  std::vector<double> rerun_errors;
  double error = kNaN;                   // N, the median run
  double criterion = kNaN;
  double frequency = kNaN;               // share of resamples in which it passes (pair_frequency)
  bool accepted = false;
  nlohmann::json to_json() const;
};

// What a diagnosis concluded (Diagnosis::outcome; diagnosis.json writes it by name).
enum class DiagnosisOutcome {
  no_effect_needed,  // the base fit is within the noise, or no effect is worth its parameters there
  missing_effect,    // one effect accepted: Diagnosis::chosen
  undecided,         // effects tied: the data cannot tell which is missing
  unexplained,       // the base fit misses by far more than the noise and no effect tried explains it
};
std::string to_string(DiagnosisOutcome outcome);  // "no_effect_needed" | "missing_effect" | ...

// What the selection concluded for one candidate effect (diagnosis.json writes it by name).
enum class CandidateVerdict {
  not_tried,  // not calibrated: ranked out, over the budget, or nothing to explain
  accepted,   // its criterion falls by more than the evidence threshold, and no rival ties it
  rejected,   // short of the criterion, spoils held-out data, or clearly behind an accepted one
  tied,       // the data cannot tell it from another effect
};
std::string to_string(CandidateVerdict verdict);  // "not tried" | "accepted" | "rejected" | "tied"

struct EffectCandidate {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  std::string effect;                      // dem effect name
  std::string target;                      // what it was switched on for ("" = the effect's default)
  double signature_score = 0;              // in [0, 1], see signature_score()
  bool tried = false;                      // calibrated (else ranked out or over budget)
  std::map<std::string, double> params;    // best set of the extended calibration (base + effect)
  double fitness = kNaN;                   // the campaign objective of that set
  std::map<std::string, double> rms;       // "<case>/<channel>" -> RMS force error, N
  double error = kNaN;                     // RMS force error over all channels, N
  // Other targets calibrated because their signatures came close (DiagnoseOptions::close_target_share):
  // each one's signature share and fit; the fit above is the best of them and `target`.
  struct OtherTarget {
    std::string target;
    double signature_score = 0;
    double error = kNaN;                   // RMS force error of its fit (median run), N
    long simulations = 0;
  };
  std::vector<OtherTarget> other_targets;
  // The overall error of the best set and of its re-runs with the parameters moved by k x 1e-7
  // (DiagnoseOptions::scatter_runs); rms, error, score and residuals are those of the median run.
  std::vector<double> rerun_errors;
  int effect_parameters = 0;               // parameters the effect adds (the criterion's penalty)
  double score = kNaN;                     // information criterion change against the base (< 0 better),
                                           // with the diagnosis's effective_points
  CandidateVerdict verdict = CandidateVerdict::not_tried;
  std::string reason;                      // one line: why this verdict
  long simulations = 0;                    // of its calibration, archived runs included
  std::vector<ChannelResidual> residuals;  // of the best extended set
  // Every run behind rerun_errors (same order): the fitted channels' residuals and the held-out
  // channels' RMS errors, the round-off realisations of verdict_frequency. Not in diagnosis.json.
  std::vector<std::vector<ChannelResidual>> run_residuals;
  std::vector<std::map<std::string, double>> run_held_out_rms;
  std::map<std::string, double> held_out_rms;  // "<case>/<channel>" -> N, on data not fitted
  double held_out_error = kNaN;            // RMS force error over the held-out channels, N
  std::vector<ParameterBound> bounds;      // of the effect's parameters, when accepted or tied
  ContinuedSearch continued;               // when searched further (candidates_to_search_further); the fit above is the kept one
  UnionSearch union_search;                // DiagnoseOptions::union_rounds; the fit above is the kept one
  // effect parameter -> {lowest, highest} value searched: the registry's range, or for a
  // structure-relative one (dem::SearchScale) that of this structure; the calibration's box when
  // the effect was calibrated (a residual friction below the lowest friction searched), else the
  // signature probes' range
  std::map<std::string, std::array<double, 2>> search_ranges;
};

struct Diagnosis {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  CampaignStatus status = CampaignStatus::completed;  // diagnosis.json: "completed" | "failed"
  std::string message;
  std::map<std::string, double> base_params;
  double base_fitness = kNaN;
  // Where the candidates' searches start besides the base best (further_start_sets; diagnosis.json
  // base.further_starts): the best base sets of other regions; of a further step (with an effect
  // added), those of the added effect's searches.
  std::vector<std::map<std::string, double>> further_starts;
  // The fitted channels ("<case>/<channel>" -> share) of which the campaign's window (the paper's)
  // covered less than kNarrowWindow of the measured range at the refined base fit: the diagnosis
  // then refined it again and compared every channel over its measured range from there on
  // (diagnosis.json base.widened_window). Empty: the campaign's window throughout.
  std::map<std::string, double> widened_window;
  std::map<std::string, double> base_rms;  // "<case>/<channel>" -> N
  // The overall error of the base best set and of its re-runs (DiagnoseOptions::scatter_runs); like
  // a candidate, the base is judged on the run of median error: base_rms, base_residuals and
  // error_before are that run's.
  std::vector<double> base_rerun_errors;
  std::map<std::string, double> noise;     // "<case>/<channel>" -> N
  std::map<std::string, double> scatter;   // "<case>/<channel>" -> N, the simulation's own (scatter_runs)
  std::vector<ChannelResidual> base_residuals;
  std::vector<EffectCandidate> candidates; // signature order (best first)
  // The criterion's effective points, "<case>/<channel>" -> n, and the fit they were taken from
  // ("base" or an effect): common_effective_points over the base and every calibrated candidate.
  std::map<std::string, double> effective_points;
  std::map<std::string, std::string> effective_points_from;
  std::vector<std::string> chosen;         // the effects added, in order; [] = none (no effect needed, a tie)
  // One entry per effect added: the first from the base model, each further one from the model
  // with the effects before it (that step's own diagnosis.json and report.md are in `folder`).
  struct AddedEffect {
    std::string effect;
    std::string target;
    std::string parameters;        // "name ≈ value (range)", as in the headline
    double error_before = kNaN;    // N, of the model it was added to
    double error_after = kNaN;     // N, of its fit
    std::string folder;            // "" for the first (this diagnosis's own folder)
    double frequency = kNaN;       // its step's VerdictFrequency::verdict (NaN: added tentatively)
    bool tentative = false;        // added without passing alone (DiagnoseOptions::tentative_effect)
    // Its parameters' bounds (DiagnoseOptions::parameter_bounds): its candidate's, of the step that
    // added it; for one added tentatively, taken in the model with every effect of the diagnosis.
    std::vector<ParameterBound> bounds;
  };
  std::vector<AddedEffect> added;
  // Each effect added, its removal check (removal_criteria): the model with the others (the base
  // alone for one) re-calibrated without it, and the criterion change from that fit to the model
  // with all. An effect no longer needed (its removal costs no evidence, or the fit without it is
  // explained) is dropped again (`dropped`), left out of `chosen`. An undecided verdict gets the same
  // check of its closest fit (the candidate of lowest error): where `dropped`, no effect is needed
  // there (or none found) and the outcome says so.
  struct RemovalCheck {
    std::string effect;
    double criterion = kNaN;      // negative: the effect still pays for its parameters; NaN: no fit
    double error_without = kNaN;  // N, the fit without it
    std::string folder;           // its calibration
    bool dropped = false;
    double explained_level = kNaN;  // N: a fit without it at or below this is explained (removal_criteria)
  };
  std::vector<RemovalCheck> removal_checks;
  PairSearch pair_search;  // DiagnoseOptions::pair_rounds
  DiagnosisOutcome outcome = DiagnosisOutcome::no_effect_needed;
  // The verdict three ways: `headline`, one sentence a person reads first ("Missing:
  // support-compliance at abutment_right: support_kx ≈ 1.83 MN/m (1.2–3.1 MN/m); force error 232 ->
  // 125 N against 44 N of noise."); `conclusion`, the selection's finding in full; `notes`, each
  // further thing the diagnosis saw (a search continued, bounds, a split response, ...); `verdict`,
  // the conclusion and the notes as one text.
  std::string headline;
  std::string conclusion;
  std::vector<std::string> notes;
  std::string verdict;
  // How often the selection reaches the verdict's choice when it is taken again on resamples
  // (verdict_frequency); `resamples` 0 when not measured.
  struct VerdictFrequency {
    long resamples = 0;
    std::map<std::string, double> effects;  // effect -> share of the resamples choosing it
    double none = kNaN;                     // share choosing no effect
    double undecided = kNaN;                // share left undecided (a tie)
    double verdict = kNaN;                  // share reaching the verdict's own choice
    nlohmann::json to_json() const;
  } frequency;
  long advised_candidate_simulations = 0;  // a longer search the verdict advises (0: none; see
                                           // advised_candidate_simulations())
  double error_before = kNaN;              // RMS force error over all channels, N
  double error_after = kNaN;
  double peak_normal_stress = kNaN;        // Pa, largest contact stress of the base best run over the
                                           // fitted cases (scales the compressive strength's range)
  double start_normal_stress = kNaN;       // Pa, the same at the start of loading (its lower end)
  std::map<std::string, double> held_out_rms;  // base fit on the data not fitted, "<case>/<channel>" -> N
  std::map<std::string, double> held_out_noise;
  double held_out_error = kNaN;            // the base fit's RMS force error there, N (NaN: no such data)
  std::vector<std::string> held_out_checked;  // those of its channels that check the fits (held_out_checks)
  // Runs the whole diagnosis evaluated, those its calibrations read from the archive included: a
  // resumed diagnosis reports (and budgets, max_simulations) what an uninterrupted one would.
  long simulations = 0;
  long simulated_this_session = 0;         // of them, run by this process (the rest from the archive)
  double wall_time_s = 0;
  double simulation_time_s = 0;            // this session: waiting for simulations (probes and calibrations)
  double model_time_s = 0;                 // this session: the calibrations' surrogate fits and search
  nlohmann::json to_json() const;          // the diagnosis.json layout
};

// The held-out channels ("<case>/<channel>") that check the fits: those the base fit of `diagnosis`
// reproduces, RMS error at most `options.held_out_ratio` x their noise.
std::vector<std::string> held_out_checks(const Diagnosis& diagnosis, const DiagnoseOptions& options);

// The check on data no fit used, over the held-out channels of held_out_checks().
struct HeldOutCheck {
  int channels = 0;                        // checking channels (0: nothing checks the fits)
  double base_error = Diagnosis::kNaN;     // RMS force error of the base fit over them, N
  double candidate_error = Diagnosis::kNaN;// of the candidate's fit, N (NaN: it no longer reaches them)
  bool spoils = false;                     // worse than the base by more than the larger of their
                                           // noise and options.held_out_tolerance x base_error
};
HeldOutCheck check_held_out(const EffectCandidate& candidate, const Diagnosis& diagnosis, const DiagnoseOptions& options);

// When the diagnosis names no effect: a sentence for its verdict on the held-out channels that the
// base fit misses (not in diagnosis.held_out_checked), with their RMS error against their noise,
// since an effect may show only in data the fits did not use. "" when there are none.
std::string unfitted_data_note(const Diagnosis& diagnosis);

// A sentence for the verdict on the base fit's fitted channels whose window covers less than
// `kNarrowWindow` of the measured range (possible with the paper's window only: the simulated gauge
// stopped short, and a gauge that hardly moves matches there): those of the refined base fit
// (Diagnosis::widened_window), after which the diagnosis compared over the measured window, and
// those of the final base fit, for which it recommends that window. "" when there are none.
constexpr double kNarrowWindow = 0.5;
std::string narrow_window_note(const Diagnosis& diagnosis);

// Whether the base fit's re-runs scatter (overall, N) by more than options.scatter_floor_ratio x the
// noise (N): the fit sits where the model's response splits. False for a NaN scatter (no re-runs).
bool response_splits(double scatter, double noise, const DiagnoseOptions& options);

// How many effects step 4 calibrates at most: options.candidates, or where the base response
// splits options.candidates_at_split (0: every effect), never fewer than candidates.
int candidates_to_calibrate(bool splits, const DiagnoseOptions& options);

// The first point of a candidate's search over `space` (its free parameters, in order): each from
// `warm` (the effect's best probe), else from `best` (the base fit), else the middle of its range
// (an effect none of whose probes could be scored), clipped to the box.
std::vector<double> candidate_start(const optimise::ParameterSpace& space, const std::map<std::string, double>& warm,
                                    const std::map<std::string, double>& best);

// The further starts of a candidate's search (DiagnoseOptions::candidate_starts): of `runs` (the
// base calibrations' sets; those of non-finite fitness or lacking a free parameter left out), in
// order of fitness, each set whose distance in the unit cube of `space`'s free parameters from
// `best` and from every set already taken is at least `separation`; at most `count`.
std::vector<std::map<std::string, double>> further_start_sets(const std::map<std::string, double>& best,
                                                              const std::vector<ParameterSet>& runs,
                                                              const optimise::ParameterSpace& space, int count,
                                                              double separation);

// The space of the union search (DiagnoseOptions::union_rounds): the base parameters (unit values in
// the campaign's bounds), then for each model of a candidate (an effect at its target) a switch and
// that model's own parameters (unit values in the box its calibration searched). A run of the base
// model is the point with every switch at 0; a run of model m has m's switch at 1 and its own
// parameters at their unit values. A model switched off has its parameters at the middle of its
// box: "off" is one point of its block, so that one emulator of the curves over this space learns
// from every model's runs how the base parameters act, and each model's search starts from what
// the others found, the base fit's compensation included or not.
class UnionLayout {
 public:
  explicit UnionLayout(optimise::ParameterSpace base);
  // Adds the model whose calibration searched `space` (the base parameters and its own, which no
  // model added before may share); returns its index.
  int add_model(const optimise::ParameterSpace& space);
  int models() const { return static_cast<int>(blocks_.size()); }
  Eigen::Index dimension() const { return dimension_; }
  // The union point of a set of model `model` (-1: the base model): empty when a free parameter of
  // that model is missing or not finite. Values outside a box are clipped to it.
  Eigen::VectorXd point(int model, const std::map<std::string, double>& params) const;
  // `x` with model `model` switched on (-1: none) and every other off.
  Eigen::VectorXd switched(int model, Eigen::VectorXd x) const;
  // The coordinates of `model`'s own search: the base parameters' and its own (not its switch).
  std::vector<Eigen::Index> coordinates(int model) const;
  // The free parameters of model `model` (-1: the base) at union point `x`, physical, within the
  // box of that model's own space.
  std::map<std::string, double> parameters(int model, const Eigen::VectorXd& x) const;
  // The same for several models switched on together (none: the base), the combination whose
  // effects are all on: `params` must hold every model's own parameters, and the base parameters
  // come back within every such model's box.
  Eigen::VectorXd point(const std::vector<int>& on, const std::map<std::string, double>& params) const;
  Eigen::VectorXd switched(const std::vector<int>& on, Eigen::VectorXd x) const;
  std::vector<Eigen::Index> coordinates(const std::vector<int>& on) const;
  std::map<std::string, double> parameters(const std::vector<int>& on, const Eigen::VectorXd& x) const;

 private:
  struct Block {
    optimise::ParameterSpace space;   // the model's calibration space
    std::vector<std::string> own;     // its parameters the base lacks
    Eigen::Index offset = 0;          // its switch; its own parameters follow
  };
  optimise::ParameterSpace base_;
  std::vector<Block> blocks_;
  Eigen::Index dimension_ = 0;
};

// A sentence for the verdict when the base fit's re-runs scatter by more than
// options.scatter_floor_ratio x the noise: the fit sits where the model's response splits, the
// floor counted that scatter only up to the cap (error_floor), and the candidates were not chosen
// by their signatures (candidates_to_calibrate). "" otherwise.
std::string split_response_note(const Diagnosis& diagnosis, const DiagnoseOptions& options);

// A sentence for the verdict naming the base fit's free parameters within kAtBound (a share of the
// unit cube) of a bound of their calibration range: the data ask for more than the range allows,
// because the range is too narrow or because the parameter stands in for something the base model
// lacks (stiff linear joints for joints that stiffen as they close). "" when there are none.
constexpr double kAtBound = 0.01;
std::string base_at_bound_note(const Diagnosis& diagnosis, const optimise::ParameterSpace& space);

// A sentence for the verdict on the fitted channels whose measurement leaves a gap wider than
// `kSparseGap` of the compared range in which the base fit or a candidate's fit, recorded more
// densely than the measurement (more than `kDenserRecord` x its rows), has at least `kShapeInGap`
// simulated envelope points: a fast event (a slip, a snap) recorded densely by the simulation and at
// two points by the measurement, so that the simulated curve is compared with a straight line there
// and keeps an error no parameter removes (docs/diagnose.md). It names those fits and recommends
// recording the simulation at the measurement's rate. "" when there are none.
constexpr double kSparseGap = 0.25;
constexpr int kShapeInGap = 3;
constexpr double kDenserRecord = 1.5;
std::string sparse_measurement_note(const Diagnosis& diagnosis);

// Step 5, the verdict from the tried candidates (their score, error and held-out errors) and the
// base residuals (their noise): each candidate's verdict and reason, diagnosis.chosen, error_after
// and verdict. Accepted: criterion change below -evidence, error below the base's, and
// the held-out data not spoilt; two accepted within tie_margin are tied, and so are two accepted
// of which the criterion prefers one and the error the other by more than the noise; one accepted
// while a candidate short of the criterion fits the curves better by more than the noise: both
// tied (the criterion would name the worse fit); and so are one accepted and a candidate that
// lowers the error and falls short of its criterion by less than tie_margin. None: "No effect needed", or
// "No effect found" when the base error exceeds kUnexplainedRatio x the noise and scatter combined
// (the model lacks something the candidates do not supply; the closest fit is named, or, where no
// candidate could be fitted, why each was not).
constexpr double kUnexplainedRatio = 2;
void select_effect(Diagnosis& diagnosis, const DiagnoseOptions& options);

// The runs a verdict is resampled over: the base fit's run and re-runs, each one's fitted residuals
// (on the base grid) and held-out RMS errors.
struct FitRuns {
  std::vector<std::vector<ChannelResidual>> residuals;
  std::vector<std::map<std::string, double>> held_out_rms;
};

// How often select_effect reaches each choice when taken again on `options.resamples` resamples,
// each of them: one run drawn for the base fit (`base_runs`) and for every tried candidate
// (EffectCandidate::run_residuals), the round-off a search's best set happens to meet; and one
// moving-block bootstrap of every fitted channel's grid points, shared by all fits, with blocks of
// n / effective points (the diagnosis's, `effective_points`) consecutive points, so that each block
// is about one independent point of the data. Criterion changes are taken with the same effective
// points. A deterministic function of its inputs and `seed`. `resamples` 0 when nothing was tried.
Diagnosis::VerdictFrequency verdict_frequency(const Diagnosis& diagnosis, const FitRuns& base_runs,
                                              const std::vector<double>& effective_points,
                                              const DiagnoseOptions& options, std::uint64_t seed);

// How often a fit of two effects found together (PairSearch) passes against the base on
// `resamples` resamples drawn as verdict_frequency draws them: one of the base fit's runs and one of
// the pair fit's, and one moving-block bootstrap of every channel's grid points. It passes where its
// criterion change (`parameters` of both effects, `effective_points`) falls below -evidence and its
// error below the base's. NaN without runs or resamples. A deterministic function of its inputs.
double pair_frequency(const std::vector<std::vector<ChannelResidual>>& base_runs,
                      const std::vector<std::vector<ChannelResidual>>& pair_runs, int parameters,
                      const std::vector<double>& effective_points, double evidence, int resamples,
                      std::uint64_t seed);

// The verdict when its choice holds in fewer than options.verdict_share of the resamples
// (diagnosis.frequency): "no effect" when at least that share of them choose no effect (needed, or
// found where the base misses by more than kUnexplainedRatio x the floor; the share becomes the
// verdict's); else undecided, every choice with its share named. A tie stays as it is. True when
// the verdict changed.
bool settle_on_frequency(Diagnosis& diagnosis, const DiagnoseOptions& options);

// Step 5b, after select_effect: the candidates whose search goes on (DiagnoseOptions::
// continued_simulations), by name, in the diagnosis's order; called again after each round.
// - An accepted effect whose fit is above the level at which the loop calls a fit explained
//   (noise_level_ratio x error_floor): that effect alone.
// - Then, while no accepted fit is at that level, the contenders above it: the tied candidates
//   (a tie is undecided however close the base fit is), and, where the base fit misses by more
//   than kUnexplainedRatio x the floor, those whose criterion falls by more than
//   evidence without spoiling held-out data (rejected because their error did not
//   fall, or as clearly less good than an accepted fit that itself stayed above the level after
//   its own further search). Each gets the same further budget, so that no effect wins by search
//   effort: the truth of an effect can be a valley its first search missed (docs/diagnose.md).
// - Where there is no such contender, nothing is accepted and the base fit misses by more than
//   kUnexplainedRatio x the floor ("no effect found"): the lead, the candidate tentative_effect
//   would add (lowest criterion among those whose criterion falls and whose error is below the
//   base's), once per step, before any other further search. Its fit is the evidence the verdict
//   and the tentative step rest on.
// A candidate already searched further (continued.simulations > 0) is not named again.
std::vector<std::string> candidates_to_search_further(const Diagnosis& diagnosis, const DiagnoseOptions& options);

// Step 8 where no effect passes (DiagnoseOptions::tentative_effect): the effect added tentatively,
// the tried candidate of lowest criterion among those whose criterion falls and whose fit lowers the
// error without spoiling the held-out data; "" when none does, when the outcome is not
// "unexplained" (no effect needed: nothing to look for; a tie: the data already disagree) or when
// the options rule it out (tentative_effect or removal_check off, max_effects 1).
std::string tentative_effect(const Diagnosis& diagnosis, const DiagnoseOptions& options);
// Where the effect added tentatively (`first`) is kept beside a further effect: the conclusion,
// the first step's "No effect found: ...", which would contradict the headline, replaced by what
// the step did ("No effect passed alone (...); <effect> ... was added tentatively ..."), and the
// verdict (the conclusion, then the notes) with it.
void conclude_tentative(Diagnosis& diagnosis, const EffectCandidate& first);
// Where the removal check leaves the base model alone (every effect added dropped, or an undecided
// verdict's closest fit no longer needed; the re-fit's error already in error_after, N): the
// outcome, "no effect found" above kUnexplainedRatio x `floor` (N) and "no effect needed" below; the
// conclusion, the outcome's words and `settled` (what the check found, "the base model re-fitted
// ... reaches 43.3 N, so ..."), in place of the selection's, which becomes the first note ("Before
// the removal check: ..."), and the verdict with them; frequency.verdict the share of
// the resamples choosing no effect; and, "no effect needed" being a settled verdict, no advice of a
// longer search (the note more_search_note gave with `per_candidate` taken back, the number 0).
void conclude_on_base_alone(Diagnosis& diagnosis, const std::string& settled, double floor, long per_candidate);

// A sentence for the verdict when the chosen effect's fit, after any further search, still misses
// the curves by more than the level at which the loop calls a fit explained (noise_level_ratio x
// error_floor): the effect explains part of the residual, not all of it, and the closest other fit
// is named with its error and criterion (a joint gap can be imitated by a compliant support whose
// fit stays above that level). "" otherwise.
std::string unexplained_fit_note(const Diagnosis& diagnosis, const DiagnoseOptions& options);

// The simulations of each candidate calibration and of the base refinement: options.candidate_simulations,
// or where that is 0 the campaign's own budget (its optimiser's evaluation_budget()).
long candidate_budget(const DiagnoseOptions& options, const CampaignConfig& config);

// The simulations per candidate a further diagnosis should get when this one leaves the question
// open (no effect found: the base misses by more than kUnexplainedRatio x the floor and no
// candidate is accepted; a tie; or a chosen fit above the explained level): twice `per_candidate`.
// A longer search can reach a valley a shorter one missed (docs/diagnose.md). 0 when the verdict
// is settled.
long advised_candidate_simulations(const Diagnosis& diagnosis, const DiagnoseOptions& options, long per_candidate);

// The verdict's sentence advising that further diagnosis ("" when `advised` is 0).
std::string more_search_note(long advised, long per_candidate);

// What no model can remove (N): the hypotenuse of the measurement noise and the simulation's own
// scatter, the scatter counted up to options.scatter_floor_ratio x the noise (a NaN scatter: none).
// Step 2's "nothing to explain" test and step 5's "No effect found" both measure against it.
double error_floor(double noise, double scatter, const DiagnoseOptions& options);

// The verdict in one sentence (Diagnosis::headline) from the outcome, the chosen fit with its
// parameters in engineering units and their bounds where checked, the errors, the noise and the
// simulation's scatter (NaN: not measured), all N.
std::string verdict_headline(const Diagnosis& diagnosis, double noise, double scatter);

// Runs the loop on a campaign (the same file `demcal calibrate` takes). Throws CampaignError for
// bad input found before the first simulation; failed candidate calibrations become "rejected"
// candidates with a reason, and the diagnosis goes on.
Diagnosis run_diagnosis(const CampaignConfig& config, const DiagnoseOptions& options);

}  // namespace demcal::pipelines
