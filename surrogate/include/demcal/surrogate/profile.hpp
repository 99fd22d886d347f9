// Profiles of the fitness on an emulator: for each coordinate of the optimiser's unit cube, the
// smallest fitness reachable with that coordinate held at a value, the others free. What a
// calibration reports as "the range of values that fit within the noise band" (pipelines/,
// Identifiability in campaign.hpp) comes from these profiles, not only from the sets the optimiser
// happened to evaluate (a converged swarm samples a small cluster of a long valley).
//
// Method (profile_fitness):
//   1. Emulator: a GaussianProcess (gaussian_process.hpp) on the finite rows (distinct points; at
//      most max_training_rows, chosen by select_training_rows), on log fitness by default (the band
//      is relative, and the arch's fitness spans decades).
//   2. For each coordinate k and each of grid_points values v uniform in [0, 1] (a log-scaled
//      parameter is therefore uniform in its logarithm): the emulator's mean minimised over the other
//      coordinates with coordinate k held at v, by NLopt LN_BOBYQA from several starts: the optimum
//      at the neighbouring grid value (the grid is swept outwards from the best row, so a valley is
//      followed), the best distinct rows with coordinate k moved to v, and seeded uniform points.
//   3. The threshold: reference x (1 + relative_band), the reference being the larger of the best
//      finite fitness and the emulator's smallest predicted fitness. The emulator's mean is a
//      smoothed fitness (its nugget absorbs objective 2's stick-slip jumps); the best row is the
//      luckiest draw of those jumps, so comparing the smooth profile with it would shrink the band.
//   4. Profile range: the hull of the grid values whose profile is within the threshold, widened
//      to the linearly interpolated crossings with the neighbouring grid values outside it. The
//      reported range is the hull of the profile range and the range over the rows within the band
//      (best x (1 + relative_band)), so it is never narrower than the evaluated range.
// With fewer than min_rows distinct finite rows (or when the emulator cannot be fitted) only the
// evaluated ranges are given (status too_few_rows / emulator_failed, reported = evaluated).
//
// A pure function of the rows, the band and the options: same input, same output (the wall times
// excepted). Single-threaded. Everything is in unit-cube coordinates; the caller maps them with
// optimise::ParameterSpace.
#pragma once

#include "demcal/surrogate/gaussian_process.hpp"
#include "demcal/surrogate/surrogate.hpp"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace demcal::surrogate {

// Campaign key "identifiability": {"profile": {...}} (docs/pipelines.md, "Identifiability").
struct ProfileOptions {
  bool enabled = true;               // false: the evaluated ranges only (no emulator)
  int grid_points = 41;              // values per coordinate, uniform over [0, 1] (both ends
                                     // included; 41 = steps of 1/40 of the range), >= 3
  int projected_starts = 5;          // best distinct rows, moved onto the grid value, as starts, >= 0
  int random_starts = 3;             // seeded uniform starts per grid value, >= 0
  int local_evaluations = 60;        // emulator evaluations per local search (LN_BOBYQA), >= 5
  int min_rows = 10;                 // distinct finite rows needed to train the emulator, >= 3
  int max_training_rows = 400;       // rows the emulator keeps (select_training_rows), >= 10
  std::uint64_t seed = 1;            // the random starts' stream
  // The emulator's options. log_transform "always" by default: log fitness (falls back to the
  // fitness itself when a fitness is <= 0); "auto" lets leave-one-out choose, as the surrogate does.
  GpOptions gp = [] {
    GpOptions o;
    o.log_transform = LogTransform::always;
    return o;
  }();
  // Throws std::invalid_argument naming the option and value.
  void Validate() const;
  nlohmann::json to_json() const;
  static ProfileOptions from_json(const nlohmann::json& json, const std::string& where);
};

enum class ProfileStatus {
  profiled,          // ranges from the emulator's profiles, joined with the evaluated ranges
  disabled,          // options.enabled is false: evaluated ranges only
  too_few_rows,      // fewer than min_rows distinct finite rows: evaluated ranges only
  emulator_failed,   // the emulator could not be fitted (message says why): evaluated ranges only
  no_finite_rows,    // nothing to report
};
std::string to_string(ProfileStatus status);

// One coordinate. All positions are unit-cube coordinates in [0, 1].
struct CoordinateProfile {
  double best = 0;                   // coordinate of the best finite row
  double evaluated_min = 0;          // over the distinct rows within best x (1 + relative_band)
  double evaluated_max = 0;
  // Where the profile is within the threshold (interpolated crossings); NaN when not profiled.
  double profile_min = std::numeric_limits<double>::quiet_NaN();
  double profile_max = std::numeric_limits<double>::quiet_NaN();
  double min = 0, max = 0;           // reported: hull of the evaluated and the profile ranges
  std::vector<double> grid;          // the grid values (empty when not profiled)
  std::vector<double> fitness;       // the profile at each grid value: the emulator's smallest
                                     // predicted fitness (fitness units, the median for a log model)
  std::vector<double> sd;            // the emulator's latent standard deviation there (model space:
                                     // log fitness for a log model), how far to trust the value
  std::vector<Eigen::VectorXd> argmin;  // where that minimum was found (whole unit point)
};

struct ProfileResult {
  ProfileStatus status = ProfileStatus::no_finite_rows;
  std::string message;               // why the profile is missing, else ""
  long finite_rows = 0;              // distinct points with a finite fitness
  long training_rows = 0;            // rows the emulator was trained on
  long rows_in_band = 0;             // distinct rows within best x (1 + relative_band)
  double relative_band = 0;
  double best_fitness = std::numeric_limits<double>::quiet_NaN();     // smallest finite fitness
  double band_fitness = std::numeric_limits<double>::quiet_NaN();     // best x (1 + relative_band)
  double emulator_minimum = std::numeric_limits<double>::quiet_NaN(); // smallest profile value
  double emulator_at_best = std::numeric_limits<double>::quiet_NaN(); // prediction at the best row
  double threshold = std::numeric_limits<double>::quiet_NaN();  // max(best, emulator_minimum) x (1 + band)
  bool log_transformed = false;      // the emulator models log fitness
  double loo_relative_error = std::numeric_limits<double>::quiet_NaN();  // GaussianProcess::leave_one_out
  double noise_sd = std::numeric_limits<double>::quiet_NaN();  // the emulator's nugget, model space
  Eigen::VectorXd length_scales;     // the emulator's, unit-cube lengths
  long emulator_evaluations = 0;     // predictions made by the profile searches
  double fit_seconds = 0;            // wall time of the emulator fit (differs run to run)
  double profile_seconds = 0;        // wall time of the profile searches (differs run to run)
  std::vector<CoordinateProfile> coordinates;  // one per coordinate of the rows' points
};

// Rows: unit-cube points (all of one dimension d >= 1) and their fitness (non-finite = failed run,
// ignored; a repeated point counts once, with its smallest fitness). relative_band >= 0. Throws
// std::invalid_argument for mismatched dimensions, a negative band or invalid options.
ProfileResult profile_fitness(const std::vector<TrainingRow>& rows, double relative_band,
                              const ProfileOptions& options = {});

}  // namespace demcal::surrogate
