// Studies: several algorithms x seeds on one calibration problem, compared as in the paper
// (five best sets per method, fitness statistics, simulations used).
//
// study.json:
//   {
//     "campaign": "campaign.json" | { ...campaign object... },   the problem (relative to study.json)
//     "algorithms": ["pso", "tbpso", "ga"],
//     "iterations": {"pso": 50, "ga": 50, "tbpso": 20},          optional per algorithm
//     "seeds": [1, 2, 3] | {"first": 1, "count": 10},
//     "output": "study-out"
//   }
// Every campaign runs into <output>/<algorithm>-<iterations>/seed-<seed>/ and shares one archive
// (<output>/archive.sqlite), so a run any campaign already did is never simulated again.
// Writes <output>/study.json and <output>/study.md (with a convergence figure).
#pragma once

#include "demcal/pipelines/campaign.hpp"

#include <string>
#include <vector>

namespace demcal::pipelines {

struct StudyMethod {
  std::string algorithm;
  int iterations = 0;  // 0 = the campaign's
};

struct StudyConfig {
  CampaignConfig campaign;
  std::vector<StudyMethod> methods;
  std::vector<std::uint64_t> seeds;
  std::string output = "study";
  void Validate() const;  // throws CampaignError
};

StudyConfig load_study(const std::string& path);

struct StudyMethodResult {
  StudyMethod method;
  std::vector<ParameterSet> best_per_seed;   // one per seed, in seed order (iteration field = seed index)
  std::vector<std::uint64_t> seeds;
  std::vector<ParameterSet> five_best;       // best runs of the method, best first
  double mean = 0, stddev = 0, median = 0, min = 0, max = 0;  // of the per-seed best fitness
  long simulations = 0;                      // per campaign
  double wall_time_s = 0;                    // all seeds
};

struct StudyResult {
  std::vector<StudyMethodResult> methods;
};

StudyResult run_study(const StudyConfig& config, bool progress = true);

}  // namespace demcal::pipelines
