// crushing-cap's law (effect crushing-cap, effect_crushing_cap.cpp), for the contact law
// (contact_law.hpp): the largest normal stress at a node after its plastic closure, falling linearly
// from compressive_strength to zero over crushing_softening (constant where that is 0). Off while
// compressive_strength is 0; the contact law turns the closure beyond the cap into plastic closure.
#pragma once

#include "demcal/dem/scene.hpp"

#include <algorithm>

namespace demcal::dem {

class CrushingCap {
 public:
  explicit CrushingCap(const JointMaterial& m) : strength_(m.compressive_strength), softening_(m.crushing_softening) {}

  bool on() const { return strength_ > 0; }
  // The cap (Pa) after `plastic_closure` (m).
  double strength(double plastic_closure) const {
    return softening_ > 0 ? strength_ * std::max(0.0, 1 - plastic_closure / softening_) : strength_;
  }

 private:
  double strength_, softening_;
};

}  // namespace demcal::dem
