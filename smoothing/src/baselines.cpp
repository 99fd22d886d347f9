// Discretisation onto evenly spaced abscissae and the baseline smoothers.
#include "demcal/smoothing/objective.hpp"
#include "demcal/smoothing/smoother.hpp"

#include "demcal/limits/limits.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace demcal::smoothing {

namespace {

// Integral of the piecewise-linear interpolant of `e` (strictly increasing x) over [a, b] within
// its range.
double integral(const XYSeries& e, double a, double b) {
  a = std::max(a, e.x.front());
  b = std::min(b, e.x.back());
  if (!(b > a)) return 0;
  double sum = 0;
  double prev_x = a, prev_y = interpolate(e, a);
  auto it = std::upper_bound(e.x.begin(), e.x.end(), a);
  for (; it != e.x.end() && *it < b; ++it) {
    const auto i = static_cast<std::size_t>(it - e.x.begin());
    sum += 0.5 * (prev_y + e.y[i]) * (e.x[i] - prev_x);
    prev_x = e.x[i];
    prev_y = e.y[i];
  }
  sum += 0.5 * (prev_y + interpolate(e, b)) * (b - prev_x);
  return sum;
}

}  // namespace

XYSeries discretise(const XYSeries& input, int points) {
  if (points < 2) throw std::invalid_argument("discretise: points = " + std::to_string(points) + ", must be >= 2");
  limits::require_within(limits::Limit::curve_points, points, "discretise: points");
  const XYSeries e = loading_envelope(input);
  if (e.x.size() < 2)
    throw CurveError("the curve has " + std::to_string(e.x.size()) +
                     " distinct finite displacement value(s) on its loading branch, at least 2 needed");
  const double x0 = e.x.front(), x1 = e.x.back();
  const double step = (x1 - x0) / (points - 1);
  XYSeries out;
  out.x.resize(static_cast<std::size_t>(points));
  out.y.resize(static_cast<std::size_t>(points));
  for (int k = 0; k < points; ++k) {
    const double xk = k == points - 1 ? x1 : x0 + step * k;
    out.x[static_cast<std::size_t>(k)] = xk;
    if (k == 0 || k == points - 1) {
      // A half bin would bias the end values; the ends keep the measured end points.
      out.y[static_cast<std::size_t>(k)] = k == 0 ? e.y.front() : e.y.back();
      continue;
    }
    // Mean of the interpolant over one spacing centred on x_k.
    const double a = xk - 0.5 * step, b = xk + 0.5 * step;
    out.y[static_cast<std::size_t>(k)] = integral(e, a, b) / (b - a);
  }
  return out;
}

XYSeries moving_average(const XYSeries& input, int window, int points) {
  if (window < 1 || window % 2 == 0)
    throw std::invalid_argument("moving_average: window = " + std::to_string(window) + ", must be odd and >= 1");
  const XYSeries d = discretise(input, points);
  XYSeries out = d;
  const int n = points, half = window / 2;
  for (int k = 0; k < n; ++k) {
    const int h = std::min({half, k, n - 1 - k});
    double sum = 0;
    for (int j = k - h; j <= k + h; ++j) sum += d.y[static_cast<std::size_t>(j)];
    out.y[static_cast<std::size_t>(k)] = sum / (2 * h + 1);
  }
  return out;
}

XYSeries savitzky_golay(const XYSeries& input, int window, int order, int points) {
  if (window < 3 || window % 2 == 0)
    throw std::invalid_argument("savitzky_golay: window = " + std::to_string(window) + ", must be odd and >= 3");
  if (order < 0 || order >= window)
    throw std::invalid_argument("savitzky_golay: order = " + std::to_string(order) + ", must be in [0, window)");
  if (window > points)
    throw std::invalid_argument("savitzky_golay: window = " + std::to_string(window) + " exceeds points = " +
                                std::to_string(points));
  const XYSeries d = discretise(input, points);
  XYSeries out = d;
  const int n = points, half = window / 2;
  // Least squares on the local index coordinate (the abscissae are evenly spaced).
  Eigen::MatrixXd vandermonde(window, order + 1);
  for (int i = 0; i < window; ++i)
    for (int p = 0; p <= order; ++p) vandermonde(i, p) = std::pow(static_cast<double>(i - half) / half, p);
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(vandermonde);
  for (int k = 0; k < n; ++k) {
    const int start = std::clamp(k - half, 0, n - window);
    Eigen::VectorXd y(window);
    for (int i = 0; i < window; ++i) y(i) = d.y[static_cast<std::size_t>(start + i)];
    const Eigen::VectorXd c = qr.solve(y);
    const double t = static_cast<double>(k - start - half) / half;
    double v = 0;
    for (int p = order; p >= 0; --p) v = v * t + c(p);
    out.y[static_cast<std::size_t>(k)] = v;
  }
  return out;
}

double rms_difference(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size() || a.empty())
    throw std::invalid_argument("rms_difference: sizes " + std::to_string(a.size()) + " and " +
                                std::to_string(b.size()));
  double sum = 0;
  for (std::size_t i = 0; i < a.size(); ++i) sum += (a[i] - b[i]) * (a[i] - b[i]);
  return std::sqrt(sum / static_cast<double>(a.size()));
}

}  // namespace demcal::smoothing
