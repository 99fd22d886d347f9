#include "demcal/dem/effects.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace demcal::dem {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::vector<Effect> build_registry() {
  using P = EffectParameter;
  std::vector<Effect> r;
  r.push_back({"joint-closure",
               "rough joints stiffen as they close (Bandis-Barton hyperbola); kn is the initial stiffness",
               EffectTarget::joint_groups,
               {P{"closure_max", "m", "maximum closure of the joint (asymptote of the hyperbola)", 0, 0.01, 1e-5, 1e-3,
                  true, 1e-4}}});
  r.push_back({"friction-softening",
               "friction falls linearly with accumulated slip from its peak to a residual value",
               EffectTarget::joint_groups,
               // The residual as the loss from the peak: friction_deg - friction_loss_deg stays a valid
               // residual whatever friction a calibration tries beside it.
               {P{"friction_loss_deg", "deg", "friction angle lost from the peak to the residual, at most friction_deg",
                  0, 90, 0.5, 25, false, 5},
                P{"slip_softening", "m", "slip over which friction falls to the residual", 0, kInf, 2e-4, 1e-2, true,
                  2e-3}}});
  r.push_back({"cohesion",
               "a bond at the joints present at the start with cohesion and tensile strength, brittle, then Coulomb",
               EffectTarget::joint_groups,
               {P{"cohesion", "Pa", "cohesion of the bond (shear limit c A + tan(phi) Fn)", 0, 1e8, 1e3, 1e6, true,
                  1e5},
                P{"tensile_strength", "Pa", "tensile strength of the bond", 0, 1e8, 1e3, 1e6, true, 5e4}}});
  // The compressive strength is searched over two decades around the largest contact stress of a
  // run of the plain model: from 0.03 x (the reference arch then keeps a fifth of its peak load) to
  // 3 x, since a base fit that absorbs a cap with weaker joints reaches lower stresses than the
  // structure (reference arch with a 0.5 MPa cap: base fit 0.35 MPa, the true joints uncapped 0.83).
  P strength{"compressive_strength", "Pa", "largest normal stress at a contact point", 0, 1e9, 1e6, 5e7, true, 1e7};
  strength.search_scale = SearchScale::peak_normal_stress;
  strength.scaled_min = 0.03;
  strength.scaled_max = 3.0;
  // 10 mm of softening is the range's nearest to a perfectly plastic cap (the scene's 0).
  P softening{"crushing_softening", "m", "plastic closure over which the strength falls to zero (0: none)", 0,
              kInf, 1e-4, 1e-2, true, 1e-3};
  softening.simplest_form_at_max = true;
  r.push_back({"crushing-cap",
               "compressive strength at the contact points with softening after it (toe crushing)",
               EffectTarget::joint_groups,
               {strength, softening}});
  r.push_back({"support-compliance",
               "a support (abutment, base) on elastic springs instead of rigid",
               EffectTarget::support_blocks,
               {P{"support_kx", "N/m", "horizontal spring of the support", 0, kInf, 1e6, 1e10, true, 1e8},
                P{"support_ky", "N/m", "vertical spring of the support", 0, kInf, 1e6, 1e10, true, 1e8},
                P{"support_kr", "N m/rad", "rotational spring of the support about its centroid", 0, kInf, 1e5, 1e9,
                  true, 1e7}}});
  r.push_back({"joint-gap",
               "an initial opening at one joint, uniform or wedge-shaped (imperfect fit, lost mortar)",
               EffectTarget::joint,
               // As the wider end's opening and a taper (JointGap): a wedge closed at one end, the
               // likelier imperfection, lies inside the taper's range (beyond +-1), not on its face.
               {P{"gap_opening", "m", "opening at the wider end of the joint", 0, JointGap::kMaxOpening, 0, 3e-3, false,
                  5e-4},
                P{"gap_taper", "1", "share of the opening closed at the other end: 0 uniform, 1 closed at the intrados, "
                  "-1 at the extrados (beyond 1: 1)", -JointGap::kMaxTaper, JointGap::kMaxTaper, -1.5, 1.5, false, 0}}});
  r.push_back({"boundary-restraint",
               "a loading beam neither fixed nor free in rotation: a rotational spring to its start angle",
               EffectTarget::beam_block,
               {P{"beam_kr", "N m/rad", "rotational spring of the beam", 0, kInf, 1e4, 1e9, true, 1e6}}});
  return r;
}

}  // namespace

std::string to_string(EffectTarget target) {
  switch (target) {
    case EffectTarget::joint_groups: return "joint_groups";
    case EffectTarget::support_blocks: return "support_blocks";
    case EffectTarget::joint: return "joint";
    case EffectTarget::beam_block: return "beam_block";
  }
  return "unknown";
}

EffectParameter scaled_search_range(const EffectParameter& p, const ResponseScales& scales) {
  EffectParameter out = p;
  if (p.search_scale == SearchScale::peak_normal_stress && scales.peak_normal_stress > 0 &&
      std::isfinite(scales.peak_normal_stress)) {
    const double start = std::isfinite(scales.start_normal_stress) ? scales.start_normal_stress : 0.0;
    out.search_max = std::clamp(p.scaled_max * scales.peak_normal_stress, p.lower_bound, p.upper_bound);
    out.search_min = std::clamp(std::max(p.scaled_min * scales.peak_normal_stress, start), p.lower_bound, p.upper_bound);
    if (!(out.search_min < out.search_max)) out.search_min = out.search_max * p.scaled_min / p.scaled_max;
  }
  return out;
}

const std::vector<Effect>& effect_registry() {
  static const std::vector<Effect> registry = build_registry();
  return registry;
}

const Effect& find_effect(const std::string& name) {
  for (const Effect& e : effect_registry())
    if (e.name == name) return e;
  std::string known;
  for (const Effect& e : effect_registry()) known += (known.empty() ? "" : ", ") + e.name;
  throw SceneError("effect '" + name + "'", "unknown effect (known: " + known + ")");
}

std::vector<std::string> enable_effect(Scene& scene, const std::string& name, const std::vector<std::string>& targets) {
  const Effect& effect = find_effect(name);
  const std::string where = "effect '" + name + "'";
  std::vector<std::string> controls;
  switch (effect.target) {
    case EffectTarget::joint_groups: {
      for (const auto& g : targets)
        if (!scene.joint_groups.count(g)) throw SceneError(where, "unknown joint group '" + g + "'");
      std::vector<std::string> groups = targets;
      if (groups.empty())
        for (const auto& [g, m] : scene.joint_groups) groups.push_back(g);
      for (const auto& g : groups)
        for (const EffectParameter& p : effect.parameters) {
          double value = p.default_value;
          if (p.name == "friction_loss_deg")
            value = std::min(value, scene.joint_groups.at(g).friction_angle * 180 / std::numbers::pi);
          set_parameter(scene, g + "." + p.name, value);
        }
      if (targets.empty()) {
        // One name per parameter sets every group; the defaults may differ per group only for
        // the friction loss (lowered to a group's friction angle), so list per group then.
        const bool per_group = name == "friction-softening" && scene.joint_groups.size() > 1;
        for (const EffectParameter& p : effect.parameters) {
          if (per_group && p.name == "friction_loss_deg") {
            for (const auto& g : groups) controls.push_back(g + "." + p.name);
          } else {
            controls.push_back(p.name);
          }
        }
      } else {
        for (const auto& g : groups)
          for (const EffectParameter& p : effect.parameters) controls.push_back(g + "." + p.name);
      }
      break;
    }
    case EffectTarget::support_blocks: {
      std::vector<std::string> blocks = targets;
      if (blocks.empty())
        for (const Block& b : scene.blocks)
          if (b.fixed) blocks.push_back(b.name);
      if (blocks.empty()) throw SceneError(where, "the scene has no fixed block to put on springs");
      for (const auto& b : blocks) {
        const int i = scene.block_index(b);
        if (i < 0) throw SceneError(where, "unknown block '" + b + "'");
        if (!scene.blocks[i].fixed) throw SceneError(where, "block '" + b + "' is not fixed (not a support)");
        for (const EffectParameter& p : effect.parameters) {
          set_parameter(scene, b + "." + p.name, p.default_value);
          controls.push_back(b + "." + p.name);
        }
      }
      break;
    }
    case EffectTarget::joint: {
      if (targets.size() != 1) throw SceneError(where, "name exactly one joint as 'blockA/blockB'");
      scene.joint_gap.joint = targets.front();
      for (const EffectParameter& p : effect.parameters) {
        set_parameter(scene, p.name, p.default_value);
        controls.push_back(p.name);
      }
      break;
    }
    case EffectTarget::beam_block: {
      if (targets.size() > 1) throw SceneError(where, "name at most one beam block");
      for (const EffectParameter& p : effect.parameters) {
        const std::string parameter = targets.empty() ? p.name : targets.front() + "." + p.name;
        set_parameter(scene, parameter, p.default_value);
        controls.push_back(parameter);
      }
      break;
    }
  }
  scene.Validate(where);
  return controls;
}

bool effect_enabled(const Scene& scene, const std::string& name) {
  const Effect& effect = find_effect(name);
  const auto any_group = [&](auto on) {
    return std::any_of(scene.joint_groups.begin(), scene.joint_groups.end(), [&](const auto& g) { return on(g.second); });
  };
  if (name == "joint-closure") return any_group([](const JointMaterial& m) { return m.closure_on(); });
  if (name == "friction-softening") return any_group([](const JointMaterial& m) { return m.softening_on(); });
  if (name == "cohesion") return any_group([](const JointMaterial& m) { return m.cohesion_on(); });
  if (name == "crushing-cap") return any_group([](const JointMaterial& m) { return m.crushing_on(); });
  if (name == "joint-gap") return scene.joint_gap.on();
  if (effect.target == EffectTarget::support_blocks)
    return std::any_of(scene.blocks.begin(), scene.blocks.end(), [](const Block& b) { return b.compliant_support(); });
  return std::any_of(scene.blocks.begin(), scene.blocks.end(), [](const Block& b) { return !b.fixed && b.beam_kr > 0; });
}

}  // namespace demcal::dem
