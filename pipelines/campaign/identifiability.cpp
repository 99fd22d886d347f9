// The identifiability block of result.json: ranges over the evaluated sets within the noise band,
// widened by profiles of the fitness on an emulator (surrogate/profile.hpp).
#include "campaign_internal.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::pipelines {

using nlohmann::json;

Identifiability compute_identifiability(const std::vector<ParameterSet>& all, const optimise::ParameterSpace& space,
                                        double relative_band, const surrogate::ProfileOptions& options) {
  Identifiability id;
  id.relative_band = relative_band;
  id.options = options;
  const auto names = space.free_names();
  id.coordinate_names = names;
  const auto top = detail::top_distinct(all, all.size());
  if (top.empty()) {
    id.method_note = "no parameter set with a finite fitness";
    return id;
  }

  // The evaluated ranges, in physical values exactly as evaluated.
  id.band_fitness = top.front().fitness * (1 + relative_band);
  for (const auto& name : names) {
    const double best = top.front().params.at(name);
    ParameterRange& range = id.parameters[name];
    range.best = range.min = range.max = range.evaluated_min = range.evaluated_max = best;
  }
  for (const auto& s : top) {
    if (s.fitness > id.band_fitness) break;
    ++id.sets_in_band;
    for (auto& [name, range] : id.parameters) {
      range.evaluated_min = range.min = std::min(range.evaluated_min, s.params.at(name));
      range.evaluated_max = range.max = std::max(range.evaluated_max, s.params.at(name));
    }
  }

  // The profiles, in the optimiser's unit cube.
  std::vector<surrogate::TrainingRow> rows;
  rows.reserve(all.size());
  const Eigen::Index d = space.dimension();
  for (const auto& s : all) {
    Eigen::VectorXd physical(d);
    for (Eigen::Index k = 0; k < d; ++k) physical[k] = s.params.at(names[static_cast<size_t>(k)]);
    rows.push_back({space.to_unit(physical), s.fitness});
  }
  id.profile = surrogate::profile_fitness(rows, relative_band, options);
  if (id.profile.status != surrogate::ProfileStatus::profiled) {
    id.method_note = id.profile.message;
    return id;
  }
  id.method = "profile";
  id.emulator_kind = "gp";
  // One coordinate of the unit cube to its physical value (the space maps coordinate by coordinate).
  auto physical = [&](Eigen::Index k, double unit) {
    Eigen::VectorXd u = Eigen::VectorXd::Constant(d, 0.5);
    u[k] = unit;
    return space.to_physical(u)[k];
  };
  for (Eigen::Index k = 0; k < d; ++k) {
    const auto& c = id.profile.coordinates[static_cast<size_t>(k)];
    auto& range = id.parameters.at(names[static_cast<size_t>(k)]);
    for (size_t g = 0; g < c.grid.size(); ++g) {
      range.profile_values.push_back(physical(k, c.grid[g]));
      range.profile_fitness.push_back(c.fitness[g]);
      range.profile_sd.push_back(c.sd[g]);
      for (Eigen::Index j = 0; j < d; ++j)
        if (j != k) range.profile_others[names[static_cast<size_t>(j)]].push_back(physical(j, c.argmin[g][j]));
    }
    if (std::isfinite(c.profile_min)) {
      range.profile_min = physical(k, c.profile_min);
      range.profile_max = physical(k, c.profile_max);
      range.min = std::min(range.evaluated_min, range.profile_min);
      range.max = std::max(range.evaluated_max, range.profile_max);
    }
  }
  return id;
}

namespace detail {

Identifiability identifiability(const std::vector<ParameterSet>& all, const CampaignConfig& config) {
  const double band = config.identifiability_band > 0
                          ? config.identifiability_band
                          : 1.0 / std::sqrt(2.0 * static_cast<double>(config.objective_options.points));
  return compute_identifiability(all, config.space, band, config.identifiability_profile);
}

}  // namespace detail

json Identifiability::to_json() const {
  json params = json::object();
  for (const auto& [name, r] : parameters) {
    json p = {{"best", r.best}, {"min", r.min}, {"max", r.max},
              {"evaluated_min", r.evaluated_min}, {"evaluated_max", r.evaluated_max},
              {"profile_min", finite_or_null(r.profile_min)}, {"profile_max", finite_or_null(r.profile_max)}};
    if (r.min > 0) p["max_over_min"] = r.max / r.min;
    if (r.evaluated_min > 0) p["evaluated_max_over_min"] = r.evaluated_max / r.evaluated_min;
    if (!r.profile_values.empty()) {
      json others = json::object();
      for (const auto& [other, values] : r.profile_others) others[other] = values;
      p["profile"] = {{"values", r.profile_values}, {"fitness", r.profile_fitness}, {"sd", r.profile_sd},
                      {"others", others}};
    }
    params[name] = std::move(p);
  }
  json j = {{"relative_band", relative_band}, {"band_fitness", finite_or_null(band_fitness)},
            {"sets_in_band", sets_in_band}, {"method", method}};
  if (!method_note.empty()) j["method_note"] = method_note;
  if (method == "profile") {
    const auto& p = profile;
    json lengths = json::object();  // unit-cube lengths, by parameter
    for (size_t k = 0; k < coordinate_names.size() && static_cast<Eigen::Index>(k) < p.length_scales.size(); ++k)
      lengths[coordinate_names[k]] = p.length_scales[static_cast<Eigen::Index>(k)];
    j["emulator"] = {{"kind", emulator_kind},
                     {"training_runs", p.training_rows},
                     {"finite_runs", p.finite_rows},
                     {"log_fitness", p.log_transformed},
                     {"loo_relative_error", finite_or_null(p.loo_relative_error)},
                     {"noise_sd", finite_or_null(p.noise_sd)},
                     {"length_scales", lengths},
                     {"minimum", finite_or_null(p.emulator_minimum)},
                     {"at_best", finite_or_null(p.emulator_at_best)},
                     {"threshold", finite_or_null(p.threshold)},
                     {"evaluations", p.emulator_evaluations},
                     {"options", options.to_json()}};
  }
  j["parameters"] = params;
  return j;
}

}  // namespace demcal::pipelines
