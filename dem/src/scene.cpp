#include "demcal/dem/scene.hpp"

#include "geometry.hpp"
#include "scene_checks.hpp"

#include "demcal/dem/effects.hpp"

#include "demcal/common/format.hpp"
#include "demcal/common/units.hpp"
#include "demcal/limits/limits.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <iomanip>
#include <numbers>
#include <set>
#include <sstream>

namespace demcal::dem {

using nlohmann::json;

namespace {

void require_unit(const Vec2& v, const std::string& where) {
  require_finite(v.x(), where);
  require_finite(v.y(), where);
  if (std::abs(v.norm() - 1) > 1e-6) throw SceneError(where, "must be a unit vector, got norm " + format_number(v.norm(), 10));
}

// Reads typed values from one JSON object and names the key path in every error.
class ObjectReader {
 public:
  ObjectReader(const json& object, std::string path) : object_(object), path_(std::move(path)) {
    if (!object_.is_object()) throw SceneError(path_, "expected a JSON object");
  }
  const std::string& path() const { return path_; }
  std::string key_path(const std::string& key) const { return path_ + "." + key; }
  bool has(const std::string& key) const { return object_.contains(key); }
  const json& required(const std::string& key) const {
    if (!object_.contains(key)) throw SceneError(path_, "missing key '" + key + "'");
    return object_.at(key);
  }
  double number(const std::string& key, double fallback) const {
    return has(key) ? to_number(object_.at(key), key_path(key)) : fallback;
  }
  double number(const std::string& key) const { return to_number(required(key), key_path(key)); }
  int integer(const std::string& key, int fallback) const {
    if (!has(key)) return fallback;
    const json& v = object_.at(key);
    if (!v.is_number_integer()) throw SceneError(key_path(key), "expected an integer, got " + v.dump());
    return v.get<int>();
  }
  bool boolean(const std::string& key, bool fallback) const {
    if (!has(key)) return fallback;
    const json& v = object_.at(key);
    if (!v.is_boolean()) throw SceneError(key_path(key), "expected true or false, got " + v.dump());
    return v.get<bool>();
  }
  std::string string(const std::string& key, const std::string& fallback) const {
    return has(key) ? to_string(object_.at(key), key_path(key)) : fallback;
  }
  std::string string(const std::string& key) const { return to_string(required(key), key_path(key)); }
  Vec2 vec2(const std::string& key, const Vec2& fallback) const {
    return has(key) ? to_vec2(object_.at(key), key_path(key)) : fallback;
  }
  Vec2 vec2(const std::string& key) const { return to_vec2(required(key), key_path(key)); }

  static double to_number(const json& v, const std::string& where) {
    if (!v.is_number()) throw SceneError(where, "expected a number, got " + v.dump());
    const double x = v.get<double>();
    require_finite(x, where);
    return x;
  }
  static std::string to_string(const json& v, const std::string& where) {
    if (!v.is_string()) throw SceneError(where, "expected a string, got " + v.dump());
    return v.get<std::string>();
  }
  static Vec2 to_vec2(const json& v, const std::string& where) {
    if (!v.is_array() || v.size() != 2) throw SceneError(where, "expected [x, y], got " + v.dump());
    return Vec2(to_number(v[0], where + "[0]"), to_number(v[1], where + "[1]"));
  }

 private:
  const json& object_;
  std::string path_;
};

json vec2_json(const Vec2& v) { return json::array({v.x(), v.y()}); }

}  // namespace

namespace {

// The effects' values (SceneField, effects.hpp), read, written, checked and set here by their
// declarations, in the order of the registry.

// Calls f(effect, field) for every field the effects declare.
template <class F>
void for_each_effect_field(F f) {
  for (const Effect& effect : effect_registry())
    for (const SceneField& field : effect.scene_fields) f(effect, field);
}

// A value as the file and set_parameter give it, and as the scene holds it.
double given_value(const SceneField& field, double held) { return field.degrees ? held / kDegree : held; }
double held_value(const SceneField& field, double given) { return field.degrees ? given * kDegree : given; }

// A value (as given) within its field's limits, else SceneError at `where`.
void check_limits(const SceneField& field, double v, const std::string& where) {
  if (field.lower == 0) {
    require_non_negative(v, where);
    if (v > field.upper)
      throw SceneError(where, "must be at most " + format_number(field.upper, 10) + " (" + field.reason + "), got " +
                                  format_number(v, 10));
    return;
  }
  require_finite(v, where);
  if (v < field.lower || v > field.upper)
    throw SceneError(where, "must be in [" + format_number(field.lower, 10) + ", " + format_number(field.upper, 10) +
                                "] (" + field.reason + "), got " + format_number(v, 10));
}

// Whether any of the effect's block values is on (> 0) at `block`.
bool effect_on_block(const Effect& effect, const Block& block) {
  return std::any_of(effect.scene_fields.begin(), effect.scene_fields.end(),
                     [&](const SceneField& f) { return f.block && block.*f.block > 0; });
}

// The joint gap's fields, stored (the opening and taper) or derived (its ends).
bool on_gap(const SceneField& f) { return f.gap || f.derived(); }
std::vector<const SceneField*> gap_fields(bool derived) {
  std::vector<const SceneField*> fields;
  for_each_effect_field([&](const Effect&, const SceneField& f) {
    if (on_gap(f) && f.derived() == derived) fields.push_back(&f);
  });
  return fields;
}

}  // namespace

void JointGap::set_ends(double intrados, double extrados) {
  opening = std::max(intrados, extrados);
  taper = !(opening > 0) ? 0 : extrados >= intrados ? 1 - intrados / opening : extrados / opening - 1;
}

void JointMaterial::Validate(const std::string& where) const {
  require_positive(normal_stiffness, where + ".kn");
  require_positive(shear_stiffness, where + ".ks");
  require_finite(friction_angle, where + ".friction_deg");
  if (friction_angle < 0 || friction_angle >= std::numbers::pi / 2)
    throw SceneError(where + ".friction_deg",
                     "must be in [0, 90) degrees, got " + format_number(friction_angle / kDegree, 10));
  // Each effect's values, then its rules across them.
  for (const Effect& effect : effect_registry()) {
    for (const SceneField& f : effect.scene_fields)
      if (f.material && !f.bounded_by_rule) check_limits(f, given_value(f, this->*f.material), where + "." + f.key());
    if (effect.check_material) effect.check_material(*this, where);
  }
}

int Scene::block_index(const std::string& block_name) const {
  for (std::size_t i = 0; i < blocks.size(); ++i)
    if (blocks[i].name == block_name) return static_cast<int>(i);
  return -1;
}

namespace {

void validate_joint_groups(const Scene& scene, const std::string& s) {
  if (scene.joint_groups.empty()) throw SceneError(s + "joint_groups", "at least one joint group is needed");
  for (const auto& [group, material] : scene.joint_groups) material.Validate(s + "joint_groups." + group);
  if (!scene.default_joint_group.empty() && !scene.joint_groups.count(scene.default_joint_group))
    throw SceneError(s + "default_joint_group", "unknown joint group '" + scene.default_joint_group + "'");
  for (std::size_t r = 0; r < scene.joint_group_rules.size(); ++r) {
    const auto& rule = scene.joint_group_rules[r];
    const std::string where = s + "joint_group_rules[" + std::to_string(r) + "]";
    if (!scene.joint_groups.count(rule.joint_group))
      throw SceneError(where + ".joint_group", "unknown joint group '" + rule.joint_group + "'");
    if (rule.orientation != "any" && rule.orientation != "horizontal" && rule.orientation != "vertical")
      throw SceneError(where + ".orientation", "must be any, horizontal or vertical, got '" + rule.orientation + "'");
  }
}

// A block's polygon: at least 3 finite vertices, counter-clockwise, convex, of non-zero area.
void validate_block_polygon(const Block& b, const std::string& where) {
  if (b.vertices.size() < 3) throw SceneError(where + ".vertices", "a block needs at least 3 vertices");
  if (auto m = limits::check(limits::Limit::vertices_per_block, static_cast<double>(b.vertices.size())))
    throw SceneError(where + ".vertices", *m);
  for (std::size_t v = 0; v < b.vertices.size(); ++v) {
    require_finite(b.vertices[v].x(), where + ".vertices[" + std::to_string(v) + "]");
    require_finite(b.vertices[v].y(), where + ".vertices[" + std::to_string(v) + "]");
  }
  const double area = geometry::signed_area(b.vertices);
  double extent = 0;
  for (const Vec2& v : b.vertices) extent = std::max(extent, (v - b.vertices[0]).norm());
  if (geometry::edges_self_intersect(b.vertices)) throw SceneError(where + ".vertices", "self-intersecting polygon");
  if (std::abs(area) <= 1e-12 * std::max(extent * extent, 1e-30))
    throw SceneError(where + ".vertices", "zero-area block");
  if (area < 0) throw SceneError(where + ".vertices", "vertices must be counter-clockwise");
  if (!geometry::is_convex_ccw(b.vertices)) throw SceneError(where + ".vertices", "the polygon is not convex");
}

// The effects' values of a block, then where they apply: EffectTarget::support_blocks to fixed
// blocks only, beam_block to free blocks only.
void validate_block_effects(const Block& b, const std::string& where) {
  for_each_effect_field([&](const Effect&, const SceneField& f) {
    if (f.block) check_limits(f, b.*f.block, where + "." + f.key());
  });
  for (const Effect& effect : effect_registry()) {
    if (effect.target != EffectTarget::support_blocks && effect.target != EffectTarget::beam_block) continue;
    if (b.fixed == (effect.target == EffectTarget::support_blocks) || !effect_on_block(effect, b)) continue;
    // at the value where the effect has one, at the block where the message lists them
    const auto& fields = effect.scene_fields;
    throw SceneError(fields.size() == 1 ? where + "." + fields.front().key() : where, effect.block_texts.misplaced);
  }
}

void validate_blocks(const std::vector<Block>& blocks, const std::string& s) {
  std::set<std::string> names;
  bool any_free = false;
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    const Block& b = blocks[i];
    const std::string where = s + "blocks[" + std::to_string(i) + "] '" + b.name + "'";
    if (b.name.empty()) throw SceneError(s + "blocks[" + std::to_string(i) + "].name", "a block needs a name");
    if (!names.insert(b.name).second) throw SceneError(where, "duplicate block name");
    require_positive(b.density, where + ".density");
    validate_block_polygon(b, where);
    validate_block_effects(b, where);
    any_free = any_free || !b.fixed;
  }
  if (!any_free) throw SceneError(s + "blocks", "every block is fixed: nothing can move");
}

// Blocks must not overlap at the start (touching is fine): tolerance 1e-9 of the block size.
void validate_no_overlap_at_start(const std::vector<Block>& blocks, const std::string& s) {
  for (std::size_t i = 0; i < blocks.size(); ++i)
    for (std::size_t j = i + 1; j < blocks.size(); ++j) {
      const double depth = geometry::overlap_depth(blocks[i].vertices, blocks[j].vertices);
      if (depth > 1e-7)
        throw SceneError(s + "blocks", "blocks '" + blocks[i].name + "' and '" + blocks[j].name +
                                           "' overlap at the start by " + format_number(depth, 10) + " m");
    }
}

void validate_joint_gap(const Scene& scene, const std::string& s) {
  const JointGap& joint_gap = scene.joint_gap;
  if (!joint_gap.on()) return;
  const std::string where = s + "joint_gap";
  const auto slash = joint_gap.joint.find('/');
  if (slash == std::string::npos || joint_gap.joint.find('/', slash + 1) != std::string::npos)
    throw SceneError(where + ".joint", "expected two block names as 'blockA/blockB', got '" + joint_gap.joint + "'");
  const int ia = scene.block_index(joint_gap.joint.substr(0, slash));
  const int ib = scene.block_index(joint_gap.joint.substr(slash + 1));
  if (ia < 0 || ib < 0 || ia == ib)
    throw SceneError(where + ".joint", "'" + joint_gap.joint + "' does not name two different blocks of the scene");
  Vec2 p, q;
  if (!geometry::shared_edge(scene.blocks[ia].vertices, scene.blocks[ib].vertices, p, q))
    throw SceneError(where + ".joint", "blocks of '" + joint_gap.joint + "' share no edge at the start");
  for (const SceneField* f : gap_fields(false)) check_limits(*f, joint_gap.*f->gap, where + "." + f->key());
}

void validate_contact(const ContactSettings& contact, const std::string& s) {
  const int n = contact.points_per_joint;
  if (n < 2 || n > 200)
    throw SceneError(s + "contact.points_per_joint", "must be between 2 and 200, got " + std::to_string(n));
  require_finite(contact.edge_angle_tolerance, s + "contact.edge_angle_tolerance_deg");
  if (contact.edge_angle_tolerance <= 0 || contact.edge_angle_tolerance >= std::numbers::pi / 4)
    throw SceneError(s + "contact.edge_angle_tolerance_deg", "must be in (0, 45) degrees");
  require_non_negative(contact.search_margin, s + "contact.search_margin");
}

void validate_solver(const SolverSettings& solver, const std::string& s) {
  require_finite(solver.local_damping, s + "solver.local_damping");
  if (solver.local_damping < 0 || solver.local_damping >= 1)
    throw SceneError(s + "solver.local_damping", "must be in [0, 1), got " + format_number(solver.local_damping, 10));
  require_positive(solver.time_step_safety, s + "solver.time_step_safety");
  if (solver.time_step_safety > 1)
    throw SceneError(s + "solver.time_step_safety", "must not exceed 1, got " + format_number(solver.time_step_safety, 10));
  require_non_negative(solver.time_step, s + "solver.time_step");
  if (solver.time_step_faces != "all" && solver.time_step_faces != "in_contact")
    throw SceneError(s + "solver.time_step_faces", "must be all or in_contact, got '" + solver.time_step_faces + "'");
  if (solver.time_step_stiffening != "caps" && solver.time_step_stiffening != "nodes")
    throw SceneError(s + "solver.time_step_stiffening",
                     "must be caps or nodes, got '" + solver.time_step_stiffening + "'");
  require_finite(solver.density_scaling, s + "solver.density_scaling");
  if (solver.density_scaling < 1)
    throw SceneError(s + "solver.density_scaling", "must be >= 1, got " + format_number(solver.density_scaling, 10));
  require_positive(solver.equilibrium_ratio, s + "solver.equilibrium_ratio");
  require_positive(solver.max_equilibrium_time, s + "solver.max_equilibrium_time");
  require_positive(solver.max_time, s + "solver.max_time");
  require_positive(solver.collapse_displacement, s + "solver.collapse_displacement");
  require_positive(solver.max_velocity, s + "solver.max_velocity");
}

// The driven load (point or wall) on a free block, then the constant forces.
void validate_loading(const Scene& scene, const std::string& s) {
  const Loading& l = scene.loading;
  if (l.type != "none" && l.type != "point" && l.type != "wall")
    throw SceneError(s + "loading.type", "must be none, point or wall, got '" + l.type + "'");
  if (l.type != "none") {
    if (scene.block_index(l.block) < 0) throw SceneError(s + "loading.block", "unknown block '" + l.block + "'");
    if (scene.blocks[scene.block_index(l.block)].fixed)
      throw SceneError(s + "loading.block", "the loaded block '" + l.block + "' is fixed");
    require_finite(l.point.x(), s + "loading.point");
    require_finite(l.point.y(), s + "loading.point");
    require_unit(l.direction, s + "loading.direction");
    require_positive(l.velocity, s + "loading.velocity");
    require_positive(l.max_displacement, s + "loading.max_displacement");
    require_non_negative(l.stiffness, s + "loading.stiffness");
    require_positive(l.record_interval, s + "loading.record_interval");
    if (auto m = limits::check(limits::Limit::recorded_rows, l.max_displacement / l.record_interval))
      throw SceneError(s + "loading.record_interval", limits::number_text(l.record_interval) + " m over " +
                                                          limits::number_text(l.max_displacement) + " m of travel: " + *m);
  }
  for (std::size_t f = 0; f < l.constant_forces.size(); ++f) {
    const std::string where = s + "loading.constant_forces[" + std::to_string(f) + "]";
    if (scene.block_index(l.constant_forces[f].block) < 0)
      throw SceneError(where + ".block", "unknown block '" + l.constant_forces[f].block + "'");
    require_finite(l.constant_forces[f].force.norm(), where + ".force");
    require_finite(l.constant_forces[f].point.norm(), where + ".point");
  }
}

void validate_gauges(const Scene& scene, const std::string& s) {
  const std::vector<Gauge>& gauges = scene.gauges;
  std::set<std::string> gauge_names;
  for (std::size_t g = 0; g < gauges.size(); ++g) {
    const std::string where = s + "gauges[" + std::to_string(g) + "]";
    if (gauges[g].name.empty() || gauges[g].name == "time" || gauges[g].name == "force")
      throw SceneError(where + ".name", "a gauge needs a name other than 'time' and 'force'");
    if (!gauge_names.insert(gauges[g].name).second) throw SceneError(where + ".name", "duplicate gauge '" + gauges[g].name + "'");
    if (scene.block_index(gauges[g].block) < 0)
      throw SceneError(where + ".block", "unknown block '" + gauges[g].block + "'");
    require_finite(gauges[g].point.norm(), where + ".point");
    require_unit(gauges[g].direction, where + ".direction");
  }
}

}  // namespace

void Scene::Validate(const std::string& source) const {
  const std::string s = source + ": ";
  require_positive(width, s + "width");
  require_finite(gravity.x(), s + "gravity[0]");
  require_finite(gravity.y(), s + "gravity[1]");
  if (blocks.empty()) throw SceneError(s + "blocks", "the scene has no blocks");
  if (auto m = limits::check(limits::Limit::blocks, static_cast<double>(blocks.size())))
    throw SceneError(s + "blocks", *m);
  validate_joint_groups(*this, s);
  validate_blocks(blocks, s);
  validate_no_overlap_at_start(blocks, s);
  validate_joint_gap(*this, s);
  validate_contact(contact, s);
  validate_solver(solver, s);
  validate_loading(*this, s);
  validate_gauges(*this, s);
}

namespace {

JointMaterial read_joint_material(const ObjectReader& g) {
  JointMaterial m;
  m.normal_stiffness = g.number("kn");
  m.shear_stiffness = g.number("ks");
  m.friction_angle = g.number("friction_deg") * kDegree;
  for_each_effect_field([&](const Effect&, const SceneField& f) {
    if (f.material) m.*f.material = held_value(f, g.number(f.key(), given_value(f, m.*f.material)));
  });
  return m;
}

void read_joint_groups(const json& groups, const std::string& where, Scene& scene) {
  if (!groups.is_object() || groups.empty()) throw SceneError(where, "expected an object of joint groups");
  for (const auto& [group, value] : groups.items())
    scene.joint_groups[group] = read_joint_material(ObjectReader(value, where + "." + group));
}

void read_joint_group_rules(const json& rules, const std::string& where, Scene& scene) {
  if (!rules.is_array()) throw SceneError(where, "expected an array");
  for (std::size_t r = 0; r < rules.size(); ++r) {
    const ObjectReader rr(rules[r], where + "[" + std::to_string(r) + "]");
    const json& labels = rr.required("labels");
    if (!labels.is_array() || labels.size() != 2)
      throw SceneError(rr.key_path("labels"), "expected two block labels, got " + labels.dump());
    scene.joint_group_rules.push_back({ObjectReader::to_string(labels[0], rr.key_path("labels[0]")),
                                       ObjectReader::to_string(labels[1], rr.key_path("labels[1]")),
                                       rr.string("orientation", "any"), rr.string("joint_group")});
  }
}

Block read_block(const ObjectReader& b) {
  Block block;
  block.name = b.string("name");
  block.label = b.string("label", "");
  block.density = b.number("density", block.density);
  block.fixed = b.boolean("fixed", false);
  block.fixed_rotation = b.boolean("fixed_rotation", false);
  block.gravity = b.boolean("gravity", true);
  for_each_effect_field([&](const Effect&, const SceneField& f) {
    if (f.block) block.*f.block = b.number(f.key(), block.*f.block);
  });
  const json& vertices = b.required("vertices");
  if (!vertices.is_array()) throw SceneError(b.key_path("vertices"), "expected an array of [x, y]");
  if (auto m = limits::check(limits::Limit::vertices_per_block, static_cast<double>(vertices.size())))
    throw SceneError(b.key_path("vertices"), *m);
  for (std::size_t v = 0; v < vertices.size(); ++v)
    block.vertices.push_back(ObjectReader::to_vec2(vertices[v], b.key_path("vertices[" + std::to_string(v) + "]")));
  return block;
}

void read_blocks(const json& blocks, const std::string& where, Scene& scene) {
  if (!blocks.is_array()) throw SceneError(where, "expected an array of blocks");
  if (auto m = limits::check(limits::Limit::blocks, static_cast<double>(blocks.size()))) throw SceneError(where, *m);
  for (std::size_t i = 0; i < blocks.size(); ++i)
    scene.blocks.push_back(read_block(ObjectReader(blocks[i], where + "[" + std::to_string(i) + "]")));
}

void read_contact(const ObjectReader& c, ContactSettings& contact) {
  contact.points_per_joint = c.integer("points_per_joint", contact.points_per_joint);
  contact.edge_angle_tolerance = c.number("edge_angle_tolerance_deg", contact.edge_angle_tolerance / kDegree) * kDegree;
  contact.search_margin = c.number("search_margin", contact.search_margin);
}

void read_solver(const ObjectReader& c, SolverSettings& sv) {
  sv.local_damping = c.number("local_damping", sv.local_damping);
  sv.time_step_safety = c.number("time_step_safety", sv.time_step_safety);
  sv.time_step = c.number("time_step", sv.time_step);
  sv.time_step_faces = c.string("time_step_faces", sv.time_step_faces);
  sv.time_step_stiffening = c.string("time_step_stiffening", sv.time_step_stiffening);
  sv.density_scaling = c.number("density_scaling", sv.density_scaling);
  sv.equilibrium_ratio = c.number("equilibrium_ratio", sv.equilibrium_ratio);
  sv.max_equilibrium_time = c.number("max_equilibrium_time", sv.max_equilibrium_time);
  sv.max_time = c.number("max_time", sv.max_time);
  sv.collapse_displacement = c.number("collapse_displacement", sv.collapse_displacement);
  sv.max_velocity = c.number("max_velocity", sv.max_velocity);
}

void read_loading(const ObjectReader& c, Loading& l) {
  l.type = c.string("type", l.type);
  if (l.type != "none") {
    l.block = c.string("block");
    l.point = c.vec2("point");
  }
  l.direction = c.vec2("direction", l.direction);
  l.velocity = c.number("velocity", l.velocity);
  l.max_displacement = c.number("max_displacement", l.max_displacement);
  l.stiffness = c.number("stiffness", l.stiffness);
  l.compression_only = c.boolean("compression_only", l.compression_only);
  l.record_interval = c.number("record_interval", l.record_interval);
  if (c.has("constant_forces")) {
    const json& forces = c.required("constant_forces");
    if (!forces.is_array()) throw SceneError(c.key_path("constant_forces"), "expected an array");
    for (std::size_t f = 0; f < forces.size(); ++f) {
      const ObjectReader fr(forces[f], c.key_path("constant_forces[" + std::to_string(f) + "]"));
      l.constant_forces.push_back({fr.string("block"), fr.vec2("force"), fr.vec2("point")});
    }
  }
}

void read_gauges(const json& gauges, const std::string& where, Scene& scene) {
  if (!gauges.is_array()) throw SceneError(where, "expected an array");
  for (std::size_t g = 0; g < gauges.size(); ++g) {
    const ObjectReader gr(gauges[g], where + "[" + std::to_string(g) + "]");
    scene.gauges.push_back({gr.string("name"), gr.string("block"), gr.vec2("point"), gr.vec2("direction", Vec2(1, 0))});
  }
}

// "a and b", "a, b and c": the keys of fields.
std::string and_list(const std::vector<const SceneField*>& fields) {
  std::string s;
  for (std::size_t i = 0; i < fields.size(); ++i)
    s += (i == 0 ? "" : i + 1 == fields.size() ? " and " : ", ") + fields[i]->key();
  return s;
}

// A gap is given by its stored values (the opening and taper) or by the derived ones (its ends),
// each set in turn keeping the others.
void read_joint_gap(const ObjectReader& c, JointGap& gap) {
  gap.joint = c.string("joint");
  const std::vector<const SceneField*> stored = gap_fields(false), derived = gap_fields(true);
  const auto given = [&](const std::vector<const SceneField*>& fields) {
    return std::any_of(fields.begin(), fields.end(), [&](const SceneField* f) { return c.has(f->key()); });
  };
  if (given(stored)) {
    if (given(derived))
      throw SceneError(c.path(), "give the " + and_list(stored) + " or the " + and_list(derived) + " ends, not both");
    for (const SceneField* f : stored) gap.*f->gap = c.number(f->key(), gap.*f->gap);
  } else {
    std::vector<double> values;
    for (const SceneField* f : derived) values.push_back(c.number(f->key(), 0));
    for (std::size_t i = 0; i < derived.size(); ++i)
      check_limits(*derived[i], values[i], c.key_path(derived[i]->key()));
    for (std::size_t i = 0; i < derived.size(); ++i) derived[i]->set_gap(gap, values[i]);
  }
}

}  // namespace

Scene scene_from_json(const json& j, const std::string& source) {
  Scene scene;
  const ObjectReader root(j, source);
  const auto at = [&](const std::string& key) { return source + ": " + key; };
  scene.name = root.string("name", scene.name);
  scene.width = root.number("width", scene.width);
  scene.gravity = root.vec2("gravity", scene.gravity);
  read_joint_groups(root.required("joint_groups"), at("joint_groups"), scene);
  scene.default_joint_group = root.string("default_joint_group", scene.joint_groups.begin()->first);
  if (root.has("joint_group_rules"))
    read_joint_group_rules(root.required("joint_group_rules"), at("joint_group_rules"), scene);
  read_blocks(root.required("blocks"), at("blocks"), scene);
  if (root.has("contact")) read_contact(ObjectReader(root.required("contact"), at("contact")), scene.contact);
  if (root.has("solver")) read_solver(ObjectReader(root.required("solver"), at("solver")), scene.solver);
  if (root.has("loading")) read_loading(ObjectReader(root.required("loading"), at("loading")), scene.loading);
  if (root.has("gauges")) read_gauges(root.required("gauges"), at("gauges"), scene);
  if (root.has("joint_gap")) read_joint_gap(ObjectReader(root.required("joint_gap"), at("joint_gap")), scene.joint_gap);
  scene.Validate(source);
  return scene;
}

json scene_to_json(const Scene& scene) {
  json j;
  j["format"] = "demcal-scene";
  j["version"] = 1;
  j["name"] = scene.name;
  j["width"] = scene.width;
  j["gravity"] = vec2_json(scene.gravity);
  for (const auto& [group, m] : scene.joint_groups) {
    json g = {{"kn", m.normal_stiffness}, {"ks", m.shear_stiffness}, {"friction_deg", m.friction_angle / kDegree}};
    // Effect keys appear only when set, so a scene without effects keeps its text and its hash.
    for_each_effect_field([&, &m = m](const Effect&, const SceneField& f) {
      if (f.material && (f.written ? f.written(m) : m.*f.material != 0)) g[f.key()] = given_value(f, m.*f.material);
    });
    j["joint_groups"][group] = g;
  }
  j["default_joint_group"] = scene.default_joint_group;
  j["joint_group_rules"] = json::array();
  for (const auto& r : scene.joint_group_rules)
    j["joint_group_rules"].push_back({{"labels", {r.label_a, r.label_b}}, {"orientation", r.orientation},
                                      {"joint_group", r.joint_group}});
  j["blocks"] = json::array();
  for (const Block& b : scene.blocks) {
    json vertices = json::array();
    for (const Vec2& v : b.vertices) vertices.push_back(vec2_json(v));
    json block = {{"name", b.name}, {"label", b.label}, {"density", b.density}, {"vertices", vertices}};
    if (b.fixed) block["fixed"] = true;
    if (b.fixed_rotation) block["fixed_rotation"] = true;
    if (!b.gravity) block["gravity"] = false;
    for_each_effect_field([&](const Effect&, const SceneField& f) {
      if (f.block && b.*f.block != 0) block[f.key()] = b.*f.block;
    });
    j["blocks"].push_back(block);
  }
  j["contact"] = {{"points_per_joint", scene.contact.points_per_joint},
                  {"edge_angle_tolerance_deg", scene.contact.edge_angle_tolerance / kDegree},
                  {"search_margin", scene.contact.search_margin}};
  const SolverSettings& sv = scene.solver;
  j["solver"] = {{"local_damping", sv.local_damping},         {"time_step_safety", sv.time_step_safety},
                 {"time_step", sv.time_step},                 {"density_scaling", sv.density_scaling},
                 {"equilibrium_ratio", sv.equilibrium_ratio}, {"max_equilibrium_time", sv.max_equilibrium_time},
                 {"max_time", sv.max_time},                   {"collapse_displacement", sv.collapse_displacement},
                 {"max_velocity", sv.max_velocity}};
  // Always written: the default changed from "all" to "in_contact", so a scene's hash (the archive's
  // key of its runs) must tell the two apart.
  j["solver"]["time_step_faces"] = sv.time_step_faces;
  if (sv.time_step_stiffening != SolverSettings{}.time_step_stiffening)
    j["solver"]["time_step_stiffening"] = sv.time_step_stiffening;
  const Loading& l = scene.loading;
  j["loading"] = {{"type", l.type}};
  if (l.type != "none")
    j["loading"].update({{"block", l.block}, {"point", vec2_json(l.point)}, {"direction", vec2_json(l.direction)},
                         {"velocity", l.velocity}, {"max_displacement", l.max_displacement},
                         {"stiffness", l.stiffness}, {"compression_only", l.compression_only},
                         {"record_interval", l.record_interval}});
  if (!l.constant_forces.empty()) {
    j["loading"]["constant_forces"] = json::array();
    for (const auto& f : l.constant_forces)
      j["loading"]["constant_forces"].push_back({{"block", f.block}, {"force", vec2_json(f.force)}, {"point", vec2_json(f.point)}});
  }
  j["gauges"] = json::array();
  for (const Gauge& g : scene.gauges)
    j["gauges"].push_back({{"name", g.name}, {"block", g.block}, {"point", vec2_json(g.point)},
                           {"direction", vec2_json(g.direction)}});
  if (scene.joint_gap.on()) {
    j["joint_gap"] = {{"joint", scene.joint_gap.joint}};
    for (const SceneField* f : gap_fields(false)) j["joint_gap"][f->key()] = scene.joint_gap.*f->gap;
  }
  return j;
}

Scene load_scene(const std::string& path) {
  if (auto m = limits::check_file_size(path)) throw SceneError(path, *m);
  std::ifstream in(path);
  if (!in) throw SceneError(path, "cannot open the scene file");
  json j;
  try {
    j = json::parse(in);
  } catch (const json::parse_error& e) {
    throw SceneError(path, std::string("invalid JSON: ") + e.what());
  }
  return scene_from_json(j, path);
}

void save_scene(const Scene& scene, const std::string& path) {
  std::ofstream out(path);
  if (!out) throw SceneError(path, "cannot write the scene file");
  out << scene_to_json(scene).dump(2) << "\n";
  if (!out) throw SceneError(path, "writing the scene file failed");
}

std::string scene_hash(const Scene& scene) {
  const std::string text = scene_to_json(scene).dump();
  std::uint64_t h = 1469598103934665603ull;  // FNV-1a 64
  for (unsigned char c : text) {
    h ^= c;
    h *= 1099511628211ull;
  }
  std::ostringstream s;
  s << std::hex << std::setw(16) << std::setfill('0') << h;
  return s.str();
}

namespace {

// Splits "group.kn" into ("group", "kn"); a bare "kn" gives ("", "kn").
std::pair<std::string, std::string> split_parameter(const std::string& name) {
  const auto dot = name.rfind('.');
  if (dot == std::string::npos) return {"", name};
  return {name.substr(0, dot), name.substr(dot + 1)};
}

// The plain law's joint-group parameters; the effects' follow them.
const std::vector<std::string>& base_joint_fields() {
  static const std::vector<std::string> fields = {"kn", "ks", "friction_deg"};
  return fields;
}
const std::vector<std::string>& joint_fields() {
  static const std::vector<std::string> fields = [] {
    std::vector<std::string> all = base_joint_fields();
    for_each_effect_field([&](const Effect&, const SceneField& f) {
      if (f.material) all.push_back(f.name);
    });
    return all;
  }();
  return fields;
}
bool contains(const std::vector<std::string>& list, const std::string& x) {
  return std::find(list.begin(), list.end(), x) != list.end();
}
double& base_field(JointMaterial& m, const std::string& field) {
  if (field == "kn") return m.normal_stiffness;
  if (field == "ks") return m.shear_stiffness;
  return m.friction_angle;
}

// An effect's field of that name, with its effect; null where no effect declares it.
struct EffectField {
  const Effect* effect = nullptr;
  const SceneField* field = nullptr;
};
EffectField find_effect_field(const std::string& name) {
  EffectField found;
  for_each_effect_field([&](const Effect& e, const SceneField& f) {
    if (!found.field && f.name == name) found = {&e, &f};
  });
  return found;
}

// Where a parameter name points: joint groups, blocks or the joint gap.
struct ParameterTarget {
  enum class Kind { groups, blocks, gap } kind = Kind::groups;
  std::vector<std::string> names;  // groups or blocks
  std::string field;
  EffectField effect;  // none for the plain law's parameters
};

// The blocks a bare name of an effect on blocks sets: every fixed block (support_blocks), the
// loaded block (beam_block); reading, the first fixed block with the effect on, else the first.
// Empty where the scene has none.
std::vector<std::string> default_blocks(const Scene& scene, const Effect& effect, bool for_reading) {
  if (effect.target != EffectTarget::support_blocks) {
    if (scene.loading.type == "none" || scene.block_index(scene.loading.block) < 0) return {};
    return {scene.loading.block};
  }
  std::vector<std::string> names;
  for (const Block& b : scene.blocks)
    if (b.fixed) names.push_back(b.name);
  if (!for_reading || names.empty()) return names;
  for (const Block& b : scene.blocks)
    if (b.fixed && effect_on_block(effect, b)) return {b.name};
  return {names.front()};
}

std::vector<std::string> block_field_names(const Effect& effect) {
  std::vector<std::string> names;
  for (const SceneField& f : effect.scene_fields)
    if (f.block) names.push_back(f.name);
  return names;
}

// Every parameter name, for the message refusing an unknown one.
std::string expected_parameters() {
  std::string joint;
  for (const auto& field : joint_fields()) joint += (joint.empty() ? "" : ", ") + field;
  std::vector<std::string> items = {joint + " [as <joint group>.<name> for one group]"};
  for (const Effect& effect : effect_registry()) {
    const std::vector<std::string> names = block_field_names(effect);
    if (names.empty()) continue;
    if (effect.target == EffectTarget::support_blocks) {
      std::string alternatives;
      for (const auto& name : names) alternatives += (alternatives.empty() ? "" : "|") + name;
      items.push_back("<block>." + alternatives);
    } else {
      items.insert(items.end(), names.begin(), names.end());
    }
  }
  for_each_effect_field([&](const Effect&, const SceneField& f) {
    if (on_gap(f)) items.push_back(f.name);
  });
  std::string list;
  for (std::size_t i = 0; i < items.size(); ++i)
    list += (i == 0 ? "" : i + 1 == items.size() ? " or " : ", ") + items[i];
  return list;
}

ParameterTarget resolve(const Scene& scene, const std::string& name, bool for_reading) {
  const auto [prefix, field] = split_parameter(name);
  const std::string where = "parameter '" + name + "'";
  ParameterTarget t;
  t.field = field;
  t.effect = find_effect_field(field);
  const SceneField* effect_field = t.effect.field;
  if (contains(base_joint_fields(), field) || (effect_field && effect_field->material)) {
    if (prefix.empty()) {
      if (scene.joint_groups.empty()) throw SceneError(where, "the scene has no joint groups");
      if (for_reading)
        t.names = {scene.default_joint_group.empty() ? scene.joint_groups.begin()->first : scene.default_joint_group};
      else
        for (const auto& [g, m] : scene.joint_groups) t.names.push_back(g);
    } else {
      if (!scene.joint_groups.count(prefix)) throw SceneError(where, "unknown joint group '" + prefix + "'");
      t.names = {prefix};
    }
    return t;
  }
  if (effect_field && effect_field->block) {
    t.kind = ParameterTarget::Kind::blocks;
    const Effect& effect = *t.effect.effect;
    const bool fixed = effect.target == EffectTarget::support_blocks;  // else a free block
    if (!prefix.empty()) {
      const int i = scene.block_index(prefix);
      if (i < 0) throw SceneError(where, "unknown block '" + prefix + "'");
      if (scene.blocks[i].fixed != fixed)
        throw SceneError(where, effect.block_texts.needs + "; '" + prefix + "' is " + (fixed ? "free" : "fixed"));
      t.names = {prefix};
    } else {
      t.names = default_blocks(scene, effect, for_reading);
      if (t.names.empty()) throw SceneError(where, effect.block_texts.no_default);
    }
    return t;
  }
  if (effect_field) {
    if (!prefix.empty()) throw SceneError(where, "the gap openings take no prefix (the joint is joint_gap.joint)");
    if (!scene.joint_gap.on()) throw SceneError(where, "the scene names no gap joint (set joint_gap.joint first)");
    t.kind = ParameterTarget::Kind::gap;
    return t;
  }
  throw SceneError(where, "unknown parameter (expected " + expected_parameters() + ")");
}

}  // namespace

std::string parameter_field(const std::string& name) { return split_parameter(name).second; }

void set_parameter(Scene& scene, const std::string& name, double value) {
  const ParameterTarget t = resolve(scene, name, false);  // rejects unknown names before anything changes
  if (!std::isfinite(value)) throw SceneError("parameter '" + name + "'", "value is not finite");
  const SceneField* f = t.effect.field;
  switch (t.kind) {
    case ParameterTarget::Kind::groups: {
      const double held = f ? held_value(*f, value) : t.field == "friction_deg" ? value * kDegree : value;
      for (const auto& g : t.names) {
        JointMaterial& m = scene.joint_groups.at(g);
        if (!f) {
          base_field(m, t.field) = held;
          continue;
        }
        m.*f->material = held;
        if (f->clears) m.*f->clears = 0;  // the other form of the same value
      }
      return;
    }
    case ParameterTarget::Kind::blocks:
      for (const auto& b : t.names) scene.blocks[scene.block_index(b)].*f->block = value;
      return;
    case ParameterTarget::Kind::gap:
      if (f->derived()) {
        check_limits(*f, value, "parameter '" + name + "'");
        f->set_gap(scene.joint_gap, value);
      } else {
        scene.joint_gap.*f->gap = value;
      }
      return;
  }
}

double get_parameter(const Scene& scene, const std::string& name) {
  const ParameterTarget t = resolve(scene, name, true);
  const SceneField* f = t.effect.field;
  switch (t.kind) {
    case ParameterTarget::Kind::groups: {
      JointMaterial m = scene.joint_groups.at(t.names.front());
      if (f) return given_value(*f, m.*f->material);
      const double v = base_field(m, t.field);
      return t.field == "friction_deg" ? v / kDegree : v;
    }
    case ParameterTarget::Kind::blocks:
      return scene.blocks[scene.block_index(t.names.front())].*f->block;
    case ParameterTarget::Kind::gap:
      return f->derived() ? f->get_gap(scene.joint_gap) : scene.joint_gap.*f->gap;
  }
  return 0;
}

std::vector<std::string> parameter_names(const Scene& scene) {
  std::vector<std::string> names = joint_fields();
  for (const auto& [group, m] : scene.joint_groups)
    for (const auto& field : joint_fields()) names.push_back(group + "." + field);
  for (const Effect& effect : effect_registry()) {
    const std::vector<std::string> fields = block_field_names(effect);
    if (fields.empty()) continue;
    if (effect.target == EffectTarget::support_blocks) {  // per fixed block, then bare for every one
      for (const Block& b : scene.blocks)
        if (b.fixed)
          for (const auto& field : fields) names.push_back(b.name + "." + field);
      if (!default_blocks(scene, effect, false).empty()) names.insert(names.end(), fields.begin(), fields.end());
    } else {  // bare for the loaded block, then per free block with the effect on
      if (!default_blocks(scene, effect, false).empty()) names.insert(names.end(), fields.begin(), fields.end());
      for (const Block& b : scene.blocks)
        if (!b.fixed && effect_on_block(effect, b))
          for (const auto& field : fields) names.push_back(b.name + "." + field);
    }
  }
  if (scene.joint_gap.on())
    for_each_effect_field([&](const Effect&, const SceneField& f) {
      if (on_gap(f)) names.push_back(f.name);
    });
  return names;
}

}  // namespace demcal::dem
