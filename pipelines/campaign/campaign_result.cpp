// result.json: the campaign result as JSON (its identifiability block: identifiability.cpp).
#include "campaign_internal.hpp"

#include <algorithm>
#include <cmath>
#include <set>

namespace demcal::pipelines {

using nlohmann::json;

namespace detail {

std::vector<ParameterSet> top_distinct(const std::vector<ParameterSet>& all, size_t count) {
  std::vector<const ParameterSet*> sorted;
  for (const auto& s : all)
    if (std::isfinite(s.fitness)) sorted.push_back(&s);
  std::stable_sort(sorted.begin(), sorted.end(),
                   [](const ParameterSet* a, const ParameterSet* b) { return a->fitness < b->fitness; });
  std::vector<ParameterSet> top;
  std::set<std::string> seen;
  for (const auto* s : sorted) {
    if (!seen.insert(parameter_key(s->params)).second) continue;
    top.push_back(*s);
    if (top.size() == count) break;
  }
  return top;
}

}  // namespace detail

namespace {

json params_json(const std::map<std::string, double>& params) {
  json j = json::object();
  for (const auto& [name, value] : params) j[name] = value;
  return j;
}

}  // namespace

json CampaignResult::to_json() const {
  auto set_json = [](const ParameterSet& s) {
    return json{{"params", params_json(s.params)}, {"fitness", finite_or_null(s.fitness)},
                {"iteration", s.iteration}, {"position", s.position}};
  };
  json top_json = json::array();
  for (const auto& s : top) top_json.push_back(set_json(s));
  json convergence = json::array();
  for (double v : best_history) convergence.push_back(finite_or_null(v));
  json j = {{"status", status == CampaignStatus::completed ? "completed" : "failed"},
          {"message", message},
          {"best", set_json(best)},
          {"top", top_json},
          {"simulations", simulations},
          {"candidates", candidates},
          {"failed_runs", failed_runs},
          {"iterations", iterations},
          {"optimiser_status", optimiser_status},
          {"convergence", convergence},
          {"wall_time_s", wall_time_s},
          {"timing", {{"wall_s", wall_time_s}, {"model_s", model_time_s}, {"simulations_s", simulation_time_s},
                      {"runs_summed_s", run_time_s},
                      {"identifiability_fit_s", identifiability.profile.fit_seconds},
                      {"identifiability_profile_s", identifiability.profile.profile_seconds}}},
          {"identifiability", identifiability.to_json()},
          {"session", {{"simulated", simulated_this_session}, {"reused_from_archive", reused_from_archive}}}};
  if (surrogate_used)
    j["surrogate"] = {{"kind", surrogate_kind},
                      {"screened", surrogate_screened},
                      {"simulated", surrogate_simulated},
                      {"screened_out", surrogate_screened_out},
                      {"cv_error", finite_or_null(surrogate_cv_error)}};
  if (surrogate_used && surrogate_batch > 0)
    j["surrogate"].update({{"batch", surrogate_batch},
                           {"batch_reason", surrogate_batch_reason},
                           {"predicted", surrogate_predicted},
                           {"prequential_error", finite_or_null(surrogate_prequential_error)},
                           {"prequential_coverage90", finite_or_null(surrogate_prequential_coverage90)}});
  if (polished)
    j["polish"] = {{"evaluations", polish_evaluations}, {"swarm_best_fitness", finite_or_null(swarm_best_fitness)},
                   {"status", polish_status}};
  return j;
}

}  // namespace demcal::pipelines
