#include "demcal/optimise/parameter_space.hpp"
#include "internal.hpp"

#include "demcal/common/format.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <set>
#include <sstream>
#include <stdexcept>

namespace demcal::optimise {

using detail::fail;

std::string to_string(ParameterSpec::Scale scale) {
  return scale == ParameterSpec::Scale::log10 ? "log10" : "linear";
}

ParameterSpec::Scale parse_scale(const std::string& text) {
  if (text == "linear") return ParameterSpec::Scale::linear;
  if (text == "log10" || text == "log") return ParameterSpec::Scale::log10;
  fail("unknown parameter scale '" + text + "' (expected 'linear' or 'log10')");
}

ParameterSpace::ParameterSpace(std::vector<ParameterSpec> free_parameters) : free_(std::move(free_parameters)) {}

ParameterSpace& ParameterSpace::add(ParameterSpec spec) {
  free_.push_back(std::move(spec));
  return *this;
}

ParameterSpace& ParameterSpace::add(std::string name, double lower, double upper, ParameterSpec::Scale scale) {
  return add(ParameterSpec{std::move(name), lower, upper, scale});
}

ParameterSpace& ParameterSpace::fix(std::string name, double value) {
  fixed_[std::move(name)] = value;
  return *this;
}

ParameterSpace& ParameterSpace::tie(std::string name, std::string source, double ratio) {
  tied_ = TiedParameter{std::move(name), std::move(source), ratio};
  return *this;
}

std::vector<std::string> ParameterSpace::free_names() const {
  std::vector<std::string> names;
  for (const auto& p : free_) names.push_back(p.name);
  return names;
}

Eigen::VectorXd ParameterSpace::lower_bounds() const {
  Eigen::VectorXd v(dimension());
  for (int k = 0; k < dimension(); ++k) v[k] = free_[k].lower;
  return v;
}

Eigen::VectorXd ParameterSpace::upper_bounds() const {
  Eigen::VectorXd v(dimension());
  for (int k = 0; k < dimension(); ++k) v[k] = free_[k].upper;
  return v;
}

Eigen::VectorXd ParameterSpace::to_physical(const Eigen::VectorXd& unit) const {
  if (unit.size() != dimension())
    fail("to_physical: vector of length " + std::to_string(unit.size()) + " for a space of dimension " +
         std::to_string(dimension()));
  Eigen::VectorXd x(dimension());
  for (int k = 0; k < dimension(); ++k) {
    const auto& p = free_[k];
    const double u = unit[k];
    if (u == 0.0) {
      x[k] = p.lower;
    } else if (u == 1.0) {
      x[k] = p.upper;
    } else if (p.scale == ParameterSpec::Scale::log10) {
      const double a = std::log10(p.lower), b = std::log10(p.upper);
      x[k] = std::pow(10.0, a + u * (b - a));
    } else {
      x[k] = p.lower + u * (p.upper - p.lower);
    }
  }
  return x;
}

Eigen::VectorXd ParameterSpace::to_unit(const Eigen::VectorXd& physical) const {
  if (physical.size() != dimension())
    fail("to_unit: vector of length " + std::to_string(physical.size()) + " for a space of dimension " +
         std::to_string(dimension()));
  Eigen::VectorXd u(dimension());
  for (int k = 0; k < dimension(); ++k) {
    const auto& p = free_[k];
    const double x = physical[k];
    if (x == p.lower) {
      u[k] = 0.0;
    } else if (x == p.upper) {
      u[k] = 1.0;
    } else if (p.scale == ParameterSpec::Scale::log10) {
      if (!(x > 0.0)) fail("to_unit: parameter '" + p.name + "' has value " + format_number(x, round_trip_digits) + " on a log10 scale");
      const double a = std::log10(p.lower), b = std::log10(p.upper);
      u[k] = (std::log10(x) - a) / (b - a);
    } else {
      u[k] = (x - p.lower) / (p.upper - p.lower);
    }
  }
  return u;
}

std::map<std::string, double> ParameterSpace::values(const Eigen::VectorXd& physical_free) const {
  if (physical_free.size() != dimension())
    fail("values: vector of length " + std::to_string(physical_free.size()) + " for a space of dimension " +
         std::to_string(dimension()));
  std::map<std::string, double> out = fixed_;
  for (int k = 0; k < dimension(); ++k) out[free_[k].name] = physical_free[k];
  if (tied_) {
    const auto it = out.find(tied_->source);
    if (it == out.end()) fail("tied parameter '" + tied_->name + "': source '" + tied_->source + "' does not exist");
    out[tied_->name] = it->second / tied_->ratio;
  }
  return out;
}

void ParameterSpace::Validate() const {
  if (free_.empty()) fail("parameter space: no free parameters");
  limits::require_within(limits::Limit::parameters, static_cast<double>(free_.size() + fixed_.size() + (tied_ ? 1 : 0)),
                         "parameter space");
  std::set<std::string> names;
  auto claim = [&](const std::string& name, const char* kind) {
    if (name.empty()) fail(std::string("parameter space: a ") + kind + " parameter has an empty name");
    if (!names.insert(name).second) fail("parameter space: parameter '" + name + "' is defined twice");
  };
  for (const auto& p : free_) {
    claim(p.name, "free");
    if (!std::isfinite(p.lower))
      fail("parameter '" + p.name + "': lower bound " + format_number(p.lower, round_trip_digits) + " is not finite");
    if (!std::isfinite(p.upper))
      fail("parameter '" + p.name + "': upper bound " + format_number(p.upper, round_trip_digits) + " is not finite");
    if (!(p.lower < p.upper))
      fail("parameter '" + p.name + "': lower bound " + format_number(p.lower, round_trip_digits) + " is not below upper bound " +
           format_number(p.upper, round_trip_digits));
    if (p.scale == ParameterSpec::Scale::log10 && !(p.lower > 0.0))
      fail("parameter '" + p.name + "': lower bound " + format_number(p.lower, round_trip_digits) + " must be > 0 on a log10 scale");
  }
  for (const auto& [name, value] : fixed_) {
    claim(name, "fixed");
    if (!std::isfinite(value))
      fail("fixed parameter '" + name + "': value " + format_number(value, round_trip_digits) + " is not finite");
  }
  if (tied_) {
    claim(tied_->name, "tied");
    if (tied_->source == tied_->name) fail("tied parameter '" + tied_->name + "' is tied to itself");
    bool source_found = fixed_.count(tied_->source) > 0;
    for (const auto& p : free_) source_found = source_found || p.name == tied_->source;
    if (!source_found)
      fail("tied parameter '" + tied_->name + "': source '" + tied_->source + "' is neither a free nor a fixed parameter");
    if (!std::isfinite(tied_->ratio) || !(tied_->ratio > 0.0))
      fail("tied parameter '" + tied_->name + "': ratio " + format_number(tied_->ratio, round_trip_digits) + " must be finite and > 0");
  }
}

nlohmann::json ParameterSpace::to_json() const {
  nlohmann::json out;
  out["parameters"] = nlohmann::json::array();
  for (const auto& p : free_)
    out["parameters"].push_back({{"name", p.name}, {"lower", p.lower}, {"upper", p.upper}, {"scale", to_string(p.scale)}});
  if (!fixed_.empty()) out["fixed"] = fixed_;
  if (tied_) out["tied"] = {{"name", tied_->name}, {"source", tied_->source}, {"ratio", tied_->ratio}};
  return out;
}

ParameterSpace ParameterSpace::from_json(const nlohmann::json& json, const std::string& where) {
  auto number = [&](const nlohmann::json& obj, const std::string& key, const std::string& context) {
    if (!obj.contains(key)) fail(where + ": " + context + ": missing key '" + key + "'");
    const auto& v = obj.at(key);
    if (!v.is_number()) fail(where + ": " + context + ": key '" + key + "' is not a number (" + v.dump() + ")");
    return v.get<double>();
  };
  auto text = [&](const nlohmann::json& obj, const std::string& key, const std::string& context) {
    if (!obj.contains(key)) fail(where + ": " + context + ": missing key '" + key + "'");
    const auto& v = obj.at(key);
    if (!v.is_string()) fail(where + ": " + context + ": key '" + key + "' is not a string (" + v.dump() + ")");
    return v.get<std::string>();
  };
  if (!json.is_object()) fail(where + ": expected an object, got " + json.dump());
  if (!json.contains("parameters") || !json.at("parameters").is_array())
    fail(where + ": key 'parameters' must be an array of {name, lower, upper, scale}");
  ParameterSpace space;
  int index = 0;
  for (const auto& p : json.at("parameters")) {
    const std::string context = "parameters[" + std::to_string(index++) + "]";
    if (!p.is_object()) fail(where + ": " + context + " is not an object (" + p.dump() + ")");
    ParameterSpec spec;
    spec.name = text(p, "name", context);
    spec.lower = number(p, "lower", context + " '" + spec.name + "'");
    spec.upper = number(p, "upper", context + " '" + spec.name + "'");
    if (p.contains("scale")) {
      try {
        spec.scale = parse_scale(text(p, "scale", context));
      } catch (const std::invalid_argument& e) {
        fail(where + ": " + context + " '" + spec.name + "': " + e.what());
      }
    }
    space.add(spec);
  }
  if (json.contains("fixed")) {
    const auto& fixed = json.at("fixed");
    if (!fixed.is_object()) fail(where + ": key 'fixed' must be an object name -> value, got " + fixed.dump());
    for (const auto& [name, value] : fixed.items()) space.fix(name, number(fixed, name, "fixed"));
  }
  if (json.contains("tied")) {
    const auto& tied = json.at("tied");
    if (!tied.is_object()) fail(where + ": key 'tied' must be an object {name, source, ratio}, got " + tied.dump());
    space.tie(text(tied, "name", "tied"), text(tied, "source", "tied"), number(tied, "ratio", "tied"));
  }
  try {
    space.Validate();
  } catch (const std::invalid_argument& e) {
    fail(where + ": " + e.what());
  }
  return space;
}

}  // namespace demcal::optimise
