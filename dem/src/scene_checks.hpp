// Checks of scene values that throw SceneError naming the place (internal: scene.cpp and the rules
// of the effects' files).
#pragma once

#include "demcal/common/format.hpp"
#include "demcal/dem/scene.hpp"

#include <cmath>
#include <string>

namespace demcal::dem {

inline void require_finite(double v, const std::string& where) {
  if (!std::isfinite(v)) throw SceneError(where, "value is not a finite number (" + format_number(v, 10) + ")");
}
inline void require_positive(double v, const std::string& where) {
  require_finite(v, where);
  if (v <= 0) throw SceneError(where, "must be positive, got " + format_number(v, 10));
}
inline void require_non_negative(double v, const std::string& where) {
  require_finite(v, where);
  if (v < 0) throw SceneError(where, "must not be negative, got " + format_number(v, 10));
}

}  // namespace demcal::dem
