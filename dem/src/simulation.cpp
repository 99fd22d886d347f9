#include "demcal/dem/simulation.hpp"

#include "contact_law.hpp"
#include "geometry.hpp"

#include "demcal/limits/limits.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cmath>
#include <limits>
#include <tuple>
#include <unordered_map>

namespace demcal::dem {

std::string to_string(RunStatus status) {
  switch (status) {
    case RunStatus::completed: return "completed";
    case RunStatus::collapsed: return "collapsed";
    case RunStatus::unstable: return "unstable";
    case RunStatus::step_limit: return "step_limit";
    case RunStatus::cancelled: return "cancelled";
  }
  return "unknown";
}

namespace {

using geometry::cross;
using geometry::perp;

struct Body {
  std::string name, label;
  std::vector<Vec2> local;  // vertices relative to the centroid at angle 0
  std::vector<Vec2> local_normals;  // outward unit normal of edge i (vertex i to i+1) at angle 0
  // In the world, in plain arrays (the separating-axis test's loops vectorise over them): vertex
  // coordinates, edge normals and each edge's offset (its first vertex . its normal), updated with
  // the position; vertex(i) and normal(i) read them as vectors.
  std::vector<double> world_x, world_y, normal_x, normal_y, edge_offset;
  std::vector<double> edge_lengths;
  // Edges that have carried contact nodes (an open contact within the search margin included), for
  // the time step's bound; marked only with time_step_faces "in_contact", never cleared.
  std::vector<char> edge_in_contact;
  Vec2 start_position = Vec2::Zero();
  Vec2 position = Vec2::Zero();
  double angle = 0;
  Vec2 velocity = Vec2::Zero();
  double angular_velocity = 0;
  Vec2 force = Vec2::Zero();
  double torque = 0;
  double mass = 0, inertia = 0;                 // true values
  double inertial_mass = 0, inertial_inertia = 0;  // density-scaled
  Vec2 weight = Vec2::Zero();
  bool fixed = false, fixed_rotation = false;
  // Support springs (support-compliance) and the rotational restraint (boundary-restraint): springs
  // to the start position and angle; a held direction of a compliant support does not move.
  bool springs = false, hold_x = false, hold_y = false;
  double spring_x = 0, spring_y = 0, spring_r = 0;
  bool counts_weight = true;  // part of the equilibrium reference weight (free blocks of the scene)
  double radius = 0;  // largest vertex distance from the centroid
  // The time step's bound (Engine::critical_time_step): the stiffness of the faces that count, at
  // the groups' kn and ks (N/m, translation; N m/rad, rotation), and this step's excess of the
  // touching nodes' tangent stiffnesses over them (joint-closure, shear-stiffening).
  double face_translation = 0, face_rotation = 0;
  double stiffening_translation = 0, stiffening_rotation = 0;
  Vec2 box_min = Vec2::Zero(), box_max = Vec2::Zero();

  // cos and sin of `angle` (every block starts at angle 0), kept up to date by turn().
  double cos_angle = 1, sin_angle = 0;

  Eigen::Matrix2d rotation() const { return (Eigen::Matrix2d() << cos_angle, -sin_angle, sin_angle, cos_angle).finished(); }
  Vec2 to_local(const Vec2& world_point) const { return rotation().transpose() * (world_point - position); }
  Vec2 to_world(const Vec2& local_point) const { return position + rotation() * local_point; }
  Vec2 vertex(int i) const { return Vec2(world_x[i], world_y[i]); }
  Vec2 normal(int i) const { return Vec2(normal_x[i], normal_y[i]); }
  int vertex_count() const { return static_cast<int>(local.size()); }
  Vec2 velocity_at(const Vec2& world_point) const {
    return velocity + angular_velocity * perp(world_point - position);
  }
  // Rotates by `increment` (rad): the angle-addition formulas with the increment's sine and cosine
  // from their Taylor series, exact to round-off for |increment| <= 1e-3 (truncation below 1e-17;
  // a step turns a block by 1e-7 to 1e-5 rad in the quasi-static runs), instead of a library sincos
  // per block and step. Larger increments, and every call with `exact`, take the library's values.
  void turn(double increment, bool exact) {
    angle += increment;
    if (exact || std::abs(increment) > 1e-3) {
      cos_angle = std::cos(angle);
      sin_angle = std::sin(angle);
      return;
    }
    const double squared = increment * increment;
    const double c = 1 - 0.5 * squared * (1 - squared / 12), s = increment * (1 - squared / 6);
    const double cos_new = cos_angle * c - sin_angle * s, sin_new = sin_angle * c + cos_angle * s;
    cos_angle = cos_new;
    sin_angle = sin_new;
  }
  void update_world() {
    // The rotation's columns as vectors built from the two scalars (a matrix on the stack is stored
    // as scalars and read back as a vector, which stalls the store buffer); the same operations.
    const Vec2 column_x(cos_angle, sin_angle), column_y(-sin_angle, cos_angle);
    Vec2 low = Vec2::Constant(std::numeric_limits<double>::infinity()), high = -low;
    for (std::size_t i = 0; i < local.size(); ++i) {
      const Vec2 w = position + (column_x * local[i].x() + column_y * local[i].y());
      const Vec2 n = column_x * local_normals[i].x() + column_y * local_normals[i].y();
      low = low.cwiseMin(w);
      high = high.cwiseMax(w);
      world_x[i] = w.x();
      world_y[i] = w.y();
      normal_x[i] = n.x();
      normal_y[i] = n.y();
      edge_offset[i] = w.dot(n);
    }
    box_min = low;
    box_max = high;
  }
};

// A point fixed to a body (gauge or actuator attachment).
struct AttachedPoint {
  int body = -1;
  Vec2 local = Vec2::Zero();
};

// Persistent state of one contacting pair (a joint).
struct Contact {
  std::uint64_t key = 0;  // (first block << 32) | second block
  int group = 0;
  bool ref_on_a = true;
  bool corner = false;
  bool active = false;  // within the search margin in the previous step (shear history valid)
  bool seen = false;    // within the search margin in this step
  std::vector<double> shear;  // stored shear force per node (N)
  std::vector<double> gap;    // last gap per node (m), for reports
  // The last full separating-axis test of the pair: each way's best edge and its lead over the
  // second best (m), the two blocks' positions and angles then, and a bound on the distance from
  // any edge's start to any vertex of the other block (m). See separations_still_valid().
  bool sat_valid = false;
  int sat_edge_a = 0, sat_edge_b = 0;
  double sat_lead_a = 0, sat_lead_b = 0, sat_reach = 0;
  double sat_angle_a = 0, sat_angle_b = 0;
  Vec2 sat_position_a = Vec2::Zero(), sat_position_b = Vec2::Zero();
  // Joint history since the gauges were zeroed.
  double slip = 0;
  bool ever_touched = false;
  double max_normal_stress = 0;  // Pa, over the recorded rows
  std::vector<NodeHistory> history;  // per node, only for joint groups with an effect on (kept last:
                                     // the plain law's hot fields keep their place)
};

struct GroupLaw {
  std::string name;
  JointMaterial material;
  MohrCoulombLaw law;
  EffectLaw effects;
  bool plain = true;
};

class Engine {
 public:
  explicit Engine(const Scene& scene) : scene_(scene) {
    build_bodies();
    build_groups();
    points_ = scene_.contact.points_per_joint;
    segments_ = points_ - 1;
    cos_edge_tolerance_ = std::cos(scene_.contact.edge_angle_tolerance);
    margin_ = scene_.contact.search_margin;
    // The broad phase's skin: a twentieth of the smallest block's box (a few mm for masonry units),
    // and at least the search margin. Larger means fewer sweeps and more candidates to test.
    double smallest = std::numeric_limits<double>::infinity();
    for (const Body& b : bodies_) smallest = std::min(smallest, (b.box_max - b.box_min).minCoeff());
    skin_ = std::max(margin_, 0.05 * smallest);
    setup_loading();
    setup_gap();
    sat_scratch_.assign(max_vertices_, 0.0);
    const bool automatic = scene_.solver.time_step <= 0;
    step_follows_contacts_ = automatic && scene_.solver.time_step_faces == "in_contact";
    if (automatic) face_stiffness();
    dt_ = automatic ? critical_time_step() * scene_.solver.time_step_safety : scene_.solver.time_step;
  }

  Recording run(const RunControl& control);
  double time_step() const { return dt_; }

 private:
  void build_bodies();
  void build_groups();
  void setup_loading();
  void setup_gap();
  void face_stiffness();  // each body's face_translation and face_rotation
  double critical_time_step() const;
  // A touching node's tangent stiffening (Pa/m over area m^2, at `point`, along normal n and
  // tangent t) added to both blocks' bound of this step.
  void add_stiffening(Body& a, Body& b, const Vec2& point, const Vec2& n, const Vec2& t, double area,
                      double normal, double shear) {
    for (Body* body : {&a, &b}) {
      const Vec2 r = point - body->position;
      body->stiffening_translation += area * (normal + shear);
      body->stiffening_rotation += area * (normal * std::pow(cross(r, n), 2) + shear * std::pow(cross(r, t), 2));
    }
  }
  // Marks a body's edge as in contact when the step follows the contacts; a first mark makes the
  // step be estimated again.
  void note_edge_in_contact(Body& body, int edge) {
    if (!step_follows_contacts_ || body.edge_in_contact[edge]) return;
    body.edge_in_contact[edge] = 1;
    contact_edges_changed_ = true;
  }
  int group_for(const Body& a, const Body& b, const Vec2& normal) const;
  void compute_forces();
  void sweep(double margin);  // pairs_ <- every pair whose boxes, grown by margin, overlap (sorted)
  bool candidates_stale() const;
  void sweep_candidates();
  // Every pair in two passes: first the geometry of all pairs (reading positions only), then the
  // node loops and force sums in the same order (reading velocities, adding to the blocks' forces).
  // Each pass's pairs are independent of each other, so the processor overlaps consecutive pairs
  // instead of waiting on one pair's chain from separating axis to force; the forces are summed in
  // the order of the single pass this replaces (the same bits).
  struct PairWork;
  bool pair_geometry(int ia, int ib, int& contact_index, PairWork& work);
  void pair_forces(const PairWork& work);
  // Geometry of one edge or corner contact: the reference face (r1, tr, normal: outward from the
  // reference block), the normal and tangent from block a to block b, and the gap joint flag.
  struct NodeLayout {
    Vec2 r1, tr, normal, normal_ab, tangent_ab;
    bool ref_on_a = true;
    bool gap_joint = false;
  };
  // An edge contact's nodes along the reference face: `points_` nodes evenly spaced from `lo` (m
  // along tr from r1), the gap linear in s through (s1, g1) with `slope`.
  struct EdgeSpan {
    double lo, spacing, s1, g1, slope;
  };
  // One touching pair between the two passes: its blocks and contact, the layout, and an edge
  // contact's span or a corner contact's node (s, gap, tributary length).
  struct PairWork {
    int a = 0, b = 0, contact = 0;
    bool edge_contact = true;
    NodeLayout layout;
    EdgeSpan span{};
    double corner_s = 0, corner_gap = 0, corner_length = 0;
  };
  [[gnu::noinline]] void process_nodes(Body& a, Body& b, Contact& contact, const GroupLaw& group, const NodeLayout& layout,
                                       const std::vector<double>& s_nodes, const std::vector<double>& gaps,
                                       const std::vector<double>& lengths);
  void edge_nodes(const EdgeSpan& span);
  void process_plain_edge(Body& a, Body& b, Contact& contact, const MohrCoulombLaw& law, const NodeLayout& layout,
                          const EdgeSpan& span);
  // Ends every node loop: the pair's summed node force (on b; its opposite on a) and its moment about
  // the origin go to both blocks, and while loading the joint's mean slip and first touch are kept.
  // `excess_sum`, the touching nodes' shear beyond the limit (N), gives the slip: a node's
  // excess / (ks A) weighted by its tributary length l = A / width is excess / (ks width).
  void apply_pair_sums(Body& a, Body& b, Contact& contact, bool touching, const Vec2& resultant, double moment,
                       double excess_sum, double length_total);
  void integrate();
  double unbalanced_ratio() const;
  double actuator_force() const;
  RunStatus check_state(std::string& message) const;
  void zero_gauges();
  void record_row(double load_time, double force);
  void finish(Recording& rec) const;

  const Scene& scene_;
  std::vector<Body> bodies_;
  std::vector<int> spring_bodies_;  // bodies with support springs or a rotational restraint
  std::vector<GroupLaw> groups_;
  std::vector<Contact> contacts_;                         // every joint ever within the search margin
  std::unordered_map<std::uint64_t, int> contact_index_;  // pair key -> index in contacts_
  // Broad phase with a skin (Verlet list): candidate pairs, swept with the search margin plus
  // `skin_`, sorted by (first, second), each with its contact's index (-1: none yet); the sweep is
  // repeated only once a bounding box has moved more than `skin_` / 4 since the last one, and every
  // step keeps the candidates that pass the exact box test of a sweep with the search margin.
  struct Candidate {
    int first = 0, second = 0;
    int contact = -1;
  };
  std::vector<Candidate> candidates_;
  std::vector<Vec2> swept_min_, swept_max_;  // each body's box at the last sweep
  double skin_ = 0;
  std::vector<std::pair<int, int>> pairs_;
  std::vector<PairWork> work_;  // this step's touching pairs, in candidate order
  std::vector<int> order_;
  int points_ = 15;
  double segments_ = 14;  // points_ - 1, as a double (converted once, not per pair)
  double cos_edge_tolerance_ = 1;
  double margin_ = 0;
  double dt_ = 0;
  bool step_follows_contacts_ = false;  // the automatic step over the faces in contact (time_step_faces)
  bool step_follows_stiffening_ = false;  // the automatic step at the nodes' tangent stiffnesses, each step
  bool contact_edges_changed_ = false;  // an edge was first marked in contact in this step
  double max_weight_ = 0;
  bool loading_stage_ = false;
  long integrations_ = 0;
  bool first_step_ = true;  // bonds (cohesion) exist only at joints present at the start
  long node_updates_ = 0;
  // Scratch of the node loop, sized once per joint layout (no allocation in the step).
  std::vector<double> node_s_, node_gap_, node_length_;          // per node: s along the face, gap, length
  std::size_t max_vertices_ = 0;    // of any block
  std::vector<double> sat_scratch_;  // per edge of one block: the separating-axis test's minima

  // joint-gap: the pair key and the joint's two ends in the first block's frame.
  bool has_gap_ = false;
  std::uint64_t gap_key_ = 0;
  Vec2 gap_intrados_local_ = Vec2::Zero(), gap_extrados_local_ = Vec2::Zero();
  double gap_intrados_ = 0, gap_extrados_ = 0;  // m, the openings there

  // Loading.
  bool has_actuator_ = false;
  AttachedPoint actuator_point_;
  Vec2 actuator_anchor_ = Vec2::Zero();  // at the start of loading
  Vec2 actuator_direction_ = Vec2(0, -1);
  double actuator_stiffness_ = 0;
  double actuator_travel_ = 0;
  struct AppliedForce {
    AttachedPoint at;
    Vec2 force;
  };
  std::vector<AppliedForce> constant_forces_;
  std::vector<AttachedPoint> gauge_points_;
  std::vector<Vec2> gauge_zero_;
  std::vector<double> zero_angles_;
  Recording rec_;
};

void Engine::build_bodies() {
  const double scaling = scene_.solver.density_scaling;
  for (const Block& b : scene_.blocks) {
    Body body;
    body.name = b.name;
    body.label = b.label;
    const Vec2 c = geometry::centroid(b.vertices);
    for (const Vec2& v : b.vertices) {
      body.local.push_back(v - c);
      body.radius = std::max(body.radius, (v - c).norm());
    }
    for (std::size_t i = 0; i < body.local.size(); ++i) {
      const Vec2 edge = body.local[(i + 1) % body.local.size()] - body.local[i];
      body.edge_lengths.push_back(edge.norm());
      body.local_normals.push_back(Vec2(edge.y(), -edge.x()) / edge.norm());
    }
    for (auto* soa : {&body.world_x, &body.world_y, &body.normal_x, &body.normal_y, &body.edge_offset})
      soa->assign(body.local.size(), 0.0);
    body.edge_in_contact.assign(body.local.size(), 0);
    max_vertices_ = std::max(max_vertices_, body.local.size());
    body.position = body.start_position = c;
    body.mass = b.density * scene_.width * geometry::signed_area(b.vertices);
    body.inertia = b.density * scene_.width * geometry::polar_moment(b.vertices);
    body.inertial_mass = body.mass * scaling;
    body.inertial_inertia = body.inertia * scaling;
    body.weight = b.gravity ? Vec2(body.mass * scene_.gravity) : Vec2(Vec2::Zero());
    body.fixed = b.fixed;
    body.fixed_rotation = b.fixed_rotation;
    body.counts_weight = !b.fixed;
    if (b.compliant_support()) {
      body.fixed = false;
      body.springs = true;
      body.spring_x = b.support_kx;
      body.spring_y = b.support_ky;
      body.spring_r = b.support_kr;
      body.hold_x = b.support_kx <= 0;
      body.hold_y = b.support_ky <= 0;
      body.fixed_rotation = b.support_kr <= 0;
      body.weight = Vec2::Zero();
    } else if (!b.fixed && b.beam_kr > 0) {
      body.springs = true;
      body.spring_r = b.beam_kr;
      body.fixed_rotation = false;
    }
    body.update_world();
    if (body.counts_weight) max_weight_ = std::max(max_weight_, body.mass * scene_.gravity.norm());
    if (body.springs) spring_bodies_.push_back(static_cast<int>(bodies_.size()));
    bodies_.push_back(std::move(body));
  }
}

void Engine::build_groups() {
  // Set first: the effect laws report their tangents only for a step that follows them.
  step_follows_stiffening_ =
      scene_.solver.time_step <= 0 && scene_.solver.time_step_stiffening == "nodes" &&
      std::any_of(scene_.joint_groups.begin(), scene_.joint_groups.end(), [](const auto& group) {
        return group.second.closure_on() || group.second.shear_stiffening_on();
      });
  for (const auto& [name, material] : scene_.joint_groups)
    groups_.push_back({name, material, MohrCoulombLaw(material), EffectLaw(material, step_follows_stiffening_),
                       material.plain()});
}

void Engine::setup_gap() {
  const JointGap& gap = scene_.joint_gap;
  if (!gap.on()) return;
  const auto slash = gap.joint.find('/');
  int ia = scene_.block_index(gap.joint.substr(0, slash)), ib = scene_.block_index(gap.joint.substr(slash + 1));
  if (ia > ib) std::swap(ia, ib);
  Vec2 p, q;
  geometry::shared_edge(scene_.blocks[ia].vertices, scene_.blocks[ib].vertices, p, q);  // checked by Validate
  const bool p_first = p.y() < q.y() || (p.y() == q.y() && p.x() <= q.x());
  has_gap_ = true;
  gap_key_ = (static_cast<std::uint64_t>(ia) << 32) | static_cast<std::uint32_t>(ib);
  gap_intrados_local_ = bodies_[ia].to_local(p_first ? p : q);
  gap_extrados_local_ = bodies_[ia].to_local(p_first ? q : p);
  gap_intrados_ = gap.intrados();
  gap_extrados_ = gap.extrados();
}

void Engine::setup_loading() {
  const auto attach = [&](const std::string& block, const Vec2& world_point) {
    AttachedPoint p;
    p.body = scene_.block_index(block);
    p.local = bodies_[p.body].to_local(world_point);
    return p;
  };
  for (const auto& f : scene_.loading.constant_forces) constant_forces_.push_back({attach(f.block, f.point), f.force});
  for (const Gauge& g : scene_.gauges) gauge_points_.push_back(attach(g.block, g.point));
  if (scene_.loading.type == "none") return;
  has_actuator_ = true;
  actuator_point_ = attach(scene_.loading.block, scene_.loading.point);
  actuator_direction_ = scene_.loading.direction;
  actuator_stiffness_ = scene_.loading.stiffness;
  if (actuator_stiffness_ <= 0) {
    double kn = 0, longest = 0;
    for (const auto& g : groups_) kn = std::max(kn, g.material.normal_stiffness);
    const Body& b = bodies_[actuator_point_.body];
    for (std::size_t i = 0; i < b.local.size(); ++i)
      longest = std::max(longest, (b.local[(i + 1) % b.local.size()] - b.local[i]).norm());
    actuator_stiffness_ = kn * scene_.width * longest;
  }
  // Weight carried by a loading device without gravity still counts for the equilibrium ratio.
  for (const auto& f : constant_forces_) max_weight_ = std::max(max_weight_, f.force.norm());
}

// Upper bound of the highest natural frequency per body: every face marked in contact (every face
// of a block with none marked, so every face with time_step_faces "all") in full contact with the
// stiffest group (trace of the 3x3 stiffness over the inertia), doubled for two-body coupling. A
// group's closure and shear stiffening count at their caps (16 kn, 16 ks) on every face, or with
// time_step_stiffening "nodes" at kn and ks, each step adding the touching nodes' tangent stiffness
// above them (stiffening_translation, stiffening_rotation): the bound follows the stiffening where
// it happens.
void Engine::face_stiffness() {
  const bool caps = !step_follows_stiffening_;
  double kn = 0, ks = 0;
  for (const auto& g : groups_) {
    const double closure = caps && g.material.closure_on() ? JointMaterial::kClosureStiffening : 1.0;
    kn = std::max(kn, closure * g.material.normal_stiffness);
    const double shear = caps && g.material.shear_stiffening_on() ? JointMaterial::kShearStiffening : 1.0;
    ks = std::max(ks, shear * g.material.shear_stiffness);
  }
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    Body& b = bodies_[i];
    if (b.fixed) continue;
    double k_translation = 0, k_rotation = 0;
    const std::size_t n = b.local.size();
    const bool every_face = std::find(b.edge_in_contact.begin(), b.edge_in_contact.end(), 1) == b.edge_in_contact.end();
    for (std::size_t e = 0; e < n; ++e) {
      if (!every_face && !b.edge_in_contact[e]) continue;
      const Vec2 r1 = b.local[e], r2 = b.local[(e + 1) % n];
      const double length = (r2 - r1).norm();
      const Vec2 t = (r2 - r1) / length, normal(t.y(), -t.x());
      const double c = cross(r1, normal);  // moment arm of a normal force at the edge start
      k_translation += scene_.width * length * (kn + ks);
      k_rotation += scene_.width * (kn * (c * c * length - c * length * length + length * length * length / 3) +
                                    ks * std::pow(cross(r1, t), 2) * length);
    }
    if (b.springs) {
      k_translation += b.spring_x + b.spring_y;
      k_rotation += b.spring_r;
    }
    if (has_actuator_ && static_cast<int>(i) == actuator_point_.body) {
      k_translation += actuator_stiffness_;
      k_rotation += actuator_stiffness_ * std::pow(cross(actuator_point_.local, actuator_direction_), 2);
    }
    b.face_translation = k_translation;
    b.face_rotation = k_rotation;
  }
}

double Engine::critical_time_step() const {
  double omega_squared = 0;
  for (const Body& b : bodies_) {
    if (b.fixed) continue;
    double w2 = (b.face_translation + b.stiffening_translation) / b.inertial_mass;
    if (!b.fixed_rotation) w2 += (b.face_rotation + b.stiffening_rotation) / b.inertial_inertia;
    omega_squared = std::max(omega_squared, 2 * w2);
  }
  return 2.0 / std::sqrt(omega_squared);
}

int Engine::group_for(const Body& a, const Body& b, const Vec2& normal) const {
  const bool horizontal = std::abs(normal.y()) >= std::abs(normal.x());
  for (const auto& rule : scene_.joint_group_rules) {
    const bool labels = (rule.label_a == a.label && rule.label_b == b.label) ||
                        (rule.label_a == b.label && rule.label_b == a.label);
    const bool orientation = rule.orientation == "any" || (rule.orientation == "horizontal") == horizontal;
    if (labels && orientation) {
      for (std::size_t g = 0; g < groups_.size(); ++g)
        if (groups_[g].name == rule.joint_group) return static_cast<int>(g);
    }
  }
  for (std::size_t g = 0; g < groups_.size(); ++g)
    if (groups_[g].name == scene_.default_joint_group) return static_cast<int>(g);
  return 0;
}

// One way of the separating-axis test: the largest separation of body q from the edges of body p
// (m), the first edge that gives it, and its lead over the second largest (m; 0 on a tie).
struct Separation {
  double value = 0;
  int edge = 0;
  double lead = 0;
};

// Per edge e the scalar form is
//   s_e = min over q's vertices v of (v . n_e) - offset_e,  value = the first largest s_e,
// computed with the vertex loop outside and the edge loop inside, over plain arrays: the edge loop
// vectorises, and each s_e still takes its minimum over the vertices in the same order: the same
// bits as the edge-by-edge loop. `scratch` holds p's edge count of doubles.
// N, M > 0: p's and q's vertex counts known at compile time (quadrilaterals, the common case, are
// unrolled completely); 0: read from the bodies.
template <int N, int M>
static Separation max_separation(const Body& p, const Body& q, double* __restrict scratch) {
  const int n = N > 0 ? N : static_cast<int>(p.world_x.size()), m = M > 0 ? M : static_cast<int>(q.world_x.size());
  const double* __restrict nx = p.normal_x.data();
  const double* __restrict ny = p.normal_y.data();
  double* __restrict s = scratch;
  for (int e = 0; e < n; ++e) s[e] = std::numeric_limits<double>::infinity();
  for (int v = 0; v < m; ++v) {
    const double x = q.world_x[v], y = q.world_y[v];
    for (int e = 0; e < n; ++e) s[e] = std::min(s[e], x * nx[e] + y * ny[e]);
  }
  // The first largest separation and the runner-up, by selects rather than branches (which edge
  // wins varies from pair to pair, so a branch would often be mispredicted).
  double best = -std::numeric_limits<double>::infinity(), second = best;
  int best_edge = 0;
  for (int e = 0; e < n; ++e) {
    const double separation = s[e] - p.edge_offset[e];
    const bool larger = separation > best;
    second = larger ? best : std::max(second, separation);
    best = larger ? separation : best;
    best_edge = larger ? e : best_edge;
  }
  return {best, best_edge, best - second};
}

static Separation max_separation(const Body& p, const Body& q, double* scratch) {
  if (p.world_x.size() == 4 && q.world_x.size() == 4) return max_separation<4, 4>(p, q, scratch);
  return max_separation<0, 0>(p, q, scratch);
}

// s_e of max_separation for one edge e, with the same operations in the same order (the same bits).
static double edge_separation(const Body& p, const Body& q, int e) {
  const double nx = p.normal_x[e], ny = p.normal_y[e];
  double s = std::numeric_limits<double>::infinity();
  const int m = static_cast<int>(q.world_x.size());
  for (int v = 0; v < m; ++v) s = std::min(s, q.world_x[v] * nx + q.world_y[v] * ny);
  return s - p.edge_offset[e];
}

// Whether the best edges of the contact's last full separating-axis test are still the best ones
// both ways, proven from how far the blocks have moved since: every vertex of a block has moved by at
// most d = |dx| + |dy| + |dθ| R (R: its farthest vertex from the centroid), and an edge normal has
// turned by |dθ| of its block, so each separation s_e (a vertex minus an edge start, along the
// normal, at most `reach` long) has changed by at most B = d_a + d_b + |dθ_p| reach. The best edge
// keeps its place while its lead over the second best exceeds 2 B (plus 1 nm for rounding); its own
// separation is then recomputed exactly (edge_separation), which gives the bits of a full test.
static bool separations_still_valid(const Body& a, const Body& b, const Contact& c) {
  if (!c.sat_valid) return false;
  const double turn_a = std::abs(a.angle - c.sat_angle_a), turn_b = std::abs(b.angle - c.sat_angle_b);
  const double moved = (a.position - c.sat_position_a).cwiseAbs().sum() + turn_a * a.radius +
                       (b.position - c.sat_position_b).cwiseAbs().sum() + turn_b * b.radius;
  constexpr double rounding = 1e-9;
  return c.sat_lead_a > 2 * (moved + turn_a * c.sat_reach) + rounding &&
         c.sat_lead_b > 2 * (moved + turn_b * c.sat_reach) + rounding;
}

// `contact_index`: the pair's contact in contacts_, or -1 (set here when the contact is created).
// False when the pair does not touch (no work).
bool Engine::pair_geometry(int ia, int ib, int& contact_index, PairWork& work) {
  Body& a = bodies_[ia];
  Body& b = bodies_[ib];
  const std::uint64_t key = (static_cast<std::uint64_t>(ia) << 32) | static_cast<std::uint32_t>(ib);
  // Separating-axis test: the full test, or for a contact whose best edges are proven unchanged since
  // its last full test, only those two edges' separations (the same values).
  Contact* existing = contact_index >= 0 ? &contacts_[contact_index] : nullptr;
  Separation from_a, from_b;
  const bool full_test = existing == nullptr || !separations_still_valid(a, b, *existing);
  if (full_test) {
    from_a = max_separation(a, b, sat_scratch_.data());
    if (from_a.value > margin_) return false;
    from_b = max_separation(b, a, sat_scratch_.data());
  } else {
    from_a = {edge_separation(a, b, existing->sat_edge_a), existing->sat_edge_a, 0};
    if (from_a.value > margin_) return false;
    from_b = {edge_separation(b, a, existing->sat_edge_b), existing->sat_edge_b, 0};
  }
  if (from_b.value > margin_) return false;
  const double sep_a = from_a.value, sep_b = from_b.value;
  const int edge_a = from_a.edge, edge_b = from_b.edge;

  // Reference face: the polygon whose face separates more; hysteresis keeps the previous choice
  // while the two are within a small tolerance (near-parallel faces would otherwise flip).
  const double tolerance = 1e-3 * margin_ + 1e-12;
  bool ref_on_a = sep_a >= sep_b;
  if (existing != nullptr && existing->active)
    ref_on_a = existing->ref_on_a ? sep_a >= sep_b - tolerance : sep_a > sep_b + tolerance;

  const Body& ref = ref_on_a ? a : b;
  const Body& inc = ref_on_a ? b : a;
  const int ref_edge = ref_on_a ? edge_a : edge_b;
  const int ni = inc.vertex_count();
  const Vec2 r1 = ref.vertex(ref_edge);
  const double ref_length = ref.edge_lengths[ref_edge];
  const Vec2 normal = ref.normal(ref_edge);  // outward from the reference polygon
  const Vec2 tr(-normal.y(), normal.x());

  int inc_edge = 0;
  double most_opposed = std::numeric_limits<double>::infinity();
  for (int e = 0; e < ni; ++e) {  // selects, not branches: the winning edge varies from pair to pair
    const double c = inc.normal(e).dot(normal);
    const bool more = c < most_opposed;
    most_opposed = more ? c : most_opposed;
    inc_edge = more ? e : inc_edge;
  }
  const bool edge_contact = -most_opposed >= cos_edge_tolerance_;

  // Nodes along the reference face (coordinate s from r1 along tr): an edge contact's span, or the
  // one node of a corner contact in the scratch arrays.
  EdgeSpan span{};
  if (edge_contact) {
    const Vec2 q1 = inc.vertex(inc_edge), q2 = inc.vertex(inc_edge + 1 < ni ? inc_edge + 1 : 0);  // no integer division
    const double s1 = (q1 - r1).dot(tr), s2 = (q2 - r1).dot(tr);
    const double lo = std::max(0.0, std::min(s1, s2)), hi = std::min(ref_length, std::max(s1, s2));
    if (hi - lo <= 1e-9 * ref_length) return false;
    const double g1 = (q1 - r1).dot(normal), g2 = (q2 - r1).dot(normal);
    span = {lo, (hi - lo) / segments_, s1, g1, (g2 - g1) / (s2 - s1)};
    note_edge_in_contact(ref_on_a ? b : a, inc_edge);
  } else {
    // Corner against face: the deepest vertex of the incident polygon, if it lies over the face.
    int deepest = 0;
    double depth = std::numeric_limits<double>::infinity();
    for (int v = 0; v < ni; ++v) {
      const double g = (inc.vertex(v) - r1).dot(normal);
      if (g < depth) {
        depth = g;
        deepest = v;
      }
    }
    const double s = (inc.vertex(deepest) - r1).dot(tr);
    if (s < 0 || s > ref_length) return false;
    const int next = deepest + 1 < ni ? deepest + 1 : 0, previous = deepest > 0 ? deepest - 1 : ni - 1;
    const double shorter = std::min((inc.vertex(next) - inc.vertex(deepest)).norm(),
                                    (inc.vertex(previous) - inc.vertex(deepest)).norm());
    work.corner_s = s;
    work.corner_gap = depth;
    work.corner_length = shorter / (2.0 * segments_);
    note_edge_in_contact(ref_on_a ? b : a, previous);
    note_edge_in_contact(ref_on_a ? b : a, deepest);
  }
  note_edge_in_contact(ref_on_a ? a : b, ref_edge);

  const Vec2 normal_ab = ref_on_a ? normal : Vec2(-normal);
  const Vec2 tangent_ab = perp(normal_ab);
  if (existing == nullptr) {
    Contact c;
    c.key = key;
    c.group = group_for(a, b, normal_ab);
    contact_index = static_cast<int>(contacts_.size());
    contact_index_.emplace(key, contact_index);
    contacts_.push_back(std::move(c));
  }
  Contact& contact = contacts_[contact_index];
  if (full_test) {
    contact.sat_valid = true;
    contact.sat_edge_a = edge_a;
    contact.sat_edge_b = edge_b;
    contact.sat_lead_a = from_a.lead;
    contact.sat_lead_b = from_b.lead;
    contact.sat_reach = (b.position - a.position).norm() + a.radius + b.radius;
    contact.sat_angle_a = a.angle;
    contact.sat_angle_b = b.angle;
    contact.sat_position_a = a.position;
    contact.sat_position_b = b.position;
  }
  const int count = edge_contact ? points_ : 1;
  const GroupLaw& group = groups_[contact.group];
  if (!contact.active || contact.corner != !edge_contact || static_cast<int>(contact.shear.size()) != count) {
    contact.shear.assign(count, 0.0);
    if (!group.plain) {
      NodeHistory fresh;
      contact.history.assign(count, fresh);
    }
  }
  contact.seen = true;
  contact.corner = !edge_contact;
  contact.ref_on_a = ref_on_a;
  if (static_cast<int>(contact.gap.size()) != count) contact.gap.resize(count);

  const bool gap_joint = has_gap_ && key == gap_key_;
  work.a = ia;
  work.b = ib;
  work.contact = contact_index;
  work.edge_contact = edge_contact;
  work.layout = {r1, tr, normal, normal_ab, tangent_ab, ref_on_a, gap_joint};
  work.span = span;
  return true;
}

void Engine::pair_forces(const PairWork& work) {
  Body& a = bodies_[work.a];
  Body& b = bodies_[work.b];
  Contact& contact = contacts_[work.contact];
  const GroupLaw& group = groups_[contact.group];
  if (work.edge_contact && group.plain && !work.layout.gap_joint) {
    process_plain_edge(a, b, contact, group.law, work.layout, work.span);
    return;
  }
  if (work.edge_contact) {
    edge_nodes(work.span);
  } else {
    node_s_.assign(1, work.corner_s);
    node_gap_.assign(1, work.corner_gap);
    node_length_.assign(1, work.corner_length);
  }
  process_nodes(a, b, contact, group, work.layout, node_s_, node_gap_, node_length_);
}

// An edge contact's nodes in the scratch arrays, for process_nodes: s along the face,
// the gap and the tributary length (half a spacing at the two ends).
void Engine::edge_nodes(const EdgeSpan& span) {
  const int n = points_;
  node_s_.resize(n);
  node_gap_.resize(n);
  node_length_.resize(n);
  for (int k = 0; k < n; ++k) {
    node_s_[k] = span.lo + k * span.spacing;
    node_gap_[k] = span.g1 + (node_s_[k] - span.s1) * span.slope;
    node_length_[k] = span.spacing;
  }
  node_length_[0] = 0.5 * span.spacing;
  node_length_[n - 1] = 0.5 * span.spacing;
}

// The plain law over an edge contact's nodes. Per node k the scalar form is
//   point = r1 + s tr + 0.5 gap normal,  s = lo + k spacing,  gap = g1 + (s - s1) slope;
//   increment = (v_b(point) - v_a(point)) . t dt,  v(p) = v + w perp(p - c);
//   force on b = f_n n + f_s t,  moment about the origin += point x force.
// The nodes are evenly spaced and the gap is linear along the face, so point, gap and increment are
// linear in k (p0 + k dp, g0 + k dg, i0 + k di) and the moment of the resultant follows from four
// sums over the touching nodes: p0 x (F_n n + F_s t) + dp x (K_n n + K_s t), with F the sums of
// f_n, f_s and K the sums of k f_n, k f_s. The loop is left with the law itself.
void Engine::process_plain_edge(Body& a, Body& b, Contact& contact, const MohrCoulombLaw& group_law,
                                const NodeLayout& layout, const EdgeSpan& span) {
  // The law's constants and the node arrays in locals: the loop's stores to the contact's arrays
  // could otherwise alias them, and each node would load them again.
  const MohrCoulombLaw law = group_law;
  double* __restrict gaps = contact.gap.data();
  double* __restrict shears = contact.shear.data();
  const int count = points_;
  const double g0 = span.g1 + (span.lo - span.s1) * span.slope, dg = span.spacing * span.slope;
  const Vec2 p0 = layout.r1 + span.lo * layout.tr + 0.5 * g0 * layout.normal;
  const Vec2 dp = span.spacing * layout.tr + 0.5 * dg * layout.normal;
  const Vec2 n = layout.normal_ab, t = layout.tangent_ab;
  const double i0 = (b.velocity_at(p0) - a.velocity_at(p0)).dot(t) * dt_;
  const double di = ((b.angular_velocity - a.angular_velocity) * perp(dp)).dot(t) * dt_;
  const double inner_area = span.spacing * scene_.width;
  double fn_sum = 0, fs_sum = 0, fn_first_moment = 0, fs_first_moment = 0, excess_sum = 0, length_total = 0;
  bool touching = false;
  double index = 0;  // k as a double, counted rather than converted (exact for any node count)
  for (int k = 0; k < count; ++k, index += 1) {
    const int slot = layout.ref_on_a ? k : count - 1 - k;  // stored in order along tangent_ab
    const double gap = g0 + index * dg;
    gaps[slot] = gap;
    const double end = k == 0 || k == count - 1 ? 0.5 : 1.0;
    NodeKinematics kin;
    kin.penetration = -gap;
    kin.area = end * inner_area;
    kin.shear_increment = i0 + index * di;
    const NodeForces f = law.evaluate(kin, shears[slot]);
    if (f.normal == 0) continue;
    touching = true;
    fn_sum += f.normal;
    fs_sum += f.shear;
    fn_first_moment += index * f.normal;
    fs_first_moment += index * f.shear;
    excess_sum += f.excess_shear;
    length_total += end * span.spacing;
  }
  node_updates_ += count;
  const Vec2 resultant = fn_sum * n + fs_sum * t;
  const double moment = cross(p0, resultant) + cross(dp, fn_first_moment * n + fs_first_moment * t);
  apply_pair_sums(a, b, contact, touching, resultant, moment, excess_sum, length_total);
}

void Engine::apply_pair_sums(Body& a, Body& b, Contact& contact, bool touching, const Vec2& resultant, double moment,
                             double excess_sum, double length_total) {
  if (touching) {
    b.force += resultant;
    b.torque += moment - cross(b.position, resultant);
    a.force -= resultant;
    a.torque -= moment - cross(a.position, resultant);
  }
  if (loading_stage_ && length_total > 0) {
    const double slip_weighted = excess_sum / (groups_[contact.group].material.shear_stiffness * scene_.width);
    contact.slip += slip_weighted / length_total;
  }
  if (touching && loading_stage_) contact.ever_touched = true;
}

// The node loop, node by node: a corner contact's single node, a joint group with effects on
// (EffectLaw and its node history), or the gap joint (whose group may be plain).
void Engine::process_nodes(Body& a, Body& b, Contact& contact, const GroupLaw& group, const NodeLayout& layout,
                           const std::vector<double>& s_nodes, const std::vector<double>& gaps,
                           const std::vector<double>& lengths) {
  const int count = static_cast<int>(s_nodes.size());
  const bool plain = group.plain;
  double excess_sum = 0, length_total = 0;
  bool touching = false;
  Vec2 resultant = Vec2::Zero();
  double moment = 0;
  Vec2 gap_from = Vec2::Zero(), gap_along = Vec2::Zero();
  if (layout.gap_joint) {  // the joint's ends at the start, carried by block a
    gap_from = a.to_world(gap_intrados_local_);
    gap_along = a.to_world(gap_extrados_local_) - gap_from;
  }
  for (int k = 0; k < count; ++k) {
    const int slot = layout.ref_on_a ? k : count - 1 - k;
    double gap = gaps[k];
    const Vec2 point = layout.r1 + s_nodes[k] * layout.tr + 0.5 * gap * layout.normal;
    if (layout.gap_joint) {
      const double t = std::clamp((point - gap_from).dot(gap_along) / gap_along.squaredNorm(), 0.0, 1.0);
      gap += gap_intrados_ + t * (gap_extrados_ - gap_intrados_);
    }
    contact.gap[slot] = gap;
    // A bond exists only where the faces touch at the start (within 1 um).
    if (first_step_ && !plain) contact.history[slot].bonded = group.effects.bonds() && gap <= 1e-6;
    NodeKinematics kin;
    kin.penetration = -gap;
    kin.area = lengths[k] * scene_.width;
    if (kin.penetration > 0 || (!plain && contact.history[slot].bonded))
      kin.shear_increment = (b.velocity_at(point) - a.velocity_at(point)).dot(layout.tangent_ab) * dt_;
    const NodeForces f = plain ? group.law.evaluate(kin, contact.shear[slot])
                               : group.effects.evaluate(kin, contact.shear[slot], contact.history[slot]);
    ++node_updates_;
    if (f.normal == 0) continue;
    touching = true;
    const Vec2 force_on_b = f.normal * layout.normal_ab + f.shear * layout.tangent_ab;
    resultant += force_on_b;
    moment += cross(point, force_on_b);
    excess_sum += f.excess_shear;
    length_total += lengths[k];
    if (step_follows_stiffening_ && f.stiffening_normal + f.stiffening_shear > 0)
      add_stiffening(a, b, point, layout.normal_ab, layout.tangent_ab, kin.area, f.stiffening_normal,
                     f.stiffening_shear);
  }
  apply_pair_sums(a, b, contact, touching, resultant, moment, excess_sum, length_total);
}

// The broad phase's exact test: the two boxes, grown by `margin`, overlap along x and along y. It is
// the test of the sweep below (which sorts by box_min.x and stops at the first box beyond reach).
static bool boxes_within(const Body& p, const Body& q, double margin) {
  return !(q.box_min.x() > p.box_max.x() + margin || p.box_min.x() > q.box_max.x() + margin ||
           q.box_min.y() > p.box_max.y() + margin || p.box_min.y() > q.box_max.y() + margin);
}

// Sweep along x over the bounding boxes grown by `margin`: pairs_ gets every pair (first < second)
// within reach that is not two fixed blocks, sorted.
void Engine::sweep(double margin) {
  order_.resize(bodies_.size());
  for (std::size_t i = 0; i < bodies_.size(); ++i) order_[i] = static_cast<int>(i);
  std::sort(order_.begin(), order_.end(), [&](int i, int j) {
    return bodies_[i].box_min.x() < bodies_[j].box_min.x() || (bodies_[i].box_min.x() == bodies_[j].box_min.x() && i < j);
  });
  pairs_.clear();
  for (std::size_t p = 0; p < order_.size(); ++p) {
    const Body& bi = bodies_[order_[p]];
    for (std::size_t q = p + 1; q < order_.size(); ++q) {
      const Body& bj = bodies_[order_[q]];
      if (bj.box_min.x() > bi.box_max.x() + margin) break;
      if (bi.fixed && bj.fixed) continue;
      if (bj.box_min.y() > bi.box_max.y() + margin || bi.box_min.y() > bj.box_max.y() + margin) continue;
      pairs_.emplace_back(std::min(order_[p], order_[q]), std::max(order_[p], order_[q]));
    }
  }
  std::sort(pairs_.begin(), pairs_.end());
}

// The candidates stay a superset of this step's pairs while no box coordinate has moved more than
// d = skin / 4 since their sweep: a pair within `margin` now was within margin + 2 d < margin + skin
// then (the factor 2 left over covers rounding).
bool Engine::candidates_stale() const {
  if (swept_min_.size() != bodies_.size()) return true;
  const double limit = 0.25 * skin_;
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    const Body& b = bodies_[i];
    if ((b.box_min - swept_min_[i]).cwiseAbs().maxCoeff() > limit || (b.box_max - swept_max_[i]).cwiseAbs().maxCoeff() > limit)
      return true;
  }
  return false;
}

// A new candidate list: a sweep with the search margin plus the skin; each candidate finds its
// contact through the hash map (a sweep is rare: once a block has moved a quarter of the skin).
void Engine::sweep_candidates() {
  sweep(margin_ + skin_);
  candidates_.clear();
  for (const auto& [i, j] : pairs_) {
    const std::uint64_t key = (static_cast<std::uint64_t>(i) << 32) | static_cast<std::uint32_t>(j);
    const auto found = contact_index_.find(key);
    candidates_.push_back({i, j, found == contact_index_.end() ? -1 : found->second});
  }
  swept_min_.resize(bodies_.size());
  swept_max_.resize(bodies_.size());
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    swept_min_[i] = bodies_[i].box_min;
    swept_max_[i] = bodies_[i].box_max;
  }
}

void Engine::compute_forces() {
  for (Body& b : bodies_) {
    b.force = b.weight;
    b.torque = 0;
  }
  for (int i : spring_bodies_) {
    Body& b = bodies_[i];
    const Vec2 moved = b.position - b.start_position;
    b.force -= Vec2(b.spring_x * moved.x(), b.spring_y * moved.y());
    b.torque -= b.spring_r * b.angle;
  }
  for (const auto& f : constant_forces_) {
    Body& b = bodies_[f.at.body];
    const Vec2 p = b.to_world(f.at.local);
    b.force += f.force;
    b.torque += cross(p - b.position, f.force);
  }
  if (has_actuator_ && loading_stage_) {
    Body& b = bodies_[actuator_point_.body];
    const Vec2 p = b.to_world(actuator_point_.local);
    const Vec2 force = actuator_force() * actuator_direction_;
    b.force += force;
    b.torque += cross(p - b.position, force);
  }

  if (candidates_stale()) sweep_candidates();
  for (Contact& c : contacts_) c.seen = false;
  if (step_follows_stiffening_)
    for (Body& b : bodies_) b.stiffening_translation = b.stiffening_rotation = 0;
  work_.resize(candidates_.size());
  std::size_t touching = 0;
  for (Candidate& c : candidates_)
    if (boxes_within(bodies_[c.first], bodies_[c.second], margin_) &&
        pair_geometry(c.first, c.second, c.contact, work_[touching]))
      ++touching;
  for (std::size_t i = 0; i < touching; ++i) pair_forces(work_[i]);
  if (contact_edges_changed_) face_stiffness();
  if (contact_edges_changed_ || step_follows_stiffening_) dt_ = critical_time_step() * scene_.solver.time_step_safety;
  contact_edges_changed_ = false;
  first_step_ = false;
  for (Contact& c : contacts_) {
    c.active = c.seen;
    if (!c.active) std::fill(c.gap.begin(), c.gap.end(), std::numeric_limits<double>::infinity());
  }
}

double Engine::actuator_force() const {
  const Body& b = bodies_[actuator_point_.body];
  const Vec2 anchor = actuator_anchor_ + actuator_travel_ * actuator_direction_;
  const double extension = (anchor - b.to_world(actuator_point_.local)).dot(actuator_direction_);
  const double force = actuator_stiffness_ * extension;
  return scene_.loading.compression_only ? std::max(0.0, force) : force;
}

// Central differences with local (non-viscous) damping per degree of freedom:
// F_damped = F - alpha |F| sign(v).
void Engine::integrate() {
  const double alpha = scene_.solver.local_damping;
  const auto damped = [alpha](double f, double v) { return v == 0 ? f : f - alpha * std::abs(f) * (v > 0 ? 1 : -1); };
  // The library's sine and cosine every 1024 steps bound the drift of the incremental rotation.
  const bool exact_rotation = (integrations_++ & 1023) == 0;
  // Component by component in registers: the velocity written as two scalars and read back as one
  // vector stalls the store buffer (the same operations as `position += dt velocity`).
  for (Body& b : bodies_) {
    if (b.fixed) continue;
    double vx = b.velocity.x(), vy = b.velocity.y();
    const double step_over_mass = dt_ / b.inertial_mass;
    if (!b.hold_x) vx += damped(b.force.x(), vx) * step_over_mass;  // a compliant support
    if (!b.hold_y) vy += damped(b.force.y(), vy) * step_over_mass;  // may hold a direction
    b.velocity = Vec2(vx, vy);
    if (!b.fixed_rotation) b.angular_velocity += damped(b.torque, b.angular_velocity) * (dt_ / b.inertial_inertia);
    b.position = Vec2(b.position.x() + dt_ * vx, b.position.y() + dt_ * vy);
    b.turn(dt_ * b.angular_velocity, exact_rotation);
    b.update_world();
  }
}

double Engine::unbalanced_ratio() const {
  double worst = 0;
  for (const Body& b : bodies_) {
    if (b.fixed) continue;
    if (b.hold_x || b.hold_y)  // a held direction carries a reaction, not an unbalance
      worst = std::max(worst, Vec2(b.hold_x ? 0.0 : b.force.x(), b.hold_y ? 0.0 : b.force.y()).norm());
    else
      worst = std::max(worst, b.force.norm());
    if (!b.fixed_rotation) worst = std::max(worst, std::abs(b.torque) / b.radius);
  }
  return max_weight_ > 0 ? worst / max_weight_ : worst;
}

// A cheap pass first, without square roots: a Euclidean norm is at most the sum of the absolute
// components, and a NaN or an infinity fails the comparisons, so a block whose sums stay within the
// limits passes every check below. Only a block that does not is checked exactly.
RunStatus Engine::check_state(std::string& message) const {
  for (const Body& b : bodies_) {
    if (b.fixed) continue;
    const double speed_bound = std::abs(b.velocity.x()) + std::abs(b.velocity.y()) + std::abs(b.angular_velocity) * b.radius;
    const double moved_bound = std::abs(b.position.x() - b.start_position.x()) + std::abs(b.position.y() - b.start_position.y());
    if (speed_bound <= scene_.solver.max_velocity && moved_bound <= scene_.solver.collapse_displacement &&
        std::isfinite(b.angle))
      continue;
    if (!b.position.allFinite() || !std::isfinite(b.angle) || !b.velocity.allFinite()) {
      message = "non-finite state of block '" + b.name + "'";
      return RunStatus::unstable;
    }
    const double speed = b.velocity.norm() + std::abs(b.angular_velocity) * b.radius;
    if (speed > scene_.solver.max_velocity) {
      message = "block '" + b.name + "' exceeded max_velocity (" + std::to_string(speed) + " m/s)";
      return RunStatus::unstable;
    }
    if ((b.position - b.start_position).norm() > scene_.solver.collapse_displacement) {
      message = "block '" + b.name + "' moved more than collapse_displacement";
      return RunStatus::collapsed;
    }
  }
  return RunStatus::completed;
}

void Engine::zero_gauges() {
  gauge_zero_.clear();
  for (const auto& g : gauge_points_) gauge_zero_.push_back(bodies_[g.body].to_world(g.local));
  // Self-weight runs report joint rotations from the start; loaded runs from the zeroed state.
  zero_angles_.assign(bodies_.size(), 0.0);
  if (has_actuator_)
    for (std::size_t i = 0; i < bodies_.size(); ++i) zero_angles_[i] = bodies_[i].angle;
  if (has_actuator_) actuator_anchor_ = bodies_[actuator_point_.body].to_world(actuator_point_.local);
}

void Engine::record_row(double load_time, double force) {
  rec_.time.push_back(load_time);
  rec_.force.push_back(force);
  for (std::size_t g = 0; g < gauge_points_.size(); ++g) {
    const Vec2 p = bodies_[gauge_points_[g].body].to_world(gauge_points_[g].local);
    rec_.gauge_values[g].push_back((p - gauge_zero_[g]).dot(scene_.gauges[g].direction));
  }
  // Normal stress at each node from its last gap, through the group's closure law (the elastic
  // closure: penetration less any plastic closure after crushing).
  double row_max = 0;
  for (Contact& c : contacts_) {
    if (!c.active) continue;
    const EffectLaw& law = groups_[c.group].effects;
    for (std::size_t k = 0; k < c.gap.size(); ++k) {
      const double elastic = -c.gap[k] - (k < c.history.size() ? c.history[k].plastic_closure : 0.0);
      if (elastic > 0) c.max_normal_stress = std::max(c.max_normal_stress, law.normal_stress(elastic));
    }
    row_max = std::max(row_max, c.max_normal_stress);
  }
  if (rec_.time.size() == 1) rec_.start_normal_stress = row_max;
}

Recording Engine::run(const RunControl& control) {
  const auto started = std::chrono::steady_clock::now();
  rec_ = Recording{};
  for (const Gauge& g : scene_.gauges) rec_.gauge_names.push_back(g.name);
  rec_.gauge_values.assign(scene_.gauges.size(), {});
  const SolverSettings& sv = scene_.solver;
  const bool loaded = has_actuator_;
  const double gravity_limit = loaded ? sv.max_equilibrium_time : std::min(sv.max_equilibrium_time, sv.max_time);
  // Equilibrium must hold for a stretch of steps: a single body swinging through its rest
  // position has zero force for an instant.
  const long settle_steps = 100;

  double time = 0;
  long steps = 0, below = 0;
  RunStatus status = RunStatus::completed;
  std::string message;
  const auto stopped = [&]() {
    if (control.cancel && (steps & 255) == 0 && control.cancel->load(std::memory_order_relaxed)) {
      status = RunStatus::cancelled;
      message = "cancelled by the caller";
      return true;
    }
    status = check_state(message);
    return status != RunStatus::completed;
  };

  // Stage 1: self-weight to equilibrium.
  bool equilibrium = false;
  while (!stopped()) {
    compute_forces();
    below = unbalanced_ratio() < sv.equilibrium_ratio ? below + 1 : 0;
    if (below >= settle_steps) {
      equilibrium = true;
      break;
    }
    if (time >= gravity_limit) break;
    integrate();
    time += dt_;
    ++steps;
  }
  rec_.gravity_steps = steps;
  if (status == RunStatus::completed && !equilibrium) {
    status = RunStatus::step_limit;
    message = "no equilibrium under self-weight within " + std::to_string(gravity_limit) +
              " s (unbalanced force ratio " + std::to_string(unbalanced_ratio()) + ")";
  }
  zero_gauges();
  if (status == RunStatus::completed && !loaded) message = "equilibrium under self-weight after " + std::to_string(time) + " s";

  // Stage 2: displacement-controlled loading.
  if (status == RunStatus::completed && loaded) {
    loading_stage_ = true;
    const Loading& l = scene_.loading;
    double load_time = 0, next_record = 0;
    const double travel_time = l.max_displacement / l.velocity;
    bool last_step = false;
    double regular_step = dt_;  // the step before the last, cut one (reported)
    while (true) {
      actuator_travel_ = last_step ? l.max_displacement : std::min(l.velocity * load_time, l.max_displacement);
      compute_forces();
      if (actuator_travel_ >= next_record - 1e-15) {
        record_row(load_time, actuator_force());
        next_record += l.record_interval;
      }
      if (actuator_travel_ >= l.max_displacement) {
        message = "target displacement reached";
        break;
      }
      if (time >= sv.max_time) {
        status = RunStatus::step_limit;
        message = "max_time of " + std::to_string(sv.max_time) + " s reached";
        break;
      }
      // The last step is cut to the time left, so that the anchor ends exactly at max_displacement
      // with the blocks moved over the same time; a full step clamped at the end would leave the
      // actuator's spring short by up to velocity x dt, and the last row's force low by k v dt.
      if (load_time + dt_ >= travel_time) {
        last_step = true;
        regular_step = dt_;
        dt_ = travel_time - load_time;
      }
      integrate();
      time += dt_;
      load_time += dt_;
      ++steps;
      if (stopped()) break;
    }
    if (last_step) dt_ = regular_step;
  }
  rec_.status = status;
  rec_.message = message;
  rec_.steps = steps;
  rec_.time_step = dt_;
  rec_.contact_point_updates = node_updates_;
  finish(rec_);
  rec_.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return std::move(rec_);
}

void Engine::finish(Recording& rec) const {
  rec.peak_force = rec.force.empty() ? 0 : *std::max_element(rec.force.begin(), rec.force.end());
  for (const Body& b : bodies_) {
    BlockState s;
    s.name = b.name;
    for (int i = 0; i < b.vertex_count(); ++i) s.vertices.push_back(b.vertex(i));
    s.displacement = b.position - b.start_position;
    s.rotation = b.angle;
    s.fixed = !b.counts_weight;  // fixed in the scene (a compliant support included)
    if (b.counts_weight) rec.max_block_displacement = std::max(rec.max_block_displacement, s.displacement.norm());
    rec.final_blocks.push_back(std::move(s));
  }
  std::vector<std::pair<std::uint64_t, const Contact*>> sorted;
  for (const Contact& c : contacts_) sorted.emplace_back(c.key, &c);
  std::sort(sorted.begin(), sorted.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
  for (const auto& [key, c] : sorted) {
    const int ia = static_cast<int>(key >> 32), ib = static_cast<int>(key & 0xffffffffu);
    if (!c->ever_touched && !loading_stage_) {
      // Self-weight runs report every joint that carries load at the end.
      bool carrying = false;
      for (double g : c->gap) carrying = carrying || g < 0;
      if (!carrying) continue;
    } else if (!c->ever_touched) {
      continue;
    }
    JointReport j;
    j.name = bodies_[ia].name + "/" + bodies_[ib].name;
    j.joint_group = groups_[c->group].name;
    int open = 0;
    for (double g : c->gap) open += g > 0;
    j.open_fraction = c->gap.empty() ? 1.0 : double(open) / c->gap.size();
    j.rotation = (bodies_[ib].angle - zero_angles_[ib]) - (bodies_[ia].angle - zero_angles_[ia]);
    j.slip = c->slip;
    j.max_normal_stress = c->max_normal_stress;
    rec.max_normal_stress = std::max(rec.max_normal_stress, c->max_normal_stress);
    rec.joints.push_back(std::move(j));
  }
  // A hinge or a sliding joint is one of the mechanism's dominant joints: at least a quarter of the
  // largest rotation (slip) of the run, and above an absolute floor that ignores elastic motion.
  double max_rotation = 0, max_slip = 0;
  for (const JointReport& j : rec.joints) {
    max_rotation = std::max(max_rotation, std::abs(j.rotation));
    max_slip = std::max(max_slip, j.slip);
  }
  for (JointReport& j : rec.joints) {
    j.hinge = j.open_fraction >= 0.25 && std::abs(j.rotation) >= std::max(1e-3, 0.25 * max_rotation);
    j.sliding = j.slip >= std::max(2e-4, 0.25 * max_slip);
    if (j.hinge) rec.hinges.push_back(j.name);
    if (j.sliding) rec.sliding_joints.push_back(j.name);
  }
}

}  // namespace

Recording simulate(const Scene& scene, const RunControl& control) {
  scene.Validate(scene.name);
  Engine engine(scene);
  // The steps the run may take at its first time step, refused before the first one.
  const double steps = (scene.solver.max_equilibrium_time + scene.solver.max_time) / engine.time_step();
  if (auto m = limits::check(limits::Limit::time_steps, steps))
    throw SceneError(scene.name + ": solver.max_time",
                     limits::number_text(scene.solver.max_time) + " s (and " +
                         limits::number_text(scene.solver.max_equilibrium_time) + " s to equilibrium) at a time step of " +
                         limits::number_text(engine.time_step()) + " s: " + *m);
  return engine.run(control);
}

}  // namespace demcal::dem
