// PSO (paper eqs. 1-10) and the trust-based PSO (eqs. 11-15) in the unit cube.
#include "demcal/optimise/swarm.hpp"

#include "internal.hpp"

#include "demcal/common/random.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace demcal::optimise {

Eigen::MatrixXd tbpso_relative_distances(const Eigen::MatrixXd& positions) {
  const Eigen::Index n = positions.rows();
  Eigen::MatrixXd d = Eigen::MatrixXd::Zero(n, n);
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = 0; j < n; ++j)
      if (i != j) d(i, j) = (positions.row(i) - positions.row(j)).norm();
  for (Eigen::Index i = 0; i < n; ++i) {
    const double sum = d.row(i).sum();
    if (sum > 0.0) d.row(i) /= sum;
  }
  return d;
}

Eigen::MatrixXd tbpso_trust_update(const Eigen::MatrixXd& previous_trust, const Eigen::VectorXd& personal_best_values,
                                   const Eigen::VectorXd& current_values) {
  const Eigen::Index n = personal_best_values.size();
  if (previous_trust.rows() != n || previous_trust.cols() != n || current_values.size() != n)
    throw std::invalid_argument("tbpso_trust_update: sizes of trust matrix and value vectors differ");
  Eigen::MatrixXd trust = Eigen::MatrixXd::Zero(n, n);
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = 0; j < n; ++j) {
      if (i == j || personal_best_values[i] <= personal_best_values[j]) continue;  // C_ij = 0
      trust(i, j) = current_values[j] <= personal_best_values[j] ? previous_trust(i, j) + 1.0
                                                                 : previous_trust(i, j) - 1.0;
    }
  return trust;
}

Eigen::MatrixXd tbpso_trust_pull(const Eigen::MatrixXd& positions, const Eigen::MatrixXd& trust,
                                 TrustDirection direction) {
  const Eigen::Index n = positions.rows();
  if (trust.rows() != n || trust.cols() != n)
    throw std::invalid_argument("tbpso_trust_pull: trust matrix does not match the number of particles");
  const Eigen::MatrixXd relative = tbpso_relative_distances(positions);
  Eigen::MatrixXd pull = Eigen::MatrixXd::Zero(n, positions.cols());
  const double sign = direction == TrustDirection::toward ? 1.0 : -1.0;
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = 0; j < n; ++j) {
      const double weight = relative(i, j) * trust(i, j);
      if (weight != 0.0) pull.row(i) += weight * sign * (positions.row(j) - positions.row(i));
    }
  return pull;
}

double constriction_factor(double phi) {
  if (!(phi >= 4.0)) throw std::invalid_argument("constriction factor needs phi >= 4, got " + std::to_string(phi));
  return 2.0 / std::abs(2.0 - phi - std::sqrt(phi * phi - 4.0 * phi));
}

namespace detail {
namespace {

class SwarmOptimiser final : public Optimiser {
 public:
  SwarmOptimiser(const ParameterSpace& space, const OptimiserOptions& options, bool trust_based)
      : Optimiser(space, options, trust_based ? "tbpso" : "pso"),
        trust_based_(trust_based),
        direction_(parse_trust_direction(options.trust_direction)),
        n_(options.population),
        d_(space.dimension()),
        rng_(options.seed) {
    x_.resize(n_, d_);
    v_ = Eigen::MatrixXd::Zero(n_, d_);
    for (int i = 0; i < n_; ++i)
      for (int k = 0; k < d_; ++k) x_(i, k) = uniform01(rng_);
    if (options.initial_velocity > 0.0)
      for (int i = 0; i < n_; ++i)
        for (int k = 0; k < d_; ++k) v_(i, k) = options.initial_velocity * (2.0 * uniform01(rng_) - 1.0);
    p_ = x_;
    fp_ = Eigen::VectorXd::Constant(n_, HUGE_VAL);
    fx_ = Eigen::VectorXd::Constant(n_, HUGE_VAL);
    trust_ = Eigen::MatrixXd::Zero(n_, n_);
    const long budget = options.evaluation_budget();
    const long per_iteration = planned_batch(options);
    planned_iterations_ = static_cast<int>((budget + per_iteration - 1) / per_iteration);
    x_before_ = x_;
    v_before_ = v_;
    withdrawn_.assign(static_cast<std::size_t>(n_), false);
  }

  std::vector<Eigen::VectorXd> ask() override {
    if (!pending_) {
      if (done()) return {};
      const long remaining = options_.evaluation_budget() - evaluations_;
      pending_count_ = static_cast<int>(std::min<long>(n_, remaining));
      pending_ = true;
      withdrawn_.assign(static_cast<std::size_t>(n_), false);
    }
    std::vector<Eigen::VectorXd> batch;
    for (int i = 0; i < pending_count_; ++i) batch.push_back(physical(x_.row(i).transpose()));
    return batch;
  }

  void tell(const std::vector<double>& fitness) override {
    detail::check_told_batch(name_, pending_, pending_count_, fitness.size());
    for (int i = 0; i < pending_count_; ++i)
      if (withdrawn_[static_cast<std::size_t>(i)] && !std::isnan(fitness[static_cast<std::size_t>(i)]))
        throw std::invalid_argument(name_ + ": tell() got a value for withdrawn candidate " + std::to_string(i) +
                                    " (pass NaN: a withdrawn candidate is not evaluated)");
    for (int i = 0; i < pending_count_; ++i) {
      if (withdrawn_[static_cast<std::size_t>(i)]) {
        x_.row(i) = x_before_.row(i);  // the move is undone; fx_, p_, fp_ keep what was evaluated
        v_.row(i) = v_before_.row(i);
        continue;
      }
      fx_[i] = record(x_.row(i).transpose(), fitness[static_cast<std::size_t>(i)]);
      if (fx_[i] <= fp_[i]) {
        fp_[i] = fx_[i];
        p_.row(i) = x_.row(i);
      }
    }
    if (trust_based_) trust_ = tbpso_trust_update(trust_, fp_, fx_);
    pending_ = false;
    ++iteration_;
    update_status_after_tell();
    if (iteration_ >= planned_iterations_ && status_ == OptimiserStatus::running)
      status_ = OptimiserStatus::budget_exhausted;
    if (!done()) move();
  }

  bool can_substitute() const override { return true; }

  void substitute(std::size_t index, const Eigen::VectorXd& physical_point) override {
    const Eigen::VectorXd unit =
        detail::substitution_in_unit_cube(name_, space_, pending_, pending_count_, index, physical_point);
    const auto i = static_cast<Eigen::Index>(index);
    x_.row(i) = unit.transpose();
    if (moved_) v_.row(i) = x_.row(i) - x_before_.row(i);  // the move that reaches the substitute
  }

  std::vector<Eigen::VectorXd> alternatives(std::size_t index, int count) const override {
    detail::check_pending_index(name_, "alternatives", pending_, pending_count_, index);
    std::mt19937_64 rng = alternatives_rng(options_.seed, iteration_, index);
    std::vector<Eigen::VectorXd> out;
    const auto i = static_cast<Eigen::Index>(index);
    if (!moved_) {  // the first batch is uniform random: so are its alternatives
      for (int c = 0; c < count; ++c) {
        Eigen::VectorXd u(d_);
        for (int k = 0; k < d_; ++k) u[k] = uniform01(rng);
        out.push_back(physical(u));
      }
      return out;
    }
    const MoveTerms terms = move_terms();
    Eigen::RowVectorXd x(d_), v(d_);
    for (int c = 0; c < count; ++c) {
      draw_move(i, rng, terms, x, v);
      out.push_back(physical(x.transpose()));
    }
    return out;
  }

  void withdraw(std::size_t index) override {
    detail::check_pending_index(name_, "withdraw", pending_, pending_count_, index);
    withdrawn_[index] = true;
  }

  nlohmann::json save_state() const override {
    nlohmann::json s = save_common();
    s["x"] = matrix_to_json(x_);
    s["v"] = matrix_to_json(v_);
    s["p"] = matrix_to_json(p_);
    s["fp"] = vector_to_json(fp_);
    s["fx"] = vector_to_json(fx_);
    s["trust"] = matrix_to_json(trust_);
    s["rng"] = rng_to_string(rng_);
    s["pending"] = pending_;
    s["pending_count"] = pending_count_;
    s["x_before"] = matrix_to_json(x_before_);
    s["v_before"] = matrix_to_json(v_before_);
    s["moved"] = moved_;
    nlohmann::json withdrawn = nlohmann::json::array();
    for (std::size_t i = 0; i < withdrawn_.size(); ++i)
      if (withdrawn_[i]) withdrawn.push_back(i);
    s["withdrawn"] = withdrawn;
    return s;
  }

  void load_state(const nlohmann::json& state) override {
    load_common(state);
    auto matrix = [&](const char* key, Eigen::Index rows, Eigen::Index cols) {
      Eigen::MatrixXd m = matrix_from_json(state_field(state, key), key);
      if (m.rows() != rows || m.cols() != cols)
        throw std::invalid_argument(name_ + " state: '" + key + "' has the wrong shape");
      return m;
    };
    auto vector = [&](const char* key) {
      Eigen::VectorXd v = vector_from_json(state_field(state, key), key);
      if (v.size() != n_) throw std::invalid_argument(name_ + " state: '" + key + "' has the wrong length");
      return v;
    };
    x_ = matrix("x", n_, d_);
    v_ = matrix("v", n_, d_);
    p_ = matrix("p", n_, d_);
    trust_ = matrix("trust", n_, n_);
    fp_ = vector("fp");
    fx_ = vector("fx");
    rng_from_string(rng_, state_field(state, "rng").get<std::string>());
    pending_ = state_field(state, "pending").get<bool>();
    pending_count_ = state_field(state, "pending_count").get<int>();
    // States written before pre-screening existed have no pre-move record: the move is then not
    // redrawable, which only matters to alternatives().
    x_before_ = state.contains("x_before") ? matrix("x_before", n_, d_) : x_;
    v_before_ = state.contains("v_before") ? matrix("v_before", n_, d_) : v_;
    moved_ = state.contains("moved") ? state.at("moved").get<bool>() : iteration_ > 0;
    withdrawn_.assign(static_cast<std::size_t>(n_), false);
    if (state.contains("withdrawn"))
      for (const auto& i : state.at("withdrawn")) {
        const auto index = i.get<std::size_t>();
        if (index >= withdrawn_.size()) throw std::invalid_argument(name_ + " state: 'withdrawn' index out of range");
        withdrawn_[index] = true;
      }
  }

 private:
  Eigen::VectorXd global_best() const {
    Eigen::Index best = 0;
    for (Eigen::Index i = 1; i < fp_.size(); ++i)
      if (fp_[i] < fp_[best]) best = i;
    return p_.row(best).transpose();
  }

  double inertia() const {
    // The velocity update after round r (r = 1 .. planned-1) uses ω from inertia_start (first
    // update) to inertia_end (last update), linearly (eq. 6).
    if (planned_iterations_ <= 2) return options_.inertia_start;
    const double t = static_cast<double>(iteration_ - 1) / (planned_iterations_ - 2);
    return options_.inertia_start - (options_.inertia_start - options_.inertia_end) * std::min(1.0, t);
  }

  // Everything a move depends on besides the random coefficients (fixed between tell() and the
  // next tell(), so alternatives() redraws exactly the move that was made).
  struct MoveTerms {
    double phi1, phi2, phi3, k_factor, omega;
    Eigen::VectorXd g;
    Eigen::MatrixXd pull;
  };
  MoveTerms move_terms() const {
    MoveTerms t;
    t.phi1 = trust_based_ ? options_.tbpso_cognitive : options_.pso_cognitive;
    t.phi2 = trust_based_ ? options_.tbpso_social : options_.pso_social;
    t.phi3 = trust_based_ ? options_.tbpso_trust : 0.0;
    t.k_factor = options_.constriction ? constriction_factor(t.phi1 + t.phi2 + t.phi3) : 1.0;
    t.omega = inertia();
    t.g = global_best();
    if (trust_based_) t.pull = tbpso_trust_pull(x_before_, trust_, direction_);
    return t;
  }

  void move() {
    x_before_ = x_;
    v_before_ = v_;
    moved_ = true;
    const MoveTerms terms = move_terms();
    Eigen::RowVectorXd x(d_), v(d_);
    for (int i = 0; i < n_; ++i) {
      draw_move(i, rng_, terms, x, v);
      x_.row(i) = x;
      v_.row(i) = v;
    }
  }

  // Particle i's move from (x_before_, v_before_) with coefficients drawn from rng (eqs. 1-15).
  void draw_move(Eigen::Index i, std::mt19937_64& rng, const MoveTerms& t, Eigen::RowVectorXd& x_out,
                 Eigen::RowVectorXd& v_out) const {
    const double vmax = options_.max_velocity;
    {
      for (int k = 0; k < d_; ++k) {
        const double r1 = uniform01(rng);
        const double r2 = uniform01(rng);
        double v = t.omega * v_before_(i, k) + t.phi1 * r1 * (p_(i, k) - x_before_(i, k)) +
                   t.phi2 * r2 * (t.g[k] - x_before_(i, k));
        if (trust_based_) v += t.phi3 * uniform01(rng) * t.pull(i, k);
        v *= t.k_factor;
        if (vmax > 0.0) v = std::clamp(v, -vmax, vmax);
        double x = x_before_(i, k) + v;
        if (x < 0.0 || x > 1.0) {
          if (options_.bounds == BoundHandling::reflect) {
            x = x < 0.0 ? -x : 2.0 - x;
            v = -v;
            x = std::clamp(x, 0.0, 1.0);
          } else {
            x = std::clamp(x, 0.0, 1.0);
            v = 0.0;
          }
        }
        x_out[k] = x;
        v_out[k] = v;
      }
    }
  }

  bool trust_based_;
  TrustDirection direction_;
  int n_, d_;
  int planned_iterations_ = 1;
  Eigen::MatrixXd x_, v_, p_, trust_;
  Eigen::VectorXd fp_, fx_;
  Eigen::MatrixXd x_before_, v_before_;  // positions and velocities before the last move
  bool moved_ = false;                   // false while the batch is the initial random one
  std::vector<bool> withdrawn_;          // per particle of the pending batch
  std::mt19937_64 rng_;
  bool pending_ = false;
  int pending_count_ = 0;
};

}  // namespace

std::unique_ptr<Optimiser> make_swarm(const ParameterSpace& space, const OptimiserOptions& options, bool trust_based) {
  return std::make_unique<SwarmOptimiser>(space, options, trust_based);
}

}  // namespace detail
}  // namespace demcal::optimise
