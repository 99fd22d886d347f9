// Studies: several algorithms x seeds on one calibration problem, compared as in the paper's
// Tables 1-4 (five best solution sets per method with their fitness), with the fitness statistics
// of the per-seed best, the simulations used, a convergence figure and the calibrated sets in
// parameter space (the paper's Figures 14, 17, 20, 23).
//
// study.json (relative paths are relative to the study file):
//   {
//     "campaign": "campaign.json" | { ...campaign object... },   the problem
//     "algorithms": ["pso", "tbpso",                             a name (iterations from the map
//                    {"algorithm": "pso", "iterations": 20,       below, else the campaign's), or an
//                     "label": "pso-20"}],                        object: the same algorithm may
//                                                                 appear with several budgets
//     "iterations": {"pso": 50, "ga": 50, "tbpso": 20},          optional, for names given as strings
//     "seeds": [1, 2, 3] | {"first": 1, "count": 10},            default {"first": 1, "count": 10}
//     "output": "study-out"                                      default "study"
//   }
// Population, objective, bounds, backend and every other option come from the campaign; only the
// algorithm, its iterations and the seed change between the campaigns of a study.
//
// Every campaign runs into <output>/<label>/seed-<seed>/ (result.json, no report) and all share one
// archive, <output>/archive.sqlite: a simulation any campaign already did is read back, never
// repeated. Each campaign runs with --resume semantics, so a study that was interrupted and is run
// again continues where it stopped and ends with the result of an uninterrupted study.
// Writes <output>/study.json, <output>/study.md and <output>/figures/*.png.
#pragma once

#include "demcal/pipelines/campaign.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace demcal::pipelines {

struct StudyMethod {
  std::string algorithm;   // "pso" | "tbpso" | "ga" | "nlopt:<NAME>" (OptimiserOptions::algorithm)
  int iterations = 0;      // 0 = the campaign's optimiser.iterations
  std::string label;       // "" = "<algorithm>-<iterations>"; names the method's folder and table rows
};

struct StudyConfig {
  CampaignConfig campaign;             // the problem; optimiser.algorithm/iterations/seed are replaced
  std::vector<StudyMethod> methods;
  std::vector<std::uint64_t> seeds;    // one campaign per method and seed
  std::string output = "study";        // folder of study.json, study.md, figures/, archive.sqlite
  bool resume = true;                  // continue campaigns already in the study's archive
  std::string source = "study";        // the study file, for messages
  // Throws CampaignError: no methods or seeds, duplicate seeds or labels, iterations < 0, an
  // algorithm the optimisers do not know (the message names the method and the value).
  void Validate() const;
};

// Parses study.json. Throws CampaignError naming the file, the key and the bad value.
StudyConfig load_study(const std::string& path);
StudyConfig study_from_json(const nlohmann::json& json, const std::string& base_dir, const std::string& source);

// One campaign of a study.
struct StudyCampaign {
  std::uint64_t seed = 0;
  CampaignStatus status = CampaignStatus::completed;
  std::string message;
  ParameterSet best;                    // iteration/position: where in the campaign it was found
  long simulations = 0;                 // simulations the campaign used (candidates x cases)
  long simulated = 0;                   // of which run by this study session (the rest: archive)
  double wall_time_s = 0;               // this session
  std::vector<double> best_history;     // best fitness after each candidate
};

// Statistics of the per-seed best fitness (finite values only; all 0 and count 0 when none is).
struct FitnessStatistics {
  long count = 0;
  double mean = 0, stddev = 0, median = 0, min = 0, max = 0;  // stddev: sample (n - 1)
};
FitnessStatistics fitness_statistics(std::vector<double> values);

struct StudyMethodResult {
  StudyMethod method;                   // label and iterations filled in
  std::vector<StudyCampaign> campaigns; // one per seed, in the study's seed order
  std::vector<size_t> five_best;        // indices into campaigns: the five best per-seed bests, best first
  FitnessStatistics fitness;            // of the per-seed best
  // The same statistics of the best fitness after the study's common budget (the fewest
  // simulations any method used), so methods with different budgets compare at equal cost.
  FitnessStatistics fitness_at_common_budget;
  long simulations_per_campaign = 0;    // the largest over seeds (they are equal unless a run failed)
  long simulations_total = 0;           // over seeds
  double wall_time_s = 0;               // over seeds, this session
};

struct StudyResult {
  std::vector<StudyMethodResult> methods;
  long common_budget = 0;               // simulations (see fitness_at_common_budget)
  std::string markdown_path, json_path;
};

// Runs every method x seed (methods in order, seeds in order), then writes study.json, study.md
// and figures. progress: one line per campaign on stderr. Throws CampaignError for bad input.
StudyResult run_study(const StudyConfig& config, bool progress = true);

}  // namespace demcal::pipelines
