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
// - ordered by their unit point (lexicographic), not by run id: parallel runs get their ids in the
//   order they finish, and a model must not depend on that.
std::vector<surrogate::TrainingRow> archive_training_rows(const RunArchive& archive,
                                                          const optimise::ParameterSpace& space,
                                                          const std::vector<ArchivedCase>& cases,
                                                          std::int64_t max_run_id = INT64_MAX);

// The unit-cube point of a parameter set if it belongs to the space (see above), else empty.
Eigen::VectorXd unit_point_in_space(const optimise::ParameterSpace& space, const std::map<std::string, double>& params);

// What `demcal surrogate train|check` works on: one scene hash and objective key of an archive, the
// parameter space of the newest campaign that ran that scene, and that campaign's surrogate options
// (defaults if it had none).
struct ArchivedProblem {
  std::string model_hash;
  std::string objective_key;
  std::string campaign_name;
  optimise::ParameterSpace space;
  surrogate::SurrogateOptions options;
  std::vector<surrogate::TrainingRow> rows;  // archive_training_rows of that scene and objective
};
// scene_hash "" = the (scene, objective) pair with the most scored runs; objective_key "" = the
// scene's objective with the most scored runs. Throws ArchiveError naming the archive and the hash
// when nothing matches.
ArchivedProblem find_archived_problem(const RunArchive& archive, const std::string& scene_hash = "",
                                      const std::string& objective_key = "");

}  // namespace demcal::pipelines
