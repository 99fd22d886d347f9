// Residual analysis and evidence of the diagnosis (diagnose.hpp): pure functions of curves.
#include "demcal/pipelines/diagnose.hpp"
#include "diagnose_internal.hpp"
#include "demcal/smoothing/objective.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>

namespace demcal::pipelines {

using nlohmann::json;
using smoothing::XYSeries;

namespace {

// Rows of a recorded series with a finite displacement and force.
std::size_t finite_rows(const XYSeries& series) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < series.x.size() && i < series.y.size(); ++i)
    n += std::isfinite(series.x[i]) && std::isfinite(series.y[i]) ? 1 : 0;
  return n;
}

double mean_of(const std::vector<double>& v) {
  return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
}

double median_of(std::vector<double> v) {
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(mid), v.end());
  if (v.size() % 2) return v[mid];
  const double upper = v[mid];
  return 0.5 * (upper + *std::max_element(v.begin(), v.begin() + static_cast<long>(mid)));
}

ResidualRegion region(const std::string& name, const ChannelResidual& c, std::size_t from, std::size_t to) {
  ResidualRegion r;
  r.name = name;
  if (from >= to) return r;
  r.lower = c.displacement[from];
  r.upper = c.displacement[to - 1];
  r.points = static_cast<int>(to - from);
  double sum = 0, squares = 0;
  for (std::size_t i = from; i < to; ++i) {
    const double e = c.measured[i] - c.simulated[i];
    sum += e;
    squares += e * e;
  }
  r.mean = sum / r.points;
  r.rms = std::sqrt(squares / r.points);
  return r;
}

}  // namespace

std::vector<double> ChannelResidual::residual() const {
  std::vector<double> r(measured.size());
  for (std::size_t i = 0; i < r.size(); ++i) r[i] = measured[i] - simulated[i];
  return r;
}

json ChannelResidual::to_json() const {
  json regions_json = json::array();
  for (const auto& r : regions)
    regions_json.push_back({{"name", r.name}, {"lower", r.lower}, {"upper", r.upper}, {"points", r.points},
                            {"mean", r.mean}, {"rms", r.rms}});
  return {{"case", case_name},
          {"channel", channel},
          {"points", displacement.size()},
          {"window", {displacement.empty() ? 0.0 : displacement.front(), displacement.empty() ? 0.0 : displacement.back()}},
          {"noise", finite_or_null(noise)},
          {"bias", bias},
          {"trend", trend},
          {"rms", rms},
          {"rms_over_noise", finite_or_null(rms / noise)},
          {"peak_displacement", peak_displacement},
          {"coverage", coverage},
          {"measured_gap", {{"lower", gap_lower}, {"upper", gap_upper}, {"simulated_points", simulated_in_gap}}},
          {"rows", {{"measured", measured_rows}, {"simulated", simulated_rows}}},
          {"regions", regions_json},
          {"autocorrelation", autocorrelation},
          {"effective_points", effective_points}};
}

double lag1_autocorrelation(const std::vector<double>& v) {
  if (v.size() < 3) return 0;
  const double m = mean_of(v);
  double num = 0, den = 0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    den += (v[i] - m) * (v[i] - m);
    if (i + 1 < v.size()) num += (v[i] - m) * (v[i + 1] - m);
  }
  return den > 0 ? num / den : 0.0;
}

double estimate_noise(const XYSeries& measured) {
  const XYSeries e = smoothing::loading_envelope(measured);
  if (e.x.size() < 3) return std::numeric_limits<double>::quiet_NaN();
  std::vector<double> pseudo;
  pseudo.reserve(e.x.size() - 2);
  for (std::size_t i = 1; i + 1 < e.x.size(); ++i) {
    const double span = e.x[i + 1] - e.x[i - 1];
    const double a = (e.x[i + 1] - e.x[i]) / span, b = (e.x[i] - e.x[i - 1]) / span;
    pseudo.push_back(std::abs((a * e.y[i - 1] + b * e.y[i + 1] - e.y[i]) / std::sqrt(a * a + b * b + 1)));
  }
  return 1.4826 * median_of(pseudo);
}

void complete_residual(ChannelResidual& c) {
  const std::size_t n = c.displacement.size();
  if (n < 4 || c.measured.size() != n || c.simulated.size() != n)
    throw smoothing::CurveError("residual analysis needs at least 4 grid points of measured and simulated force");

  const std::vector<double> r = c.residual();
  c.bias = mean_of(r);
  double squares = 0;
  for (double e : r) squares += e * e;
  c.rms = std::sqrt(squares / static_cast<double>(n));
  const double x_mean = mean_of(c.displacement);
  double sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < n; ++i) {
    sxx += (c.displacement[i] - x_mean) * (c.displacement[i] - x_mean);
    sxy += (c.displacement[i] - x_mean) * (r[i] - c.bias);
  }
  c.trend = sxx > 0 ? sxy / sxx : 0.0;

  // The measured peak on a lightly smoothed copy (5-point running mean), so one noisy sample does
  // not move it; the initial branch ends where the curve first reaches half that peak.
  std::vector<double> smooth(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t a = i >= 2 ? i - 2 : 0, b = std::min(n - 1, i + 2);
    double sum = 0;
    for (std::size_t k = a; k <= b; ++k) sum += c.measured[k];
    smooth[i] = sum / static_cast<double>(b - a + 1);
  }
  const std::size_t peak = static_cast<std::size_t>(std::max_element(smooth.begin(), smooth.end()) - smooth.begin());
  c.peak_displacement = c.displacement[peak];
  std::size_t half = 0;
  while (half < peak && smooth[half] < 0.5 * smooth[peak]) ++half;
  c.regions = {region("initial", c, 0, half), region("to_peak", c, half, peak + 1), region("after_peak", c, peak + 1, n)};

  c.autocorrelation = lag1_autocorrelation(r);
  const double rho = std::max(0.0, c.autocorrelation);
  c.effective_points = std::clamp(static_cast<double>(n) * (1 - rho) / (1 + rho), 1.0, static_cast<double>(n));
}

ChannelResidual analyse_channel(const XYSeries& measured, const XYSeries& simulated, int points,
                                smoothing::ObjectiveWindow window) {
  if (points < 4) throw smoothing::CurveError("residual analysis needs at least 4 grid points");
  const XYSeries m = smoothing::loading_envelope(measured), s = smoothing::loading_envelope(simulated);
  if (m.x.size() < 2 || s.x.empty())
    throw smoothing::CurveError("residual analysis: a curve has too few loading points to compare");
  const auto [lower, upper] = smoothing::objective_window(m, s, window, "residual analysis");

  ChannelResidual c;
  c.coverage = m.x.back() > m.x.front() ? (upper - lower) / (m.x.back() - m.x.front()) : 1.0;
  const auto n = static_cast<std::size_t>(points);
  c.displacement.resize(n);
  c.measured.resize(n);
  c.simulated.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = lower + (upper - lower) * static_cast<double>(i) / static_cast<double>(n - 1);
    c.displacement[i] = x;
    c.measured[i] = smoothing::interpolate(m, x);
    c.simulated[i] = smoothing::interpolate(s, x);
  }
  c.noise = estimate_noise(measured);
  complete_residual(c);

  // The widest stretch between consecutive measured envelope points (the window's ends included).
  double previous = lower;
  c.gap_lower = c.gap_upper = lower;
  for (std::size_t i = 0; i <= m.x.size(); ++i) {
    const double x = i < m.x.size() ? std::min(m.x[i], upper) : upper;
    if (x <= previous) continue;
    if (x - previous > c.gap_upper - c.gap_lower) {
      c.gap_lower = previous;
      c.gap_upper = x;
    }
    previous = x;
  }
  c.measured_rows = finite_rows(measured);
  detail::note_simulated_sampling(c, simulated, s);
  return c;
}

void detail::note_simulated_sampling(ChannelResidual& r, const XYSeries& simulated, const XYSeries& envelope) {
  r.simulated_rows = finite_rows(simulated);
  r.simulated_in_gap = static_cast<int>(
      std::count_if(envelope.x.begin(), envelope.x.end(), [&](double x) { return x > r.gap_lower && x < r.gap_upper; }));
}

ChannelResidual resimulated(const ChannelResidual& base, const smoothing::XYSeries& simulated) {
  ChannelResidual r = base;
  const auto envelope = smoothing::loading_envelope(simulated);
  // on the base's grid, held beyond its reach (a one-point envelope: a gauge that never passed its start)
  if (envelope.x.empty()) throw smoothing::CurveError("a simulated curve has no loading point");
  for (std::size_t i = 0; i < r.displacement.size(); ++i) r.simulated[i] = smoothing::interpolate(envelope, r.displacement[i]);
  complete_residual(r);
  detail::note_simulated_sampling(r, simulated, envelope);
  return r;
}

double ChannelResidual::gap_share() const {
  if (displacement.size() < 2 || !(displacement.back() > displacement.front())) return 0;
  return (gap_upper - gap_lower) / (displacement.back() - displacement.front());
}

double information_criterion_change(const std::vector<ChannelResidual>& base, const std::vector<ChannelResidual>& extended,
                                    int extra_parameters, const std::vector<double>& effective_points) {
  if (base.size() != extended.size() || base.empty())
    throw std::invalid_argument("information criterion: base and extended fits must cover the same channels");
  if (!effective_points.empty() && effective_points.size() != base.size())
    throw std::invalid_argument("information criterion: one effective point count per channel");
  double change = 0, total_effective = 0;
  for (std::size_t c = 0; c < base.size(); ++c) {
    const double rss_base = base[c].rms * base[c].rms, rss_ext = extended[c].rms * extended[c].rms;
    const double n_eff = effective_points.empty() ? extended[c].effective_points : effective_points[c];
    total_effective += n_eff;
    // Within the measurement noise a channel tells nothing: each side counts at least the noise's
    // variance (and at least 1e-12 of the other, so that a perfect fit keeps the logarithm finite).
    const double noise = std::isfinite(base[c].noise) ? base[c].noise * base[c].noise : 0.0;
    const double floor = std::max(noise, 1e-12 * std::max(rss_base, rss_ext) + 1e-300);
    change += n_eff * std::log(std::max(rss_ext, floor) / std::max(rss_base, floor));
  }
  return change + extra_parameters * std::log(std::max(total_effective, 1.0));
}

std::vector<double> common_effective_points(const std::vector<const std::vector<ChannelResidual>*>& fits,
                                            std::vector<int>* from) {
  std::vector<double> points;
  std::vector<int> closest;
  for (std::size_t f = 0; f < fits.size(); ++f) {
    const auto& fit = *fits[f];
    if (fit.empty() || (!closest.empty() && fit.size() != closest.size())) continue;
    if (closest.empty()) {
      closest.assign(fit.size(), static_cast<int>(f));
      continue;
    }
    for (std::size_t c = 0; c < fit.size(); ++c)
      if (fit[c].rms < (*fits[closest[c]])[c].rms) closest[c] = static_cast<int>(f);
  }
  for (std::size_t c = 0; c < closest.size(); ++c) points.push_back((*fits[closest[c]])[c].effective_points);
  if (from) *from = closest;
  return points;
}

std::vector<double> removal_criteria(const std::vector<ChannelResidual>& with_all,
                                     const std::vector<std::vector<ChannelResidual>>& without,
                                     const std::vector<int>& parameters, double evidence, int& drop,
                                     double explained) {
  if (parameters.size() != without.size())
    throw std::invalid_argument("removal criteria: " + std::to_string(without.size()) + " fits without an effect, " +
                                std::to_string(parameters.size()) + " parameter counts");
  std::vector<const std::vector<ChannelResidual>*> fits = {&with_all};
  for (const auto& w : without)
    if (w.size() == with_all.size()) fits.push_back(&w);
  const std::vector<double> points = common_effective_points(fits);
  std::vector<double> criteria;
  drop = -1;
  for (std::size_t i = 0; i < without.size(); ++i) {
    const bool fitted = without[i].size() == with_all.size() && !with_all.empty();
    criteria.push_back(fitted ? information_criterion_change(without[i], with_all, parameters[i], points) : Diagnosis::kNaN);
    const bool not_needed = criteria[i] > -evidence || (fitted && overall_error(without[i]) <= explained);
    if (std::isfinite(criteria[i]) && not_needed && (drop < 0 || criteria[i] > criteria[static_cast<std::size_t>(drop)]))
      drop = static_cast<int>(i);
  }
  return criteria;
}

double signature_score(const std::vector<double>& residual, const std::vector<std::vector<double>>& base_sensitivities,
                       const std::vector<std::vector<double>>& signatures) {
  const auto n = static_cast<Eigen::Index>(residual.size());
  auto matrix = [&](const std::vector<std::vector<double>>& columns) {
    Eigen::MatrixXd m(n, static_cast<Eigen::Index>(columns.size()));
    for (std::size_t j = 0; j < columns.size(); ++j) {
      if (static_cast<Eigen::Index>(columns[j].size()) != n)
        throw std::invalid_argument("signature score: a column differs in length from the residual");
      m.col(static_cast<Eigen::Index>(j)) = Eigen::Map<const Eigen::VectorXd>(columns[j].data(), n);
    }
    return m;
  };
  const Eigen::MatrixXd j = matrix(base_sensitivities), s = matrix(signatures);
  Eigen::VectorXd r = Eigen::Map<const Eigen::VectorXd>(residual.data(), n);
  if (!r.allFinite() || !j.allFinite() || !s.allFinite() || s.cols() == 0) return 0;

  // What the base parameters cannot remove: residual and signatures with J's span projected out.
  Eigen::MatrixXd s_left = s;
  if (j.cols() > 0) {
    const auto decomposition = j.completeOrthogonalDecomposition();
    r -= j * decomposition.solve(r);
    s_left -= j * decomposition.solve(s);
  }
  const double without = r.squaredNorm();
  if (!(without > 0)) return 0;
  // Non-negative least squares by enumerating the subsets of the (few) signature columns.
  const auto k = static_cast<int>(s_left.cols());
  if (k > 12) throw std::invalid_argument("signature score: at most 12 signature columns");
  double best = without;
  for (int mask = 1; mask < (1 << k); ++mask) {
    std::vector<Eigen::Index> picked;
    for (int c = 0; c < k; ++c)
      if (mask & (1 << c)) picked.push_back(c);
    Eigen::MatrixXd a(n, static_cast<Eigen::Index>(picked.size()));
    for (std::size_t c = 0; c < picked.size(); ++c) a.col(static_cast<Eigen::Index>(c)) = s_left.col(picked[c]);
    const Eigen::VectorXd w = a.completeOrthogonalDecomposition().solve(r);
    if ((w.array() < 0).any()) continue;  // an effect acts in one direction only
    best = std::min(best, (r - a * w).squaredNorm());
  }
  return std::clamp(1 - best / without, 0.0, 1.0);
}

std::vector<double> linearised_fractions(const std::vector<double>& residual,
                                         const std::vector<std::vector<double>>& base_sensitivities,
                                         const std::vector<std::vector<double>>& probes, std::size_t parameters,
                                         double strong, double mild) {
  const auto n = static_cast<Eigen::Index>(residual.size());
  const auto p = static_cast<Eigen::Index>(parameters);
  const auto k = static_cast<Eigen::Index>(base_sensitivities.size());
  if (probes.size() != 2 * parameters + 1 || !(mild != strong)) return {};
  for (const auto* columns : {&probes, &base_sensitivities})
    for (const auto& c : *columns)
      if (static_cast<Eigen::Index>(c.size()) != n) return {};
  const auto column = [&](const std::vector<double>& v) { return Eigen::Map<const Eigen::VectorXd>(v.data(), n); };
  Eigen::MatrixXd a(n, p + k);
  for (Eigen::Index i = 0; i < p; ++i)
    a.col(i) = (column(probes[static_cast<std::size_t>(2 * i + 2)]) - column(probes[static_cast<std::size_t>(2 * i + 1)])) /
               (mild - strong);
  for (Eigen::Index j = 0; j < k; ++j) a.col(p + j) = column(base_sensitivities[static_cast<std::size_t>(j)]);
  const Eigen::VectorXd target = column(residual) - column(probes.front());
  if (!a.allFinite() || !target.allFinite()) return {};
  const Eigen::VectorXd step = a.completeOrthogonalDecomposition().solve(target);
  std::vector<double> t;
  for (Eigen::Index i = 0; i < p; ++i) t.push_back(std::clamp(0.5 + step[i], 0.0, 1.0));
  return t;
}

ParameterBound bound_from_trials(const std::string& name, double best, std::vector<std::pair<double, double>> trials,
                                 double threshold) {
  ParameterBound b;
  b.name = name;
  b.best = best;
  trials.erase(std::remove_if(trials.begin(), trials.end(), [](const auto& t) { return !std::isfinite(t.second); }),
               trials.end());
  std::sort(trials.begin(), trials.end());
  for (const auto& [value, change] : trials) {
    if (!(change > threshold)) continue;
    if (value < best) b.lower = value;                               // the last one below is the nearest
    if (value > best && !std::isfinite(b.upper)) b.upper = value;    // the first one above is the nearest
  }
  b.trials = std::move(trials);
  return b;
}

ParameterBound profile_bound(const std::string& name, double best, const std::vector<double>& values,
                             const std::function<double(double)>& conditional,
                             const std::function<double(double)>& refitted, double threshold) {
  std::vector<std::pair<double, double>> trials;
  for (double v : values) trials.emplace_back(v, conditional(v));
  std::sort(trials.begin(), trials.end());
  std::vector<double> refitted_values;
  // Outward from the best on one side: trials [from, to) in the order `step` walks them.
  const auto walk_side = [&](long from, long to, long step) {
    for (long i = from; i != to; i += step) {
      auto& [value, change] = trials[static_cast<std::size_t>(i)];
      if (!(change > threshold)) continue;
      const double after = refitted(value);
      if (std::isfinite(after)) {
        change = std::min(change, after);
        refitted_values.push_back(value);
      }
      if (change > threshold) return;  // still ruled out: the side's bound
    }
  };
  const long above = std::upper_bound(trials.begin(), trials.end(), std::make_pair(best, HUGE_VAL)) - trials.begin();
  walk_side(above - 1, -1, -1);
  walk_side(above, static_cast<long>(trials.size()), 1);
  ParameterBound b = bound_from_trials(name, best, std::move(trials), threshold);
  std::sort(refitted_values.begin(), refitted_values.end());
  b.refitted = std::move(refitted_values);
  return b;
}

std::string ParameterBound::describe() const {
  const auto number = [](double v) { return format_number(v, 3); };
  // An unbounded side: the farthest value tried there fits as well, or nothing could be tried there.
  auto open_side = [&](bool below) {
    double v = best;
    for (const auto& [value, change] : trials)
      if (below ? value < v : value > v) v = value;
    if (v == best) return std::string(below ? "at the bottom" : "at the top") + " of its search range";
    return std::string(below ? "not bounded below (down to " : "not bounded above (up to ") + number(v) + " fits as well)";
  };
  std::string s = name + " " + number(best) + ": ";
  if (trials.empty()) return s + "not checked (every run of the check failed)";
  if (bounded()) return s + "between " + number(lower) + " and " + number(upper) + " (values beyond fit clearly worse)";
  if (std::isfinite(lower)) return s + "above " + number(lower) + ", " + open_side(false);
  if (std::isfinite(upper)) return s + "below " + number(upper) + ", " + open_side(true);
  return s + "not pinned by the data: " + open_side(true) + ", " + open_side(false);
}

json ParameterBound::to_json() const {
  json t = json::array();
  for (const auto& [value, change] : trials) t.push_back({value, change});
  return {{"best", best}, {"lower", finite_or_null(lower)}, {"upper", finite_or_null(upper)}, {"trials", t},
          {"refitted", refitted}};
}

}  // namespace demcal::pipelines
