#include "demcal/optimise/test_functions.hpp"
#include "internal.hpp"

#include <cmath>
#include <stdexcept>

namespace demcal::optimise {

const std::vector<std::string>& test_function_names() {
  static const std::vector<std::string> names = {"sphere", "rosenbrock", "rastrigin", "ackley"};
  return names;
}

TestFunction make_test_function(const std::string& name, int dimension, bool shifted) {
  if (dimension < 1) throw std::invalid_argument("test function dimension " + std::to_string(dimension) + " must be >= 1");
  limits::require_within(limits::Limit::parameters, dimension, "test function dimension");
  TestFunction f;
  f.name = name;
  f.dimension = dimension;
  double low = 0.0, high = 0.0;
  if (name == "sphere" || name == "rastrigin") {
    low = -5.12, high = 5.12;
  } else if (name == "rosenbrock") {
    if (dimension < 2) throw std::invalid_argument("rosenbrock needs dimension >= 2, got " + std::to_string(dimension));
    low = -5.0, high = 10.0;
  } else if (name == "ackley") {
    low = -32.768, high = 32.768;
  } else {
    throw std::invalid_argument("unknown test function '" + name + "' (expected sphere, rosenbrock, rastrigin or ackley)");
  }
  f.lower = Eigen::VectorXd::Constant(dimension, low);
  f.upper = Eigen::VectorXd::Constant(dimension, high);
  const double half_width = 0.5 * (high - low);
  Eigen::VectorXd shift = Eigen::VectorXd::Zero(dimension);
  if (shifted)
    for (int k = 0; k < dimension; ++k) shift[k] = 0.1 * (1 + k % 4) * half_width;
  if (name == "rosenbrock") {
    // Keep the optimum 1 + s inside [-5, 10].
    f.optimum = (Eigen::VectorXd::Ones(dimension) + shift).cwiseMin(high - 1.0);
    shift = f.optimum - Eigen::VectorXd::Ones(dimension);
  } else {
    f.optimum = shift;
  }
  if (name == "sphere") {
    f.evaluate = [shift](const Eigen::VectorXd& x) { return (x - shift).squaredNorm(); };
  } else if (name == "rosenbrock") {
    f.evaluate = [shift](const Eigen::VectorXd& x) {
      const Eigen::VectorXd z = x - shift;
      double sum = 0.0;
      for (Eigen::Index k = 0; k + 1 < z.size(); ++k)
        sum += 100.0 * std::pow(z[k + 1] - z[k] * z[k], 2) + std::pow(1.0 - z[k], 2);
      return sum;
    };
  } else if (name == "rastrigin") {
    f.evaluate = [shift](const Eigen::VectorXd& x) {
      const Eigen::VectorXd z = x - shift;
      double sum = 10.0 * static_cast<double>(z.size());
      for (Eigen::Index k = 0; k < z.size(); ++k) sum += z[k] * z[k] - 10.0 * std::cos(2.0 * M_PI * z[k]);
      return sum;
    };
  } else {
    f.evaluate = [shift](const Eigen::VectorXd& x) {
      const Eigen::VectorXd z = x - shift;
      const double n = static_cast<double>(z.size());
      double cosines = 0.0;
      for (Eigen::Index k = 0; k < z.size(); ++k) cosines += std::cos(2.0 * M_PI * z[k]);
      const double value = -20.0 * std::exp(-0.2 * std::sqrt(z.squaredNorm() / n)) - std::exp(cosines / n) + 20.0 + std::exp(1.0);
      return std::max(0.0, value);
    };
  }
  return f;
}

}  // namespace demcal::optimise
