// Objective functions 1 and 2 (paper eqs. 16–20): the misfit between a measured and a simulated
// curve, summed over channels.
//
// Channel convention (both files): one column named `force_column` ("force"); every other column,
// except those in `ignored_columns` ("time"), is a displacement. The channels are the displacement
// columns present in both curves (an error if there is none). Fitness is in the files' force unit.
//
// Objective 1, per channel c (force F against displacement w):
//   1. each curve is reduced to its loading envelope (rows with NaN in w or F dropped; a point is
//      kept only where w exceeds every earlier w, and a point at the same w as the last kept point
//      replaces it, so the latest force at a repeated displacement counts). Unloading, cycles and
//      snap-back therefore do not enter the fitness: the monotonic loading branch is compared.
//   2. window (ObjectiveWindow): `common` (the paper's eqs. 16–17, the default): lower = max(min
//      w_exp, min w_sim), upper = min(max w_exp, max w_sim); error if upper <= lower (the curves
//      share no displacement range). `measured`: [min w_exp, max w_exp], the simulated envelope held
//      at its end forces where it does not reach. With `common`, a simulated gauge that hardly moves
//      shrinks its channel's window to a sliver of the measured range, over which it matches: a fit
//      that keeps a gauge still scores near zero on that gauge (docs/smoothing.md). With `measured`,
//      a simulated gauge that never passes its first reading (it moved only against the loading
//      direction: an abutment pushed back) has a one-point envelope and is scored as holding that
//      point's force over the whole window; with `common` such a channel has no window (an error).
//   3. `points` (200) evenly spaced w in [lower, upper], both ends included; F_exp and F_sim
//      linearly interpolated there.
//   4. f_c = sqrt(sum_k (F_exp,k - F_sim,k)^2).
// fitness = sum_c weight_c f_c (weights default to 1).
// Objective 2 is objective 1 applied to the neural smoother's 200-point fits of both curves
// (smoother.hpp); the measured curves are smoothed once when an Objective2 is built.
#pragma once

#include "demcal/smoothing/curve.hpp"
#include "demcal/smoothing/smoother.hpp"

#include <map>
#include <string>
#include <vector>

namespace demcal::smoothing {

// The displacement window of each channel (step 2 above).
enum class ObjectiveWindow {
  common,    // the range both loading envelopes share (paper, eqs. 16–17)
  measured,  // the measured envelope's range; the simulation held at its end forces beyond its own
};
std::string to_string(ObjectiveWindow window);
// "common" or "measured"; throws std::invalid_argument naming the value otherwise.
ObjectiveWindow parse_objective_window(const std::string& name);

struct ObjectiveOptions {
  int points = 200;                                   // evaluation points per channel, >= 2
  ObjectiveWindow window = ObjectiveWindow::common;
  std::map<std::string, double> channel_weights;      // per displacement column; absent = 1, >= 0
  std::string force_column = "force";
  std::vector<std::string> ignored_columns = {"time"};  // neither force nor displacement
  // Throws std::invalid_argument naming the bad field and value.
  void Validate() const;
};

struct FitnessResult {
  double fitness = 0;                        // weighted sum of the channel values
  std::map<std::string, double> channels;    // unweighted f_c per displacement column
};

// Displacement columns of a curve under the convention above (file order). Throws CurveError if
// the force column is missing.
std::vector<std::string> displacement_columns(const Curve& curve, const ObjectiveOptions& options);
// Displacement columns present in both curves (experiment's order). Throws CurveError naming both
// files and their columns when there is none in common.
std::vector<std::string> common_channels(const Curve& experiment, const Curve& simulation,
                                         const ObjectiveOptions& options);

// The loading envelope of step 1: strictly increasing x, NaN rows dropped.
XYSeries loading_envelope(const XYSeries& series);
// Linear interpolation of a strictly increasing series at x (clamped to the end values outside).
double interpolate(const XYSeries& envelope, double x);

// Step 2's window [lower, upper] of two loading envelopes. A one-point simulated envelope (a gauge
// that never passed its first reading) shares no range with the measurement and gets the measured
// window under either choice, held at that point's force. Throws CurveError (naming `label`) when
// the window is empty (with `common`: the ranges do not overlap).
std::pair<double, double> objective_window(const XYSeries& experiment_envelope, const XYSeries& simulation_envelope,
                                           ObjectiveWindow window, const std::string& label = "channel");

// f_c of one channel from two series (steps 1–4). Throws CurveError (naming `label`) when the
// experiment has fewer than 2 envelope points, the simulation none, or the window is empty.
double channel_misfit(const XYSeries& experiment, const XYSeries& simulation, int points,
                      const std::string& label = "channel", ObjectiveWindow window = ObjectiveWindow::common);
// channel_misfit of two series that are loading envelopes already (loading_envelope's output:
// strictly increasing x, finite): the same value, without enveloping them again. A caller that
// compares many simulated series with one measured series envelopes the measured one once.
double envelope_misfit(const XYSeries& experiment_envelope, const XYSeries& simulation_envelope, int points,
                       const std::string& label = "channel", ObjectiveWindow window = ObjectiveWindow::common);

// The largest displacement of each displacement column's loading envelope (column -> x); columns
// with fewer than 2 envelope points are left out.
std::map<std::string, double> envelope_ends(const Curve& curve, const ObjectiveOptions& options = {});

// A curve that stops before the end of the test because the structure collapsed, continued at zero
// force: it carries nothing after its collapse. Two rows are appended: every displacement column at
// its largest value so far (the envelope's last point, whose force is replaced by 0: a step), then
// at `ends` (the measured curve's envelope ends) where those lie further. Without it the window of
// step 2 shrinks to what the run reached, and a run that collapses at once scores well.
Curve continued_after_collapse(const Curve& simulation, const std::map<std::string, double>& ends,
                               const ObjectiveOptions& options = {});

// Objective 1 (eqs. 16–20). Throws CurveError on missing force column, no common channel, a weight
// naming no common channel, non-overlapping windows.
FitnessResult objective1(const Curve& experiment, const Curve& simulation,
                         const ObjectiveOptions& options = {});

// Objective 2 with the measured curves smoothed once, in the constructor.
class Objective2 {
 public:
  Objective2(const Curve& experiment, ObjectiveOptions objective = {}, SmootherOptions smoother = {});

  // Smooths the simulation's channels (one batched training pass) and applies objective 1.
  FitnessResult evaluate(const Curve& simulation) const;
  // All simulations' channels in ONE batched training pass (e.g. ten particles x two channels).
  std::vector<FitnessResult> evaluate_batch(const std::vector<Curve>& simulations) const;

  // The smoothed measured curve of each displacement column of the experiment.
  const std::map<std::string, XYSeries>& smoothed_experiment() const { return smoothed_experiment_; }
  // The smoothed channels of a simulation, as evaluate uses them (for plots and reports).
  std::map<std::string, XYSeries> smooth_simulation(const Curve& simulation) const;
  const ObjectiveOptions& objective_options() const { return objective_; }
  const SmootherOptions& smoother_options() const { return smoother_; }

 private:
  ObjectiveOptions objective_;
  SmootherOptions smoother_;
  Curve experiment_;  // columns only, for channel matching and messages
  std::map<std::string, XYSeries> smoothed_experiment_;
};

}  // namespace demcal::smoothing
