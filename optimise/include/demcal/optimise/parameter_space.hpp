// Parameter spaces: the named, bounded, possibly log-scaled quantities an optimiser searches over.
//
// Every optimiser in demcal works inside the unit cube [0,1]^d. A ParameterSpace maps between that
// cube and physical values:
//   linear scale:  physical = lower + u * (upper - lower)
//   log10 scale:   physical = 10^( log10(lower) + u * (log10(upper) - log10(lower)) )
// so a parameter spanning decades (normal and shear stiffness kn, ks in Pa/m, e.g. [1e8, 1e10])
// is searched uniformly in its exponent. u = 0 and u = 1 map exactly onto lower and upper.
//
// Besides the free parameters (the optimiser's coordinates, in the order they were added) a space
// carries fixed parameters (name -> constant value) and at most one tied parameter, whose value is
// another parameter divided by a ratio (ks = kn / ratio, as manual calibrations fix kn/ks).
// values() returns all of them by name, which is what the simulation side consumes.
//
// JSON form (to_json / from_json), as used in campaign files:
//   { "parameters": [ {"name": "kn", "lower": 1e8, "upper": 1e10, "scale": "log10"},
//                     {"name": "friction_angle", "lower": 25, "upper": 45, "scale": "linear"} ],
//     "fixed": { "damping": 0.8 },
//     "tied":  { "name": "ks", "source": "kn", "ratio": 2.5 } }          ("fixed", "tied" optional)
#pragma once

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace demcal::optimise {

// One free parameter: a name, closed bounds [lower, upper] in physical units, and a scale.
struct ParameterSpec {
  enum class Scale { linear, log10 };
  std::string name;
  double lower = 0.0;        // physical lower bound (> 0 on a log10 scale)
  double upper = 1.0;        // physical upper bound (> lower)
  Scale scale = Scale::linear;
};

// "linear" / "log10" <-> Scale; parse throws std::invalid_argument naming the bad text.
std::string to_string(ParameterSpec::Scale scale);
ParameterSpec::Scale parse_scale(const std::string& text);

// A parameter that follows another: value = value_of(source) / ratio. source may be a free or a
// fixed parameter; ratio must be finite and > 0.
struct TiedParameter {
  std::string name;
  std::string source;
  double ratio = 1.0;
};

class ParameterSpace {
 public:
  ParameterSpace() = default;
  explicit ParameterSpace(std::vector<ParameterSpec> free_parameters);

  // Builders (chainable). They do not validate; call Validate() once the space is complete
  // (make_optimiser does).
  ParameterSpace& add(ParameterSpec spec);
  ParameterSpace& add(std::string name, double lower, double upper,
                      ParameterSpec::Scale scale = ParameterSpec::Scale::linear);
  ParameterSpace& fix(std::string name, double value);
  ParameterSpace& tie(std::string name, std::string source, double ratio);

  // Number of free parameters, i.e. the optimiser's dimension d.
  int dimension() const { return static_cast<int>(free_.size()); }
  const std::vector<ParameterSpec>& free_parameters() const { return free_; }
  const std::map<std::string, double>& fixed_parameters() const { return fixed_; }
  const std::optional<TiedParameter>& tied_parameter() const { return tied_; }
  // Names of the free parameters in coordinate order.
  std::vector<std::string> free_names() const;

  // Physical bounds of the free parameters (length d).
  Eigen::VectorXd lower_bounds() const;
  Eigen::VectorXd upper_bounds() const;

  // Unit cube <-> physical, coordinate by coordinate (length d, else std::invalid_argument).
  // No clamping: u outside [0,1] maps outside the bounds and vice versa; the optimisers only
  // ever produce points inside the cube.
  Eigen::VectorXd to_physical(const Eigen::VectorXd& unit) const;
  Eigen::VectorXd to_unit(const Eigen::VectorXd& physical) const;

  // All parameters by name: the free ones from physical_free (length d), the fixed ones, and the
  // tied one computed from its source.
  std::map<std::string, double> values(const Eigen::VectorXd& physical_free) const;

  // Throws std::invalid_argument naming the parameter and the value for: no free parameters,
  // empty or duplicate names (across free, fixed and tied), NaN/infinite bounds, lower >= upper,
  // lower <= 0 on a log10 scale, a non-finite fixed value, a tied parameter whose source does not
  // exist or whose ratio is not finite and > 0.
  void Validate() const;

  nlohmann::json to_json() const;
  // Parses the JSON form above; errors name `where` (e.g. the file) and the key and value.
  static ParameterSpace from_json(const nlohmann::json& json, const std::string& where = "parameter space");

 private:
  std::vector<ParameterSpec> free_;
  std::map<std::string, double> fixed_;
  std::optional<TiedParameter> tied_;
};

}  // namespace demcal::optimise
