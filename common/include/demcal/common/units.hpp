// Unit conversions at the edges: demcal holds SI units inside (radians, metres, newtons); degrees
// appear only in files, flags and reports.
#pragma once

#include <numbers>

namespace demcal {

// Radians per degree: angle_rad = angle_deg * kDegree, angle_deg = angle_rad / kDegree.
inline constexpr double kDegree = std::numbers::pi / 180.0;

}  // namespace demcal
