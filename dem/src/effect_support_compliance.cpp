// support-compliance: a support on elastic springs instead of rigid (Block::support_kx, ky, kr; the
// law: the springs of the integrator, simulation.cpp).
#include "effect_definitions.hpp"

#include <algorithm>

namespace demcal::dem::effects {

Effect support_compliance() {
  Effect e{"support-compliance", "a support (abutment, base) on elastic springs instead of rigid",
           EffectTarget::support_blocks,
           {EffectParameter{"support_kx", "N/m", "horizontal spring of the support", 0, kInf, 1e6, 1e10, true, 1e8},
            EffectParameter{"support_ky", "N/m", "vertical spring of the support", 0, kInf, 1e6, 1e10, true, 1e8},
            EffectParameter{"support_kr", "N m/rad", "rotational spring of the support about its centroid", 0, kInf,
                            1e5, 1e9, true, 1e7}}};
  e.scene_fields = {{.name = "support_kx", .unit = "N/m", .block = &Block::support_kx},
                    {.name = "support_ky", .unit = "N/m", .block = &Block::support_ky},
                    {.name = "support_kr", .unit = "N m/rad", .block = &Block::support_kr}};
  e.flags = {{"support_kx", "--support-kx", "support-compliance: horizontal support spring (N/m)"},
             {"support_ky", "--support-ky", "support-compliance: vertical support spring (N/m)"},
             {"support_kr", "--support-kr", "support-compliance: rotational support spring (N m/rad)"},
             {.option = "support_blocks",
              .flag = "--support-blocks",
              .help = "support-compliance: comma-separated supports (default: every fixed block, {fixed blocks})",
              .names_target = true}};
  e.block_texts = {.misplaced = "support springs (support_kx, support_ky, support_kr) apply to fixed blocks only",
                   .needs = "support springs need a fixed block",
                   .no_default = "the scene has no fixed block"};
  e.enabled = [](const Scene& scene) {
    return std::any_of(scene.blocks.begin(), scene.blocks.end(), [](const Block& b) { return b.compliant_support(); });
  };
  e.finding = [](const FittedEffect& fit) -> std::string {
    std::string s = "the supports yield elastically instead of being rigid";
    if (const auto kx = fit.effect_value("support_kx"))
      s += ": horizontal stiffness about " + format_number(*kx / 1e6, 3) + " MN/m (a 10 kN thrust moves it by about " +
           format_number(1e4 / *kx * 1e3, 3) + " mm)";
    if (const auto ky = fit.effect_value("support_ky")) s += ", vertical about " + format_number(*ky / 1e6, 3) + " MN/m";
    if (const auto kr = fit.effect_value("support_kr"))
      s += ", rotational about " + format_number(*kr / 1e3, 3) + " kN·m/rad";
    return s;
  };
  return e;
}

}  // namespace demcal::dem::effects
