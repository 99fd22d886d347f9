// friction-softening's law (effect friction-softening, effect_friction_softening.cpp), for the
// contact law (contact_law.hpp): the friction coefficient after a node's accumulated slip, falling
// linearly from tan(friction_angle) to tan(residual_friction()) over slip_softening; the peak's
// while slip_softening is 0 (off).
#pragma once

#include "demcal/dem/scene.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::dem {

class FrictionSoftening {
 public:
  explicit FrictionSoftening(const JointMaterial& m)
      : tan_peak_(std::tan(m.friction_angle)),
        tan_residual_(std::tan(m.residual_friction())),
        slip_softening_(m.slip_softening) {}

  // tan(phi) after `slip` (m) of sliding. By reference, so that the node's slip is read only where
  // softening is on: by value the node loop's machine code changed (2 % more instructions).
  double tan_friction(const double& slip) const {
    double tan_phi = tan_peak_;
    if (slip_softening_ > 0)
      tan_phi = tan_residual_ + (tan_peak_ - tan_residual_) * std::max(0.0, 1 - slip / slip_softening_);
    return tan_phi;
  }

 private:
  double tan_peak_, tan_residual_, slip_softening_;
};

}  // namespace demcal::dem
