// joint-gap: one joint open before loading, uniform or wedge-shaped (Scene::joint_gap; the law: the
// gaps of that joint's nodes, simulation.cpp).
#include "effect_definitions.hpp"

namespace demcal::dem::effects {

Effect joint_gap() {
  // As the wider end's opening and a taper (JointGap): a wedge closed at one end, the likelier
  // imperfection, lies inside the taper's range (beyond +-1), not on its face.
  Effect e{"joint-gap", "an initial opening at one joint, uniform or wedge-shaped (imperfect fit, lost mortar)",
           EffectTarget::joint,
           {EffectParameter{"gap_opening", "m", "opening at the wider end of the joint", 0, JointGap::kMaxOpening, 0, 3e-3,
                            false, 5e-4},
            EffectParameter{"gap_taper", "1",
                            "share of the opening closed at the other end: 0 uniform, 1 closed at the intrados, "
                            "-1 at the extrados (beyond 1: 1)",
                            -JointGap::kMaxTaper, JointGap::kMaxTaper, -1.5, 1.5, false, 0}}};
  // The ends, each set keeping the other: the scene file's other form of the opening and taper.
  e.scene_fields = {
      {.name = "gap_intrados",
       .json_key = "intrados",
       .unit = "m",
       .get_gap = [](const JointGap& g) { return g.intrados(); },
       .set_gap = [](JointGap& g, double v) { g.set_ends(v, g.extrados()); }},
      {.name = "gap_extrados",
       .json_key = "extrados",
       .unit = "m",
       .get_gap = [](const JointGap& g) { return g.extrados(); },
       .set_gap = [](JointGap& g, double v) { g.set_ends(g.intrados(), v); }},
      {.name = "gap_opening",
       .json_key = "opening",
       .unit = "m",
       .gap = &JointGap::opening,
       .upper = JointGap::kMaxOpening,
       .reason = "m; a fit imperfection"},
      {.name = "gap_taper",
       .json_key = "taper",
       .unit = "1",
       .gap = &JointGap::taper,
       .lower = -JointGap::kMaxTaper,
       .upper = JointGap::kMaxTaper,
       .reason = "beyond 1 it equals 1"}};
  e.flags = {{.option = "gap_joint",
              .flag = "--gap-joint",
              .help = "joint-gap: the joint, as blockA/blockB",
              .names_target = true},
             {"gap_intrados", "--gap-intrados", "joint-gap: opening at the lower (intrados) end (m)"},
             {"gap_extrados", "--gap-extrados", "joint-gap: opening at the upper (extrados) end (m)"}};
  e.enabled = [](const Scene& scene) { return scene.joint_gap.on(); };
  e.finding = [](const FittedEffect& fit) -> std::string {
    const auto opening = fit.effect_value("gap_opening");
    const auto taper = fit.effect_value("gap_taper");
    if (!opening || !taper) return "";
    const JointGap gap{fit.target, *opening, *taper};
    return "joint " + fit.target + " was already open before loading: about " + format_number(gap.intrados() * 1e3, 3) +
           " mm at the intrados and " + format_number(gap.extrados() * 1e3, 3) +
           " mm at the extrados (imperfect fit or lost mortar)";
  };
  return e;
}

}  // namespace demcal::dem::effects
