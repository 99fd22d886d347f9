// Scene description of the 2D rigid-block engine: blocks, joint groups, solver settings, loading
// and gauges. Plane model: every block carries the scene's out-of-plane width, so areas are
// (length along the joint) x width. SI units throughout (m, kg, N, Pa/m, s, rad); the JSON file
// says friction in degrees (`friction_deg`), converted on reading.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>

#include <algorithm>
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

// Contact law parameters of one joint group: Mohr-Coulomb, no cohesion, no tension by default.
// The effects below are options of the group; each is OFF at its default value, and a group with
// every effect off runs the plain law with bit-identical results (and the same scene hash).
// JSON keys and set_parameter names are given after each field; the file format is in
// docs/scene-format.md, the physics in docs/engine.md.
struct JointMaterial {
  double normal_stiffness = 4e9;      // kn, Pa/m (force per unit area per unit penetration)
  double shear_stiffness = 1.6e9;     // ks, Pa/m
  double friction_angle = 0.5323254;  // phi, rad (30.5 deg)

  // joint-closure (`closure_max`, m; 0 = off): Bandis-Barton hyperbolic closure of a rough joint,
  // Fn = kn A d / (1 - d / closure_max) with kn the initial stiffness. The hyperbola is followed up
  // to the closure where its tangent stiffness reaches kClosureStiffening x kn (3/4 of closure_max),
  // then continued linearly with that tangent, so that an explicit step can never meet the asymptote.
  double closure_max = 0;
  static constexpr double kClosureStiffening = 16;

  // friction-softening (on when `slip_softening` > 0): the friction coefficient falls linearly
  // with a node's accumulated sliding from tan(friction_angle) to tan(residual_friction()), reached
  // after `slip_softening` (m) of slip. The residual is given one of two ways:
  //   - as an angle, `friction_residual` (JSON/parameter `friction_residual_deg`, degrees);
  //   - as the loss from the peak, `friction_loss` (`friction_loss_deg`): residual = friction_angle
  //     - friction_loss, which follows the peak when friction_angle changes, so a calibration that
  //     searches both friction and the loss meets no pair with the residual above the peak.
  // Set one: JSON with both is an error; setting either parameter clears the other.
  double friction_residual = 0;  // rad, in [0, friction_angle]
  double friction_loss = 0;      // rad, in [0, friction_angle]; > 0 replaces friction_residual
  double slip_softening = 0;     // m; 0 = off
  double residual_friction() const { return friction_loss > 0 ? friction_angle - friction_loss : friction_residual; }

  // cohesion (on when either is > 0): a bond present at the start of the run carries cohesion
  // `cohesion` (Pa: shear limit c A + tan(phi) Fn) and tension up to `tensile_strength` (Pa). A node
  // whose bond fails in tension or shear is broken for good (brittle) and follows the plain law.
  double cohesion = 0;          // Pa
  double tensile_strength = 0;  // Pa

  // crushing-cap (on when `compressive_strength` > 0): the normal stress at a node cannot exceed
  // `compressive_strength` (Pa); plastic closure beyond it lowers the strength linearly to zero
  // over `crushing_softening` (m) of plastic closure (0: a perfectly plastic cap, no softening).
  double compressive_strength = 0;  // Pa
  double crushing_softening = 0;    // m

  // shear-stiffening (`shear_stiffening_stress`, Pa; 0 = off): the shear stiffness grows with the
  // node's normal stress s, ks (1 + s / shear_stiffening_stress), up to kShearStiffening x ks, as
  // rough joints stiffen in shear under pressure (Kulhawy; Bandis, Lumsden and Barton): the stress
  // given doubles ks. Joints that carry more pre-compression then take shear load more stiffly.
  double shear_stiffening_stress = 0;
  static constexpr double kShearStiffening = 16;

  bool closure_on() const { return closure_max > 0; }
  bool shear_stiffening_on() const { return shear_stiffening_stress > 0; }
  bool softening_on() const { return slip_softening > 0; }
  bool cohesion_on() const { return cohesion > 0 || tensile_strength > 0; }
  bool crushing_on() const { return compressive_strength > 0; }
  bool plain() const {
    return !closure_on() && !shear_stiffening_on() && !softening_on() && !cohesion_on() && !crushing_on();
  }

  void Validate(const std::string& where) const;  // throws SceneError naming the value
};

// joint-gap: an initial opening at one joint (imperfect fit, lost mortar). The opening varies
// linearly from one end of the joint to the other (uniform when equal). The intrados end is the end
// of the shared edge with the lower y at the start (for a level joint, the one with the lower x): for
// the radial joints of an arch whose centre lies below, the inner end. It is held as
//   opening  the wider end's opening (m);
//   taper    the share of it closed at the other end: 0 uniform, +1 a wedge closed at the intrados
//            (open at the extrados), -1 closed at the extrados. A taper beyond +-1 (up to
//            +-kMaxTaper) means +-1: a search ranging past +-1 holds a closed end on a finite part
//            of its range, not on one face of its box, where a wedge's best fit would lie;
// the two ends (intrados(), extrados()) follow from them. The joint is a scene option
// (`joint_gap.joint`, "blockA/blockB" in either order, the two blocks must share an edge at the
// start); the numeric parameters are `gap_opening` and `gap_taper` (setting one keeps the other),
// or the ends `gap_intrados` and `gap_extrados` (setting one keeps the other end). Off while
// `joint` is empty.
struct JointGap {
  std::string joint;   // "voussoir_9/voussoir_10"
  double opening = 0;  // m, in [0, kMaxOpening]
  double taper = 0;    // in [-kMaxTaper, kMaxTaper]
  static constexpr double kMaxOpening = 0.01;  // m: larger openings are not a fit imperfection
  static constexpr double kMaxTaper = 2;
  bool on() const { return !joint.empty(); }
  double intrados() const { return taper > 0 ? opening * (1 - std::min(taper, 1.0)) : opening; }
  double extrados() const { return taper < 0 ? opening * (1 + std::max(taper, -1.0)) : opening; }
  // Both ends, >= 0 (not checked here): the wider one becomes the opening.
  void set_ends(double intrados, double extrados);
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

  // support-compliance (fixed blocks only; on when any is > 0): the block rests on springs to its
  // start position at its centroid instead of being rigid. A stiffness of 0 keeps that direction
  // rigid. The support's own weight is taken by its foundation before the run (not applied), so
  // the springs answer only to what the structure puts on them. JSON keys and parameter names
  // `<block>.support_kx` etc.
  double support_kx = 0;  // N/m, horizontal
  double support_ky = 0;  // N/m, vertical
  double support_kr = 0;  // N m/rad, rotation about the centroid
  // boundary-restraint (free blocks only; on when > 0): a rotational spring to the start angle,
  // N m/rad (the wall's top beam, neither fixed nor free in rotation). When on, the rotation is
  // free against this spring whatever `fixed_rotation` says. Parameter `beam_kr` (the loaded
  // block) or `<block>.beam_kr`.
  double beam_kr = 0;

  bool compliant_support() const { return fixed && (support_kx > 0 || support_ky > 0 || support_kr > 0); }
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
  // Faces the automatic step counts as in full contact: "in_contact" (each block's faces that have
  // carried contact nodes so far, every face before its first contact; the step is estimated again
  // whenever a face first comes into contact: 1.31 x larger on the reference arch, the same physics
  // by the round-off test) or "all" (every face from the start, one step for the run).
  std::string time_step_faces = "in_contact";
  // How the automatic step meets joint closure and shear stiffening, whose tangent stiffness grows
  // up to 16 kn and 16 ks: "caps" (every face counted at the caps from the first step) or "nodes"
  // (each step, the faces at kn and ks plus the touching nodes' tangent stiffness above them: the
  // same physics by the round-off test in 2-3 x fewer steps; docs/engine.md, "Integration").
  // Written to a scene file only when "nodes", so the hashes of scenes without the key stay theirs.
  std::string time_step_stiffening = "caps";
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
  JointGap joint_gap;  // joint-gap effect, off by default

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

// Calibration parameters by name. Joint-group parameters: "kn", "ks" (Pa/m), "friction_deg"
// (degrees) and the effect parameters "closure_max" (m), "friction_residual_deg" or
// "friction_loss_deg" (degrees; setting one clears the other),
// "slip_softening" (m), "shear_stiffening_stress", "cohesion", "tensile_strength", "compressive_strength" (Pa),
// "crushing_softening" (m): a bare name sets every joint group, "<group>.<name>" one group.
// Support springs by block: "<block>.support_kx", "<block>.support_ky" (N/m), "<block>.support_kr"
// (N m/rad); bare, they set every fixed block. "beam_kr" (N m/rad) sets the loaded block's
// rotational spring, "<block>.beam_kr" any free block's. "gap_intrados", "gap_extrados" (m), or
// "gap_opening" (m) and "gap_taper" (JointGap), set the openings of the scene's joint gap (the
// joint itself is the scene option joint_gap.joint). Unknown names throw SceneError; values are
// checked by Scene::Validate, not here, except a gap's end below 0 (the opening and taper hold none).
void set_parameter(Scene& scene, const std::string& name, double value);
double get_parameter(const Scene& scene, const std::string& name);
// The field a set_parameter name sets, without its group or block: "arch_joints.closure_max" ->
// "closure_max"; a bare name is its own field.
std::string parameter_field(const std::string& name);
// Every name set_parameter accepts for this scene (joint-group names, the support blocks' springs,
// beam_kr when the scene has a loaded block, the gap openings when a gap joint is set).
std::vector<std::string> parameter_names(const Scene& scene);

}  // namespace demcal::dem
