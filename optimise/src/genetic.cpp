// Real-valued genetic algorithm (section 3.1 of the paper) in the unit cube.
#include "internal.hpp"

#include "demcal/common/random.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace demcal::optimise::detail {
namespace {

class GeneticOptimiser final : public Optimiser {
 public:
  GeneticOptimiser(const ParameterSpace& space, const OptimiserOptions& options)
      : Optimiser(space, options, "ga"), n_(options.population), d_(space.dimension()), rng_(options.seed) {
    genes_.resize(n_, d_);
    for (int i = 0; i < n_; ++i)
      for (int k = 0; k < d_; ++k) genes_(i, k) = uniform01(rng_);
    fitness_ = Eigen::VectorXd::Constant(n_, HUGE_VAL);
    const long budget = options.evaluation_budget();
    const long first = std::min<long>(n_, planned_batch(options));
    const long per_generation = std::min<long>(planned_batch(options), n_ - options.elitism);
    planned_generations_ =
        1 + static_cast<int>(std::max<long>(0, (budget - first + per_generation - 1) / per_generation));
    parents_ = genes_;
    parent_fitness_ = fitness_;
    withdrawn_.assign(static_cast<std::size_t>(n_), false);
  }

  std::vector<Eigen::VectorXd> ask() override {
    if (!pending_) {
      if (done()) return {};
      const long remaining = options_.evaluation_budget() - evaluations_;
      pending_count_ = static_cast<int>(std::min<long>(n_ - first_candidate_, remaining));
      pending_ = true;
      withdrawn_.assign(static_cast<std::size_t>(n_), false);
    }
    std::vector<Eigen::VectorXd> batch;
    for (int i = 0; i < pending_count_; ++i) batch.push_back(physical(genes_.row(first_candidate_ + i).transpose()));
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
        fitness_[first_candidate_ + i] = HUGE_VAL;  // discarded: weight 0 in the next selection
        continue;
      }
      fitness_[first_candidate_ + i] =
          record(genes_.row(first_candidate_ + i).transpose(), fitness[static_cast<std::size_t>(i)]);
    }
    pending_ = false;
    ++iteration_;
    update_status_after_tell();
    if (!done()) breed();
  }

  bool can_substitute() const override { return true; }

  void substitute(std::size_t index, const Eigen::VectorXd& physical_point) override {
    const Eigen::VectorXd unit =
        detail::substitution_in_unit_cube(name_, space_, pending_, pending_count_, index, physical_point);
    genes_.row(first_candidate_ + static_cast<Eigen::Index>(index)) = unit.transpose();
  }

  std::vector<Eigen::VectorXd> alternatives(std::size_t index, int count) const override {
    detail::check_pending_index(name_, "alternatives", pending_, pending_count_, index);
    std::mt19937_64 rng = alternatives_rng(options_.seed, iteration_, index);
    std::vector<Eigen::VectorXd> out;
    if (iteration_ == 0) {  // the first population is uniform random: so are its alternatives
      for (int c = 0; c < count; ++c) {
        Eigen::VectorXd u(d_);
        for (int k = 0; k < d_; ++k) u[k] = uniform01(rng);
        out.push_back(physical(u));
      }
      return out;
    }
    const Eigen::VectorXd weights = selection_weights(parent_fitness_);
    const double total = weights.sum();
    const double sigma = mutation_sigma();
    for (int c = 0; c < count; ++c) {
      const int a = select(weights, total, rng);
      const int b = select(weights, total, rng);
      Eigen::RowVectorXd child = parents_.row(a), other = parents_.row(b);
      for (int k = 0; k < d_; ++k)
        if (uniform01(rng) < options_.crossover_probability) std::swap(child[k], other[k]);
      mutate(child, sigma, rng);
      out.push_back(physical(child.transpose()));
    }
    return out;
  }

  void withdraw(std::size_t index) override {
    detail::check_pending_index(name_, "withdraw", pending_, pending_count_, index);
    withdrawn_[index] = true;
  }

  nlohmann::json save_state() const override {
    nlohmann::json s = save_common();
    s["genes"] = matrix_to_json(genes_);
    s["fitness"] = vector_to_json(fitness_);
    s["first_candidate"] = first_candidate_;
    s["rng"] = rng_to_string(rng_);
    s["pending"] = pending_;
    s["pending_count"] = pending_count_;
    s["parents"] = matrix_to_json(parents_);
    s["parent_fitness"] = vector_to_json(parent_fitness_);
    nlohmann::json withdrawn = nlohmann::json::array();
    for (std::size_t i = 0; i < withdrawn_.size(); ++i)
      if (withdrawn_[i]) withdrawn.push_back(i);
    s["withdrawn"] = withdrawn;
    return s;
  }

  void load_state(const nlohmann::json& state) override {
    load_common(state);
    genes_ = matrix_from_json(state_field(state, "genes"), "genes");
    fitness_ = vector_from_json(state_field(state, "fitness"), "fitness");
    if (genes_.rows() != n_ || genes_.cols() != d_ || fitness_.size() != n_)
      throw std::invalid_argument("ga state: population has the wrong shape");
    first_candidate_ = state_field(state, "first_candidate").get<int>();
    rng_from_string(rng_, state_field(state, "rng").get<std::string>());
    pending_ = state_field(state, "pending").get<bool>();
    pending_count_ = state_field(state, "pending_count").get<int>();
    // States written before pre-screening existed have no parents: only alternatives() needs them.
    parents_ = state.contains("parents") ? matrix_from_json(state.at("parents"), "parents") : genes_;
    parent_fitness_ =
        state.contains("parent_fitness") ? vector_from_json(state.at("parent_fitness"), "parent_fitness") : fitness_;
    if (parents_.rows() != n_ || parents_.cols() != d_ || parent_fitness_.size() != n_)
      throw std::invalid_argument("ga state: parents have the wrong shape");
    withdrawn_.assign(static_cast<std::size_t>(n_), false);
    if (state.contains("withdrawn"))
      for (const auto& i : state.at("withdrawn")) {
        const auto index = i.get<std::size_t>();
        if (index >= withdrawn_.size()) throw std::invalid_argument("ga state: 'withdrawn' index out of range");
        withdrawn_[index] = true;
      }
  }

 private:
  // Fitness-proportionate weights for minimisation: w_i = (f_worst − f_i) + 0.1 (f_worst − f_best)
  // over the finite values (failed candidates weigh 0); all equal or all failed -> equal weights.
  static Eigen::VectorXd selection_weights(const Eigen::VectorXd& fitness_) {
    const auto n_ = static_cast<int>(fitness_.size());
    double best = HUGE_VAL, worst = -HUGE_VAL;
    for (int i = 0; i < n_; ++i)
      if (std::isfinite(fitness_[i])) {
        best = std::min(best, fitness_[i]);
        worst = std::max(worst, fitness_[i]);
      }
    Eigen::VectorXd w = Eigen::VectorXd::Zero(n_);
    if (!(worst > best)) {
      for (int i = 0; i < n_; ++i) w[i] = (std::isfinite(fitness_[i]) || !std::isfinite(best)) ? 1.0 : 0.0;
      return w;
    }
    const double floor = 0.1 * (worst - best);
    for (int i = 0; i < n_; ++i)
      if (std::isfinite(fitness_[i])) w[i] = (worst - fitness_[i]) + floor;
    return w;
  }

  int select(const Eigen::VectorXd& weights, double total, std::mt19937_64& rng) const {
    const double r = uniform01(rng) * total;
    double cumulative = 0.0;
    for (int i = 0; i < n_; ++i) {
      cumulative += weights[i];
      if (r < cumulative) return i;
    }
    for (int i = n_ - 1; i >= 0; --i)
      if (weights[i] > 0.0) return i;
    return n_ - 1;
  }

  double mutation_sigma() const {
    if (planned_generations_ <= 2) return options_.ga_sigma_start;
    const double t = std::min(1.0, static_cast<double>(iteration_ - 1) / (planned_generations_ - 2));
    return options_.ga_sigma_start * std::pow(options_.ga_sigma_end / options_.ga_sigma_start, t);
  }

  void mutate(Eigen::Ref<Eigen::RowVectorXd> child, double sigma, std::mt19937_64& rng) const {
    for (int k = 0; k < d_; ++k) {
      if (uniform01(rng) >= options_.mutation_probability) continue;
      if (options_.ga_mutation == GaMutation::reset) {
        child[k] = uniform01(rng);
      } else {
        child[k] = std::clamp(child[k] + sigma * normal(rng), 0.0, 1.0);
      }
    }
  }

  void breed() {
    const int elites = options_.elitism;
    std::vector<int> order(static_cast<std::size_t>(n_));
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return fitness_[a] < fitness_[b]; });
    const Eigen::VectorXd weights = selection_weights(fitness_);
    parents_ = genes_;
    parent_fitness_ = fitness_;
    const double total = weights.sum();
    const double sigma = mutation_sigma();

    Eigen::MatrixXd next(n_, d_);
    Eigen::VectorXd next_fitness = Eigen::VectorXd::Constant(n_, HUGE_VAL);
    for (int e = 0; e < elites; ++e) {
      next.row(e) = genes_.row(order[static_cast<std::size_t>(e)]);
      next_fitness[e] = fitness_[order[static_cast<std::size_t>(e)]];
    }
    int filled = elites;
    while (filled < n_) {
      const int a = select(weights, total, rng_);
      const int b = select(weights, total, rng_);
      Eigen::RowVectorXd child1 = genes_.row(a), child2 = genes_.row(b);
      for (int k = 0; k < d_; ++k)
        if (uniform01(rng_) < options_.crossover_probability) std::swap(child1[k], child2[k]);
      mutate(child1, sigma, rng_);
      mutate(child2, sigma, rng_);
      next.row(filled++) = child1;
      if (filled < n_) next.row(filled++) = child2;
    }
    genes_ = next;
    fitness_ = next_fitness;
    first_candidate_ = elites;
  }

  int n_, d_;
  int planned_generations_ = 1;
  Eigen::MatrixXd genes_;    // rows [0, first_candidate_) are elites with known fitness
  Eigen::VectorXd fitness_;
  int first_candidate_ = 0;
  Eigen::MatrixXd parents_;          // the population the pending offspring were bred from
  Eigen::VectorXd parent_fitness_;
  std::vector<bool> withdrawn_;      // per slot of the pending batch
  std::mt19937_64 rng_;
  bool pending_ = false;
  int pending_count_ = 0;
};

}  // namespace

std::unique_ptr<Optimiser> make_genetic(const ParameterSpace& space, const OptimiserOptions& options) {
  return std::make_unique<GeneticOptimiser>(space, options);
}

}  // namespace demcal::optimise::detail
