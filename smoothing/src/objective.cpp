// Loading envelope, interpolation, objective functions 1 and 2.
#include "demcal/smoothing/objective.hpp"

#include "demcal/common/format.hpp"
#include "demcal/limits/limits.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

namespace demcal::smoothing {

namespace {

std::string join(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& n : names) out += (out.empty() ? "" : ", ") + n;
  return out.empty() ? "none" : out;
}

}  // namespace

std::string to_string(ObjectiveWindow window) { return window == ObjectiveWindow::common ? "common" : "measured"; }

ObjectiveWindow parse_objective_window(const std::string& name) {
  if (name == "common") return ObjectiveWindow::common;
  if (name == "measured") return ObjectiveWindow::measured;
  throw std::invalid_argument("'" + name + "': must be \"common\" or \"measured\"");
}

void ObjectiveOptions::Validate() const {
  if (points < 2)
    throw std::invalid_argument("ObjectiveOptions.points = " + std::to_string(points) + ": must be >= 2");
  limits::require_within(limits::Limit::curve_points, points, "ObjectiveOptions.points");
  if (force_column.empty()) throw std::invalid_argument("ObjectiveOptions.force_column is empty");
  for (const auto& [name, w] : channel_weights)
    if (!(w >= 0) || !std::isfinite(w))
      throw std::invalid_argument("ObjectiveOptions.channel_weights['" + name + "'] = " + format_number(w, 10) +
                                  ": must be finite and >= 0");
  for (const auto& name : ignored_columns)
    if (name == force_column)
      throw std::invalid_argument("ObjectiveOptions.ignored_columns contains the force column '" +
                                  name + "'");
}

XYSeries loading_envelope(const XYSeries& s) {
  if (s.x.size() != s.y.size())
    throw CurveError("loading_envelope: x and y differ in length (" + std::to_string(s.x.size()) +
                     " and " + std::to_string(s.y.size()) + ")");
  XYSeries env;
  env.x.reserve(s.x.size());
  env.y.reserve(s.y.size());
  for (std::size_t i = 0; i < s.x.size(); ++i) {
    const double x = s.x[i], y = s.y[i];
    if (!std::isfinite(x) || !std::isfinite(y)) continue;
    if (env.x.empty() || x > env.x.back()) {
      env.x.push_back(x);
      env.y.push_back(y);
    } else if (x == env.x.back()) {
      env.y.back() = y;  // the latest force at a repeated displacement
    }
  }
  return env;
}

double interpolate(const XYSeries& e, double x) {
  if (e.x.empty()) throw CurveError("interpolate: empty series");
  if (x <= e.x.front()) return e.y.front();
  if (x >= e.x.back()) return e.y.back();
  const auto it = std::upper_bound(e.x.begin(), e.x.end(), x);
  const std::size_t i = static_cast<std::size_t>(it - e.x.begin());  // e.x[i-1] <= x < e.x[i]
  const double t = (x - e.x[i - 1]) / (e.x[i] - e.x[i - 1]);
  return e.y[i - 1] + t * (e.y[i] - e.y[i - 1]);
}

namespace {

// interpolate() at displacements that mostly increase: the bracketing interval is found by walking
// forward from the last one (a search again when x goes back), with the same arithmetic, so the
// values are interpolate()'s to the bit.
class InterpolationSweep {
 public:
  explicit InterpolationSweep(const XYSeries& e) : e_(e) {
    if (e.x.empty()) throw CurveError("interpolate: empty series");
  }
  double operator()(double x) {
    if (x <= e_.x.front()) return e_.y.front();
    if (x >= e_.x.back()) return e_.y.back();
    if (x < e_.x[i_ - 1]) i_ = static_cast<std::size_t>(std::upper_bound(e_.x.begin(), e_.x.end(), x) - e_.x.begin());
    while (e_.x[i_] <= x) ++i_;  // e.x[i-1] <= x < e.x[i]
    const double t = (x - e_.x[i_ - 1]) / (e_.x[i_] - e_.x[i_ - 1]);
    return e_.y[i_ - 1] + t * (e_.y[i_] - e_.y[i_ - 1]);
  }

 private:
  const XYSeries& e_;
  std::size_t i_ = 1;
};

}  // namespace

std::pair<double, double> objective_window(const XYSeries& e, const XYSeries& s, ObjectiveWindow window,
                                           const std::string& label) {
  // A simulated gauge that never passed its first reading shares no range with the measurement:
  // it is compared over the measured one, held at that reading, under either window.
  const bool common = window == ObjectiveWindow::common && s.x.size() > 1;
  const double lower = common ? std::max(e.x.front(), s.x.front()) : e.x.front();
  const double upper = common ? std::min(e.x.back(), s.x.back()) : e.x.back();
  if (!(upper > lower))
    throw CurveError(label + ": displacement ranges do not overlap (experiment [" + format_number(e.x.front(), 10) + ", " +
                     format_number(e.x.back(), 10) + "], simulation [" + format_number(s.x.front(), 10) + ", " +
                     format_number(s.x.back(), 10) + "])");
  return {lower, upper};
}

double channel_misfit(const XYSeries& experiment, const XYSeries& simulation, int points,
                      const std::string& label, ObjectiveWindow window) {
  if (points < 2) throw std::invalid_argument("channel_misfit: points must be >= 2");
  return envelope_misfit(loading_envelope(experiment), loading_envelope(simulation), points, label, window);
}

double envelope_misfit(const XYSeries& e, const XYSeries& s, int points, const std::string& label,
                       ObjectiveWindow window) {
  if (points < 2) throw std::invalid_argument("channel_misfit: points must be >= 2");
  if (e.x.size() < 2)
    throw CurveError(label + ": the experiment has fewer than 2 loading points (finite, increasing displacement)");
  if (s.x.empty()) throw CurveError(label + ": the simulation has no loading point (finite, increasing displacement)");
  const auto [lower, upper] = objective_window(e, s, window, label);
  // The displacements increase with k: each series is walked once instead of searched per point.
  InterpolationSweep at_e(e), at_s(s);
  double sum = 0;
  for (int k = 0; k < points; ++k) {
    const double w = k == points - 1 ? upper : lower + (upper - lower) * k / (points - 1);
    const double d = at_e(w) - at_s(w);
    sum += d * d;
  }
  return std::sqrt(sum);
}

std::vector<std::string> displacement_columns(const Curve& curve, const ObjectiveOptions& options) {
  if (!curve.has_column(options.force_column))
    throw CurveError(curve.source + ": no force column '" + options.force_column + "' (columns: " +
                     join(curve.column_names()) + ")");
  std::vector<std::string> out;
  for (const auto& c : curve.columns) {
    if (c.name == options.force_column) continue;
    if (std::find(options.ignored_columns.begin(), options.ignored_columns.end(), c.name) !=
        options.ignored_columns.end())
      continue;
    out.push_back(c.name);
  }
  return out;
}

std::map<std::string, double> envelope_ends(const Curve& curve, const ObjectiveOptions& options) {
  std::map<std::string, double> ends;
  for (const auto& column : displacement_columns(curve, options)) {
    const XYSeries e = loading_envelope(series(curve, column, options.force_column));
    if (e.x.size() >= 2) ends[column] = e.x.back();
  }
  return ends;
}

Curve continued_after_collapse(const Curve& simulation, const std::map<std::string, double>& ends,
                               const ObjectiveOptions& options) {
  Curve out = simulation;
  if (out.rows() == 0) return out;
  const auto displacements = displacement_columns(out, options);
  auto is_displacement = [&](const std::string& name) {
    return std::find(displacements.begin(), displacements.end(), name) != displacements.end();
  };
  bool further = false;
  std::vector<double> at_collapse, at_end;
  for (const auto& c : out.columns) {
    double value = c.values.back();  // other columns (time, ignored ones) keep their last value
    if (c.name == options.force_column) {
      value = 0;
    } else if (is_displacement(c.name)) {
      value = -std::numeric_limits<double>::infinity();
      for (double v : c.values)
        if (std::isfinite(v)) value = std::max(value, v);
      if (!std::isfinite(value)) value = c.values.back();
    }
    at_collapse.push_back(value);
    const auto end = ends.find(c.name);
    const bool beyond = is_displacement(c.name) && end != ends.end() && end->second > value;
    further = further || beyond;
    at_end.push_back(beyond ? end->second : value);
  }
  for (std::size_t k = 0; k < out.columns.size(); ++k) {
    out.columns[k].values.push_back(at_collapse[k]);
    if (further) out.columns[k].values.push_back(at_end[k]);
  }
  return out;
}

std::vector<std::string> common_channels(const Curve& experiment, const Curve& simulation,
                                         const ObjectiveOptions& options) {
  const auto e = displacement_columns(experiment, options);
  const auto s = displacement_columns(simulation, options);
  std::vector<std::string> common;
  for (const auto& name : e)
    if (std::find(s.begin(), s.end(), name) != s.end()) common.push_back(name);
  if (common.empty())
    throw CurveError("no displacement column in common: " + experiment.source + " has (" + join(e) +
                     "), " + simulation.source + " has (" + join(s) + ")");
  return common;
}

namespace {

void check_weights(const std::vector<std::string>& channels, const ObjectiveOptions& options) {
  for (const auto& [name, w] : options.channel_weights)
    if (std::find(channels.begin(), channels.end(), name) == channels.end())
      throw CurveError("channel weight given for '" + name + "', which is not a common channel (" +
                       join(channels) + ")");
}

double weight_of(const ObjectiveOptions& options, const std::string& channel) {
  const auto it = options.channel_weights.find(channel);
  return it == options.channel_weights.end() ? 1.0 : it->second;
}

FitnessResult combine(const std::map<std::string, double>& channels, const ObjectiveOptions& options) {
  FitnessResult r;
  r.channels = channels;
  for (const auto& [name, f] : channels) r.fitness += weight_of(options, name) * f;
  return r;
}

std::string channel_label(const Curve& experiment, const Curve& simulation, const std::string& channel) {
  return "channel '" + channel + "' (" + experiment.source + " vs " + simulation.source + ")";
}

}  // namespace

FitnessResult objective1(const Curve& experiment, const Curve& simulation, const ObjectiveOptions& options) {
  options.Validate();
  const auto channels = common_channels(experiment, simulation, options);
  check_weights(channels, options);
  std::map<std::string, double> values;
  for (const auto& c : channels)
    values[c] = channel_misfit(series(experiment, c, options.force_column),
                               series(simulation, c, options.force_column), options.points,
                               channel_label(experiment, simulation, c), options.window);
  return combine(values, options);
}

Objective2::Objective2(const Curve& experiment, ObjectiveOptions objective, SmootherOptions smoother)
    : objective_(std::move(objective)), smoother_(std::move(smoother)) {
  objective_.Validate();
  smoother_.Validate();
  experiment_.source = experiment.source;
  experiment_.columns = experiment.columns;
  const auto channels = displacement_columns(experiment, objective_);
  if (channels.empty())
    throw CurveError(experiment.source + ": no displacement column besides '" + objective_.force_column + "'");
  std::vector<XYSeries> inputs;
  for (const auto& c : channels) inputs.push_back(series(experiment, c, objective_.force_column));
  const auto results = smooth_batch(inputs, smoother_);
  for (std::size_t i = 0; i < channels.size(); ++i) {
    if (results[i].status != SmoothStatus::ok)
      throw CurveError(experiment.source + ": cannot smooth channel '" + channels[i] + "': " + results[i].message);
    smoothed_experiment_[channels[i]] = results[i].smoothed;
  }
}

std::vector<FitnessResult> Objective2::evaluate_batch(const std::vector<Curve>& simulations) const {
  // Gather every channel of every simulation, then one batched training pass.
  std::vector<std::vector<std::string>> channels(simulations.size());
  std::vector<XYSeries> inputs;
  for (std::size_t i = 0; i < simulations.size(); ++i) {
    channels[i] = common_channels(experiment_, simulations[i], objective_);
    check_weights(channels[i], objective_);
    for (const auto& c : channels[i]) inputs.push_back(series(simulations[i], c, objective_.force_column));
  }
  const auto smoothed = smooth_batch(inputs, smoother_);
  std::vector<FitnessResult> out;
  std::size_t next = 0;
  for (std::size_t i = 0; i < simulations.size(); ++i) {
    std::map<std::string, double> values;
    for (const auto& c : channels[i]) {
      const auto& r = smoothed[next];
      const XYSeries& input = inputs[next++];
      const std::string label = channel_label(experiment_, simulations[i], c);
      // A one-point envelope, which the measured window scores, has no curve to smooth: it is its own fit.
      const XYSeries* fit = &r.smoothed;
      XYSeries start_only;
      if (r.status != SmoothStatus::ok) {
        start_only = loading_envelope(input);
        if (r.status != SmoothStatus::too_few_points || start_only.x.size() != 1)
          throw CurveError(label + ": cannot smooth the simulation: " + r.message);
        fit = &start_only;
      }
      values[c] = channel_misfit(smoothed_experiment_.at(c), *fit, objective_.points, label, objective_.window);
    }
    out.push_back(combine(values, objective_));
  }
  return out;
}

FitnessResult Objective2::evaluate(const Curve& simulation) const {
  return evaluate_batch({simulation}).front();
}

std::map<std::string, XYSeries> Objective2::smooth_simulation(const Curve& simulation) const {
  const auto channels = common_channels(experiment_, simulation, objective_);
  std::vector<XYSeries> inputs;
  for (const auto& c : channels) inputs.push_back(series(simulation, c, objective_.force_column));
  const auto smoothed = smooth_batch(inputs, smoother_);
  std::map<std::string, XYSeries> out;
  for (std::size_t i = 0; i < channels.size(); ++i) {
    if (smoothed[i].status != SmoothStatus::ok)
      throw CurveError(simulation.source + ": cannot smooth channel '" + channels[i] + "': " + smoothed[i].message);
    out[channels[i]] = smoothed[i].smoothed;
  }
  return out;
}

}  // namespace demcal::smoothing
