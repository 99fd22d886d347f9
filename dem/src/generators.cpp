#include "demcal/dem/generators.hpp"

#include "demcal/dem/effects.hpp"
#include "demcal/common/units.hpp"

#include "demcal/limits/limits.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

namespace demcal::dem {

namespace {

// Below this springing-joint angle above horizontal the abutment's top is the springing face
// extended: twice the contact search's default edge-angle tolerance (10 deg), so that the level
// top and the springing face are never taken for one face.
const double kFlatSpringingAngle = 2 * ContactSettings{}.edge_angle_tolerance;

void check(bool ok, const std::string& flag, const std::string& rule, double value) {
  if (!ok) throw SceneError(flag, rule + ", got " + std::to_string(value));
}

// Refuses a derived count over its limit (demcal/limits): `flags` names what the user typed.
void check_limit(limits::Limit limit, double count, const std::string& flags, const std::string& what) {
  if (auto m = limits::check(limit, count)) throw SceneError(flags, what + ": " + *m);
}

// Rows recorded over the actuator's travel (0: the generator's default interval, always within).
void check_recorded_rows(double record_interval, double max_displacement) {
  if (record_interval > 0)
    check_limit(limits::Limit::recorded_rows, max_displacement / record_interval, "--record-interval",
                limits::number_text(record_interval) + " m over " + limits::number_text(max_displacement) + " m of travel");
}

JointMaterial material(double kn, double ks, double friction_deg) {
  JointMaterial m;
  m.normal_stiffness = kn;
  m.shear_stiffness = ks;
  m.friction_angle = friction_deg * kDegree;
  return m;
}

Vec2 polar(const Vec2& centre, double radius, double angle) {
  return centre + radius * Vec2(std::cos(angle), std::sin(angle));
}

// Straight-sided voussoirs between angles (counter-clockwise polygon).
Block voussoir(const std::string& name, const Vec2& centre, double r_in, double r_out, double from, double to,
               double density) {
  Block b;
  b.name = name;
  b.label = "voussoir";
  b.density = density;
  b.vertices = {polar(centre, r_in, from), polar(centre, r_in, to), polar(centre, r_out, to), polar(centre, r_out, from)};
  return b;
}

Block rectangle(const std::string& name, const std::string& label, double x0, double y0, double x1, double y1,
                double density) {
  Block b;
  b.name = name;
  b.label = label;
  b.density = density;
  b.vertices = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
  return b;
}

Vec2 centroid_of(const Block& b) {
  Vec2 c = Vec2::Zero();
  for (const Vec2& v : b.vertices) c += v;
  return c / static_cast<double>(b.vertices.size());
}

// Refuses an option name that no effect declares (Effect::flags) rather than leave it unread.
void check_effect_option_names(const EffectOptions& e) {
  const auto declared = [](const std::string& option, bool target) {
    for (const Effect& effect : effect_registry())
      for (const EffectFlag& f : effect.flags)
        if (f.option == option && f.names_target == target) return true;
    return false;
  };
  for (const auto& [option, value] : e.values)
    if (!declared(option, false)) throw SceneError("effect option '" + option + "'", "no effect declares it");
  for (const auto& [option, text] : e.targets)
    if (!declared(option, true)) throw SceneError("effect option '" + option + "'", "no effect declares it");
}

// The blocks of a comma-separated list, each as a parameter prefix ("abutment_right."); none: {""},
// the bare names.
std::vector<std::string> block_prefixes(const std::string& list) {
  std::vector<std::string> prefixes;
  for (std::size_t from = 0; from <= list.size();) {
    const std::size_t comma = std::min(list.find(',', from), list.size());
    if (comma > from) prefixes.push_back(list.substr(from, comma - from) + ".");
    from = comma + 1;
  }
  if (prefixes.empty()) prefixes.push_back("");
  return prefixes;
}

}  // namespace

// Each effect's options together: once any of its values is not 0, every one is set, for each of
// its target blocks (none: bare names) or at its joint, in the order the effect declares them.
void apply_effects(Scene& s, const EffectOptions& e) {
  check_effect_option_names(e);
  for (const Effect& effect : effect_registry()) {
    std::string target, target_flag, value_flags;
    std::vector<std::pair<std::string, double>> values;
    bool any_on = false;
    for (const EffectFlag& f : effect.flags) {
      if (f.names_target) {
        if (e.targets.count(f.option)) target = e.targets.at(f.option);
        target_flag = f.flag;
        continue;
      }
      const double value = e.values.count(f.option) ? e.values.at(f.option) : 0.0;
      values.emplace_back(f.option, value);
      any_on = any_on || value != 0;
      value_flags += (value_flags.empty() ? "" : "/") + f.flag;
    }
    if (effect.target == EffectTarget::joint) {
      if (!target.empty())
        s.joint_gap.joint = target;
      else if (any_on)
        throw SceneError(value_flags, "need " + target_flag + " to name the joint");
    }
    if (!any_on) continue;
    const std::vector<std::string> prefixes =
        effect.target == EffectTarget::joint ? std::vector<std::string>{""} : block_prefixes(target);
    for (const auto& prefix : prefixes)
      for (const auto& [option, value] : values) set_parameter(s, prefix + option, value);
  }
  s.Validate(s.name);
}

void ArchOptions::Validate() const {
  check(span > 0 && std::isfinite(span), "--span", "must be positive", span);
  check(rise > 0 && rise <= span / 2 && std::isfinite(rise), "--rise", "must be in (0, span/2]", rise);
  check(thickness > 0 && std::isfinite(thickness), "--thickness", "must be positive", thickness);
  check(width > 0 && std::isfinite(width), "--width", "must be positive", width);
  check(voussoirs >= 3, "--voussoirs", "must be at least 3", voussoirs);
  check_limit(limits::Limit::blocks, voussoirs + 2.0, "--voussoirs", std::to_string(voussoirs) + " voussoirs and 2 abutments");
  check(density > 0 && std::isfinite(density), "--density", "must be positive", density);
  check(kn > 0 && std::isfinite(kn), "--kn", "must be positive", kn);
  check(ks > 0 && std::isfinite(ks), "--ks", "must be positive", ks);
  check(friction_deg >= 0 && friction_deg < 90, "--friction-deg", "must be in [0, 90)", friction_deg);
  check(contacts_per_joint >= 2 && contacts_per_joint <= 200, "--contacts-per-joint", "must be between 2 and 200",
        contacts_per_joint);
  check(load_voussoir >= 1 && load_voussoir <= voussoirs, "--load-voussoir", "must be between 1 and --voussoirs",
        load_voussoir);
  check(velocity > 0 && std::isfinite(velocity), "--velocity", "must be positive", velocity);
  check(max_displacement > 0 && std::isfinite(max_displacement), "--max-displacement", "must be positive", max_displacement);
  check(max_time >= 0 && std::isfinite(max_time), "--max-time", "must not be negative", max_time);
  check(record_interval >= 0 && record_interval <= max_displacement, "--record-interval",
        "must be in [0, --max-displacement]", record_interval);
  check_recorded_rows(record_interval, max_displacement);
  if (load != "point" && load != "none") throw SceneError("--load", "must be point or none, got '" + load + "'");
}

Scene make_arch(const ArchOptions& o) {
  o.Validate();
  Scene s;
  s.name = "arch";
  s.width = o.width;
  const double r_in = (o.span * o.span / 4 + o.rise * o.rise) / (2 * o.rise);
  const double r_out = r_in + o.thickness;
  const Vec2 centre(0, o.rise - r_in);
  const double half_angle = std::asin(o.span / 2 / r_in);
  const double left = std::numbers::pi / 2 + half_angle, step = 2 * half_angle / o.voussoirs;
  s.joint_groups["arch_joints"] = material(o.kn, o.ks, o.friction_deg);
  s.joint_groups["abutment_joints"] = material(o.kn, o.ks, o.friction_deg);
  s.default_joint_group = "arch_joints";
  s.joint_group_rules = {{"voussoir", "voussoir", "any", "arch_joints"},
                         {"voussoir", "abutment", "any", "abutment_joints"}};

  // Abutments: fixed blocks whose face matches the radial springing joint. A steep springing joint
  // (segmental arch) gets a level top beside it; a springing joint close to horizontal (rise near
  // span/2, the semicircle at the limit) would make that top nearly or exactly collinear with the
  // joint (a degenerate, non-convex polygon, and two faces the contact search could confuse), so
  // there the springing face itself is extended outward by abutment_depth.
  const Vec2 i0 = polar(centre, r_in, left), e0 = polar(centre, r_out, left);
  const double d = o.abutment_depth;
  const double springing_tilt = std::numbers::pi - left;  // angle of the springing joint above horizontal
  Block abutment_left;
  abutment_left.name = "abutment_left";
  abutment_left.label = "abutment";
  abutment_left.density = o.density;
  abutment_left.fixed = true;
  if (springing_tilt >= kFlatSpringingAngle) {
    abutment_left.vertices = {i0, e0, {e0.x() - d, e0.y()}, {e0.x() - d, -d}, {i0.x(), -d}};
  } else {
    const Vec2 outer = e0 + d * (e0 - i0).normalized();
    abutment_left.vertices = {i0, outer, {outer.x(), -d}, {i0.x(), -d}};
  }
  s.blocks.push_back(abutment_left);
  for (int k = 0; k < o.voussoirs; ++k)
    s.blocks.push_back(voussoir("voussoir_" + std::to_string(k + 1), centre, r_in, r_out, left - k * step,
                                left - (k + 1) * step, o.density));
  Block abutment_right = abutment_left;
  abutment_right.name = "abutment_right";
  abutment_right.vertices.clear();
  for (auto it = abutment_left.vertices.rbegin(); it != abutment_left.vertices.rend(); ++it)
    abutment_right.vertices.push_back({-it->x(), it->y()});
  s.blocks.push_back(abutment_right);

  s.contact.points_per_joint = o.contacts_per_joint;
  s.solver.collapse_displacement = o.thickness;
  s.solver.max_time = o.max_time > 0 ? o.max_time : o.max_displacement / o.velocity * 1.5 + 5;

  const Block& loaded = s.blocks[o.load_voussoir];  // blocks[0] is the left abutment
  const Vec2 extrados_middle = 0.5 * (loaded.vertices[2] + loaded.vertices[3]);
  const Vec2 load_point = extrados_middle + Vec2(0, o.interface_height);
  if (o.load == "point") {
    s.loading.type = "point";
    s.loading.block = loaded.name;
    s.loading.point = load_point;
    s.loading.direction = Vec2(0, -1);
    s.loading.velocity = o.velocity;
    s.loading.max_displacement = o.max_displacement;
    s.loading.stiffness = o.kn * o.interface_length * o.width;
    s.loading.compression_only = true;
    s.loading.record_interval = o.record_interval > 0 ? o.record_interval : o.max_displacement / 1200;
  }
  s.gauges.push_back({"load_vertical", loaded.name, load_point, Vec2(0, -1)});
  s.gauges.push_back({"abutment_horizontal", s.blocks[1].name, centroid_of(s.blocks[1]), Vec2(1, 0)});
  apply_effects(s, o.effects);
  return s;
}

void SemicircularArchOptions::Validate() const {
  check(radius > 0 && std::isfinite(radius), "--radius", "must be positive", radius);
  check(thickness_ratio > 0 && thickness_ratio < 1, "--thickness-ratio", "must be in (0, 1)", thickness_ratio);
  check(voussoirs >= 3, "--voussoirs", "must be at least 3", voussoirs);
  check_limit(limits::Limit::blocks, voussoirs + 2.0, "--voussoirs", std::to_string(voussoirs) + " voussoirs and 2 supports");
  check(width > 0 && std::isfinite(width), "--width", "must be positive", width);
  check(density > 0 && std::isfinite(density), "--density", "must be positive", density);
  check(kn > 0 && std::isfinite(kn), "--kn", "must be positive", kn);
  check(ks > 0 && std::isfinite(ks), "--ks", "must be positive", ks);
  check(friction_deg >= 0 && friction_deg < 90, "--friction-deg", "must be in [0, 90)", friction_deg);
  check(contacts_per_joint >= 2 && contacts_per_joint <= 200, "--contacts-per-joint", "must be between 2 and 200",
        contacts_per_joint);
}

Scene make_semicircular_arch(const SemicircularArchOptions& o) {
  o.Validate();
  Scene s;
  s.name = "semicircular-arch";
  s.width = o.width;
  const double t = o.thickness_ratio * o.radius;
  const double r_in = o.radius - t / 2, r_out = o.radius + t / 2;
  s.joint_groups["arch_joints"] = material(o.kn, o.ks, o.friction_deg);
  s.default_joint_group = "arch_joints";
  const double step = std::numbers::pi / o.voussoirs;
  s.blocks.push_back(rectangle("base_left", "base", -r_out - t, -t, -r_in + t / 2, 0, o.density));
  s.blocks.back().fixed = true;
  for (int k = 0; k < o.voussoirs; ++k)
    s.blocks.push_back(voussoir("voussoir_" + std::to_string(k + 1), Vec2::Zero(), r_in, r_out,
                                std::numbers::pi - k * step, std::numbers::pi - (k + 1) * step, o.density));
  s.blocks.push_back(rectangle("base_right", "base", r_in - t / 2, -t, r_out + t, 0, o.density));
  s.blocks.back().fixed = true;
  s.contact.points_per_joint = o.contacts_per_joint;
  s.solver.collapse_displacement = 0.05 * o.radius;
  s.solver.max_equilibrium_time = 5;
  s.solver.max_time = 5;
  s.loading.type = "none";
  s.gauges.push_back({"crown_vertical", s.blocks[1 + o.voussoirs / 2].name,
                      centroid_of(s.blocks[1 + o.voussoirs / 2]), Vec2(0, -1)});
  return s;
}

void WallOptions::Validate() const {
  check(height > 0 && std::isfinite(height), "--height", "must be positive", height);
  check(length > 0 && std::isfinite(length), "--length", "must be positive", length);
  check(thickness > 0 && std::isfinite(thickness), "--thickness", "must be positive", thickness);
  check(unit_height > 0 && unit_height <= height, "--unit-height", "must be in (0, height]", unit_height);
  check(unit_length > 0 && unit_length <= length, "--unit-length", "must be in (0, length]", unit_length);
  // Courses x units per course, before a block is made (a wall of 1e6 x 1e6 units is refused here).
  const double courses = std::max(1.0, std::round(height / unit_height)), per_course = std::ceil(length / unit_length) + 1;
  check_limit(limits::Limit::blocks, courses * per_course + 2, "--height/--unit-height/--length/--unit-length",
              "a wall of " + limits::number_text(courses) + " courses of up to " + limits::number_text(per_course) + " units");
  check(density > 0 && std::isfinite(density), "--density", "must be positive", density);
  check(precompression_mpa >= 0 && std::isfinite(precompression_mpa), "--precompression", "must not be negative",
        precompression_mpa);
  check(kn > 0 && std::isfinite(kn), "--kn", "must be positive", kn);
  check(ks > 0 && std::isfinite(ks), "--ks", "must be positive", ks);
  check(friction_deg >= 0 && friction_deg < 90, "--friction-deg", "must be in [0, 90)", friction_deg);
  check(contacts_per_joint >= 2 && contacts_per_joint <= 200, "--contacts-per-joint", "must be between 2 and 200",
        contacts_per_joint);
  check(velocity > 0 && std::isfinite(velocity), "--velocity", "must be positive", velocity);
  check(max_displacement > 0 && std::isfinite(max_displacement), "--max-displacement", "must be positive", max_displacement);
  check(beam_height > 0 && std::isfinite(beam_height), "--beam-height", "must be positive", beam_height);
  check(load_height >= 0 && std::isfinite(load_height), "--load-height", "must not be negative", load_height);
  check(max_time >= 0 && std::isfinite(max_time), "--max-time", "must not be negative", max_time);
  check(actuator_stiffness > 0 && std::isfinite(actuator_stiffness), "--actuator-stiffness", "must be positive",
        actuator_stiffness);
  check(record_interval >= 0 && record_interval <= max_displacement, "--record-interval",
        "must be in [0, --max-displacement]", record_interval);
  check_recorded_rows(record_interval, max_displacement);
}

Scene make_wall(const WallOptions& o) {
  o.Validate();
  Scene s;
  s.name = "wall";
  s.width = o.thickness;
  s.joint_groups["bed_joints"] = material(o.kn, o.ks, o.friction_deg);
  s.joint_groups["head_joints"] = material(o.kn, o.ks, o.friction_deg);
  s.default_joint_group = "bed_joints";
  s.joint_group_rules = {{"unit", "unit", "horizontal", "bed_joints"},
                         {"unit", "unit", "vertical", "head_joints"},
                         {"unit", "base", "any", "bed_joints"},
                         {"unit", "beam", "any", "bed_joints"}};
  const double margin = 0.1 * o.length;
  s.blocks.push_back(rectangle("base", "base", -margin, -o.unit_height, o.length + margin, 0, o.density));
  s.blocks.back().fixed = true;
  const int courses = std::max(1, static_cast<int>(std::lround(o.height / o.unit_height)));
  const double h = o.height / courses;
  for (int c = 0; c < courses; ++c) {
    // Running bond: odd courses start with a half unit. A last piece shorter than a quarter unit
    // is merged into its neighbour (a sliver would be a near-zero-mass block and a tiny time step).
    std::vector<double> edges = {0};
    double x = (c % 2 == 1) ? o.unit_length / 2 : o.unit_length;
    while (x < o.length - o.unit_length / 4) {
      edges.push_back(x);
      x += o.unit_length;
    }
    edges.push_back(o.length);
    for (std::size_t u = 0; u + 1 < edges.size(); ++u)
      s.blocks.push_back(rectangle("unit_c" + std::to_string(c + 1) + "_" + std::to_string(u + 1), "unit", edges[u],
                                   c * h, edges[u + 1], (c + 1) * h, o.density));
  }
  const double top = courses * h;
  s.blocks.push_back(rectangle("beam", "beam", 0, top, o.length, top + o.beam_height, o.density));
  s.blocks.back().gravity = false;
  s.blocks.back().fixed_rotation = !o.beam_rotation;
  const double vertical_force = o.precompression_mpa * 1e6 * o.length * o.thickness;
  s.loading.constant_forces.push_back({"beam", Vec2(0, -vertical_force), Vec2(o.length / 2, top + o.beam_height)});
  s.contact.points_per_joint = o.contacts_per_joint;
  s.solver.collapse_displacement = std::max(0.1, 5 * o.max_displacement);
  s.solver.max_time = o.max_time > 0 ? o.max_time : o.max_displacement / o.velocity * 1.5 + 5;
  const Vec2 load_point(0, top + o.load_height);
  s.loading.type = "wall";
  s.loading.block = "beam";
  s.loading.point = load_point;
  s.loading.direction = Vec2(1, 0);
  s.loading.velocity = o.velocity;
  s.loading.max_displacement = o.max_displacement;
  s.loading.stiffness = o.actuator_stiffness;
  s.loading.compression_only = false;
  s.loading.record_interval = o.record_interval > 0 ? o.record_interval : o.max_displacement / 1000;
  s.gauges.push_back({"top_horizontal", "beam", load_point, Vec2(1, 0)});
  apply_effects(s, o.effects);
  return s;
}

}  // namespace demcal::dem
