#include "demcal/pipelines/surrogate_data.hpp"

#include <algorithm>
#include <cmath>
#include <map>

using nlohmann::json;

namespace demcal::pipelines {

namespace {
bool same(double a, double b) { return a == b || std::abs(a - b) <= 1e-12 * std::max(std::abs(a), std::abs(b)); }
}  // namespace

Eigen::VectorXd unit_point_in_space(const optimise::ParameterSpace& space, const std::map<std::string, double>& params) {
  const auto& free = space.free_parameters();
  const auto& fixed = space.fixed_parameters();
  const auto& tied = space.tied_parameter();
  const size_t expected = free.size() + fixed.size() + (tied ? 1 : 0);
  if (params.size() != expected) return {};
  Eigen::VectorXd physical(static_cast<Eigen::Index>(free.size()));
  for (size_t k = 0; k < free.size(); ++k) {
    const auto it = params.find(free[k].name);
    if (it == params.end() || !(it->second >= free[k].lower && it->second <= free[k].upper)) return {};
    physical[static_cast<Eigen::Index>(k)] = it->second;
  }
  for (const auto& [name, value] : fixed) {
    const auto it = params.find(name);
    if (it == params.end() || !same(it->second, value)) return {};
  }
  if (tied) {
    const auto it = params.find(tied->name);
    const auto source = params.find(tied->source);
    if (it == params.end() || source == params.end() || !same(it->second, source->second / tied->ratio)) return {};
  }
  return space.to_unit(physical).cwiseMax(0.0).cwiseMin(1.0);
}

std::vector<surrogate::TrainingRow> archive_training_rows(const RunArchive& archive,
                                                          const optimise::ParameterSpace& space,
                                                          const std::vector<ArchivedCase>& cases,
                                                          std::int64_t max_run_id) {
  std::vector<surrogate::TrainingRow> rows;
  if (cases.empty()) return rows;
  // Later cases: parameter key -> weighted fitness.
  std::vector<std::map<std::string, double>> others;
  for (size_t k = 1; k < cases.size(); ++k) {
    std::map<std::string, double> by_key;
    for (const auto& r : archive.run_fitness(cases[k].model_hash, cases[k].objective_key, max_run_id))
      if (r.status != "cancelled") by_key[parameter_key(r.params)] = r.fitness;
    others.push_back(std::move(by_key));
  }
  for (const auto& r : archive.run_fitness(cases[0].model_hash, cases[0].objective_key, max_run_id)) {
    if (r.status == "cancelled") continue;
    Eigen::VectorXd unit = unit_point_in_space(space, r.params);
    if (unit.size() == 0) continue;
    double fitness = cases[0].weight * r.fitness;
    bool complete = true;
    if (!others.empty()) {
      const std::string key = parameter_key(r.params);
      for (size_t k = 1; k < cases.size() && complete; ++k) {
        const auto it = others[k - 1].find(key);
        if (it == others[k - 1].end()) complete = false;
        else fitness += cases[k].weight * it->second;
      }
    }
    if (!complete) continue;
    rows.push_back({std::move(unit), std::isfinite(fitness) ? fitness : std::numeric_limits<double>::quiet_NaN()});
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
