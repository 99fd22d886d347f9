// Contact law at one contact node (internal header). The integrator calls only evaluate(); new
// effects (cohesion, tension cut-off, residual friction, nonlinear closure, crushing cap) change
// this file and JointMaterial, never the integrator.
#pragma once

#include "demcal/dem/scene.hpp"

#include <cmath>

namespace demcal::dem {

// Per-node inputs in the contact frame: penetration (m, > 0 when the surfaces overlap), the shear
// displacement increment of this step along the contact tangent (m) and the node's tributary area (m^2).
struct NodeKinematics {
  double penetration = 0;
  double shear_increment = 0;
  double area = 0;
};

struct NodeForces {
  double normal = 0;         // N, compression positive
  double shear = 0;          // N along the contact tangent, acting on the second block
  double plastic_slip = 0;   // m of sliding in this step (0 while sticking)
};

// Mohr-Coulomb, no cohesion, no tension: Fn = kn A pen; Fs incremental with ks A, capped at Fn tan(phi).
// `shear_state` is the node's stored shear force (N), updated in place.
class MohrCoulombLaw {
 public:
  explicit MohrCoulombLaw(const JointMaterial& m)
      : kn_(m.normal_stiffness), ks_(m.shear_stiffness), tan_phi_(std::tan(m.friction_angle)) {}

  NodeForces evaluate(const NodeKinematics& k, double& shear_state) const {
    NodeForces f;
    if (k.penetration <= 0) {  // open node: no force, shear memory lost
      shear_state = 0;
      return f;
    }
    f.normal = kn_ * k.area * k.penetration;
    const double trial = shear_state - ks_ * k.area * k.shear_increment;
    const double limit = tan_phi_ * f.normal;
    if (std::abs(trial) > limit) {
      f.shear = std::copysign(limit, trial);
      f.plastic_slip = (std::abs(trial) - limit) / (ks_ * k.area);
    } else {
      f.shear = trial;
    }
    shear_state = f.shear;
    return f;
  }

 private:
  double kn_, ks_, tan_phi_;
};

}  // namespace demcal::dem
