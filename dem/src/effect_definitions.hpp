// The effects of effects.hpp, one file each (effect_<name>.cpp): its parameters with units, bounds
// and search ranges, whether a scene has it on, and its finding in a verdict. The law itself is
// the scene's (scene.hpp) and the contact law's. A new effect is one more file and one line in
// effects.cpp's registry.
#pragma once

#include "demcal/common/format.hpp"
#include "demcal/dem/effects.hpp"

#include <algorithm>
#include <limits>

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

}  // namespace demcal::dem::effects
