// Analytic test functions for comparing optimisers (the `demcal optimise` command and the
// optimiser benchmark). All have minimum value 0.
//
// The optimum is shifted away from the centre of the box (unless shifted = false): a method that
// samples the centre first (DIRECT) would otherwise find it with its first point. The shift is
// s_k = 0.1 * (1 + k mod 4) * half_width, i.e. 10-40 % of the half-width, the same for every run.
//   sphere      f(x) = Σ z_k²,                                   box [-5.12, 5.12]^d, z = x - s
//   rosenbrock  f(x) = Σ 100 (z_{k+1} - z_k²)² + (1 - z_k)²,      box [-5, 10]^d,      z = x - s
//               (minimum at z = 1, i.e. x = 1 + s; the shift uses the half-width 7.5 but is kept
//                within the box)
//   rastrigin   f(x) = 10 d + Σ (z_k² - 10 cos 2π z_k),          box [-5.12, 5.12]^d
//   ackley      f(x) = -20 exp(-0.2 sqrt(Σ z_k²/d)) - exp(Σ cos(2π z_k)/d) + 20 + e,  box [-32.768, 32.768]^d
#pragma once

#include <Eigen/Core>

#include <functional>
#include <string>
#include <vector>

namespace demcal::optimise {

struct TestFunction {
  std::string name;
  int dimension = 0;
  Eigen::VectorXd lower, upper;  // search box
  Eigen::VectorXd optimum;       // location of the minimum (value 0)
  std::function<double(const Eigen::VectorXd&)> evaluate;
};

// name: "sphere" | "rosenbrock" | "rastrigin" | "ackley"; dimension >= 1 (rosenbrock >= 2).
// Throws std::invalid_argument naming the bad value.
TestFunction make_test_function(const std::string& name, int dimension, bool shifted = true);
const std::vector<std::string>& test_function_names();

}  // namespace demcal::optimise
