// Profiles of the fitness on a Gaussian-process emulator (profile.hpp).
#include "demcal/surrogate/profile.hpp"
#include "internal.hpp"

#include "demcal/common/random.hpp"

#include <nlopt.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <numeric>
#include <stdexcept>
#include <tuple>

namespace demcal::surrogate {

std::string to_string(ProfileStatus status) {
  switch (status) {
    case ProfileStatus::profiled: return "profiled";
    case ProfileStatus::disabled: return "disabled";
    case ProfileStatus::too_few_rows: return "too_few_rows";
    case ProfileStatus::emulator_failed: return "emulator_failed";
    case ProfileStatus::no_finite_rows: return "no_finite_rows";
  }
  return "no_finite_rows";
}

void ProfileOptions::Validate() const {
  auto at_least = [](const char* name, long value, long least) {
    if (value < least)
      throw std::invalid_argument(std::string("profile ") + name + " = " + std::to_string(value) + " must be >= " +
                                  std::to_string(least));
  };
  at_least("grid_points", grid_points, 3);
  at_least("projected_starts", projected_starts, 0);
  at_least("random_starts", random_starts, 0);
  at_least("local_evaluations", local_evaluations, 5);
  at_least("min_rows", min_rows, 3);
  at_least("max_training_rows", max_training_rows, 10);
  limits::require_within(limits::Limit::training_rows, max_training_rows, "profile max_training_rows");
  limits::require_within(limits::Limit::training_rows, min_rows, "profile min_rows");
  limits::require_within(limits::Limit::population, grid_points, "profile grid_points");
  limits::require_within(limits::Limit::population, projected_starts, "profile projected_starts");
  limits::require_within(limits::Limit::population, random_starts, "profile random_starts");
  limits::require_within(limits::Limit::iterations, local_evaluations, "profile local_evaluations");
  gp.Validate();
}

namespace {

const FieldTable<ProfileOptions>& profile_fields() {
  static const FieldTable<ProfileOptions> table{
      field("enabled", &ProfileOptions::enabled),
      field("grid_points", &ProfileOptions::grid_points),
      field("projected_starts", &ProfileOptions::projected_starts),
      field("random_starts", &ProfileOptions::random_starts),
      field("local_evaluations", &ProfileOptions::local_evaluations),
      field("min_rows", &ProfileOptions::min_rows),
      field("max_training_rows", &ProfileOptions::max_training_rows),
      field("seed", &ProfileOptions::seed),
      custom_field<ProfileOptions>(
          "gp",
          [](ProfileOptions& o, const nlohmann::json& value, const std::string& where) {
            // keys not given keep the profile's defaults (log_transform "always")
            nlohmann::json merged = o.gp.to_json();
            if (value.is_object()) merged.update(value);
            else merged = value;
            o.gp = GpOptions::from_json(merged, where + ".gp");
          },
          [](const ProfileOptions& o) -> std::optional<nlohmann::json> { return o.gp.to_json(); }),
  };
  return table;
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The emulator's mean (model space) with coordinate `fixed` held at `value`; the free coordinates
// are the others, in order.
struct SliceObjective {
  const GaussianProcess* gp = nullptr;
  int fixed = 0;
  double value = 0;
  Eigen::VectorXd point;  // scratch, the whole unit point
  long evaluations = 0;

  void fill(const double* free) {
    for (int k = 0, j = 0; k < point.size(); ++k) point[k] = k == fixed ? value : free[j++];
  }
  double operator()(const double* free) {
    fill(free);
    ++evaluations;
    return gp->predict_mean(point);
  }
};

double slice_nlopt(unsigned, const double* x, double*, void* data) { return (*static_cast<SliceObjective*>(data))(x); }

// The minimum of the slice from one start (whole unit point, coordinate `fixed` already at the
// value): a bounded LN_BOBYQA search over the free coordinates. Returns the model-space value and
// leaves the minimiser in `start`.
double minimise_slice(SliceObjective& slice, Eigen::VectorXd& start, int max_evaluations) {
  const int d = static_cast<int>(start.size());
  std::vector<double> free;
  for (int k = 0; k < d; ++k)
    if (k != slice.fixed) free.push_back(std::clamp(start[k], 0.0, 1.0));
  double value = slice(free.data());
  if (!free.empty()) {
    const std::vector<double> lower(free.size(), 0.0), upper(free.size(), 1.0), step(free.size(), 0.1);
    // BOBYQA needs two coordinates; one goes to COBYLA, which takes one
    nlopt_opt opt = nlopt_create(free.size() >= 2 ? NLOPT_LN_BOBYQA : NLOPT_LN_COBYLA, static_cast<unsigned>(free.size()));
    nlopt_set_lower_bounds(opt, lower.data());
    nlopt_set_upper_bounds(opt, upper.data());
    nlopt_set_min_objective(opt, slice_nlopt, &slice);
    nlopt_set_maxeval(opt, max_evaluations);
    nlopt_set_initial_step(opt, step.data());
    nlopt_set_xtol_abs1(opt, 1e-4);
    std::vector<double> x = free;
    double found = value;
    const nlopt_result status = nlopt_optimize(opt, x.data(), &found);
    nlopt_destroy(opt);
    if (status > 0 || status == NLOPT_ROUNDOFF_LIMITED) {  // a failed start keeps its starting value
      if (found < value && std::isfinite(found)) {
        value = found;
        free = x;
      }
    }
  }
  for (int k = 0, j = 0; k < d; ++k) start[k] = k == slice.fixed ? slice.value : free[j++];
  return value;
}

// Distinct points (exact repeats merged, keeping the smallest fitness), finite fitness only, in the
// order of their first appearance.
std::vector<TrainingRow> distinct_finite_rows(const std::vector<TrainingRow>& rows) {
  std::vector<TrainingRow> out;
  std::map<std::vector<double>, size_t> index;
  for (const auto& row : rows) {
    if (!std::isfinite(row.fitness)) continue;
    std::vector<double> key(row.unit.data(), row.unit.data() + row.unit.size());
    const auto [it, inserted] = index.emplace(std::move(key), out.size());
    if (inserted) out.push_back(TrainingRow{row.unit, row.fitness});
    else out[it->second].fitness = std::min(out[it->second].fitness, row.fitness);
  }
  return out;
}

// Where the profile is within the threshold: the hull of the in-band grid values, each end moved
// to the linear crossing with its outside neighbour. {NaN, NaN} when no grid value is in the band.
std::pair<double, double> band_hull(const std::vector<double>& grid, const std::vector<double>& fitness, double threshold) {
  long first = -1, last = -1;
  for (size_t i = 0; i < grid.size(); ++i)
    if (fitness[i] <= threshold) {
      if (first < 0) first = static_cast<long>(i);
      last = static_cast<long>(i);
    }
  if (first < 0) return {std::nan(""), std::nan("")};
  auto crossing = [&](size_t inside, size_t outside) {
    const double fi = fitness[inside], fo = fitness[outside];
    if (!(fo > fi) || !std::isfinite(fo)) return grid[inside];
    return grid[inside] + (grid[outside] - grid[inside]) * (threshold - fi) / (fo - fi);
  };
  const double lo = first > 0 ? crossing(static_cast<size_t>(first), static_cast<size_t>(first - 1)) : grid.front();
  const double hi = last + 1 < static_cast<long>(grid.size())
                        ? crossing(static_cast<size_t>(last), static_cast<size_t>(last + 1))
                        : grid.back();
  return {lo, hi};
}

}  // namespace

nlohmann::json ProfileOptions::to_json() const { return profile_fields().to_json(*this); }

ProfileOptions ProfileOptions::from_json(const nlohmann::json& j, const std::string& where) {
  return detail::options_from_json(j, where, profile_fields());
}

namespace {

// The band over the evaluated sets (`order`: `distinct` by fitness, best first): each coordinate's
// best, its evaluated range, and its reported range, to be widened by the profile.
void evaluated_ranges(ProfileResult& result, const std::vector<TrainingRow>& distinct, const std::vector<size_t>& order) {
  const TrainingRow& best = distinct[order.front()];
  const long d = best.unit.size();
  result.best_fitness = best.fitness;
  result.band_fitness = best.fitness * (1 + result.relative_band);
  result.coordinates.resize(static_cast<size_t>(d));
  for (long k = 0; k < d; ++k) {
    auto& c = result.coordinates[static_cast<size_t>(k)];
    c.best = c.evaluated_min = c.evaluated_max = best.unit[k];
  }
  for (size_t i : order) {
    if (distinct[i].fitness > result.band_fitness) break;
    ++result.rows_in_band;
    for (long k = 0; k < d; ++k) {
      auto& c = result.coordinates[static_cast<size_t>(k)];
      c.evaluated_min = std::min(c.evaluated_min, distinct[i].unit[k]);
      c.evaluated_max = std::max(c.evaluated_max, distinct[i].unit[k]);
    }
  }
  for (auto& c : result.coordinates) {
    c.min = c.evaluated_min;
    c.max = c.evaluated_max;
  }
}

// The emulator of the fitness on `distinct`, its figures into `result`; false (status and message
// set) when it cannot be fitted.
bool fit_emulator(GaussianProcess& gp, ProfileResult& result, const std::vector<TrainingRow>& distinct,
                  const TrainingRow& best, const ProfileOptions& options) {
  const auto fit_start = std::chrono::steady_clock::now();
  const std::vector<TrainingRow> training = select_training_rows(distinct, options.max_training_rows);
  Eigen::MatrixXd X(static_cast<Eigen::Index>(training.size()), best.unit.size());
  Eigen::VectorXd y(static_cast<Eigen::Index>(training.size()));
  for (size_t i = 0; i < training.size(); ++i) {
    X.row(static_cast<Eigen::Index>(i)) = training[i].unit.transpose();
    y[static_cast<Eigen::Index>(i)] = training[i].fitness;
  }
  GpOptions gp_options = options.gp;
  if (gp_options.log_transform == LogTransform::always && !(y.array() > 0).all()) gp_options.log_transform = LogTransform::never;
  gp = GaussianProcess(gp_options);
  try {
    gp.fit(X, y);
  } catch (const std::exception& e) {
    result.status = ProfileStatus::emulator_failed;
    result.message = std::string("emulator not fitted (") + e.what() + "): ranges over the evaluated sets only";
    result.fit_seconds = seconds_since(fit_start);
    return false;
  }
  result.fit_seconds = seconds_since(fit_start);
  if (!gp.fitted()) {
    result.status = ProfileStatus::emulator_failed;
    result.message = "emulator not fitted: ranges over the evaluated sets only";
    return false;
  }
  result.training_rows = gp.points();
  result.log_transformed = gp.log_transformed();
  result.loo_relative_error = gp.leave_one_out().relative_error;
  result.noise_sd = gp.noise_sd();
  result.length_scales = gp.length_scales();
  result.emulator_at_best = gp.from_model(gp.predict_mean(best.unit));
  return true;
}

// The profile of coordinate k on the emulator, swept outwards from the grid value nearest the best
// row: at each value the emulator minimised over the other coordinates from the neighbour's
// minimiser, the best rows projected onto the value and seeded random points. Returns the emulator
// evaluations it took.
long profile_coordinate(CoordinateProfile& c, long k, const GaussianProcess& gp,
                        const std::vector<TrainingRow>& distinct, const std::vector<size_t>& order,
                        const ProfileOptions& options) {
  const long d = distinct.front().unit.size();
  const int n = options.grid_points;
  const size_t projected = std::min(order.size(), static_cast<size_t>(options.projected_starts));
  c.grid.resize(static_cast<size_t>(n));
  for (int g = 0; g < n; ++g) c.grid[static_cast<size_t>(g)] = static_cast<double>(g) / (n - 1);
  std::vector<double> model(static_cast<size_t>(n), HUGE_VAL);
  c.argmin.assign(static_cast<size_t>(n), Eigen::VectorXd());
  SliceObjective slice;
  slice.gp = &gp;
  slice.fixed = static_cast<int>(k);
  slice.point = Eigen::VectorXd(d);
  const int centre = static_cast<int>(std::lround(distinct[order.front()].unit[k] * (n - 1)));
  auto profile_at = [&](int g, int neighbour) {
    slice.value = c.grid[static_cast<size_t>(g)];
    std::vector<Eigen::VectorXd> starts;
    if (neighbour >= 0) starts.push_back(c.argmin[static_cast<size_t>(neighbour)]);
    for (size_t s = 0; s < projected; ++s) starts.push_back(distinct[order[s]].unit);
    std::mt19937_64 rng = seeded_rng(options.seed, k, g);
    for (int s = 0; s < options.random_starts; ++s) {
      Eigen::VectorXd u(d);
      for (long j = 0; j < d; ++j) u[j] = uniform01(rng);
      starts.push_back(u);
    }
    for (auto& start : starts) {
      start[k] = slice.value;
      const double value = minimise_slice(slice, start, options.local_evaluations);
      if (value < model[static_cast<size_t>(g)]) {
        model[static_cast<size_t>(g)] = value;
        c.argmin[static_cast<size_t>(g)] = start;
      }
    }
  };
  profile_at(centre, -1);
  for (int g = centre + 1; g < n; ++g) profile_at(g, g - 1);
  for (int g = centre - 1; g >= 0; --g) profile_at(g, g + 1);
  c.fitness.resize(static_cast<size_t>(n));
  c.sd.resize(static_cast<size_t>(n));
  for (int g = 0; g < n; ++g) {
    c.sd[static_cast<size_t>(g)] = gp.predict(c.argmin[static_cast<size_t>(g)]).sd;
    c.fitness[static_cast<size_t>(g)] = gp.from_model(model[static_cast<size_t>(g)]);
  }
  return slice.evaluations;
}

}  // namespace

ProfileResult profile_fitness(const std::vector<TrainingRow>& rows, double relative_band, const ProfileOptions& options) {
  options.Validate();
  if (!(relative_band >= 0) || !std::isfinite(relative_band))
    throw std::invalid_argument("profile: relative_band = " + std::to_string(relative_band) + " must be finite and >= 0");
  const long d = rows.empty() ? 0 : static_cast<long>(rows.front().unit.size());
  for (const auto& row : rows)
    if (row.unit.size() != d) throw std::invalid_argument("profile: rows of different dimensions");

  ProfileResult result;
  result.relative_band = relative_band;
  const std::vector<TrainingRow> distinct = distinct_finite_rows(rows);
  result.finite_rows = static_cast<long>(distinct.size());
  if (distinct.empty() || d == 0) {
    result.message = "no parameter set with a finite fitness";
    return result;
  }
  // Rows by fitness, best first (stable: ties keep their order).
  std::vector<size_t> order(distinct.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return distinct[a].fitness < distinct[b].fitness; });
  evaluated_ranges(result, distinct, order);
  if (!options.enabled) {
    result.status = ProfileStatus::disabled;
    result.message = "profile disabled: ranges over the evaluated sets only";
    return result;
  }
  if (result.finite_rows < options.min_rows) {
    result.status = ProfileStatus::too_few_rows;
    result.message = std::to_string(result.finite_rows) + " distinct parameter sets with a finite fitness, " +
                     std::to_string(options.min_rows) + " needed to train an emulator: ranges over the evaluated sets only";
    return result;
  }
  GaussianProcess gp;
  if (!fit_emulator(gp, result, distinct, distinct[order.front()], options)) return result;
  const auto profile_start = std::chrono::steady_clock::now();
  double smallest = HUGE_VAL;
  for (long k = 0; k < d; ++k) {
    auto& c = result.coordinates[static_cast<size_t>(k)];
    result.emulator_evaluations += profile_coordinate(c, k, gp, distinct, order, options);
    for (double f : c.fitness) smallest = std::min(smallest, f);
  }
  result.emulator_minimum = smallest;
  // The threshold, the profile ranges and the reported ranges.
  result.threshold = std::max(result.best_fitness, result.emulator_minimum) * (1 + relative_band);
  for (auto& c : result.coordinates) {
    std::tie(c.profile_min, c.profile_max) = band_hull(c.grid, c.fitness, result.threshold);
    if (std::isfinite(c.profile_min)) {
      c.min = std::min(c.min, c.profile_min);
      c.max = std::max(c.max, c.profile_max);
    }
  }
  result.profile_seconds = seconds_since(profile_start);
  result.status = ProfileStatus::profiled;
  return result;
}

}  // namespace demcal::surrogate
