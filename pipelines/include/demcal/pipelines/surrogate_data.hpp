// The archive as training data for the surrogate module: plain rows (unit-cube point, fitness) read
// from the runs the archive already keeps.
#pragma once

#include "demcal/optimise/parameter_space.hpp"
#include "demcal/pipelines/archive.hpp"
#include "demcal/smoothing/objective.hpp"
#include "demcal/surrogate/surrogate.hpp"

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace demcal::pipelines {

// How a run's curves become a surrogate row's outputs (the "mlp" kind), and how predicted outputs
// become a fitness again. Per displacement channel of the measurement: the force of the run's
// loading envelope at `points` displacements over the measured channel's range, spaced
// quadratically (w_k = lower + (upper − lower) (k / (points − 1))², dense where the initial branch
// rises steeply; interpolated, held at the end values outside the run's range), then the largest
// displacement the run reached on that channel. The fitness of predicted outputs is objective 1 of each channel's
// predicted curve against the measured one — the raw measurement for objective 1, the smoother's
// fit of it for objective 2, where the prediction stands for the smoothed simulation — weighted as
// the objective weighs channels and the campaign weighs the case.
struct CurveGrid {
  struct Channel {
    std::string column;
    double lower = 0, upper = 0;      // the measured channel's displacement range
    double weight = 1;                // the objective's channel weight
    smoothing::XYSeries measured;     // what a predicted curve is compared with, as its loading envelope
  };
  std::vector<Channel> channels;
  std::string force_column = "force";
  int points = 40;                    // grid points per channel, >= 2
  int objective_points = 200;         // the objective's evaluation points
  smoothing::ObjectiveWindow objective_window = smoothing::ObjectiveWindow::common;  // and its window
  double case_weight = 1;
  Eigen::Index size() const { return static_cast<Eigen::Index>(channels.size()) * (points + 1); }
  double displacement(const Channel& c, int k) const {
    const double s = static_cast<double>(k) / (points - 1);
    return c.lower + (c.upper - c.lower) * s * s;
  }
};
// `objective2` null for objective 1. Throws CurveError when the measurement has no displacement
// channel.
CurveGrid make_curve_grid(const smoothing::Curve& measured, const smoothing::ObjectiveOptions& objective,
                          const smoothing::Objective2* objective2, double case_weight, int points = 40);
// The outputs of a run's curves; empty when the run lacks a channel or has fewer than 2 envelope
// points on one.
Eigen::VectorXd curve_outputs(const smoothing::Curve& run, const CurveGrid& grid);
// Channel `channel` of the outputs that start at `offset`, as a curve: the grid points below the
// run's end displacement (at least the first two), then the end point.
smoothing::XYSeries output_channel(const Eigen::VectorXd& outputs, Eigen::Index offset, const CurveGrid& grid,
                                   size_t channel);
// Σ over the grids (cases, in order; the outputs concatenated) of case weight x Σ channel weight x
// channel misfit.
double curve_fitness(const Eigen::VectorXd& outputs, const std::vector<std::shared_ptr<const CurveGrid>>& grids);

// One case of a campaign as the archive knows it: its model (scene) hash, its objective key (which
// measurement, objective and smoother the fitness rows belong to) and its weight in the fitness;
// with a grid, the rows carry the runs' outputs (the "mlp" kind).
struct ArchivedCase {
  std::string model_hash;
  std::string objective_key;
  double weight = 1;
  std::shared_ptr<const CurveGrid> grid = nullptr;
};

// One case's run as run_outputs reads it: its status ("collapsed" continues the curves at zero force
// to the end of the grid, as the campaign scores it) and its curves.
struct RunCurves {
  std::string status;
  const smoothing::Curve* curves = nullptr;
};
// The outputs of one parameter set's runs (one per case, in case order), concatenated; empty when a
// case has no grid or curves or a run no outputs.
Eigen::VectorXd run_outputs(const std::vector<RunCurves>& runs, const std::vector<ArchivedCase>& cases);
// The same for archived runs (run_ids: one per case, in case order).
Eigen::VectorXd archived_outputs(const RunArchive& archive, const std::vector<std::int64_t>& run_ids,
                                 const std::vector<ArchivedCase>& cases);

// Every finished run of the campaign's scene(s) with a fitness for the campaign's objective, from
// this campaign and earlier ones, with run id <= max_run_id, as surrogate rows:
// - a row is a parameter set with a fitness row in every case (fitness = Σ weight x case fitness;
//   NaN when any case failed);
// - only parameter sets of this space: the same parameter names, free values within the bounds,
//   fixed values equal and the tied value equal to source / ratio (relative 1e-12); others are
//   runs of a different calibration of the same scene and are skipped;
// - when every case has a grid, each row's outputs are its runs' curve_outputs, concatenated in case
//   order (empty if any run has none);
// - runs with status "cancelled" are skipped (they say nothing about the parameters);
// - ordered by their unit point (lexicographic), not by run id: parallel runs get their ids in the
//   order they finish, and a model must not depend on that.
std::vector<surrogate::TrainingRow> archive_training_rows(const RunArchive& archive,
                                                          const optimise::ParameterSpace& space,
                                                          const std::vector<ArchivedCase>& cases,
                                                          std::int64_t max_run_id = INT64_MAX);

// Why a parameter set is not a point of the (campaign's) space, "" when it is: a free parameter
// missing or outside its bounds, a name the space lacks, a fixed value missing or other, the tied
// value not source / ratio (relative 1e-12). The first reason found, with the name and values.
std::string outside_space(const optimise::ParameterSpace& space, const std::map<std::string, double>& params);
// The unit-cube point of a parameter set if it belongs to the space (outside_space is ""), else empty.
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
