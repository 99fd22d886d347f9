// cohesion: a brittle bond at the joints (JointMaterial::cohesion, tensile_strength; the law:
// effect_cohesion_law.hpp).
#include "effect_definitions.hpp"

namespace demcal::dem::effects {

namespace {
constexpr double kMaxBondStrength = 1e8;  // Pa: no masonry bond carries 100 MPa
}  // namespace

Effect cohesion() {
  Effect e{"cohesion",
           "a bond at the joints present at the start with cohesion and tensile strength, brittle, then Coulomb",
           EffectTarget::joint_groups,
           {EffectParameter{"cohesion", "Pa", "cohesion of the bond (shear limit c A + tan(phi) Fn)", 0,
                            kMaxBondStrength, 1e3, 1e6, true, 1e5},
            EffectParameter{"tensile_strength", "Pa", "tensile strength of the bond", 0, kMaxBondStrength, 1e3, 1e6,
                            true, 5e4}}};
  e.scene_fields = {
      {.name = "cohesion",
       .unit = "Pa",
       .material = &JointMaterial::cohesion,
       .upper = kMaxBondStrength,
       .reason = "Pa"},
      {.name = "tensile_strength",
       .unit = "Pa",
       .material = &JointMaterial::tensile_strength,
       .upper = kMaxBondStrength,
       .reason = "Pa"}};
  e.flags = {{"cohesion", "--cohesion", "cohesion: bond cohesion (Pa)"},
             {"tensile_strength", "--tensile-strength", "cohesion: bond tensile strength (Pa)"}};
  e.enabled = [](const Scene& scene) { return any_joint_group(scene, &JointMaterial::cohesion_on); };
  e.finding = [](const FittedEffect& fit) -> std::string {
    const auto bond = fit.effect_value("cohesion");
    if (!bond) return "";
    std::string s = "the joints are bonded: a cohesion of about " + format_number(*bond / 1e3, 3) + " kPa";
    if (const auto tension = fit.effect_value("tensile_strength"))
      s += " and a tensile strength of about " + format_number(*tension / 1e3, 3) + " kPa";
    return s + " hold until the first failure of each joint";
  };
  return e;
}

}  // namespace demcal::dem::effects
