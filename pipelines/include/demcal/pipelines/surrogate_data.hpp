// The archive as training data for the surrogate module: plain rows (unit-cube point, fitness) read
// from the runs the archive already keeps.
#pragma once

#include "demcal/optimise/parameter_space.hpp"
#include "demcal/pipelines/archive.hpp"
#include "demcal/surrogate/surrogate.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace demcal::pipelines {

// One case of a campaign as the archive knows it: its model (scene) hash, its objective key (which
// measurement, objective and smoother the fitness rows belong to) and its weight in the fitness.
struct ArchivedCase {
  std::string model_hash;
  std::string objective_key;
  double weight = 1;
};

// Every finished run of the campaign's scene(s) with a fitness for the campaign's objective, from
// this campaign and earlier ones, with run id <= max_run_id, as surrogate rows:
// - a row is a parameter set with a fitness row in every case (fitness = Σ weight x case fitness;
//   NaN when any case failed);
// - only parameter sets of this space: the same parameter names, free values within the bounds,
//   fixed values equal and the tied value equal to source / ratio (relative 1e-12); others are
//   runs of a different calibration of the same scene and are skipped;
// - runs with status "cancelled" are skipped (they say nothing about the parameters);
// - ordered by the run id of the first case.
std::vector<surrogate::TrainingRow> archive_training_rows(const RunArchive& archive,
                                                          const optimise::ParameterSpace& space,
                                                          const std::vector<ArchivedCase>& cases,
                                                          std::int64_t max_run_id = INT64_MAX);

// The unit-cube point of a parameter set if it belongs to the space (see above), else empty.
Eigen::VectorXd unit_point_in_space(const optimise::ParameterSpace& space, const std::map<std::string, double>& params);

}  // namespace demcal::pipelines
