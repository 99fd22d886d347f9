// Optimiser benchmark (not a test): median and quartiles of the best value found by demcal's PSO,
// TBPSO (both readings of Δx), GA, the NLopt algorithms, and pagmo2's pso and sga, at equal
// evaluation budgets, on Sphere, Rosenbrock, Rastrigin and Ackley (shifted, see test_functions.hpp)
// in 3 and 10 dimensions, at 200 and 500 evaluations, over 25 seeds. Prints Markdown tables.
// Rows "<algorithm>+polish" give the last fifth of the budget to a LN_BOBYQA polish from the best.
//
//   bench_optimise_pagmo [--seeds N] [--quick]     (--quick: 5 seeds, 3-D only)
//   bench_optimise_pagmo [--seeds N] --sphere-2000  (Sphere 3-D, 2000 evaluations, with and without
//                                                    a 200-evaluation LN_BOBYQA polish)
//   bench_optimise_pagmo [--seeds N] --tbpso-long   (TBPSO at 2000 evaluations: readings, clamps,
//                                                    bound handling, trust size, pinned particles)
#include <demcal/optimise/optimise.hpp>

#include <pagmo/algorithms/pso.hpp>
#include <pagmo/algorithms/sga.hpp>
#include <pagmo/population.hpp>
#include <pagmo/problem.hpp>

#include <algorithm>
#include <cmath>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <vector>

using namespace demcal::optimise;

namespace {

// pagmo user-defined problem wrapping a demcal test function; records the best value ever evaluated
// and the number of evaluations, so both libraries are scored the same way.
struct PagmoProblem {
  TestFunction function;
  std::shared_ptr<double> best = std::make_shared<double>(HUGE_VAL);
  std::shared_ptr<long> count = std::make_shared<long>(0);
  pagmo::vector_double fitness(const pagmo::vector_double& x) const {
    const double f = function.evaluate(Eigen::Map<const Eigen::VectorXd>(x.data(), static_cast<Eigen::Index>(x.size())));
    *best = std::min(*best, f);
    ++*count;
    return {f};
  }
  std::pair<pagmo::vector_double, pagmo::vector_double> get_bounds() const {
    return {pagmo::vector_double(function.lower.data(), function.lower.data() + function.dimension),
            pagmo::vector_double(function.upper.data(), function.upper.data() + function.dimension)};
  }
};

constexpr int kPopulation = 10;

double run_pagmo(const std::string& which, const TestFunction& f, long budget, unsigned seed, long& evaluations) {
  PagmoProblem udp{f};
  auto best = udp.best;
  auto count = udp.count;
  pagmo::problem problem{udp};
  pagmo::population population{problem, kPopulation, seed};
  const unsigned generations = static_cast<unsigned>(budget / kPopulation - 1);
  if (which == "pagmo:pso") {
    pagmo::algorithm algorithm{pagmo::pso(generations, 0.7298, 2.05, 2.05, 0.5, 5u, 2u, 4u, false, seed)};
    population = algorithm.evolve(population);
  } else {
    pagmo::algorithm algorithm{pagmo::sga(generations, 0.9, 1.0, 0.02, 1.0, 2u, "exponential", "polynomial",
                                          "tournament", seed)};
    population = algorithm.evolve(population);
  }
  evaluations = *count;
  return *best;
}

double run_demcal(const std::string& algorithm, const TestFunction& f, long budget, unsigned seed, long& evaluations,
                  long polish_evaluations = 0) {
  ParameterSpace space;
  for (int k = 0; k < f.dimension; ++k) space.add(std::string("x").append(std::to_string(k)), f.lower[k], f.upper[k]);
  OptimiserOptions options;
  options.population = kPopulation;
  options.max_evaluations = budget;
  options.seed = seed;
  options.algorithm = algorithm;
  // "<algorithm>+polish": the last fifth of the budget goes to the LN_BOBYQA polish.
  const std::string suffix = "+polish";
  std::string base = algorithm;
  if (base.size() > suffix.size() && base.compare(base.size() - suffix.size(), suffix.size(), suffix) == 0) {
    base.resize(base.size() - suffix.size());
    options.algorithm = base;
    if (polish_evaluations == 0) polish_evaluations = budget / 5;
  }
  if (base == "tbpso:paper" || base == "tbpso:toward") {
    options.algorithm = "tbpso";
    options.trust_direction = base.substr(6);
  }
  if (base == "ga:gaussian-elitist") {
    options.algorithm = "ga";
    options.ga_mutation = GaMutation::gaussian;
    options.elitism = 1;
  }
  options.polish_evaluations = polish_evaluations;
  auto optimiser = make_optimiser(space, options);
  const auto summary = minimise(*optimiser, f.evaluate);
  evaluations = summary.evaluations;
  return summary.best_value;
}

struct Quartiles {
  double q1, median, q3;
};

Quartiles quartiles(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  auto at = [&](double q) {
    const double position = q * static_cast<double>(values.size() - 1);
    const auto lo = static_cast<std::size_t>(position);
    const auto hi = std::min(lo + 1, values.size() - 1);
    return values[lo] + (position - static_cast<double>(lo)) * (values[hi] - values[lo]);
  };
  return {at(0.25), at(0.5), at(0.75)};
}

std::string cell(const Quartiles& q) {
  char text[96];
  std::snprintf(text, sizeof text, "%.3g [%.3g, %.3g]", q.median, q.q1, q.q3);
  return text;
}

// Sphere 3-D at 2000 evaluations, with and without the polish (the last polish_evaluations of the
// budget to LN_BOBYQA from the best point): how many seeds reach < 1e-6, median and worst.
void sphere_2000(int seeds, long polish_evaluations) {
  const TestFunction f = make_test_function("sphere", 3);
  const std::vector<std::string> algorithms = {"pso", "tbpso:paper", "tbpso:toward", "ga", "ga:gaussian-elitist",
                                               "nlopt:GN_DIRECT_L", "nlopt:GN_CRS2_LM", "nlopt:GN_ISRES",
                                               "nlopt:GN_ESCH"};
  std::printf("### Sphere 3-D, 2000 evaluations, %d seeds (1..%d)\n\n", seeds, seeds);
  std::printf("| algorithm | no polish: seeds < 1e-6 | median | worst | polish %ld of 2000: seeds < 1e-6 | median | "
              "worst | most evaluations |\n|---|---|---|---|---|---|---|---|\n",
              polish_evaluations);
  for (const auto& algorithm : algorithms) {
    std::printf("| %s |", algorithm.c_str());
    long most = 0;
    for (long polish : {0L, polish_evaluations}) {
      std::vector<double> best;
      int reached = 0;
      for (int seed = 1; seed <= seeds; ++seed) {
        long evaluations = 0;
        best.push_back(run_demcal(algorithm, f, 2000, static_cast<unsigned>(seed), evaluations, polish));
        reached += best.back() < 1e-6;
        most = std::max(most, evaluations);
      }
      const Quartiles q = quartiles(best);
      std::printf(" %d / %d | %.3g | %.3g |", reached, seeds, q.median, *std::max_element(best.begin(), best.end()));
    }
    std::printf(" %ld |\n", most);
    std::fflush(stdout);
  }
}

// TBPSO on Sphere 3-D at 2000 evaluations (no polish), by reading of Δx, velocity clamp and bound
// handling: seeds reaching < 1e-6, median, worst, the largest |C_ij| at the end, and how many of
// the 10 particles end pinned (a coordinate on a bound with zero velocity), from save_state().
void tbpso_long(int seeds) {
  const TestFunction f = make_test_function("sphere", 3);
  std::printf("### TBPSO, Sphere 3-D, 2000 evaluations, %d seeds\n\n", seeds);
  std::printf("| reading | max_velocity | bounds | seeds < 1e-6 | median | worst | max abs(C) at the end (median) | "
              "particles pinned at a bound at the end (mean of 10) |\n|---|---|---|---|---|---|---|---|\n");
  for (const char* reading : {"paper", "toward"})
    for (double vmax : {0.5, 0.2, 0.1})
      for (auto bounds : {BoundHandling::clamp, BoundHandling::reflect}) {
        std::vector<double> best, max_trust;
        int reached = 0;
        double pinned = 0.0;
        for (int seed = 1; seed <= seeds; ++seed) {
          ParameterSpace space;
          for (int k = 0; k < f.dimension; ++k) space.add(std::string("x").append(std::to_string(k)), f.lower[k], f.upper[k]);
          OptimiserOptions options;
          options.algorithm = "tbpso";
          options.trust_direction = reading;
          options.max_evaluations = 2000;
          options.seed = static_cast<std::uint64_t>(seed);
          options.max_velocity = vmax;
          options.bounds = bounds;
          auto optimiser = make_optimiser(space, options);
          const auto summary = minimise(*optimiser, f.evaluate);
          best.push_back(summary.best_value);
          reached += summary.best_value < 1e-6;
          const auto state = optimiser->save_state();
          double largest = 0.0;
          for (const auto& row : state["trust"])
            for (const auto& c : row) largest = std::max(largest, std::abs(c.get<double>()));
          max_trust.push_back(largest);
          for (std::size_t i = 0; i < state["x"].size(); ++i) {
            bool at_bound = false;
            for (std::size_t k = 0; k < state["x"][i].size(); ++k) {
              const double x = state["x"][i][k].get<double>(), v = state["v"][i][k].get<double>();
              at_bound = at_bound || ((x == 0.0 || x == 1.0) && v == 0.0);
            }
            pinned += at_bound;
          }
        }
        std::printf("| %s | %.1f | %s | %d / %d | %.3g | %.3g | %.0f | %.1f |\n", reading, vmax, to_string(bounds).c_str(),
                    reached, seeds, quartiles(best).median, *std::max_element(best.begin(), best.end()),
                    quartiles(max_trust).median, pinned / seeds);
        std::fflush(stdout);
      }
}

}  // namespace

int main(int argc, char** argv) {
  int seeds = 25;
  std::vector<int> dimensions = {3, 10};
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--seeds") && i + 1 < argc) seeds = std::atoi(argv[++i]);
    if (!std::strcmp(argv[i], "--quick")) seeds = 5, dimensions = {3};
    if (!std::strcmp(argv[i], "--tbpso-long")) {
      tbpso_long(seeds);
      return 0;
    }
    if (!std::strcmp(argv[i], "--sphere-2000")) {
      sphere_2000(seeds, 200);
      return 0;
    }
  }
  const std::vector<std::string> algorithms = {
      "pso", "tbpso:toward", "tbpso:paper", "ga", "ga:gaussian-elitist",
      "nlopt:GN_DIRECT_L", "nlopt:GN_CRS2_LM", "nlopt:GN_ISRES", "nlopt:GN_ESCH",
      "nlopt:LN_BOBYQA", "nlopt:LN_NELDERMEAD", "nlopt:LN_SBPLX", "pagmo:pso", "pagmo:sga",
      "pso+polish", "tbpso:paper+polish", "tbpso:toward+polish", "ga+polish"};
  const auto& functions = test_function_names();
  // medians[dim][budget][function][algorithm]
  std::map<int, std::map<long, std::map<std::string, std::map<std::string, double>>>> medians;
  const auto start = std::chrono::steady_clock::now();

  std::printf("Population/batch %d for the population-based methods; %d seeds (1..%d) per cell; "
              "cells: median [first quartile, third quartile] of the best value found.\n\n",
              kPopulation, seeds, seeds);
  for (int dimension : dimensions) {
    for (long budget : {200L, 500L}) {
      std::printf("### %d-D, %ld evaluations\n\n| algorithm |", dimension, budget);
      for (const auto& name : functions) std::printf(" %s |", name.c_str());
      std::printf("\n|---|");
      for (std::size_t k = 0; k < functions.size(); ++k) std::printf("---|");
      std::printf("\n");
      for (const auto& algorithm : algorithms) {
        std::printf("| %s |", algorithm.c_str());
        for (const auto& name : functions) {
          const TestFunction f = make_test_function(name, dimension);
          std::vector<double> best;
          long max_evaluations = 0;
          for (int seed = 1; seed <= seeds; ++seed) {
            long evaluations = 0;
            const bool pagmo = algorithm.rfind("pagmo:", 0) == 0;
            best.push_back(pagmo ? run_pagmo(algorithm, f, budget, static_cast<unsigned>(seed), evaluations)
                                 : run_demcal(algorithm, f, budget, static_cast<unsigned>(seed), evaluations));
            max_evaluations = std::max(max_evaluations, evaluations);
          }
          if (max_evaluations > budget)
            std::fprintf(stderr, "warning: %s used %ld > %ld evaluations on %s\n", algorithm.c_str(), max_evaluations,
                         budget, name.c_str());
          const Quartiles q = quartiles(best);
          medians[dimension][budget][name][algorithm] = q.median;
          std::printf(" %s |", cell(q).c_str());
        }
        std::printf("\n");
        std::fflush(stdout);
      }
      std::printf("\n");
    }
  }

  std::printf("### Goals\n\n");
  for (int dimension : dimensions)
    for (long budget : {200L, 500L})
      for (const auto& name : functions) {
        const auto& m = medians[dimension][budget][name];
        const double ratio = m.at("pso") / std::max(m.at("pagmo:pso"), 1e-300);
        std::printf("- %d-D %ld evals %s: PSO median / pagmo PSO median = %.3g (%s); TBPSO(toward) / PSO = %.3g, "
                    "TBPSO(paper) / PSO = %.3g\n",
                    dimension, budget, name.c_str(), ratio, ratio <= 1.10 ? "within 10 % or better" : "worse",
                    m.at("tbpso:toward") / std::max(m.at("pso"), 1e-300),
                    m.at("tbpso:paper") / std::max(m.at("pso"), 1e-300));
      }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("\nWall time %.1f s.\n", seconds);
  return 0;
}
