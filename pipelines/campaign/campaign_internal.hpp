// Pieces of run_campaign shared by campaign.cpp (the stages), campaign_cases.cpp (cases, backend,
// fitness workers) and campaign_result.cpp (result.json). Not a public header.
#pragma once

#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/backend.hpp"
#include "demcal/pipelines/campaign.hpp"

#include <nlohmann/json.hpp>

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace demcal::pipelines::detail {

// A run whose curves can be scored: the engine finished it (collapse and step limit included).
bool usable_status(const std::string& status);


// Everything prepared before the first simulation, per case: the measured curve, the objective key
// its fitness rows are archived under, objective 2's smoother, and the scene (engine backends only).
struct PreparedCases {
  std::vector<smoothing::Curve> measured;
  std::vector<std::string> objective_keys;
  std::vector<std::unique_ptr<smoothing::Objective2>> objective2;  // per case, objective 2 only
  std::vector<dem::Scene> scenes;                                   // engine backends only
};

// Throws CampaignError naming the file, key or parameter at fault.
PreparedCases prepare_cases(const CampaignConfig& config);
// The "mlp" surrogate's curve grid of case k (surrogate_data.hpp). Throws CampaignError naming the case.
std::shared_ptr<const CurveGrid> case_curve_grid(const CampaignConfig& config, const PreparedCases& prepared, size_t k);
// The cases' scenes, each checked to know every parameter of the space.
std::vector<dem::Scene> build_scenes(const CampaignConfig& config);
std::unique_ptr<EvaluationBackend> make_backend(const CampaignConfig& config, const PreparedCases& prepared,
                                                const RunOptions& options);
// The campaign's external command as a backend (its template, timeout, output limit, each
// case's name and scene file), `parallel` runs at once, per-run folders under `work_root`; the parameter
// names are the caller's. Throws CampaignError naming backend.command when the template is bad.
std::unique_ptr<CommandBackend> make_command_backend(const CampaignConfig& config, const std::string& work_root,
                                                     std::vector<std::string> parameter_names, int parallel);

// The fitness workers' thread count: backend.fitness_threads, or every hardware thread when 0.
int fitness_thread_count(const CampaignConfig& config);

// Fitness jobs of one iteration on worker threads. Jobs are submitted as runs become available (from
// the archive at once, simulated ones as each finishes), so the objective-2 smoothing of finished
// runs overlaps the simulations still running. Each curve is smoothed by its own network, so a value
// does not depend on which jobs share a worker: the result is that of a sequential evaluation.
class FitnessWorkers {
 public:
  FitnessWorkers(int threads, const PreparedCases& prepared, const CampaignConfig& config);
  ~FitnessWorkers();
  FitnessWorkers(const FitnessWorkers&) = delete;
  FitnessWorkers& operator=(const FitnessWorkers&) = delete;
  // Queues the fitness of run `run_id` (its status and curves) against case `case_index`; returns
  // the job's index in finish()'s result.
  size_t submit(std::int64_t run_id, std::string status, smoothing::Curve curves, size_t case_index);
  // Waits for every submitted job; results in submission order.
  std::vector<FitnessRecord> finish();

 private:
  struct Job {
    std::int64_t run_id;
    std::string status;
    smoothing::Curve curves;
    size_t case_index;
  };
  void work();
  void stop();
  const PreparedCases& prepared_;
  const CampaignConfig& config_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<size_t> queue_;
  std::deque<Job> jobs_;
  std::vector<FitnessRecord> results_;
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

// The `count` best distinct parameter sets with a finite fitness, best first (ties: evaluation order).
std::vector<ParameterSet> top_distinct(const std::vector<ParameterSet>& all, size_t count);
// The identifiability band of the campaign's evaluations (campaign.hpp, Identifiability).
Identifiability identifiability(const std::vector<ParameterSet>& all, const CampaignConfig& config);

}  // namespace demcal::pipelines::detail
