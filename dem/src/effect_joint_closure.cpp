// joint-closure: rough joints that stiffen as they close (JointMaterial::closure_max; the law:
// effect_joint_closure_law.hpp).
#include "effect_definitions.hpp"

namespace demcal::dem::effects {

namespace {
constexpr double kMaxClosure = 0.01;  // m: rough-joint closures are micrometres to a millimetre
}  // namespace

Effect joint_closure() {
  Effect e{"joint-closure", "rough joints stiffen as they close (Bandis-Barton hyperbola); kn is the initial stiffness",
           EffectTarget::joint_groups,
           {EffectParameter{"closure_max", "m", "maximum closure of the joint (asymptote of the hyperbola)", 0,
                            kMaxClosure, 1e-5, 1e-3, true, 1e-4}}};
  e.scene_fields = {{.name = "closure_max",
                     .unit = "m",
                     .material = &JointMaterial::closure_max,
                     .upper = kMaxClosure,
                     .reason = "m; a rough joint closes by at most millimetres"}};
  e.flags = {{"closure_max", "--closure-max", "joint-closure: maximum joint closure, every joint group (m)"}};
  e.enabled = [](const Scene& scene) { return any_joint_group(scene, &JointMaterial::closure_on); };
  e.finding = [](const FittedEffect& fit) -> std::string {
    const auto closure = fit.effect_value("closure_max");
    if (!closure) return "";
    return "the joints are rough and close nonlinearly: they stiffen as they close, up to a maximum closure of about " +
           format_number(*closure * 1e3, 3) + " mm";
  };
  return e;
}

}  // namespace demcal::dem::effects
