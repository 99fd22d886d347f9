// boundary-restraint: a loading beam on a rotational spring (Block::beam_kr; the law: the springs
// of the integrator, simulation.cpp).
#include "effect_definitions.hpp"

#include <algorithm>

namespace demcal::dem::effects {

Effect boundary_restraint() {
  Effect e{"boundary-restraint", "a loading beam neither fixed nor free in rotation: a rotational spring to its start angle",
           EffectTarget::beam_block,
           {EffectParameter{"beam_kr", "N m/rad", "rotational spring of the beam", 0, kInf, 1e4, 1e9, true, 1e6}}};
  e.scene_fields = {{.name = "beam_kr", .unit = "N m/rad", .block = &Block::beam_kr}};
  e.flags = {{.option = "beam_kr",
              .flag = "--beam-kr",
              .help = "boundary-restraint: rotational spring of the loaded block (N m/rad)",
              .help_if_rotation_held = "; frees the beam's rotation against it"}};
  e.block_texts = {.misplaced = "a rotational restraint applies to a free block, not a fixed one",
                   .needs = "beam_kr needs a free block",
                   .no_default = "the scene has no loaded block; name one as <block>.beam_kr"};
  e.enabled = [](const Scene& scene) {
    return std::any_of(scene.blocks.begin(), scene.blocks.end(), [](const Block& b) { return !b.fixed && b.beam_kr > 0; });
  };
  e.finding = [](const FittedEffect& fit) -> std::string {
    const auto kr = fit.effect_value("beam_kr");
    if (!kr) return "";
    return "the loading beam is neither fixed nor free in rotation: a rotational restraint of about " +
           format_number(*kr / 1e3, 3) + " kN·m/rad";
  };
  return e;
}

}  // namespace demcal::dem::effects
