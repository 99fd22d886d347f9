// NLopt algorithms behind ask/tell: NLopt runs on a worker thread; each objective call it makes is
// handed to the caller through ask() (a batch of one point) and answered by tell().
#include "internal.hpp"

#include <nlopt.h>

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <stdexcept>
#include <thread>

namespace demcal::optimise::detail {
namespace {

class NloptOptimiser final : public Optimiser {
 public:
  NloptOptimiser(const ParameterSpace& space, const OptimiserOptions& options, const std::string& algorithm_name)
      : Optimiser(space, options, "nlopt:" + algorithm_name), d_(space.dimension()) {
    algorithm_ = nlopt_algorithm_from_string(algorithm_name.c_str());
    if (static_cast<int>(algorithm_) < 0) throw std::invalid_argument("unknown NLopt algorithm '" + algorithm_name + "'");
    start_ = Eigen::VectorXd::Constant(d_, 0.5);
    if (!options.initial_point.empty()) {
      const Eigen::VectorXd physical_start =
          Eigen::Map<const Eigen::VectorXd>(options.initial_point.data(), static_cast<Eigen::Index>(d_));
      const Eigen::VectorXd unit = space.to_unit(physical_start);
      for (int k = 0; k < d_; ++k)
        if (!(unit[k] >= -1e-12 && unit[k] <= 1.0 + 1e-12))
          throw std::invalid_argument("option initial_point: value " + std::to_string(physical_start[k]) +
                                      " of parameter '" + space.free_parameters()[k].name + "' is outside its bounds");
      start_ = unit.cwiseMax(0.0).cwiseMin(1.0);
    }
  }

  ~NloptOptimiser() override { stop_worker(); }

  bool done() const override {
    if (status_ != OptimiserStatus::running) return true;
    if (pending_) return false;
    auto* self = const_cast<NloptOptimiser*>(this);
    self->ensure_started();
    std::unique_lock lock(mutex_);
    cv_.wait(lock, [&] { return phase_ != Phase::computing; });
    if (phase_ == Phase::finished) {
      self->status_from_result();
      return true;
    }
    return false;
  }

  std::vector<Eigen::VectorXd> ask() override {
    if (!pending_) {
      if (done()) return {};
      pending_ = true;
    }
    return {physical(point_)};
  }

  void tell(const std::vector<double>& fitness) override {
    detail::check_told_batch(name_, pending_, 1, fitness.size());
    const double value = record(point_, fitness[0]);
    history_.push_back({point_, value});
    pending_ = false;
    ++iteration_;
    update_status_after_tell();
    {
      std::lock_guard lock(mutex_);
      value_ = value;
      value_ready_ = true;
      phase_ = Phase::computing;
    }
    cv_.notify_all();
  }

  nlohmann::json save_state() const override {
    nlohmann::json s = save_common();
    nlohmann::json history = nlohmann::json::array();
    for (const auto& told : history_) history.push_back({{"x", vector_to_json(told.x)}, {"f", number_to_json(told.f)}});
    s["history"] = history;
    return s;
  }

  void load_state(const nlohmann::json& state) override {
    stop_worker();
    load_common(state);
    history_.clear();
    const auto& history = state_field(state, "history");
    if (!history.is_array()) throw std::invalid_argument(name_ + " state: 'history' is not an array");
    for (const auto& told : history) {
      Told t{vector_from_json(state_field(told, "x"), "history.x"), number_from_json(state_field(told, "f"), "history.f")};
      if (t.x.size() != d_) throw std::invalid_argument(name_ + " state: a history point has the wrong dimension");
      history_.push_back(std::move(t));
    }
    if (static_cast<long>(history_.size()) != evaluations_)
      throw std::invalid_argument(name_ + " state: history holds " + std::to_string(history_.size()) +
                                  " points but 'evaluations' says " + std::to_string(evaluations_));
    pending_ = false;
  }

 private:
  struct Told {
    Eigen::VectorXd x;  // unit cube
    double f;           // sanitised told value (+inf for a failure)
  };
  enum class Phase { computing, point_ready, finished };

  void ensure_started() {
    if (started_) return;
    started_ = true;
    phase_ = Phase::computing;
    value_ready_ = false;
    abort_ = false;
    replay_ = history_;  // the worker answers these itself, in order
    worker_ = std::thread([this] { run(); });
  }

  void stop_worker() {
    if (worker_.joinable()) {
      {
        std::lock_guard lock(mutex_);
        abort_ = true;
      }
      cv_.notify_all();
      worker_.join();
    }
    started_ = false;
    abort_ = false;
  }

  void status_from_result() {
    if (status_ != OptimiserStatus::running) return;
    if (!replay_error_.empty()) {
      status_ = OptimiserStatus::failed;
      message_ = replay_error_;
      return;
    }
    switch (result_) {
      case NLOPT_MAXEVAL_REACHED: status_ = OptimiserStatus::budget_exhausted; break;
      case NLOPT_STOPVAL_REACHED: status_ = OptimiserStatus::target_reached; break;
      case NLOPT_SUCCESS:
      case NLOPT_FTOL_REACHED:
      case NLOPT_XTOL_REACHED:
      case NLOPT_MAXTIME_REACHED:
      case NLOPT_ROUNDOFF_LIMITED: status_ = OptimiserStatus::converged; break;  // normal stops
      default: status_ = OptimiserStatus::failed; break;
    }
    message_ = std::string("NLopt returned ") + nlopt_result_to_string(result_);
  }

  // Value handed to NLopt for a told value: failures become a finite penalty (the worst finite value
  // so far plus 10 % of its magnitude, or 1e30 before any finite value), since NLopt's model-based
  // methods break down on infinities.
  double value_for_nlopt(double told) {
    if (std::isfinite(told)) {
      worst_finite_ = have_finite_ ? std::max(worst_finite_, told) : told;
      have_finite_ = true;
      return told;
    }
    return have_finite_ ? worst_finite_ + 0.1 * std::abs(worst_finite_) + 1e-300 : 1e30;
  }

  static double callback(unsigned n, const double* x, double* gradient, void* data) {
    (void)n;
    (void)gradient;
    return static_cast<NloptOptimiser*>(data)->objective(x);
  }

  double objective(const double* x) {
    const Eigen::VectorXd point = Eigen::Map<const Eigen::VectorXd>(x, d_);
    double told = 0.0;
    if (replay_next_ < replay_.size()) {
      const Told& recorded = replay_[replay_next_];
      if (!(recorded.x.array() == point.array()).all()) {
        replay_error_ = "NLopt replay diverged at point " + std::to_string(replay_next_) +
                        ": the restored run asked for a different point than the recorded one";
        nlopt_force_stop(opt_);
        return HUGE_VAL;
      }
      told = recorded.f;
      ++replay_next_;
    } else {
      std::unique_lock lock(mutex_);
      point_ = point;
      phase_ = Phase::point_ready;
      cv_.notify_all();
      cv_.wait(lock, [&] { return value_ready_ || abort_; });
      if (abort_) {
        nlopt_force_stop(opt_);
        return HUGE_VAL;
      }
      value_ready_ = false;
      told = value_;
    }
    return value_for_nlopt(told);
  }

  void run() {
    replay_next_ = 0;
    have_finite_ = false;
    worst_finite_ = 0.0;
    replay_error_.clear();
    nlopt_srand(static_cast<unsigned long>(options_.seed));
    opt_ = nlopt_create(algorithm_, static_cast<unsigned>(d_));
    const std::vector<double> lower(static_cast<std::size_t>(d_), 0.0), upper(static_cast<std::size_t>(d_), 1.0);
    nlopt_set_lower_bounds(opt_, lower.data());
    nlopt_set_upper_bounds(opt_, upper.data());
    nlopt_set_min_objective(opt_, &NloptOptimiser::callback, this);
    nlopt_set_maxeval(opt_, static_cast<int>(std::min<long>(options_.evaluation_budget(), 2000000000L)));
    if (std::isfinite(options_.target_value)) nlopt_set_stopval(opt_, options_.target_value);
    if (options_.xtol_rel > 0.0) nlopt_set_xtol_rel(opt_, options_.xtol_rel);
    if (options_.ftol_abs > 0.0) nlopt_set_ftol_abs(opt_, options_.ftol_abs);
    if (options_.nlopt_population > 0) nlopt_set_population(opt_, static_cast<unsigned>(options_.nlopt_population));
    if (options_.initial_step > 0.0) nlopt_set_initial_step1(opt_, options_.initial_step);
    std::vector<double> x(start_.data(), start_.data() + d_);
    double f = 0.0;
    const nlopt_result result = nlopt_optimize(opt_, x.data(), &f);
    nlopt_destroy(opt_);
    opt_ = nullptr;
    {
      std::lock_guard lock(mutex_);
      result_ = result;
      phase_ = Phase::finished;
    }
    cv_.notify_all();
  }

  int d_;
  nlopt_algorithm algorithm_{};
  Eigen::VectorXd start_;
  std::vector<Told> history_;  // every told point, in order (main thread)
  bool pending_ = false;
  bool started_ = false;

  // Shared with the worker under mutex_.
  mutable std::mutex mutex_;
  mutable std::condition_variable cv_;
  Phase phase_ = Phase::computing;
  bool value_ready_ = false;
  bool abort_ = false;
  double value_ = 0.0;
  Eigen::VectorXd point_;
  nlopt_result result_ = NLOPT_SUCCESS;
  std::thread worker_;

  // Worker-only while it runs (read by the main thread only after phase_ == finished).
  std::vector<Told> replay_;
  std::size_t replay_next_ = 0;
  bool have_finite_ = false;
  double worst_finite_ = 0.0;
  std::string replay_error_;
  nlopt_opt opt_ = nullptr;
};

}  // namespace

std::unique_ptr<Optimiser> make_nlopt(const ParameterSpace& space, const OptimiserOptions& options,
                                      const std::string& algorithm_name) {
  return std::make_unique<NloptOptimiser>(space, options, algorithm_name);
}

}  // namespace demcal::optimise::detail
