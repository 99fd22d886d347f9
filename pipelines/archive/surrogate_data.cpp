#include "demcal/pipelines/surrogate_data.hpp"

#include "demcal/common/format.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <stdexcept>

using nlohmann::json;

namespace demcal::pipelines {

namespace {
bool same(double a, double b) { return a == b || std::abs(a - b) <= 1e-12 * std::max(std::abs(a), std::abs(b)); }

}  // namespace

Eigen::VectorXd run_outputs(const std::vector<RunCurves>& runs, const std::vector<ArchivedCase>& cases) {
  if (runs.size() != cases.size() || cases.empty()) return {};
  std::vector<Eigen::VectorXd> parts;
  Eigen::Index total = 0;
  for (size_t k = 0; k < cases.size(); ++k) {
    if (!cases[k].grid || !runs[k].curves) return {};
    // scored as the campaign scored it: a collapsed run carries nothing after its collapse
    std::map<std::string, double> ends;
    for (const auto& c : cases[k].grid->channels) ends[c.column] = c.upper;
    smoothing::ObjectiveOptions columns;
    columns.force_column = cases[k].grid->force_column;
    parts.push_back(curve_outputs(runs[k].status == "collapsed" ? smoothing::continued_after_collapse(*runs[k].curves, ends, columns)
                                                                : *runs[k].curves,
                                  *cases[k].grid));
    if (parts.back().size() == 0) return {};
    total += parts.back().size();
  }
  Eigen::VectorXd outputs(total);
  Eigen::Index offset = 0;
  for (const auto& part : parts) {
    outputs.segment(offset, part.size()) = part;
    offset += part.size();
  }
  return outputs;
}

Eigen::VectorXd archived_outputs(const RunArchive& archive, const std::vector<std::int64_t>& run_ids,
                                 const std::vector<ArchivedCase>& cases) {
  if (run_ids.size() != cases.size() || cases.empty()) return {};
  std::vector<std::optional<RunRecord>> records;
  std::vector<RunCurves> runs;
  for (const auto id : run_ids) {
    records.push_back(archive.run(id));
    if (!records.back()) return {};
  }
  for (const auto& r : records) runs.push_back({r->status, &r->curves});
  return run_outputs(runs, cases);
}

CurveGrid make_curve_grid(const smoothing::Curve& measured, const smoothing::ObjectiveOptions& objective,
                          const smoothing::Objective2* objective2, double case_weight, int points) {
  if (points < 2) throw std::invalid_argument("curve grid: points = " + std::to_string(points) + " must be >= 2");
  CurveGrid grid;
  grid.force_column = objective.force_column;
  grid.points = points;
  grid.objective_points = objective.points;
  grid.objective_window = objective.window;
  grid.case_weight = case_weight;
  for (const auto& column : smoothing::displacement_columns(measured, objective)) {
    const auto envelope = smoothing::loading_envelope(smoothing::series(measured, column, objective.force_column));
    if (envelope.x.size() < 2) throw smoothing::CurveError(measured.source + ": channel '" + column + "' has fewer than 2 loading points");
    CurveGrid::Channel c;
    c.column = column;
    c.lower = envelope.x.front();
    c.upper = envelope.x.back();
    const auto w = objective.channel_weights.find(column);
    c.weight = w == objective.channel_weights.end() ? 1.0 : w->second;
    c.measured = objective2 ? smoothing::loading_envelope(objective2->smoothed_experiment().at(column)) : envelope;
    grid.channels.push_back(std::move(c));
  }
  if (grid.channels.empty()) throw smoothing::CurveError(measured.source + ": no displacement channel");
  return grid;
}

Eigen::VectorXd curve_outputs(const smoothing::Curve& run, const CurveGrid& grid) {
  Eigen::VectorXd outputs(grid.size());
  Eigen::Index i = 0;
  for (const auto& c : grid.channels) {
    if (!run.has_column(c.column) || !run.has_column(grid.force_column)) return {};
    const auto envelope = smoothing::loading_envelope(smoothing::series(run, c.column, grid.force_column));
    if (envelope.x.empty()) return {};
    for (int k = 0; k < grid.points; ++k) outputs[i++] = smoothing::interpolate(envelope, grid.displacement(c, k));
    outputs[i++] = envelope.x.back();
  }
  return outputs;
}

smoothing::XYSeries output_channel(const Eigen::VectorXd& outputs, Eigen::Index offset, const CurveGrid& grid,
                                   size_t channel) {
  const auto& c = grid.channels.at(channel);
  const Eigen::Index start = offset + static_cast<Eigen::Index>(channel) * (grid.points + 1);
  const double end = std::clamp(outputs[start + grid.points], grid.displacement(c, 1), c.upper);
  smoothing::XYSeries s;
  s.x.reserve(static_cast<std::size_t>(grid.points));
  s.y.reserve(static_cast<std::size_t>(grid.points));
  for (int k = 0; k < grid.points; ++k) {
    const double w = grid.displacement(c, k);
    if (w >= end) {
      // The end point, interpolated between the grid points either side of it.
      const double before = grid.displacement(c, k - 1);
      const double t = (end - before) / (w - before);
      s.x.push_back(end);
      s.y.push_back(outputs[start + k - 1] + t * (outputs[start + k] - outputs[start + k - 1]));
      break;
    }
    s.x.push_back(w);
    s.y.push_back(outputs[start + k]);
  }
  return s;
}

double curve_fitness(const Eigen::VectorXd& outputs, const std::vector<std::shared_ptr<const CurveGrid>>& grids) {
  double fitness = 0;
  Eigen::Index offset = 0;
  for (const auto& grid : grids) {
    double f = 0;
    for (size_t c = 0; c < grid->channels.size(); ++c) {
      // Its displacements increase strictly, so only a non-finite force leaves a row out of its envelope.
      smoothing::XYSeries predicted = output_channel(outputs, offset, *grid, c);
      if (!std::all_of(predicted.y.begin(), predicted.y.end(), [](double y) { return std::isfinite(y); }))
        predicted = smoothing::loading_envelope(predicted);
      f += grid->channels[c].weight * smoothing::envelope_misfit(grid->channels[c].measured, predicted, grid->objective_points,
                                                                 grid->channels[c].column, grid->objective_window);
    }
    fitness += grid->case_weight * f;
    offset += grid->size();
  }
  return fitness;
}

std::string outside_space(const optimise::ParameterSpace& space, const std::map<std::string, double>& params) {
  const auto& free = space.free_parameters();
  const auto& fixed = space.fixed_parameters();
  const auto& tied = space.tied_parameter();
  for (const auto& p : free) {
    const auto it = params.find(p.name);
    if (it == params.end()) return "no value for the campaign's parameter '" + p.name + "'";
    if (!(it->second >= p.lower && it->second <= p.upper))
      return p.name + " = " + format_number(it->second, 6) + " lies outside the campaign's bounds [" + format_number(p.lower, 6) +
             ", " + format_number(p.upper, 6) + "]";
  }
  for (const auto& [name, value] : params) {
    const bool known = fixed.count(name) || (tied && tied->name == name) ||
                       std::any_of(free.begin(), free.end(), [&name = name](const auto& p) { return p.name == name; });
    if (!known) return "'" + name + "' is not a parameter of the campaign";
  }
  for (const auto& [name, value] : fixed) {
    const auto it = params.find(name);
    if (it == params.end()) return "no value for the campaign's fixed parameter '" + name + "'";
    if (!same(it->second, value))
      return name + " = " + format_number(it->second, 6) + ", but the campaign fixes it at " + format_number(value, 6);
  }
  if (tied) {
    const auto it = params.find(tied->name);
    const auto source = params.find(tied->source);
    if (it == params.end() || source == params.end() || !same(it->second, source->second / tied->ratio))
      return tied->name + " is not " + tied->source + " / " + format_number(tied->ratio, 6) + ", as the campaign ties it";
  }
  return "";
}

Eigen::VectorXd unit_point_in_space(const optimise::ParameterSpace& space, const std::map<std::string, double>& params) {
  if (!outside_space(space, params).empty()) return {};
  const auto& free = space.free_parameters();
  Eigen::VectorXd physical(static_cast<Eigen::Index>(free.size()));
  for (size_t k = 0; k < free.size(); ++k) physical[static_cast<Eigen::Index>(k)] = params.at(free[k].name);
  return space.to_unit(physical).cwiseMax(0.0).cwiseMin(1.0);
}

std::vector<surrogate::TrainingRow> archive_training_rows(const RunArchive& archive,
                                                          const optimise::ParameterSpace& space,
                                                          const std::vector<ArchivedCase>& cases,
                                                          std::int64_t max_run_id) {
  std::vector<surrogate::TrainingRow> rows;
  if (cases.empty()) return rows;
  const bool with_outputs = std::all_of(cases.begin(), cases.end(), [](const ArchivedCase& c) { return c.grid != nullptr; });
  // Later cases: parameter key -> (fitness, run id).
  std::vector<std::map<std::string, std::pair<double, std::int64_t>>> others;
  for (size_t k = 1; k < cases.size(); ++k) {
    std::map<std::string, std::pair<double, std::int64_t>> by_key;
    for (const auto& r : archive.run_fitness(cases[k].model_hash, cases[k].objective_key, max_run_id))
      if (r.status != "cancelled") by_key[parameter_key(r.params)] = {r.fitness, r.run_id};
    others.push_back(std::move(by_key));
  }
  for (const auto& r : archive.run_fitness(cases[0].model_hash, cases[0].objective_key, max_run_id)) {
    if (r.status == "cancelled") continue;
    Eigen::VectorXd unit = unit_point_in_space(space, r.params);
    if (unit.size() == 0) continue;
    double fitness = cases[0].weight * r.fitness;
    std::vector<std::int64_t> run_ids = {r.run_id};
    bool complete = true;
    if (!others.empty()) {
      const std::string key = parameter_key(r.params);
      for (size_t k = 1; k < cases.size() && complete; ++k) {
        const auto it = others[k - 1].find(key);
        if (it == others[k - 1].end()) {
          complete = false;
        } else {
          fitness += cases[k].weight * it->second.first;
          run_ids.push_back(it->second.second);
        }
      }
    }
    if (!complete) continue;
    const bool finite = std::isfinite(fitness);
    rows.push_back({std::move(unit), finite ? fitness : std::numeric_limits<double>::quiet_NaN(),
                    finite && with_outputs ? archived_outputs(archive, run_ids, cases) : Eigen::VectorXd()});
  }
  // Run ids follow the order in which parallel runs finished; the rows must not, or a model trained
  // on them (and every choice made with it) would depend on the machine's load.
  std::sort(rows.begin(), rows.end(), [](const surrogate::TrainingRow& a, const surrogate::TrainingRow& b) {
    return std::lexicographical_compare(a.unit.data(), a.unit.data() + a.unit.size(), b.unit.data(),
                                        b.unit.data() + b.unit.size());
  });
  return rows;
}

ArchivedProblem find_archived_problem(const RunArchive& archive, const std::string& scene_hash,
                                      const std::string& objective_key) {
  ArchivedProblem p;
  for (const auto& mo : archive.model_objectives()) {  // most rows first
    if (!scene_hash.empty() && mo.model_hash != scene_hash) continue;
    if (!objective_key.empty() && mo.objective_key != objective_key) continue;
    p.model_hash = mo.model_hash;
    p.objective_key = mo.objective_key;
    break;
  }
  if (p.model_hash.empty())
    throw ArchiveError(archive.path() + ": no scored run" + (scene_hash.empty() ? "" : " of scene hash " + scene_hash) +
                       (objective_key.empty() ? "" : " with objective key " + objective_key));
  // The newest campaign whose first evaluation ran this scene gives the parameter space.
  const auto campaigns = archive.campaigns();
  for (auto c = campaigns.rbegin(); c != campaigns.rend(); ++c) {
    const auto evaluations = archive.evaluations(c->id);
    bool ran_scene = false;
    for (const auto& e : evaluations) {
      for (auto id : e.run_ids)
        if (auto run = archive.run(id); run && run->model_hash == p.model_hash) ran_scene = true;
      break;
    }
    if (!ran_scene) continue;
    try {
      p.space = optimise::ParameterSpace::from_json(c->config.at("parameters"), archive.path() + ": campaign " + c->name);
      if (c->config.contains("surrogate")) {
        json options = c->config.at("surrogate");
        options.erase("model");
        options.erase("model_content_hash");
        p.options = surrogate::SurrogateOptions::from_json(options, archive.path() + ": campaign " + c->name + ": surrogate");
      }
    } catch (const std::exception& e) {
      throw ArchiveError(archive.path() + ": campaign '" + c->name + "': cannot read its parameter space: " + e.what());
    }
    p.campaign_name = c->name;
    break;
  }
  if (p.campaign_name.empty())
    throw ArchiveError(archive.path() + ": no campaign in the archive ran scene hash " + p.model_hash +
                       " (its parameter space is unknown)");
  p.rows = archive_training_rows(archive, p.space, {{p.model_hash, p.objective_key, 1.0}});
  return p;
}

}  // namespace demcal::pipelines
