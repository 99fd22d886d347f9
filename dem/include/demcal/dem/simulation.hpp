// Running a scene: simulate(scene) -> Recording. Deterministic: the same scene gives bit-identical
// results (no randomness, no threads inside one run, a fixed order of contact processing).
//
// Stages: (1) gravity alone until equilibrium (max unbalanced force / max block weight below
// solver.equilibrium_ratio) or collapse; gauges are then zeroed, as the paper counts displacements
// from the self-weight state. (2) With loading "point" or "wall", the actuator anchor moves at its
// velocity until its travel reaches max_displacement; a row is recorded every record_interval of
// travel. With loading "none" the run ends after stage 1.
#pragma once

#include "demcal/dem/scene.hpp"

#include <atomic>
#include <string>
#include <vector>

namespace demcal::dem {

enum class RunStatus {
  completed,   // target displacement reached (or equilibrium, with loading "none")
  collapsed,   // a free block moved more than solver.collapse_displacement
  unstable,    // non-finite state or a block faster than solver.max_velocity
  step_limit,  // solver.max_time (or max_equilibrium_time with loading "none") ran out
  cancelled,   // the caller's cancel flag was raised
};
std::string to_string(RunStatus status);

// Final state of one block (for VTK output and failure-mode pictures).
struct BlockState {
  std::string name;
  std::vector<Vec2> vertices;  // world coordinates at the end (m)
  Vec2 displacement = Vec2::Zero();  // centroid displacement since the start of the run (m)
  double rotation = 0;               // rad since the start, counter-clockwise positive
  bool fixed = false;
};

// What happened at one joint (a pair of blocks that touched), named "blockA/blockB".
struct JointReport {
  std::string name;
  std::string joint_group;
  double open_fraction = 0;   // share of the joint's nodes open (gap > 0) at the end
  double rotation = 0;        // relative rotation of the two blocks since zeroing (rad)
  double slip = 0;            // accumulated plastic (sliding) slip along the joint since zeroing (m)
  double max_normal_stress = 0;  // Pa, largest normal stress at a node of the joint in a recorded row
  // Dominant joints of the mechanism: hinge when open_fraction >= 0.25 and |rotation| >= max(1e-3 rad,
  // a quarter of the run's largest joint rotation); sliding when slip >= max(0.2 mm, a quarter of
  // the largest slip).
  bool hinge = false;
  bool sliding = false;
};

struct Recording {
  RunStatus status = RunStatus::completed;
  std::string message;

  // Time series, one row per recorded step: time (s, from the start of loading), actuator force (N,
  // positive along the pushing direction) and one column per gauge (m), in scene.gauges order.
  std::vector<double> time;
  std::vector<double> force;
  std::vector<std::string> gauge_names;
  std::vector<std::vector<double>> gauge_values;  // [gauge][row]

  double peak_force = 0;              // N, max of `force`
  long steps = 0;                     // time steps in both stages
  long gravity_steps = 0;             // of which in the gravity stage
  double time_step = 0;               // s, at the end of the run (faces coming into contact, joint closure
                                      // and shear stiffening change it during the run)
  double wall_time_s = 0;
  double max_block_displacement = 0;  // m, largest centroid displacement of a free block (from start)
  // Pa, largest normal stress at any contact node in a recorded row (the loading stage): the scale
  // against which a compressive strength matters (a cap above it never acts).
  double max_normal_stress = 0;
  // Pa, the same in the first recorded row (the start of loading: self-weight and pre-compression).
  double start_normal_stress = 0;
  long contact_point_updates = 0;     // contact-node force evaluations, for speed figures
  std::vector<JointReport> joints;
  std::vector<std::string> hinges;          // names of joints with hinge = true
  std::vector<std::string> sliding_joints;  // names of joints with sliding = true
  std::vector<BlockState> final_blocks;
};

struct RunControl {
  const std::atomic<bool>* cancel = nullptr;  // polled every few hundred steps; may be null
};

// Validates the scene (throws SceneError on bad input) and runs it.
Recording simulate(const Scene& scene, const RunControl& control = {});

// Output helpers for `demcal simulate`.
nlohmann::json summary_json(const Recording& recording);
void write_curves_csv(const Recording& recording, const std::string& path);
void write_vtk(const Recording& recording, const std::string& path);  // legacy VTK polydata

}  // namespace demcal::dem
