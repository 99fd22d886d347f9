#include "demcal/dem/effects.hpp"
#include "effect_definitions.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::dem {

namespace {

std::vector<Effect> build_registry() {
  return {effects::joint_closure(),      effects::friction_softening(), effects::cohesion(),
          effects::crushing_cap(),       effects::support_compliance(), effects::joint_gap(),
          effects::boundary_restraint(), effects::shear_stiffening()};
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

namespace {

// Whether `p` has a structure-relative range and the structure's stress is known.
bool scale_applies(const EffectParameter& p, const ResponseScales& scales) {
  return p.search_scale != SearchScale::absolute && scales.peak_normal_stress > 0 && std::isfinite(scales.peak_normal_stress);
}

}  // namespace

EffectParameter scaled_search_range(const EffectParameter& p, const ResponseScales& scales) {
  EffectParameter out = p;
  if (scale_applies(p, scales)) {
    const bool strength = p.search_scale == SearchScale::peak_normal_stress;
    const double start = strength && std::isfinite(scales.start_normal_stress) ? scales.start_normal_stress : 0.0;
    out.search_max = std::clamp(p.scaled_max * scales.peak_normal_stress, p.lower_bound, p.upper_bound);
    out.search_min = std::clamp(std::max(p.scaled_min * scales.peak_normal_stress, start), p.lower_bound, p.upper_bound);
    if (!(out.search_min < out.search_max)) out.search_min = out.search_max * p.scaled_min / p.scaled_max;
  }
  return out;
}

std::string scaled_range_words(const EffectParameter& p, const ResponseScales& scales) {
  if (!scale_applies(p, scales)) return "";
  const auto number = [](double v) { return format_number(v, {.significant_digits = 3, .non_finite = "–"}); };
  std::string words = number(p.scaled_min) + " to " + number(p.scaled_max) + " x the largest contact stress of the base fit, " +
                      number(scales.peak_normal_stress) + " Pa";
  if (p.search_scale == SearchScale::peak_normal_stress)
    words += ", and not below the largest at the start of loading, " + number(scales.start_normal_stress) + " Pa";
  return words;
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
          if (!p.capped_by.empty()) value = std::min(value, get_parameter(scene, g + "." + p.capped_by));
          set_parameter(scene, g + "." + p.name, value);
        }
      if (targets.empty()) {
        // One name per parameter sets every group; a capped parameter's default may differ per
        // group (lowered to each group's cap), so it is listed per group where there are several.
        for (const EffectParameter& p : effect.parameters) {
          if (!p.capped_by.empty() && scene.joint_groups.size() > 1) {
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

bool effect_enabled(const Scene& scene, const std::string& name) { return find_effect(name).enabled(scene); }

std::optional<double> FittedEffect::effect_value(const std::string& field) const {
  for (const auto& [name, value] : params)
    if (parameter_field(name) == field && !base_params.count(name)) return value;
  return std::nullopt;
}

std::optional<double> FittedEffect::fitted_value(const std::string& field) const {
  for (const auto& [name, value] : params)
    if (parameter_field(name) == field) return value;
  return std::nullopt;
}

const EffectParameter* Effect::parameter(const std::string& field) const {
  for (const EffectParameter& p : parameters)
    if (p.name == field) return &p;
  return nullptr;
}

std::string describe_fit(const Effect& effect, const FittedEffect& fit) {
  const std::string sentence = effect.finding ? effect.finding(fit) : "";
  return sentence.empty() ? "effect " + effect.name : sentence;
}

}  // namespace demcal::dem
