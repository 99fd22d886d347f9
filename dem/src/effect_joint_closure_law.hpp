// joint-closure's law (effect joint-closure, effect_joint_closure.cpp), for the contact law
// (contact_law.hpp): the normal stress of a rough joint from its elastic closure, the Bandis-Barton
// hyperbola sigma = kn d / (1 - d / closure_max), followed up to the closure where its tangent
// reaches JointMaterial::kClosureStiffening x kn and continued linearly with that tangent. With
// closure_max 0 (off) the plain sigma = kn d.
#pragma once

#include "demcal/dem/scene.hpp"

#include <cmath>

namespace demcal::dem {

class ClosureLaw {
 public:
  explicit ClosureLaw(const JointMaterial& m) : kn_(m.normal_stiffness), closure_max_(m.closure_max) {
    if (closure_max_ > 0) {
      closure_switch_ = closure_max_ * (1 - 1 / std::sqrt(JointMaterial::kClosureStiffening));
      stress_switch_ = kn_ * closure_switch_ / (1 - closure_switch_ / closure_max_);
    }
  }

  // Normal stress (Pa) for an elastic closure d (m); tension (d < 0) stays linear.
  double normal_stress(double d) const {
    if (closure_max_ <= 0 || d <= 0) return kn_ * d;
    if (d <= closure_switch_) return kn_ * d / (1 - d / closure_max_);
    return stress_switch_ + JointMaterial::kClosureStiffening * kn_ * (d - closure_switch_);
  }
  // The tangent stiffness dsigma/dd above kn (Pa/m) at an elastic closure d (m): kn ((1 -
  // d/closure_max)^-2 - 1) on the hyperbola, (kClosureStiffening - 1) kn beyond it, 0 while off or open.
  double tangent_excess(double d) const {
    if (closure_max_ <= 0 || d <= 0) return 0;
    if (d > closure_switch_) return (JointMaterial::kClosureStiffening - 1) * kn_;
    const double open = 1 - d / closure_max_;
    return kn_ * (1 / (open * open) - 1);
  }
  // Inverse of normal_stress for a compressive stress s >= 0.
  double elastic_closure(double s) const {
    if (closure_max_ <= 0) return s / kn_;
    if (s <= stress_switch_) return s / (kn_ + s / closure_max_);
    return closure_switch_ + (s - stress_switch_) / (JointMaterial::kClosureStiffening * kn_);
  }

 private:
  double kn_, closure_max_;
  double closure_switch_ = 0, stress_switch_ = 0;
};

}  // namespace demcal::dem
