#include "geometry.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace demcal::dem::geometry {

double signed_area(const std::vector<Vec2>& p) {
  double a = 0;
  for (std::size_t i = 0; i < p.size(); ++i) a += cross(p[i], p[(i + 1) % p.size()]);
  return 0.5 * a;
}

Vec2 centroid(const std::vector<Vec2>& p) {
  // Relative to the first vertex, to keep precision for blocks far from the origin.
  const Vec2 o = p[0];
  double a = 0;
  Vec2 c = Vec2::Zero();
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Vec2 u = p[i] - o, v = p[(i + 1) % p.size()] - o;
    const double w = cross(u, v);
    a += w;
    c += w * (u + v);
  }
  return o + c / (3.0 * a);
}

double polar_moment(const std::vector<Vec2>& p) {
  const Vec2 c = centroid(p);
  double j = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Vec2 u = p[i] - c, v = p[(i + 1) % p.size()] - c;
    j += cross(u, v) * (u.squaredNorm() + u.dot(v) + v.squaredNorm());
  }
  return std::abs(j) / 12.0;
}

bool is_convex_ccw(const std::vector<Vec2>& p) {
  const std::size_t n = p.size();
  if (n < 3) return false;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec2 e1 = p[(i + 1) % n] - p[i], e2 = p[(i + 2) % n] - p[(i + 1) % n];
    if (cross(e1, e2) <= 1e-14 * e1.norm() * e2.norm()) return false;
  }
  return signed_area(p) > 0;
}

static bool segments_cross(const Vec2& a, const Vec2& b, const Vec2& c, const Vec2& d) {
  const double d1 = cross(b - a, c - a), d2 = cross(b - a, d - a);
  const double d3 = cross(d - c, a - c), d4 = cross(d - c, b - c);
  return ((d1 > 0) != (d2 > 0)) && ((d3 > 0) != (d4 > 0)) && d1 != 0 && d2 != 0 && d3 != 0 && d4 != 0;
}

bool edges_self_intersect(const std::vector<Vec2>& p) {
  const std::size_t n = p.size();
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 2; j < n; ++j) {
      if (i == 0 && j == n - 1) continue;  // adjacent through the closing edge
      if (segments_cross(p[i], p[(i + 1) % n], p[j], p[(j + 1) % n])) return true;
    }
  return false;
}

// Largest separation of b from a's edges (SAT, one direction).
static double max_separation(const std::vector<Vec2>& a, const std::vector<Vec2>& b) {
  double best = -std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < a.size(); ++i) {
    const Vec2 e = a[(i + 1) % a.size()] - a[i];
    const Vec2 normal = Vec2(e.y(), -e.x()).normalized();  // outward for CCW
    double s = std::numeric_limits<double>::infinity();
    for (const Vec2& v : b) s = std::min(s, (v - a[i]).dot(normal));
    best = std::max(best, s);
  }
  return best;
}

double overlap_depth(const std::vector<Vec2>& a, const std::vector<Vec2>& b) {
  return -std::max(max_separation(a, b), max_separation(b, a));
}

bool shared_edge(const std::vector<Vec2>& a, const std::vector<Vec2>& b, Vec2& p, Vec2& q, double tolerance) {
  double best = tolerance;
  bool found = false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const Vec2 a1 = a[i], a2 = a[(i + 1) % a.size()];
    const double length = (a2 - a1).norm();
    const Vec2 t = (a2 - a1) / length, n(t.y(), -t.x());
    for (std::size_t j = 0; j < b.size(); ++j) {
      const Vec2 b1 = b[j], b2 = b[(j + 1) % b.size()];
      if (std::abs((b1 - a1).dot(n)) > tolerance || std::abs((b2 - a1).dot(n)) > tolerance) continue;
      const double s1 = (b1 - a1).dot(t), s2 = (b2 - a1).dot(t);
      const double lo = std::max(0.0, std::min(s1, s2)), hi = std::min(length, std::max(s1, s2));
      if (hi - lo > best) {
        best = hi - lo;
        p = a1 + lo * t;
        q = a1 + hi * t;
        found = true;
      }
    }
  }
  return found;
}

}  // namespace demcal::dem::geometry
