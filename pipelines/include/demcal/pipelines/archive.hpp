// The run archive: one SQLite file (WAL journal) holding every simulation a campaign asked for, the
// fitness of each run against each measurement, and the optimiser's state after every iteration.
//
// Nothing is lost on a crash: each write is its own short transaction (BEGIN IMMEDIATE ... COMMIT),
// committed before the call returns, so a process killed with SIGKILL keeps every run, fitness and
// iteration it had committed, and loses at most the one write in flight, whole.
//
// Several processes may write one archive at once (two campaigns, a study beside a campaign): the
// WAL journal lets readers go on while one writes; a writer that finds the archive locked waits
// (SQLite's busy handler, 10 s per attempt) and retries, for at most 120 s in all, before it gives
// up with an ArchiveError saying so. A file that is not an SQLite database, or an SQLite database
// of something else (tables but no demcal schema version), is refused, never modified. Runs are
// keyed by (model hash, parameter key): a run whose model and parameters are already archived is
// read back instead of simulated again, whichever campaign made it.
//
// Schema (docs/pipelines.md has the full description):
//   meta(key, value)                                   schema version
//   runs(id, model_hash, param_key, params_json, code_version, backend, status, message,
//        wall_time_s, curve_columns, curve_units, curve_data, details_json, created_at)
//   fitness(run_id, objective_key, objective, objective1, objective2, fitness, channels_json,
//           wall_time_s)                               one row per run and measurement/objective
//   campaigns(id, name, config_key, config_json, code_version, created_at)
//   iterations(campaign_id, iteration, optimiser_state, best_fitness, evaluations, wall_time_s,
//              created_at)                             optimiser state after the iteration's tell()
//   evaluations(campaign_id, iteration, position, params_json, run_ids_json, fitness)
// Doubles are stored as 8-byte IEEE values (curves as one column-major BLOB), so everything reads
// back bit-identical. A NaN fitness (a failed run) is stored as NULL and read back as NaN.
#pragma once

#include "demcal/smoothing/curve.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <limits>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

struct sqlite3;

namespace demcal::pipelines {

// An archive that cannot be opened, read or written; the message names the file and the statement.
class ArchiveError : public std::runtime_error {
 public:
  explicit ArchiveError(const std::string& message) : std::runtime_error(message) {}
};

// Exact key of a parameter set: "name=<hex float>;..." sorted by name (e.g. "kn=0x1.dcd65p+31").
// Two sets share a key exactly when every value is bit-identical.
std::string parameter_key(const std::map<std::string, double>& params);
// The parameter set back from its key, bit-identical (parameters cross processes and ranks as keys).
std::map<std::string, double> params_from_key(const std::string& key);

// FNV-1a 64-bit hash of a text, as 16 hex digits (model and objective keys).
std::string hash_text(const std::string& text);

// One simulation (whichever backend ran it).
struct RunRecord {
  std::int64_t id = 0;                   // archive row id (set by insert_run / read back)
  std::string model_hash;                // scene hash, or hash of the external command and case
  std::map<std::string, double> params;  // SI units, friction in degrees (friction_deg)
  std::string code_version;              // demcal version that ran it
  std::string backend;                   // "threads", "command", "mpi"
  std::string status;                    // engine status (completed, collapsed, unstable, step_limit,
                                         // cancelled) or "failed" (command crashed, timed out, ...)
  std::string message;
  double wall_time_s = 0;                // simulation wall time
  smoothing::Curve curves;               // time (s), force (N), one column per gauge (m)
  nlohmann::json details = nlohmann::json::object();  // engine summary: peak force, steps,
                                         // hinges, sliding joints, final blocks (for pictures)
  std::string created_at;                // UTC, ISO 8601
};

// Fitness of one run against one measurement and objective (objective_key says which).
struct FitnessRecord {
  std::int64_t run_id = 0;
  std::string objective_key;
  int objective = 1;                           // the campaign's objective (1 or 2)
  double objective1 = std::numeric_limits<double>::quiet_NaN();
  double objective2 = std::numeric_limits<double>::quiet_NaN();  // NaN when objective == 1
  double fitness = std::numeric_limits<double>::quiet_NaN();     // the value given to the optimiser
  nlohmann::json channels = nlohmann::json::object();           // per-channel values of `objective`
  double wall_time_s = 0;                                        // time spent computing it
};

struct CampaignRecord {
  std::int64_t id = 0;
  std::string name;
  std::string config_key;   // hash of everything that determines the campaign's result
  nlohmann::json config;
  std::string code_version;
  std::string created_at;
};

struct IterationRecord {
  std::int64_t campaign_id = 0;
  int iteration = 0;                    // 0-based
  std::string optimiser_state;          // the optimiser's save_state() after tell()
  double best_fitness = std::numeric_limits<double>::quiet_NaN();
  int evaluations = 0;                  // candidates evaluated so far in the campaign
  double wall_time_s = 0;               // campaign wall time when the iteration ended
  std::string created_at;
};

// One candidate of one iteration: its parameters, the runs (one per case) and its fitness.
struct EvaluationRecord {
  std::int64_t campaign_id = 0;
  int iteration = 0;
  int position = 0;                          // index in the iteration's ask() order
  std::map<std::string, double> params;
  std::vector<std::int64_t> run_ids;
  double fitness = std::numeric_limits<double>::quiet_NaN();
};

// A finished run with its fitness against one objective key, without the curves (surrogate
// training data: pipelines/surrogate_data.hpp).
struct RunFitness {
  std::int64_t run_id = 0;
  std::map<std::string, double> params;       // bit-identical (from the parameter key)
  std::string status;                          // engine status or "failed"
  double fitness = std::numeric_limits<double>::quiet_NaN();  // NaN: the run failed
};

class RunArchive {
 public:
  // Opens (creating if needed) the archive file and its tables; WAL journal. Throws ArchiveError
  // naming the file: cannot be opened or created, not an SQLite database, a foreign database, a
  // schema version this demcal does not read.
  explicit RunArchive(const std::string& path);
  ~RunArchive();
  RunArchive(const RunArchive&) = delete;
  RunArchive& operator=(const RunArchive&) = delete;

  const std::string& path() const { return path_; }

  // Runs. insert_run returns the new id; inserting an existing (model_hash, params) keeps the first
  // row and returns its id (the archive never holds a run twice).
  std::int64_t insert_run(const RunRecord& run);
  std::optional<RunRecord> find_run(const std::string& model_hash,
                                    const std::map<std::string, double>& params) const;
  std::optional<RunRecord> run(std::int64_t id) const;
  std::int64_t run_count() const;
  // SQLite's PRAGMA integrity_check: "ok", or the problems it lists (one per line).
  std::string integrity_check() const;
  // Every run with this status ("failed", "unstable", ...), in id order, without curves.
  std::vector<RunRecord> runs_with_status(const std::string& status) const;
  // Largest run id (0 for an empty archive): a campaign's horizon of earlier runs.
  std::int64_t max_run_id() const;
  // Every run of a model (scene hash) with a fitness row for objective_key and id <= max_run_id,
  // in id order. Runs without that fitness row (not yet scored) are left out.
  std::vector<RunFitness> run_fitness(const std::string& model_hash, const std::string& objective_key,
                                      std::int64_t max_run_id = INT64_MAX) const;
  // Every run of a model (scene hash) without a fitness row for objective_key, cancelled ones left
  // out, in id order, without the curves (run(id) reads them): runs scored for another objective,
  // which a campaign scores for its own before its surrogate trains.
  std::vector<RunFitness> unscored_runs(const std::string& model_hash, const std::string& objective_key) const;
  // (model hash, objective key, rows) for every pair with fitness rows, most rows first.
  struct ModelObjective {
    std::string model_hash, objective_key;
    std::int64_t rows = 0;
  };
  std::vector<ModelObjective> model_objectives() const;
  // Every campaign, oldest first.
  std::vector<CampaignRecord> campaigns() const;

  // Fitness rows (one per run and objective key); put replaces.
  void put_fitness(const FitnessRecord& fitness);
  std::optional<FitnessRecord> find_fitness(std::int64_t run_id, const std::string& objective_key) const;

  // Campaigns: a new row per start; latest_campaign finds the newest with this config key.
  std::int64_t create_campaign(const CampaignRecord& campaign);
  std::optional<CampaignRecord> latest_campaign(const std::string& config_key) const;

  // Writes one iteration's evaluations and the optimiser state in ONE transaction: after a crash
  // either the whole iteration is archived or none of it is.
  void commit_iteration(const IterationRecord& iteration, const std::vector<EvaluationRecord>& evaluations);
  std::optional<IterationRecord> last_iteration(std::int64_t campaign_id) const;
  std::vector<IterationRecord> iterations(std::int64_t campaign_id) const;
  // Every evaluation of the campaign, in (iteration, position) order.
  std::vector<EvaluationRecord> evaluations(std::int64_t campaign_id) const;

 private:
  // One short write transaction (BEGIN IMMEDIATE ... COMMIT); rolled back unless committed.
  class Transaction {
   public:
    explicit Transaction(RunArchive& archive);
    ~Transaction();
    Transaction(const Transaction&) = delete;
    Transaction& operator=(const Transaction&) = delete;
    void commit();

   private:
    RunArchive& archive_;
    bool committed_ = false;
    long number_ = 0;
  };
  void open_schema();
  void exec(const std::string& sql) const;
  std::string path_;
  sqlite3* db_ = nullptr;
};

// Column-major binary form of a curve's values (8-byte doubles), as stored in runs.curve_data and
// sent between MPI ranks; names and units travel separately.
std::string pack_curve_values(const smoothing::Curve& curve);
smoothing::Curve unpack_curve(const std::vector<std::string>& names, const std::vector<std::string>& units,
                              const std::string& packed, const std::string& source);

}  // namespace demcal::pipelines
