// Contact law at one contact node (internal header). The integrator calls only evaluate():
// MohrCoulombLaw for a joint group with every effect off (the plain law, kept bit-identical), and
// EffectLaw with its per-node history when a group has any effect of JointMaterial on.
#pragma once

#include "demcal/dem/scene.hpp"

#include <algorithm>
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
  // N by which the trial shear exceeded the limit (0 while sticking): the node slid excess / (ks A)
  // in this step. The joint's slip report sums it and divides once (Engine::apply_pair_sums).
  double excess_shear = 0;
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
      f.excess_shear = std::abs(trial) - limit;
    } else {
      f.shear = trial;
    }
    shear_state = f.shear;
    return f;
  }

 private:
  double kn_, ks_, tan_phi_;
};

// History of one contact node under EffectLaw.
struct NodeHistory {
  double slip = 0;             // m, accumulated sliding (friction-softening)
  double plastic_closure = 0;  // m, permanent closure after crushing (crushing-cap)
  bool bonded = false;         // an unbroken bond (cohesion); set for nodes present at the start
};

// Mohr-Coulomb with the joint-group effects of JointMaterial: hyperbolic closure, friction
// softening with slip, brittle cohesion and tension, and a crushing cap with softening.
// Order per node: elastic closure = penetration - plastic closure; normal force from the closure
// law (tension allowed only while bonded); the crushing cap; the tension bond check; then the
// shear trial against c A (bonded) + tan(phi(slip)) Fn, breaking the bond when exceeded.
class EffectLaw {
 public:
  explicit EffectLaw(const JointMaterial& m)
      : kn_(m.normal_stiffness),
        ks_(m.shear_stiffness),
        tan_peak_(std::tan(m.friction_angle)),
        tan_residual_(std::tan(m.residual_friction())),
        slip_softening_(m.slip_softening),
        closure_max_(m.closure_max),
        cohesion_(m.cohesion),
        tensile_strength_(m.tensile_strength),
        compressive_strength_(m.compressive_strength),
        crushing_softening_(m.crushing_softening) {
    if (closure_max_ > 0) {
      closure_switch_ = closure_max_ * (1 - 1 / std::sqrt(JointMaterial::kClosureStiffening));
      stress_switch_ = kn_ * closure_switch_ / (1 - closure_switch_ / closure_max_);
    }
  }

  bool bonds() const { return cohesion_ > 0 || tensile_strength_ > 0; }

  // Normal stress (Pa) for an elastic closure d (m); tension (d < 0) stays linear.
  double normal_stress(double d) const {
    if (closure_max_ <= 0 || d <= 0) return kn_ * d;
    if (d <= closure_switch_) return kn_ * d / (1 - d / closure_max_);
    return stress_switch_ + JointMaterial::kClosureStiffening * kn_ * (d - closure_switch_);
  }
  // Inverse of normal_stress for a compressive stress s >= 0.
  double elastic_closure(double s) const {
    if (closure_max_ <= 0) return s / kn_;
    if (s <= stress_switch_) return s / (kn_ + s / closure_max_);
    return closure_switch_ + (s - stress_switch_) / (JointMaterial::kClosureStiffening * kn_);
  }

  NodeForces evaluate(const NodeKinematics& k, double& shear_state, NodeHistory& h) const {
    NodeForces f;
    const double elastic = k.penetration - h.plastic_closure;
    if (elastic <= 0 && !h.bonded) {  // open node: no force, shear memory lost
      shear_state = 0;
      return f;
    }
    double stress = normal_stress(elastic);
    if (compressive_strength_ > 0 && stress > 0) {
      const double strength =
          crushing_softening_ > 0
              ? compressive_strength_ * std::max(0.0, 1 - h.plastic_closure / crushing_softening_)
              : compressive_strength_;
      if (stress > strength) {  // crushing: the elastic part holds the strength, the rest is permanent
        stress = strength;
        h.plastic_closure = k.penetration - elastic_closure(strength);
      }
    }
    if (h.bonded && stress < -tensile_strength_) h.bonded = false;
    if (!h.bonded && stress <= 0) {
      shear_state = 0;
      return f;
    }
    f.normal = stress * k.area;
    const double ks_area = ks_ * k.area;
    const double trial = shear_state - ks_area * k.shear_increment;
    double tan_phi = tan_peak_;
    if (slip_softening_ > 0)
      tan_phi = tan_residual_ + (tan_peak_ - tan_residual_) * std::max(0.0, 1 - h.slip / slip_softening_);
    double limit = tan_phi * f.normal + (h.bonded ? cohesion_ * k.area : 0.0);
    if (h.bonded && std::abs(trial) > limit) {  // the bond fails in shear: plain friction from now on
      h.bonded = false;
      if (f.normal <= 0) {
        shear_state = 0;
        return NodeForces{};
      }
      limit = tan_phi * f.normal;
    }
    if (std::abs(trial) > limit) {
      f.shear = std::copysign(limit, trial);
      f.excess_shear = std::abs(trial) - limit;
      h.slip += f.excess_shear / ks_area;
    } else {
      f.shear = trial;
    }
    shear_state = f.shear;
    return f;
  }

 private:
  double kn_, ks_, tan_peak_, tan_residual_, slip_softening_, closure_max_;
  double cohesion_, tensile_strength_, compressive_strength_, crushing_softening_;
  double closure_switch_ = 0, stress_switch_ = 0;
};

}  // namespace demcal::dem
