// The ask/tell optimiser interface shared by PSO, TBPSO, GA and the NLopt algorithms.
//
// Loop (what pipelines/ runs; minimise() below does the same for a cheap function):
//
//   auto opt = make_optimiser(space, options);          // validates both, seeds the RNG
//   while (!opt->done()) {
//     std::vector<Eigen::VectorXd> batch = opt->ask();  // physical coordinates, one per candidate
//     std::vector<double> f = evaluate_all(batch);      // any order, any parallelism
//     opt->tell(f);                                     // f[i] belongs to batch[i]
//     checkpoint(opt->save_state());                    // optional, JSON
//   }
//   opt->best_x(), opt->best_value()
//
// Contracts
// - Minimisation. tell() takes exactly one value per candidate of the last ask(); NaN and +/-inf
//   (a failed simulation) count as the worst possible value (+inf) and never become the best.
// - ask() is idempotent while a batch is pending: asking again before tell() returns the same
//   batch (so a crashed evaluation round can simply be asked for again after load_state()).
//   tell() without a pending batch, or with the wrong count, throws std::logic_error /
//   std::invalid_argument.
// - Every candidate lies inside the parameter space's bounds. Internally all optimisers work in
//   the unit cube [0,1]^d of the ParameterSpace (log10 scale where declared).
// - Batch size: PSO/TBPSO/GA return the whole swarm/population (options.population), except that
//   the last batch is cut to the evaluation budget. NLopt algorithms return batches of exactly one
//   point: NLopt runs on its own worker thread and each objective call it makes is handed over
//   through ask()/tell() (the thread blocks until the value is told).
// - Determinism: the same space, options (seed included) and told values give the same candidates,
//   bit for bit, on the same platform. Random numbers come from std::mt19937_64 mapped to [0,1)
//   by the top 53 bits (no std::*_distribution), so sequences are portable across standard libraries.
// - Exact resume: save_state() may be called at any time (between tell() and ask(), or with a batch
//   pending); load_state() on a fresh optimiser made from the same space and options continues
//   exactly as the uninterrupted run would. NLopt's internal state cannot be serialised, so the NLopt
//   wrapper stores the history of told (x, f) and on load_state() re-runs NLopt from the start with
//   the same seed (nlopt_srand), answering the recorded points with the recorded values (and checking
//   that NLopt asks for them again bit for bit) until the history is used up.
//
// Outside pre-screening (a surrogate filtering candidates before the expensive evaluations)
// - An outside filter sits between ask() and tell(). It may (a) tell a predicted value for a
//   candidate it chooses not to simulate (the optimiser does not distinguish predicted from
//   simulated values), or (b) replace a candidate by another point with substitute(i, x), then
//   evaluate that point: the optimiser then treats x as if it had proposed it (PSO/TBPSO: the
//   particle's position becomes x, its velocity the move from its previous position to x; GA:
//   the offspring's genes become x).
//   After substitute(), ask() returns the modified batch. NLopt algorithms cannot accept a
//   substitute (can_substitute() is false; substitute() throws std::logic_error) because NLopt
//   chose the point itself and expects its value.
// - alternatives(i, n) (where can_substitute()) returns n further proposals for candidate i, made
//   the way the optimiser made the candidate (PSO/TBPSO: the particle's last move redrawn with
//   fresh random coefficients; GA: further offspring of the same parents). They come from a
//   generator seeded by (seed, iteration, i), never from the optimiser's own stream, so asking for
//   them changes nothing the optimiser does afterwards. Substituting a PSO/TBPSO alternative also
//   sets the particle's velocity to the move that reaches it (from where it was before the move).
// - withdraw(i) marks candidate i of the pending batch as not evaluated: tell() ignores its value
//   (pass NaN), it counts no evaluation and changes no memory (PSO/TBPSO: the particle goes back to
//   where it was before the move, velocity included; GA: the offspring is discarded and weighs 0
//   in the next selection). A screen that simulates k of n candidates withdraws the other n - k:
//   the optimiser only ever learns simulated values. options.evaluations_per_iteration = k keeps
//   the planned iteration count (and so the inertia / mutation schedules) consistent with the
//   budget.
#pragma once

#include "demcal/optimise/parameter_space.hpp"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace demcal::optimise {

// How a move that leaves the unit cube is brought back (PSO and TBPSO; GA offspring and NLopt
// points never leave the cube).
enum class BoundHandling {
  clamp,    // coordinate set to the violated bound and that velocity component set to 0
  reflect,  // coordinate mirrored back into the cube and that velocity component negated
};
std::string to_string(BoundHandling handling);
BoundHandling parse_bound_handling(const std::string& text);  // "clamp" | "reflect"

// Reading of TBPSO's Δx_ij in T_i = Σ_j d_rel,ij C_ij Δx_ij (mission.md).
enum class TrustDirection {
  toward,  // Δx_ij = x_j − x_i: a particle moves toward the particles it trusts
  paper,   // Δx_ij = x_i − x_j: eq. 13 as printed in the paper
};
std::string to_string(TrustDirection direction);
TrustDirection parse_trust_direction(const std::string& text);  // "toward" | "paper"

// GA mutation operator.
enum class GaMutation {
  reset,     // paper: the gene is replaced by a uniform random value in its range
  gaussian,  // not in the paper: gene += N(0, sigma) in the unit cube, clamped; sigma shrinks
             // geometrically from ga_sigma_start to ga_sigma_end over the planned generations
};
std::string to_string(GaMutation mutation);
GaMutation parse_ga_mutation(const std::string& text);  // "reset" | "gaussian"

// Options of every optimiser. Defaults are the paper's settings (section 3 of the paper).
struct OptimiserOptions {
  // "pso" | "tbpso" | "ga" | "nlopt:<NAME>" with NAME one of nlopt_algorithms() below
  // (e.g. "nlopt:LN_BOBYQA"; the "NLOPT_" prefix and lower case are accepted too).
  std::string algorithm = "tbpso";
  int population = 10;         // swarm/population size = candidates per batch (PSO/TBPSO/GA), >= 2
  int iterations = 20;         // planned iterations (generations); > 0
  long max_evaluations = 0;    // evaluation budget; 0 = population * iterations. When > 0 it wins:
                               // PSO/TBPSO/GA plan ceil(max_evaluations / population) iterations
                               // (that count drives the inertia schedule) and cut the last batch.
  std::uint64_t seed = 1;      // the only source of randomness
  int evaluations_per_iteration = 0;  // PSO/TBPSO/GA: candidates evaluated per iteration when an
                               // outside screen withdraws the rest (0 = population); sets the
                               // planned iterations ceil(budget / this)
  double target_value = -std::numeric_limits<double>::infinity();  // done() once best <= this

  // PSO / TBPSO (eqs. 1-15). Velocities are in unit-cube lengths per iteration.
  double inertia_start = 0.8;  // ω at the first velocity update (eq. 6)
  double inertia_end = 0.4;    // ω at the last planned update
  double pso_cognitive = 2.0;  // PSO φ1
  double pso_social = 2.0;     // PSO φ2
  double tbpso_cognitive = 1.0;  // TBPSO φ1
  double tbpso_social = 1.0;     // TBPSO φ2
  double tbpso_trust = 2.0;      // TBPSO φ3
  bool constriction = false;   // multiply by K = 2/|2 − φ − sqrt(φ² − 4φ)| (eq. 8), φ = sum of the
                               // weights (PSO: φ1+φ2; TBPSO: φ1+φ2+φ3), needs φ >= 4; K = 1 without
  double max_velocity = 0.5;   // |v| per coordinate clamped to this (unit-cube lengths); 0 = none
  double initial_velocity = 0.0;  // v0 uniform in [-a, a] per coordinate (unit-cube lengths)
  BoundHandling bounds = BoundHandling::clamp;
  // TBPSO reading of Δx: "paper" (x_i − x_j, eq. 13 as printed) or "toward" (x_j − x_i). Default
  // "paper": in the benchmark (docs/benchmarks.md) it has the lower median on 3 of 4
  // functions at 200 evaluations in 3-D (the campaigns' 20 x 10) and on 4 of 4 at 500; "toward"
  // wins at 200 evaluations in 10-D. Caveat: trust grows by one per iteration without bound
  // (eq. 12), so long runs are erratic with either reading (Sphere 3-D, 2000 evaluations, 25
  // seeds: < 1e-6 on 19 ("paper") / 16 ("toward"), worst 0.22 / 0.028); use the polish there.
  std::string trust_direction = "paper";

  // GA (section 3.1 of the paper).
  double crossover_probability = 0.5;  // per gene, uniform crossover
  double mutation_probability = 0.1;   // per gene
  GaMutation ga_mutation = GaMutation::reset;
  double ga_sigma_start = 0.1;         // gaussian mutation only, unit-cube lengths
  double ga_sigma_end = 1e-4;
  int elitism = 0;                     // best individuals copied unchanged into the next
                                       // generation (paper: 0, the new population replaces the old)

  // NLopt.
  std::vector<double> initial_point;   // physical start for NLopt (empty = centre of the cube); for
                                       // `bo` (surrogate/) the first point of its initial design
  // `bo` only: further given points of its initial design, after initial_point (physical, each of
  // the space's dimension): starts in other basins than initial_point's. Ignored by the others.
  std::vector<std::vector<double>> further_starts;
  double initial_step = 0.0;           // NLopt initial step in unit-cube lengths (0 = NLopt default)
  int nlopt_population = 0;            // NLopt's own population (CRS2, ISRES, ESCH); 0 = its default
  double xtol_rel = 0.0;               // NLopt stopping tolerances (0 = off); the budget always holds
  double ftol_abs = 0.0;

  // Polish (not in the paper; off by default): the last polish_evaluations of the budget go to a
  // local NLopt run started from the best point of the main (global) phase. The main phase gets
  // evaluation_budget() - polish_evaluations (which also sets its planned iterations); if it stops
  // early (NLopt's own criteria), the polish gets everything that is left. The total never exceeds
  // evaluation_budget(). The polish is skipped when the main phase reached target_value or failed;
  // if the main phase found no finite value, the polish starts at the centre of the box. Works for
  // every algorithm; it is what lets the paper's GA, GN_ISRES, GN_ESCH and TBPSO refine an optimum
  // to 1e-6 (docs/optimise.md). The ask/tell contract is unchanged: batches of the main algorithm,
  // then batches of one point; can_substitute() is false during the polish.
  long polish_evaluations = 0;             // 0 = off; else >= 1 and < evaluation_budget()
  std::string polish_algorithm = "LN_BOBYQA";  // an NLopt name from nlopt_algorithms(), normally LN_*
  double polish_initial_step = 0.05;       // NLopt initial step of the polish, unit-cube lengths, > 0

  // Throws std::invalid_argument naming the option and its value.
  void Validate() const;
  // Evaluation budget actually used (max_evaluations, or population * iterations).
  long evaluation_budget() const;
};

enum class OptimiserStatus {
  running,           // more batches to come
  budget_exhausted,  // evaluation budget or planned iterations used up
  target_reached,    // best_value() <= options.target_value
  converged,         // NLopt stopped on its own criteria (tolerances, DIRECT's exhaustion, ...)
  failed,            // NLopt reported an error (message() says which)
};
std::string to_string(OptimiserStatus status);

class Optimiser {
 public:
  virtual ~Optimiser();
  Optimiser(const Optimiser&) = delete;
  Optimiser& operator=(const Optimiser&) = delete;

  // The next batch of candidates, physical coordinates (see the contracts above). Empty when done().
  virtual std::vector<Eigen::VectorXd> ask() = 0;
  // One fitness per candidate of the last ask(); NaN/inf = worst.
  virtual void tell(const std::vector<double>& fitness) = 0;
  // Complete state as JSON (non-finite doubles are stored as the strings "inf", "-inf", "nan").
  virtual nlohmann::json save_state() const = 0;
  // Restores a state saved by an optimiser of the same algorithm and dimension; throws
  // std::invalid_argument on a mismatch or malformed state.
  virtual void load_state(const nlohmann::json& state) = 0;
  // True once the budget or planned iterations are used up, the target is reached, or NLopt stopped.
  virtual bool done() const;

  // Outside pre-screening (see the header comment).
  virtual bool can_substitute() const { return false; }
  virtual void substitute(std::size_t index, const Eigen::VectorXd& physical);
  // Further proposals (physical) for candidate `index` of the pending batch; throws
  // std::logic_error where can_substitute() is false or no batch is pending.
  virtual std::vector<Eigen::VectorXd> alternatives(std::size_t index, int count) const;
  // Candidate `index` of the pending batch will not be evaluated (see the header comment).
  virtual void withdraw(std::size_t index);

  // Best point told so far (physical) and its value; empty vector and +inf before any finite value.
  Eigen::VectorXd best_x() const;
  double best_value() const { return best_value_; }
  // Completed ask/tell rounds (PSO/TBPSO/GA: iterations/generations; NLopt: points told).
  int iteration() const { return iteration_; }
  long evaluations() const { return evaluations_; }
  // "pso", "tbpso", "ga", "nlopt:LN_BOBYQA", ...
  std::string name() const { return name_; }
  OptimiserStatus status() const { return status_; }
  const std::string& message() const { return message_; }
  const ParameterSpace& space() const { return space_; }
  const OptimiserOptions& options() const { return options_; }

  // With options.polish_evaluations > 0: how the two phases went (nullopt without a polish).
  struct PolishReport {
    bool polishing = false;            // true once the polish phase has started
    double main_best_value = std::numeric_limits<double>::infinity();  // best of the main phase
    Eigen::VectorXd main_best_x;       // physical; empty if the main phase found no finite value
    long main_evaluations = 0;         // evaluations spent by the main phase
    long polish_evaluations = 0;       // evaluations spent by the polish so far
    std::string polish_status;         // to_string(status) of the polish run ("" before it starts)
  };
  virtual std::optional<PolishReport> polish_report() const { return std::nullopt; }

 protected:
  Optimiser(ParameterSpace space, OptimiserOptions options, std::string name);
  // Records one told value for a unit-cube point (updates best, evaluations; non-finite -> +inf).
  // Returns the sanitised value.
  double record(const Eigen::VectorXd& unit_point, double value);
  // Updates status_ after a tell() (budget, iterations, target).
  void update_status_after_tell();
  nlohmann::json save_common() const;
  void load_common(const nlohmann::json& state);
  Eigen::VectorXd physical(const Eigen::VectorXd& unit) const;
  // Best unit-cube point of another optimiser (for optimisers that drive others).
  static const Eigen::VectorXd& best_unit_of(const Optimiser& other) { return other.best_unit_; }

  ParameterSpace space_;
  OptimiserOptions options_;
  std::string name_;
  Eigen::VectorXd best_unit_;  // empty until a finite value is told
  double best_value_ = std::numeric_limits<double>::infinity();
  int iteration_ = 0;
  long evaluations_ = 0;
  OptimiserStatus status_ = OptimiserStatus::running;
  std::string message_;
};

// Makes the optimiser named by options.algorithm. Validates space and options (std::invalid_argument).
std::unique_ptr<Optimiser> make_optimiser(const ParameterSpace& space, const OptimiserOptions& options);

// NLopt algorithm names accepted after "nlopt:" (without the "NLOPT_" prefix).
const std::vector<std::string>& nlopt_algorithms();

// ---- Conveniences built on ask/tell -------------------------------------------------------

using Objective = std::function<double(const Eigen::VectorXd& physical)>;

struct MinimiseSummary {
  OptimiserStatus status = OptimiserStatus::running;
  std::string message;
  Eigen::VectorXd best_x;  // physical
  double best_value = std::numeric_limits<double>::infinity();
  long evaluations = 0;
  int iterations = 0;
  std::vector<double> best_value_history;  // best value after each tell()
};

// Runs the ask/tell loop to done() with a cheap objective, evaluated in batch order on this thread.
MinimiseSummary minimise(Optimiser& optimiser, const Objective& objective);

// Polish: a local NLopt run started from a point (typically a swarm's best), driven by the same
// ask/tell loop. The space is the same; only the algorithm, start, step and budget differ.
struct PolishOptions {
  std::string algorithm = "LN_BOBYQA";  // any NLopt name from nlopt_algorithms(), normally LN_*
  long max_evaluations = 50;            // > 0
  double initial_step = 0.05;           // unit-cube lengths, > 0
  double xtol_rel = 0.0;                // 0 = off
  std::uint64_t seed = 1;
  void Validate() const;
};
std::unique_ptr<Optimiser> make_polisher(const ParameterSpace& space, const Eigen::VectorXd& start_physical,
                                         const PolishOptions& options);

}  // namespace demcal::optimise
