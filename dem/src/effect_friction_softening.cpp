// friction-softening: friction lost with accumulated slip (JointMaterial's residual friction and
// slip_softening; the law: effect_friction_softening_law.hpp).
#include "effect_definitions.hpp"
#include "scene_checks.hpp"

namespace demcal::dem::effects {

namespace {

// An angle of the friction law (rad) in [0, friction_angle]; the upper limit only where `capped`.
void require_within_friction(double angle, double friction_angle, bool capped, const std::string& where) {
  require_finite(angle, where);
  if (angle < 0 || (capped && angle > friction_angle))
    throw SceneError(where, "must be in [0, friction_deg = " + format_number(friction_angle / kDegree, 10) +
                                "] degrees, got " + format_number(angle / kDegree, 10));
}

// The residual as an angle or as the loss from the peak, each at most the peak; one of the two.
void check_residual(const JointMaterial& m, const std::string& where) {
  require_within_friction(m.friction_residual, m.friction_angle, m.softening_on(), where + ".friction_residual_deg");
  require_within_friction(m.friction_loss, m.friction_angle, true, where + ".friction_loss_deg");
  if (m.friction_loss > 0 && m.friction_residual != 0)
    throw SceneError(where + ".friction_loss_deg", "set friction_residual_deg or friction_loss_deg, not both (got " +
                                                       format_number(m.friction_residual / kDegree, 10) + " and " +
                                                       format_number(m.friction_loss / kDegree, 10) + " degrees)");
}

// Written together once any is set: the slip, and the residual in the form it was given (an angle
// of 0 where neither is set).
bool softening_written(const JointMaterial& m) {
  return m.slip_softening != 0 || m.friction_residual != 0 || m.friction_loss != 0;
}
bool residual_angle_written(const JointMaterial& m) { return softening_written(m) && m.friction_loss == 0; }

}  // namespace

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
  e.scene_fields = {{.name = "friction_residual_deg",
                     .unit = "deg",
                     .material = &JointMaterial::friction_residual,
                     .degrees = true,
                     .upper = 90,
                     .bounded_by_rule = true,
                     .clears = &JointMaterial::friction_loss,
                     .written = residual_angle_written},
                    {.name = "friction_loss_deg",
                     .unit = "deg",
                     .material = &JointMaterial::friction_loss,
                     .degrees = true,
                     .upper = 90,
                     .bounded_by_rule = true,
                     .clears = &JointMaterial::friction_residual},
                    {.name = "slip_softening",
                     .unit = "m",
                     .material = &JointMaterial::slip_softening,
                     .written = softening_written}};
  e.flags = {
      {"friction_residual_deg", "--friction-residual-deg", "friction-softening: residual friction angle (degrees)"},
      {"slip_softening", "--slip-softening", "friction-softening: slip to the residual friction (m)"}};
  e.check_material = check_residual;
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
