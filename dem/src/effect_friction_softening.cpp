// friction-softening: friction lost with accumulated slip (JointMaterial's residual friction and
// slip_softening).
#include "effect_definitions.hpp"

namespace demcal::dem::effects {

Effect friction_softening() {
  // The residual as the loss from the peak: friction_deg - friction_loss_deg stays a valid residual
  // whatever friction a calibration tries beside it, the loss capped by that friction.
  EffectParameter loss{"friction_loss_deg", "deg", "friction angle lost from the peak to the residual, at most friction_deg",
                       0, 90, 0.5, 25, false, 5};
  loss.capped_by = "friction_deg";
  Effect e{"friction-softening", "friction falls linearly with accumulated slip from its peak to a residual value",
           EffectTarget::joint_groups,
           {loss, EffectParameter{"slip_softening", "m", "slip over which friction falls to the residual", 0, kInf, 2e-4,
                                  1e-2, true, 2e-3}}};
  e.enabled = [](const Scene& scene) { return any_joint_group(scene, &JointMaterial::softening_on); };
  e.finding = [](const FittedEffect& fit) -> std::string {
    const auto lost = fit.effect_value("friction_loss_deg");
    const auto slip = fit.effect_value("slip_softening");
    if (!lost || !slip) return "";
    std::string s = "friction is lost with sliding: its angle falls by about " + format_number(*lost, 3) + "°";
    if (const auto peak = fit.fitted_value("friction_deg"))
      s += " (from " + format_number(*peak, 3) + "° to " + format_number(*peak - *lost, 3) + "°)";
    return s + " over " + format_number(*slip * 1e3, 3) + " mm of slip";
  };
  return e;
}

}  // namespace demcal::dem::effects
