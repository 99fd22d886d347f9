// Scene description of the 2D rigid-block engine: blocks, joint groups, solver settings, loading
// and gauges. Plane model: every block carries the scene's out-of-plane width, so areas are
// (length along the joint) x width. SI units throughout (m, kg, N, Pa/m, s, rad); the JSON file
// says friction in degrees (`friction_deg`), converted on reading.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>

#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace demcal::dem {

using Vec2 = Eigen::Vector2d;

// Bad scene input. `where` names the file and the key path (e.g. "arch.json: blocks[3].vertices")
// or the block; what() holds the whole sentence.
class SceneError : public std::runtime_error {
 public:
  SceneError(std::string where, const std::string& message)
      : std::runtime_error(where + ": " + message), where_(std::move(where)) {}
  const std::string& where() const { return where_; }

 private:
  std::string where_;
};

// Contact law parameters of one joint group (Mohr-Coulomb, no cohesion, no tension by default).
// Later effects (cohesion, tension cut-off, residual friction, nonlinear closure, crushing cap)
// are added here as options whose defaults leave the plain law unchanged.
struct JointMaterial {
  double normal_stiffness = 4e9;      // kn, Pa/m (force per unit area per unit penetration)
  double shear_stiffness = 1.6e9;     // ks, Pa/m
  double friction_angle = 0.5323254;  // phi, rad (30.5 deg)

  void Validate(const std::string& where) const;  // throws SceneError naming the value
};

// Which joint group a contact between two blocks belongs to. Blocks carry a label ("voussoir",
// "abutment", "unit", "base", "beam"); a rule matches the unordered pair of labels and, optionally,
// the joint orientation at first touch: "horizontal" (bed joint, |normal_y| >= |normal_x|),
// "vertical" (head joint) or "any". First matching rule wins; else `default_joint_group`.
struct JointGroupRule {
  std::string label_a;
  std::string label_b;
  std::string orientation = "any";
  std::string joint_group;
};

struct Block {
  std::string name;                // unique; used in messages, hinge reports and VTK output
  std::string label;               // matched by JointGroupRule
  std::vector<Vec2> vertices;      // convex polygon, counter-clockwise, world coordinates at start (m)
  double density = 2650;           // kg/m^3
  bool fixed = false;              // no motion at all (supports, abutments, base)
  bool fixed_rotation = false;     // translation free, rotation held (e.g. a top beam kept level)
  bool gravity = true;             // false: the block's weight is not applied (loading devices)
};

struct ContactSettings {
  int points_per_joint = 15;             // nodes along an edge-to-edge contact, both ends included (>= 2)
  double edge_angle_tolerance = 0.1745;  // rad (10 deg): edges closer to parallel make an edge contact
  double search_margin = 1e-3;           // m: pairs closer than this are tracked as (open) contacts
};

struct SolverSettings {
  double local_damping = 0.8;         // non-viscous local damping coefficient (3DEC default 0.8)
  double time_step_safety = 0.5;      // fraction of the estimated critical time step
  double time_step = 0;               // s; 0 = automatic from masses and contact stiffnesses
  double density_scaling = 1;         // >= 1: inertia multiplied for quasi-static runs (weight unchanged)
  double equilibrium_ratio = 1e-5;    // gravity stage ends when max unbalanced force / max weight < this
  double max_equilibrium_time = 5;    // s of simulated time allowed for the gravity stage
  double max_time = 60;               // s of simulated time for the whole run (step_limit beyond)
  double collapse_displacement = 0.1; // m: a free block moving this far (from the start) = collapse
  double max_velocity = 100;          // m/s: any block faster than this = unstable
};

// Displacement-controlled loading through an actuator: a penalty spring between a moving anchor and
// a point fixed to a block. The anchor moves along `direction` at `velocity`; the spring force along
// `direction` is the recorded force. `compression_only` models a roller that can only push.
struct Loading {
  std::string type = "none";            // "none" (self-weight to equilibrium) | "point" | "wall"
  std::string block;                    // loaded block name
  Vec2 point = Vec2::Zero();            // world position at start (m), fixed to the block
  Vec2 direction = Vec2(0, -1);         // unit vector of the prescribed motion
  double velocity = 0.01;               // m/s
  double max_displacement = 0.012;      // m, actuator travel after the gravity stage
  double stiffness = 0;                 // N/m; 0 = automatic: largest kn x width x the loaded block's longest edge
  bool compression_only = true;
  double record_interval = 1e-5;        // m of actuator travel between recorded rows
  // Constant external forces applied from the start (wall pre-compression), N, at a world point.
  struct ConstantForce {
    std::string block;
    Vec2 force = Vec2::Zero();
    Vec2 point = Vec2::Zero();
  };
  std::vector<ConstantForce> constant_forces;
};

// A displacement gauge: a point fixed to a block, read along a direction, zeroed after gravity.
struct Gauge {
  std::string name;
  std::string block;
  Vec2 point = Vec2::Zero();    // world position at start (m)
  Vec2 direction = Vec2(1, 0);  // unit vector; reading = (position - position at zeroing) . direction
};

struct Scene {
  std::string name = "scene";
  double width = 0.2;  // out-of-plane width of every block (m)
  Vec2 gravity = Vec2(0, -9.81);
  std::vector<Block> blocks;
  std::map<std::string, JointMaterial> joint_groups;
  std::vector<JointGroupRule> joint_group_rules;
  std::string default_joint_group;
  ContactSettings contact;
  SolverSettings solver;
  Loading loading;
  std::vector<Gauge> gauges;

  // Checks everything a run needs (names, convexity, orientation, areas, overlaps at start,
  // finite positive values) and throws SceneError naming the key or block.
  void Validate(const std::string& source = "scene") const;
  int block_index(const std::string& name) const;  // -1 when absent
};

// JSON <-> Scene. `source` (usually the file name) prefixes every error message.
Scene scene_from_json(const nlohmann::json& j, const std::string& source = "scene");
nlohmann::json scene_to_json(const Scene& scene);
Scene load_scene(const std::string& path);  // reads, parses and validates
void save_scene(const Scene& scene, const std::string& path);

// Stable hash of everything that affects a simulation (hex string); archives key runs by it.
std::string scene_hash(const Scene& scene);

// Calibration parameters by name: "kn", "ks" (Pa/m), "friction_deg" (degrees) set every joint
// group; "<group>.kn", "<group>.ks", "<group>.friction_deg" set one. Unknown names throw SceneError.
void set_parameter(Scene& scene, const std::string& name, double value);
double get_parameter(const Scene& scene, const std::string& name);
std::vector<std::string> parameter_names(const Scene& scene);

}  // namespace demcal::dem
