// Engine studies behind docs/engine.md (minutes, not a test): loading rate, density scaling, and
// the effective thickness of a semicircular arch as the joints soften. Prints markdown tables.
//   build/bench/bench_dem_studies [rate|scaling|thickness|all]
#include "demcal/dem/generators.hpp"
#include "demcal/dem/simulation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace {

using namespace demcal::dem;

Recording run_arch(double velocity, double density_scaling = 1, double max_displacement = 0.012) {
  ArchOptions o;
  o.velocity = velocity;
  o.max_displacement = max_displacement;
  Scene s = make_arch(o);
  s.solver.density_scaling = density_scaling;
  s.solver.max_time = max_displacement / velocity * 1.2 + 60;
  return simulate(s);
}

// Force at the displacements of `grid` along the load_vertical gauge (loading branch, linear).
std::vector<double> force_on(const Recording& r, const std::vector<double>& grid) {
  const std::vector<double>& x = r.gauge_values[0];
  std::vector<double> out;
  std::size_t j = 0;
  for (double g : grid) {
    while (j + 1 < x.size() && x[j + 1] < g) ++j;
    if (j + 1 >= x.size()) {
      out.push_back(r.force.back());
      continue;
    }
    const double t = x[j + 1] > x[j] ? (g - x[j]) / (x[j + 1] - x[j]) : 0;
    out.push_back(r.force[j] + std::clamp(t, 0.0, 1.0) * (r.force[j + 1] - r.force[j]));
  }
  return out;
}

void compare(const char* label, const Recording& a, const Recording& b) {
  std::vector<double> grid;
  for (int i = 0; i < 200; ++i) grid.push_back(0.0005 + i * (0.0115 / 199));
  const auto fa = force_on(a, grid), fb = force_on(b, grid);
  double sum = 0;
  for (std::size_t i = 0; i < grid.size(); ++i) sum += (fa[i] - fb[i]) * (fa[i] - fb[i]);
  std::printf("| %s | %.0f | %.0f | %+.1f %% | %.0f |\n", label, a.peak_force, b.peak_force,
              100 * (b.peak_force / a.peak_force - 1), std::sqrt(sum / grid.size()));
}

void rate_study() {
  std::printf("\n| loading rate (mm/s) | peak (N) | force at 6 mm (N) | steps | wall time (s) | hinges | sliding joints |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  for (double v : {0.05, 0.01, 0.005, 0.001, 0.0005, 0.0001}) {
    const Recording r = run_arch(v);
    const double f6 = force_on(r, {0.006})[0];
    std::string hinges, sliding;
    for (const auto& h : r.hinges) hinges += h + " ";
    for (const auto& s : r.sliding_joints) sliding += s + " ";
    std::printf("| %g | %.0f | %.0f | %ld | %.2f | %s| %s|\n", v * 1000, r.peak_force, f6, r.steps, r.wall_time_s,
                hinges.c_str(), sliding.c_str());
    std::fflush(stdout);
  }
}

void scaling_study() {
  std::printf("\n| comparison | reference peak (N) | scaled peak (N) | peak difference | RMS force difference (N) |\n");
  std::printf("|---|---|---|---|---|\n");
  const Recording slow = run_arch(0.0001);
  compare("0.1 mm/s: unscaled vs density scaling 400", slow, run_arch(0.0001, 400));
  const Recording experiment = run_arch(5e-6, 400);
  compare("unscaled 0.1 mm/s vs 0.005 mm/s with scaling 400", slow, experiment);
  std::printf("\n0.005 mm/s with density scaling 400: %ld steps, %.1f s wall time, status %s\n", experiment.steps,
              experiment.wall_time_s, to_string(experiment.status).c_str());
}

// Smallest t/R that stands (bisection between a collapsing and a standing ratio).
void thickness_study() {
  std::printf("\n| kn (Pa/m), R = 1 m | minimum t/R that stands | vs Milankovitch 0.1075 |\n|---|---|---|\n");
  for (double kn : {1e11, 1e10, 1e9, 1e8}) {
    double lo = 0.095, hi = 0.16;  // lo collapses, hi stands (checked below)
    SemicircularArchOptions o;
    o.kn = kn;
    o.ks = kn;
    const auto stands = [&](double ratio) {
      o.thickness_ratio = ratio;
      Scene s = make_semicircular_arch(o);
      s.solver.max_equilibrium_time = 10;
      s.solver.max_time = 10;
      return simulate(s).status == RunStatus::completed;
    };
    if (stands(lo) || !stands(hi)) {
      std::printf("| %.0e | outside [%.3f, %.3f] | |\n", kn, lo, hi);
      continue;
    }
    while (hi - lo > 0.001) {
      const double mid = 0.5 * (lo + hi);
      (stands(mid) ? hi : lo) = mid;
    }
    std::printf("| %.0e | %.4f | %+.1f %% |\n", kn, hi, 100 * (hi / 0.1075 - 1));
    std::fflush(stdout);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const std::string which = argc > 1 ? argv[1] : "all";
  if (which == "rate" || which == "all") rate_study();
  if (which == "scaling" || which == "all") scaling_study();
  if (which == "thickness" || which == "all") thickness_study();
  return 0;
}
