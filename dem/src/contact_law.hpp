// Contact law at one contact node (internal header). The integrator calls only evaluate():
// MohrCoulombLaw for a joint group with every effect off (the plain law, kept bit-identical), and
// EffectLaw with its per-node history when a group has any effect of JointMaterial on.
#pragma once

#include "effect_cohesion_law.hpp"
#include "effect_crushing_cap_law.hpp"
#include "effect_friction_softening_law.hpp"
#include "effect_joint_closure_law.hpp"
#include "effect_shear_stiffening_law.hpp"

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
  // Pa/m by which the node's tangent stiffnesses exceed the group's kn and ks (joint-closure,
  // shear-stiffening), for the time step's bound (Engine::critical_time_step); 0 for the plain law
  // and for an EffectLaw that does not report tangents.
  double stiffening_normal = 0, stiffening_shear = 0;
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

// Mohr-Coulomb with the joint-group effects of JointMaterial, each effect's arithmetic from its
// header beside it (effect_<name>_law.hpp): hyperbolic closure, shear stiffness growing with the
// normal stress, friction softening with slip, brittle cohesion and tension, and a crushing cap
// with softening. They are composed here, in the order per node: elastic closure = penetration -
// plastic closure; normal force from the closure law (tension allowed only while bonded); the
// crushing cap; the tension bond check; then the shear trial, with the stiffness at that normal
// stress, against c A (bonded) + tan(phi(slip)) Fn, breaking the bond when exceeded. Direct
// inline calls, as this is the engine's inner loop: the node loop (Engine::process_nodes) compiles
// to the same instructions as with the arithmetic written here, only the members' offsets differ.
class EffectLaw {
 public:
  // `tangents`: fill NodeForces' stiffening fields (only a time step that follows them reads them).
  EffectLaw(const JointMaterial& m, bool tangents)
      : ks_(m.shear_stiffness), tangents_(tangents), closure_(m), stiffening_(m), softening_(m), bond_(m), cap_(m) {}

  bool bonds() const { return bond_.on(); }

  // Normal stress (Pa) for an elastic closure d (m) (ClosureLaw).
  double normal_stress(double d) const { return closure_.normal_stress(d); }

  NodeForces evaluate(const NodeKinematics& k, double& shear_state, NodeHistory& h) const {
    NodeForces f;
    const double elastic = k.penetration - h.plastic_closure;
    if (elastic <= 0 && !h.bonded) {  // open node: no force, shear memory lost
      shear_state = 0;
      return f;
    }
    double stress = closure_.normal_stress(elastic);
    if (cap_.on() && stress > 0) {
      const double strength = cap_.strength(h.plastic_closure);
      if (stress > strength) {  // crushing: the elastic part holds the strength, the rest is permanent
        stress = strength;
        h.plastic_closure = k.penetration - closure_.elastic_closure(strength);
      }
    }
    if (h.bonded && bond_.fails_in_tension(stress)) h.bonded = false;
    if (!h.bonded && stress <= 0) {
      shear_state = 0;
      return f;
    }
    f.normal = stress * k.area;
    const double shear_factor = stiffening_.factor(stress);
    const double ks_area = ks_ * shear_factor * k.area;
    if (tangents_) {
      f.stiffening_normal = closure_.tangent_excess(elastic);
      f.stiffening_shear = ks_ * (shear_factor - 1);
    }
    const double trial = shear_state - ks_area * k.shear_increment;
    const double tan_phi = softening_.tan_friction(h.slip);
    double limit = tan_phi * f.normal + (h.bonded ? bond_.cohesive_force(k.area) : 0.0);
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
  double ks_;
  bool tangents_;
  ClosureLaw closure_;
  ShearStiffening stiffening_;
  FrictionSoftening softening_;
  BondLaw bond_;
  CrushingCap cap_;
};

}  // namespace demcal::dem
