// The effects of effects.hpp, one file each (effect_<name>.cpp): its parameters with units, bounds
// and search ranges, its values in a scene (SceneField: file keys, where each lives, limits), its
// generator options and `demcal scene` flags, its rules, whether a scene has it on, and its finding
// in a verdict. A new effect is one more file and one line in effects.cpp's registry.
//
// The contact law's arithmetic of the joint-group effects is in inline headers beside them
// (effect_<name>_law.hpp), which the contact law (contact_law.hpp) composes in its per-node order:
// the law is the engine's inner loop, so it calls them directly, with no virtual call or
// std::function per contact node, and its node loop compiles to the same instructions as with the
// arithmetic written in the contact law (docs/engine.md, "One file per effect"). The other effects
// act in the integrator (simulation.cpp): the support and beam springs, and the gap joint's gaps.
#pragma once

#include "demcal/common/format.hpp"
#include "demcal/common/units.hpp"
#include "demcal/dem/effects.hpp"

#include <algorithm>
#include <limits>
#include <numbers>

namespace demcal::dem::effects {

inline constexpr double kInf = std::numeric_limits<double>::infinity();
// Whether any joint group of `scene` has the law `on` switched on (JointMaterial::closure_on, ...).
inline bool any_joint_group(const Scene& scene, bool (JointMaterial::*on)() const) {
  return std::any_of(scene.joint_groups.begin(), scene.joint_groups.end(),
                     [&](const auto& group) { return (group.second.*on)(); });
}

Effect joint_closure();
Effect friction_softening();
Effect cohesion();
Effect crushing_cap();
Effect support_compliance();
Effect joint_gap();
Effect boundary_restraint();
Effect shear_stiffening();

}  // namespace demcal::dem::effects
