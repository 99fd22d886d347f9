// Calibration campaigns: the configuration (campaign.json or flags), the measured curves with their
// column mapping and units, and run_campaign(), which drives optimiser, backend, archive and report.
//
// Campaign file (JSON; relative paths are relative to the file's folder). docs/pipelines.md has the
// full reference; the essentials:
//   {
//     "name": "arch-demo",
//     "scene": {"file": "arch.json"}                      a scene file, or
//              {"generator": "arch", "options": {...}}    make_arch / make_wall with ArchOptions /
//                                                         WallOptions fields by name
//     "measured": {"file": "measured.csv",
//                  "columns": {"force": {"column": "horizontal_force", "unit": "kN"},
//                              "top_horizontal": {"column": "top_displacement", "unit": "mm",
//                                                 "scale": 1}}},
//     "cases": [ {"name": ..., "scene": ..., "measured": ..., "weight": 1}, ... ]
//                                                         several experiments calibrated together
//                                                         (instead of scene + measured)
//     "parameters": [{"name": "kn", "lower": 1e8, "upper": 1e10, "scale": "log10"}, ...],
//     "fixed": {"name": value}, "tied": {"name": "ks", "source": "kn", "ratio": 2.5},
//     "objective": {"type": 2, "weights": {"load_vertical": 1}, "points": 200, "smoother": {...}},
//     "optimiser": {"algorithm": "tbpso", "population": 10, "iterations": 20,
//                   "max_evaluations": 0, "seed": 1, ... any OptimiserOptions field},
//     "backend": {"type": "threads", "threads": 0} | {"type": "command", "command": "...",
//                 "timeout_s": 60, "parallel": 0} | {"type": "mpi"},
//     "output": "out/arch-demo", "report": true
//   }
// Parameter names are those of dem::set_parameter: kn, ks (Pa/m), friction_deg (degrees) for every
// joint group, "<group>.kn" etc. for one group, and the engine effects' parameters
// (compressive_strength, abutment_right.support_kx, ...; docs/scene-format.md, "Effects"). Mapped measured columns are converted to SI
// (m, N): units mm, cm, m, um, N, kN, MN; a column's unit comes from the mapping, else from the
// file's units row, else SI is assumed.
#pragma once

#include "demcal/common/field_table.hpp"
#include "demcal/dem/scene.hpp"
#include "demcal/optimise/optimiser.hpp"
#include "demcal/optimise/parameter_space.hpp"
#include "demcal/smoothing/curve.hpp"
#include "demcal/smoothing/objective.hpp"
#include "demcal/smoothing/smoother.hpp"
#include "demcal/surrogate/profile.hpp"
#include "demcal/surrogate/surrogate.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace demcal::pipelines {

struct CurveGrid;

// A number for JSON files: the value, or null when it is NaN or infinite (JSON has no such numbers).
inline nlohmann::json finite_or_null(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

// Bad campaign input; the message names the file and key (e.g. "c.json: parameters[1].lower: ...").
class CampaignError : public std::runtime_error {
 public:
  explicit CampaignError(const std::string& message) : std::runtime_error(message) {}
};

// One measured column: which file column feeds the engine-named column `target`.
struct ColumnMapping {
  std::string target;         // "force" or a gauge name of the scene
  std::string column;         // column name in the file
  std::string unit;           // "" = the file's unit for that column (or SI if the file has none)
  double scale = 1;           // extra factor (e.g. -1 to flip a sign), applied after the unit
};

struct MeasuredSpec {
  std::string file;                    // absolute or relative to the campaign file
  std::vector<ColumnMapping> columns;  // empty = take the file's columns by name, converting units
};

struct SceneSpec {
  std::string file;                    // a scene JSON file, or
  std::string generator;               // "arch" | "wall"
  nlohmann::json options = nlohmann::json::object();  // generator fields by name
  // Solver settings laid over the scene's own (file or generator), by the scene file's names:
  // e.g. {"time_step_faces": "in_contact"}. Empty = the scene's settings as they are.
  nlohmann::json solver = nlohmann::json::object();
};

struct CaseSpec {
  std::string name = "main";
  SceneSpec scene;
  MeasuredSpec measured;
  double weight = 1;                   // this case's share of the fitness, >= 0
};

struct BackendSpec {
  std::string type = "threads";        // "threads" | "command" | "mpi"
  int threads = 0;                     // threads backend: <= 0 = every hardware thread
  std::string command;                 // command backend: argument template (backend.hpp)
  double timeout_s = 0;                // command backend: s per run, 0 = none
  int parallel = 0;                    // command backend: programs at once, <= 0 = hardware threads
  double max_output_mb = 64;           // command backend: largest file a run may write (output CSV,
                                       // stdout, stderr), MiB, (0, 1048576]; a run that goes
                                       // past it fails
  int fitness_threads = 0;             // threads computing objectives (objective 2 trains networks)
                                       // while simulations run; <= 0 = every hardware thread.
                                       // Does not change any result.
};

// Optional local polish after the swarm (campaign key "polish"): a local NLopt run (default
// LN_BOBYQA) started from the swarm's best point, one simulation per step, in the same parameter
// space. Meant for narrow basins the swarm finds but does not descend (the arch's friction angle:
// the failure mode switches between sliding and hinging within a few degrees). Its evaluations are
// archived and counted like the swarm's; --resume continues it exactly.
//   "polish": {"algorithm": "LN_BOBYQA", "max_evaluations": 30, "initial_step": 0.05, "xtol_rel": 0}
struct PolishSpec {
  bool enabled = false;
  optimise::PolishOptions options;     // initial_step in unit-cube lengths of the parameter space
};

// Surrogate pre-screening (campaign key "surrogate", flag --surrogate on|off|MODEL; docs/surrogate.md).
// With it, PSO/TBPSO/GA iterations rank a pool of pool_factor x population candidates with a model
// trained on every finished run of the same scene and objective in the archive (earlier campaigns'
// included) and simulate only the best k (0 = population); the optimiser is told simulated values
// only. Algorithm "bo" (Bayesian optimisation) uses the same options. The budget that counts is
// optimiser.max_evaluations (--max-simulations): simulations, not proposals.
//   "surrogate": {"pool_factor": 5, "k": 5, "acquisition": "ei", "min_runs": 10, "model": "m.json",
//                 "gp": {"restarts": 6, "log_transform": "auto", ...}}
struct SurrogateSpec {
  bool enabled = false;
  surrogate::SurrogateOptions options;
  std::string model_file;              // a trained model (demcal surrogate train): its hyperparameters
                                       // are kept and only conditioned on the archive's rows
};

struct CampaignConfig {
  std::string name = "campaign";
  std::string source = "campaign";     // where it came from, for messages
  std::vector<CaseSpec> cases;
  optimise::ParameterSpace space;
  int objective = 2;                   // 1 or 2 (paper eqs. 16-20; 2 = after neural smoothing)
  smoothing::ObjectiveOptions objective_options;
  smoothing::SmootherOptions smoother;
  optimise::OptimiserOptions optimiser;
  BackendSpec backend;
  std::string output = "calibration";  // output folder: result.json, report.md, archive.sqlite
  std::string archive;                 // "" = <output>/archive.sqlite
  bool report = true;                  // write report.md and figures
  PolishSpec polish;                   // off unless the campaign has a "polish" object
  SurrogateSpec surrogate;             // off unless the campaign has a "surrogate" object
  // Identifiability band (campaign key "identifiability": {"relative_band": r}): parameter sets
  // whose fitness is within best x (1 + r) are reported as indistinguishable from the best.
  // 0 = 1/sqrt(2 x objective points) (0.05 for 200 points): the relative spread of a fitness value
  // (a root sum of squares over `points` residuals) under a fresh draw of measurement noise.
  double identifiability_band = 0;
  // How the ranges are obtained (campaign key "identifiability": {"profile": {...}}, every field of
  // surrogate::ProfileOptions; {"enabled": false} = the evaluated sets only): profiles of the fitness
  // on a Gaussian-process emulator trained on the campaign's own evaluations.
  surrogate::ProfileOptions identifiability_profile;

  // Throws CampaignError naming the key and value: no case, a case without measured file or
  // scene (scene not needed for the command backend), negative weights, bad objective type,
  // inverted bounds (through ParameterSpace::Validate), invalid optimiser options, unknown backend.
  void Validate() const;
  // Everything that determines the result (not output folder, archive, backend or report), as
  // canonical JSON: its hash is the campaign's key for --resume.
  nlohmann::json result_defining_json() const;
  nlohmann::json to_json() const;
};

// Parses a campaign JSON object; base_dir resolves relative paths; source names it in errors.
CampaignConfig campaign_from_json(const nlohmann::json& json, const std::string& base_dir,
                                  const std::string& source);
CampaignConfig load_campaign(const std::string& path);
// The campaign file's "optimiser" keys (demcal/common/field_table.hpp): how each OptimiserOptions
// field a campaign sets is checked, read and written. Those with a help text are also the flags of
// `demcal optimise` (--algorithm, --seed, --trust-direction, ...).
const FieldTable<optimise::OptimiserOptions>& optimiser_fields();

// The "kind" of a surrogate model file (demcal surrogate train); "" when the file cannot be read as
// one (the campaign reports that when it loads the model). A campaign given a model takes its kind.
std::string surrogate_model_kind(const std::string& path);

// The "mlp" surrogate's curve grid of each case (surrogate_data.hpp), beside the case's objective
// key (which measurement, objective and smoother its archived fitness rows belong to). Loads and,
// for objective 2, smooths the measurements. Throws CampaignError naming the file at fault.
struct CaseCurveGrid {
  std::string objective_key;
  std::shared_ptr<const CurveGrid> grid;
};
std::vector<CaseCurveGrid> campaign_curve_grids(const CampaignConfig& config);

// "kn=1e8:1e10:log" | "friction_deg=25:45" | "ks=fixed:1e9" | "ks=tied:kn:2.5" -> added to space.
// Throws CampaignError naming the flag text.
void add_parameter_flag(optimise::ParameterSpace& space, const std::string& flag);
// "force=horizontal_force:kN" | "top_horizontal=top_displacement:mm[:scale]".
ColumnMapping parse_mapping_flag(const std::string& flag);

// The measured curve of a case, columns `force` (N) and the mapped gauges (m), rows with a NaN in
// any mapped column kept (the objectives drop them). Throws CampaignError naming file, column, unit.
smoothing::Curve load_measured(const MeasuredSpec& spec);
// Factor to SI of a unit ("mm" -> 1e-3, "kN" -> 1e3, "" -> 1); throws CampaignError for unknown ones.
double unit_factor(const std::string& unit, const std::string& where);

// The case's scene (file or generator), validated. Throws dem::SceneError / CampaignError.
dem::Scene build_scene(const SceneSpec& spec, const std::string& where);

// ---- running -----------------------------------------------------------------------------------

struct RunOptions {
  bool resume = false;       // continue the newest campaign with the same key in the archive
  bool note_fresh_resume = true;  // with resume: say on stderr when nothing matches (a new campaign)
  bool progress = true;      // progress lines on stderr
  int mpi_rank = 0;          // set by the CLI under mpirun
  int mpi_size = 1;
};

struct ParameterSet {
  std::map<std::string, double> params;
  double fitness = std::numeric_limits<double>::quiet_NaN();
  int iteration = 0;
  int position = 0;
};

enum class CampaignStatus { completed, failed };

// Identifiability (result.json key "identifiability"; docs/pipelines.md): for every free parameter,
// the range of values that fit within the noise band, fitness <= best x (1 + relative_band).
//   - evaluated range: over the distinct evaluated sets within the band. A converged swarm samples
//     a small cluster, so this is a lower bound of the indistinguishable region.
//   - profile range (method "profile"): where the parameter's profile on an emulator of the fitness
//     (a Gaussian process on log fitness, trained on every finite evaluation; the other parameters
//     re-optimised on the emulator at each of a grid of values) is within the band
//     (surrogate/profile.hpp: the band's reference is the larger of the best fitness and the
//     emulator's minimum).
//   - reported range (min, max): the hull of both, so never narrower than the evaluated range.
// Method "evaluated" when there is no emulator: fewer than profile.min_rows distinct finite sets,
// the profile switched off, or the emulator could not be fitted (method_note says which).
struct ParameterRange {
  double best = 0, min = 0, max = 0;   // SI (friction in degrees); min, max: the reported range
  double evaluated_min = 0, evaluated_max = 0;   // over the evaluated sets within the band
  double profile_min = std::numeric_limits<double>::quiet_NaN();  // NaN: no profile, or no grid
  double profile_max = std::numeric_limits<double>::quiet_NaN();  // value within the band
  // The profile: values of the parameter (a grid uniform in the optimiser's unit coordinate, so in
  // log10 for a log-scaled parameter), the emulator's smallest predicted fitness at each, its latent
  // standard deviation there (log fitness units for a log emulator), and where the other free
  // parameters were at that minimum (by name). Empty without a profile.
  std::vector<double> profile_values, profile_fitness, profile_sd;
  std::map<std::string, std::vector<double>> profile_others;
};
struct Identifiability {
  double relative_band = 0;
  double band_fitness = std::numeric_limits<double>::quiet_NaN();  // best x (1 + relative_band)
  long sets_in_band = 0;               // distinct parameter sets within the band
  std::string method = "evaluated";    // "profile" | "evaluated"
  std::string method_note;             // why "evaluated" (empty for "profile")
  // The emulator (method "profile"): kind "gp", what surrogate::profile_fitness reports (training
  // rows, log transform, leave-one-out error, threshold, ...). Its wall times go to result.json's
  // "timing" (identifiability_fit_s, identifiability_profile_s), with the other run-dependent times.
  std::string emulator_kind;
  surrogate::ProfileResult profile;    // its per-coordinate vectors are in unit coordinates; the
                                       // physical ones are in `parameters`
  surrogate::ProfileOptions options;
  std::vector<std::string> coordinate_names;  // the free parameters in the optimiser's order
  std::map<std::string, ParameterRange> parameters;  // every free parameter
  nlohmann::json to_json() const;      // ranges, plus max/min ratio for positive values
};

// The identifiability block of a set of evaluations: a pure function of the sets (non-finite
// fitness = a failed run, ignored), the space (its free parameters; every set must carry them),
// the band and the profile's options (deterministic but for the wall times it reports).
Identifiability compute_identifiability(const std::vector<ParameterSet>& all, const optimise::ParameterSpace& space,
                                        double relative_band, const surrogate::ProfileOptions& options);

struct CampaignResult {
  CampaignStatus status = CampaignStatus::completed;
  std::string message;
  ParameterSet best;
  std::vector<ParameterSet> top;             // five best distinct parameter sets, best first
  long simulations = 0;                      // candidates x cases evaluated in the campaign
  long candidates = 0;                       // parameter sets evaluated
  long failed_runs = 0;
  int iterations = 0;
  std::vector<double> best_history;          // best fitness after each candidate (convergence)
  std::vector<ParameterSet> all;             // every evaluation, in order
  double wall_time_s = 0;                    // this session
  double model_time_s = 0;                   // this session: choosing candidates (surrogate fits and search)
  double simulation_time_s = 0;              // this session: waiting for simulations and their fitness
  double run_time_s = 0;                     // this session: the simulated runs' own times, summed
  long simulated_this_session = 0;           // runs actually simulated (not read from the archive)
  long reused_from_archive = 0;
  std::string optimiser_status;
  bool polished = false;                     // the campaign has a polish phase
  long polish_evaluations = 0;               // candidates evaluated by the polish
  double swarm_best_fitness = std::numeric_limits<double>::quiet_NaN();  // before the polish
  std::string polish_status;
  Identifiability identifiability;
  // Surrogate (with pre-screening or "bo"): model kind, pool points ranked, candidates simulated
  // under the screen, candidates screened out (proposed by the optimiser, never simulated), the
  // final model's leave-one-out relative error, and one record per screened iteration (pool,
  // the model's error on the simulated candidates, each candidate's prediction and fate).
  bool surrogate_used = false;
  std::string surrogate_kind;
  long surrogate_screened = 0;
  long surrogate_simulated = 0;
  long surrogate_screened_out = 0;
  double surrogate_cv_error = std::numeric_limits<double>::quiet_NaN();
  // "bo": points per round and why (the cost-aware decision), points proposed by the model, and
  // the prequential check: the relative error (mean |ŷ − y| / mean |y − ȳ|) and 90 % interval
  // coverage of the model's predictions of those that ran (finite fitness), each made before the
  // point was simulated.
  int surrogate_batch = 0;
  std::string surrogate_batch_reason;
  long surrogate_predicted = 0;
  double surrogate_prequential_error = std::numeric_limits<double>::quiet_NaN();
  double surrogate_prequential_coverage90 = std::numeric_limits<double>::quiet_NaN();
  nlohmann::json surrogate_iterations = nlohmann::json::array();
  nlohmann::json to_json() const;            // the result.json layout
};

// Runs (or resumes) the campaign: writes <output>/result.json, the archive and (if config.report)
// report.md with figures. Throws CampaignError for bad input found before the first simulation.
CampaignResult run_campaign(const CampaignConfig& config, const RunOptions& options = {});

// Rank > 0 of an MPI job: serve simulations for the campaign's cases until rank 0 says stop.
void run_mpi_worker(const CampaignConfig& config);

}  // namespace demcal::pipelines
