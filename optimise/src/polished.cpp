// Main algorithm + local NLopt polish inside one evaluation budget (options.polish_evaluations > 0).
#include "internal.hpp"

#include <stdexcept>

namespace demcal::optimise::detail {
namespace {

std::unique_ptr<Optimiser> make_main(const ParameterSpace& space, const OptimiserOptions& options) {
  OptimiserOptions main = options;
  main.polish_evaluations = 0;
  main.max_evaluations = options.evaluation_budget() - options.polish_evaluations;
  return make_optimiser(space, main);
}

class PolishedOptimiser final : public Optimiser {
 public:
  PolishedOptimiser(const ParameterSpace& space, const OptimiserOptions& options)
      : PolishedOptimiser(space, options, make_main(space, options)) {}

  std::vector<Eigen::VectorXd> ask() override {
    while (status_ == OptimiserStatus::running) {
      auto batch = active().ask();
      if (!batch.empty()) return batch;
      advance();  // the active phase has nothing more to ask
    }
    return {};
  }

  void tell(const std::vector<double>& fitness) override {
    if (status_ != OptimiserStatus::running) throw std::logic_error(name_ + ": tell() after the run ended");
    active().tell(fitness);
    evaluations_ = main_->evaluations() + (polish_ ? polish_->evaluations() : 0);
    iteration_ = main_->iteration() + (polish_ ? polish_->iteration() : 0);
    for (const Optimiser* phase : {main_.get(), polish_.get()})
      if (phase && phase->best_value() < best_value_) {
        best_value_ = phase->best_value();
        best_unit_ = best_unit_of(*phase);
      }
    if (best_value_ <= options_.target_value) {
      status_ = OptimiserStatus::target_reached;
      return;
    }
    settle();
  }

  bool done() const override {
    const_cast<PolishedOptimiser*>(this)->settle();
    return status_ != OptimiserStatus::running;
  }

  bool can_substitute() const override { return !polish_ && main_->can_substitute(); }

  void substitute(std::size_t index, const Eigen::VectorXd& physical_point) override {
    if (polish_) throw std::logic_error(name_ + ": no substitutes during the polish (NLopt chose the point)");
    main_->substitute(index, physical_point);
  }

  std::vector<Eigen::VectorXd> alternatives(std::size_t index, int count) const override {
    if (polish_) throw std::logic_error(name_ + ": no alternatives during the polish (NLopt chose the point)");
    return main_->alternatives(index, count);
  }

  void withdraw(std::size_t index) override {
    if (polish_) throw std::logic_error(name_ + ": no withdrawal during the polish (NLopt chose the point)");
    main_->withdraw(index);
  }

  nlohmann::json save_state() const override {
    nlohmann::json s = save_common();
    s["main"] = main_->save_state();
    s["polish"] = polish_ ? polish_->save_state() : nlohmann::json(nullptr);
    return s;
  }

  void load_state(const nlohmann::json& state) override {
    load_common(state);
    polish_.reset();
    main_->load_state(state_field(state, "main"));
    const auto& polish = state_field(state, "polish");
    if (!polish.is_null()) {
      start_polish();
      polish_->load_state(polish);
    }
    if (evaluations_ != main_->evaluations() + (polish_ ? polish_->evaluations() : 0))
      throw std::invalid_argument(name_ + " state: 'evaluations' = " + std::to_string(evaluations_) +
                                  " does not match its phases");
  }

  std::optional<PolishReport> polish_report() const override {
    PolishReport report;
    report.polishing = polish_ != nullptr;
    report.main_best_value = main_->best_value();
    report.main_best_x = main_->best_x();
    report.main_evaluations = main_->evaluations();
    if (polish_) {
      report.polish_evaluations = polish_->evaluations();
      report.polish_status = to_string(polish_->status());
    }
    return report;
  }

 private:
  PolishedOptimiser(const ParameterSpace& space, const OptimiserOptions& options, std::unique_ptr<Optimiser> main)
      : Optimiser(space, options,
                  main->name() + "+polish:" + nlopt_name_from_algorithm("nlopt:" + options.polish_algorithm)),
        main_(std::move(main)) {}

  Optimiser& active() { return polish_ ? *polish_ : *main_; }

  // Moves on while the active phase is done: main -> polish -> finished.
  void settle() {
    while (status_ == OptimiserStatus::running && active().done()) advance();
  }

  void advance() {
    if (!polish_) {
      const OptimiserStatus main_status = main_->status();
      if (main_status == OptimiserStatus::target_reached || main_status == OptimiserStatus::failed ||
          options_.evaluation_budget() - main_->evaluations() <= 0) {
        status_ = main_status == OptimiserStatus::running ? OptimiserStatus::budget_exhausted : main_status;
        message_ = main_->message();
        return;
      }
      start_polish();
      return;
    }
    status_ = polish_->status() == OptimiserStatus::running ? OptimiserStatus::budget_exhausted : polish_->status();
    message_ = polish_->message();
  }

  // The polish starts at the main phase's best (the box centre if it found no finite value) and
  // gets every evaluation the main phase left.
  void start_polish() {
    OptimiserOptions o;
    o.algorithm = "nlopt:" + options_.polish_algorithm;
    o.max_evaluations = options_.evaluation_budget() - main_->evaluations();
    o.seed = options_.seed;
    o.target_value = options_.target_value;
    o.initial_step = options_.polish_initial_step;
    const Eigen::VectorXd start = main_->best_x();
    if (start.size() > 0) o.initial_point.assign(start.data(), start.data() + start.size());
    polish_ = make_optimiser(space_, o);
  }

  std::unique_ptr<Optimiser> main_;
  std::unique_ptr<Optimiser> polish_;  // null until the main phase is done
};

}  // namespace

std::unique_ptr<Optimiser> make_polished(const ParameterSpace& space, const OptimiserOptions& options) {
  return std::make_unique<PolishedOptimiser>(space, options);
}

}  // namespace demcal::optimise::detail
