// Polygon geometry used by the scene checks and the engine (internal header).
#pragma once

#include "demcal/dem/scene.hpp"

#include <vector>

namespace demcal::dem::geometry {

double signed_area(const std::vector<Vec2>& polygon);  // > 0 for counter-clockwise
Vec2 centroid(const std::vector<Vec2>& polygon);
// Polar second moment of area about the centroid (m^4): inertia = density * width * this.
double polar_moment(const std::vector<Vec2>& polygon);
bool is_convex_ccw(const std::vector<Vec2>& polygon);       // strictly convex, counter-clockwise
bool edges_self_intersect(const std::vector<Vec2>& polygon);  // any two non-adjacent edges cross
inline double cross(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }
inline Vec2 perp(const Vec2& v) { return Vec2(-v.y(), v.x()); }  // rotated +90 deg

// Depth of overlap of two convex CCW polygons by the separating axis test: > 0 when they overlap
// (the smallest push that separates them), <= 0 when apart.
double overlap_depth(const std::vector<Vec2>& a, const std::vector<Vec2>& b);

// The segment [p, q] along which two convex polygons share an edge (opposed faces on one line
// within `tolerance` m, overlapping by more than it). False when they share no edge.
bool shared_edge(const std::vector<Vec2>& a, const std::vector<Vec2>& b, Vec2& p, Vec2& q, double tolerance = 1e-7);

}  // namespace demcal::dem::geometry
