// shear-stiffening's law (effect shear-stiffening, effect_shear_stiffening.cpp), for the contact law
// (contact_law.hpp): the factor on a node's shear stiffness at normal stress s, 1 + s / stress,
// at most JointMaterial::kShearStiffening (which bounds how short the explicit step can become); 1
// while off or in tension.
#pragma once

#include "demcal/dem/scene.hpp"

#include <algorithm>

namespace demcal::dem {

class ShearStiffening {
 public:
  explicit ShearStiffening(const JointMaterial& m) : stress_(m.shear_stiffening_stress) {}

  bool on() const { return stress_ > 0; }
  double factor(double normal_stress) const {
    if (!on() || normal_stress <= 0) return 1.0;
    return std::min(JointMaterial::kShearStiffening, 1 + normal_stress / stress_);
  }

 private:
  double stress_;
};

}  // namespace demcal::dem
