// crushing-cap: a compressive strength at the contact points, softening after it
// (JointMaterial::compressive_strength, crushing_softening; the law: effect_crushing_cap_law.hpp).
#include "effect_definitions.hpp"

namespace demcal::dem::effects {

namespace {
constexpr double kMaxCompressiveStrength = 1e9;  // Pa: stronger than any stone
}  // namespace

Effect crushing_cap() {
  // The compressive strength is searched over two decades around the largest contact stress of a
  // run of the plain model: from 0.03 x (the reference arch then keeps a fifth of its peak load) to
  // 3 x, since a base fit that absorbs a cap with weaker joints reaches lower stresses than the
  // structure.
  EffectParameter strength{"compressive_strength", "Pa", "largest normal stress at a contact point", 0,
                           kMaxCompressiveStrength, 1e6, 5e7, true, 1e7};
  strength.search_scale = SearchScale::peak_normal_stress;
  strength.scaled_min = 0.03;
  strength.scaled_max = 3.0;
  // 10 mm of softening is the range's nearest to a perfectly plastic cap (the scene's 0).
  EffectParameter softening{"crushing_softening", "m", "plastic closure over which the strength falls to zero (0: none)",
                            0, kInf, 1e-4, 1e-2, true, 1e-3};
  softening.simplest_form_at_max = true;
  Effect e{"crushing-cap", "compressive strength at the contact points with softening after it (toe crushing)",
           EffectTarget::joint_groups, {strength, softening}};
  e.scene_fields = {{.name = "compressive_strength",
                     .unit = "Pa",
                     .material = &JointMaterial::compressive_strength,
                     .upper = kMaxCompressiveStrength,
                     .reason = "Pa"},
                    {.name = "crushing_softening", .unit = "m", .material = &JointMaterial::crushing_softening}};
  e.flags = {{"compressive_strength", "--compressive-strength", "crushing-cap: compressive strength (Pa)"},
             {"crushing_softening", "--crushing-softening",
              "crushing-cap: plastic closure to zero strength (m; 0 = no softening)"}};
  e.enabled = [](const Scene& scene) { return any_joint_group(scene, &JointMaterial::crushing_on); };
  e.finding = [](const FittedEffect& fit) -> std::string {
    const auto cap = fit.effect_value("compressive_strength");
    if (!cap) return "";
    std::string s = "the masonry crushes where the thrust concentrates (a hinge or the toe) at about " +
                    format_number(*cap / 1e6, 3) + " MPa";
    if (const auto over = fit.effect_value("crushing_softening"))
      s += ", losing its strength over " + format_number(*over * 1e3, 3) + " mm";
    return s;
  };
  return e;
}

}  // namespace demcal::dem::effects
