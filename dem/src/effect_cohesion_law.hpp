// cohesion's law (effect cohesion, effect_cohesion.cpp), for the contact law (contact_law.hpp): a
// node bonded at the start carries tension down to -tensile_strength and shear up to cohesion x
// area beside friction; the contact law breaks the bond for good at the first failure. Off while
// both are 0.
#pragma once

#include "demcal/dem/scene.hpp"

namespace demcal::dem {

class BondLaw {
 public:
  explicit BondLaw(const JointMaterial& m) : cohesion_(m.cohesion), tensile_strength_(m.tensile_strength) {}

  bool on() const { return cohesion_ > 0 || tensile_strength_ > 0; }
  // Whether a bonded node fails in tension under normal stress `stress` (Pa, compression positive).
  bool fails_in_tension(double stress) const { return stress < -tensile_strength_; }
  // The bond's share of a bonded node's shear limit (N) over `area` (m^2).
  double cohesive_force(double area) const { return cohesion_ * area; }

 private:
  double cohesion_, tensile_strength_;
};

}  // namespace demcal::dem
