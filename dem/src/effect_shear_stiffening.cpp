// shear-stiffening: joints whose shear stiffness grows with the normal stress
// (JointMaterial::shear_stiffening_stress; the law: effect_shear_stiffening_law.hpp).
#include "effect_definitions.hpp"

namespace demcal::dem::effects {

namespace {
constexpr double kMaxStiffeningStress = 1e9;  // Pa: beyond any stress a masonry joint carries
}  // namespace

Effect shear_stiffening() {
  // The stress that doubles ks is searched over 0.01 to 3 x the largest contact stress of a run of
  // the plain model: at 0.01 the joints reach the 16-fold cap at a sixth of that stress, at 3 the
  // stiffening stays within a third.
  EffectParameter stress{"shear_stiffening_stress", "Pa", "normal stress that doubles the shear stiffness", 0,
                         kMaxStiffeningStress, 1e4, 1e7, true, 1e6};
  stress.search_scale = SearchScale::stress_level;
  stress.scaled_min = 0.01;
  stress.scaled_max = 3.0;
  Effect e{"shear-stiffening",
           "the joints' shear stiffness grows with the normal stress they carry; ks is the stiffness without it",
           EffectTarget::joint_groups, {stress}};
  e.scene_fields = {{.name = "shear_stiffening_stress",
                     .unit = "Pa",
                     .material = &JointMaterial::shear_stiffening_stress,
                     .upper = kMaxStiffeningStress,
                     .reason = "Pa"}};
  e.flags = {{"shear_stiffening_stress", "--shear-stiffening-stress",
              "shear-stiffening: normal stress that doubles ks, every joint group (Pa)"}};
  e.enabled = [](const Scene& scene) { return any_joint_group(scene, &JointMaterial::shear_stiffening_on); };
  e.finding = [](const FittedEffect& fit) -> std::string {
    const auto stress = fit.effect_value("shear_stiffening_stress");
    if (!stress) return "";
    return "the joints stiffen in shear under pressure: their shear stiffness doubles at a normal stress of about " +
           format_number(*stress / 1e6, 3) + " MPa";
  };
  return e;
}

}  // namespace demcal::dem::effects
