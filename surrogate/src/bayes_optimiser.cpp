// "bo": Bayesian optimisation behind the ask/tell interface (surrogate.hpp, make_bayes_optimiser).
#include "demcal/surrogate/surrogate.hpp"
#include "internal.hpp"

#include "demcal/common/format.hpp"
#include "demcal/common/random.hpp"

#include <nlopt.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <optional>
#include <cmath>
#include <numeric>
#include <random>
#include <stdexcept>
#include <thread>

namespace demcal::surrogate {

namespace {

using detail::vector_from;
using detail::vector_json;

// The cost-aware batch grows at most this many times. Measured on the arch (docs/benchmarks.md,
// "Surrogate wall time"): 4 x lost 5 % of median fitness against 2 x for 25 % less model time.
constexpr int kMaxBatchFactor = 2;

// The acquisition of a batch's next point: the model's score, shifted to be >= 0 over the searched
// points, times a factor 1 − exp(−|x − p|² / (2 r²)) for every point p already in the batch (local
// penalisation: the batch spreads over the acquisition's peaks instead of piling onto one).
struct PenalisedScore {
  const SurrogateModel* model;
  double floor;
  double radius;
  const std::vector<Eigen::VectorXd>* picked;
  double penalised(const Eigen::VectorXd& u, double score) const {
    double value = score - floor;
    for (const auto& p : *picked) value *= 1 - std::exp(-(u - p).squaredNorm() / (2 * radius * radius));
    return value;
  }
  double operator()(const Eigen::VectorXd& u) const { return penalised(u, model->score(u)); }
};

double negative_penalised(unsigned n, const double* x, double*, void* data) {
  return -(*static_cast<const PenalisedScore*>(data))(Eigen::Map<const Eigen::VectorXd>(x, n));
}

// The next round's model, fitted on a thread of its own while this round's points are simulated.
// The thread is joined, not only waited for: a thread that trained runs on after its result is
// ready, while LibTorch and OpenMP free its per-thread state, and the next training should not
// begin before that ends. With std::async, which hands the result over before its thread has
// ended, a diagnosis whose every search overlapped crashed once in about 600 such fits; with the
// thread joined the crash has not been seen again (docs/journal/diagnose-studies.md).
class BackgroundFit {
 public:
  BackgroundFit() = default;
  BackgroundFit(const BackgroundFit&) = delete;
  BackgroundFit& operator=(const BackgroundFit&) = delete;
  ~BackgroundFit() { wait(); }

  void start(std::function<SurrogateModel()> fit) {
    discard();
    thread_ = std::thread([this, fit = std::move(fit)] {
      try {
        result_ = fit();
      } catch (...) {
        error_ = std::current_exception();
      }
    });
  }
  bool pending() const { return thread_.joinable(); }  // started and not taken
  void wait() {
    if (thread_.joinable()) thread_.join();
  }
  void discard() {
    wait();
    result_.reset();
    error_ = nullptr;
  }
  // The fitted model (the thread joined first); rethrows what the fit threw.
  SurrogateModel take() {
    wait();
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
    SurrogateModel model = std::move(*result_);
    result_.reset();
    return model;
  }

 private:
  std::thread thread_;
  std::optional<SurrogateModel> result_;
  std::exception_ptr error_;
};

class BayesOptimiser final : public optimise::Optimiser {
 public:
  BayesOptimiser(const optimise::ParameterSpace& space, const optimise::OptimiserOptions& options,
                 SurrogateOptions surrogate, std::vector<TrainingRow> warm, CurveHooks hooks)
      : Optimiser(space, options, "bo"), surrogate_(std::move(surrogate)), warm_(std::move(warm)), hooks_(std::move(hooks)) {
    surrogate_.Validate();
    batch_ = std::max(1, surrogate_.batch);
    overlap_ = surrogate_.overlap == "always";
    const int d = space.dimension();
    for (const auto& r : warm_)
      if (r.unit.size() != d) throw std::invalid_argument("bo: a warm row has the wrong dimension");
    // Given starts are the design's first points: a warm start from a known good set, then the
    // further starts (other basins).
    std::vector<const std::vector<double>*> starts;
    if (!options.initial_point.empty()) starts.push_back(&options.initial_point);
    for (const auto& s : options.further_starts) starts.push_back(&s);
    const long wanted = std::max<long>({surrogate_.min_runs, options.population, static_cast<long>(starts.size())});
    // Latin hypercube: one point per stratum of every coordinate, strata permuted per coordinate.
    std::mt19937_64 rng = seeded_rng(options.seed);
    Eigen::MatrixXd lhs(wanted, d);
    for (int k = 0; k < d; ++k) {
      std::vector<long> perm(static_cast<size_t>(wanted));
      std::iota(perm.begin(), perm.end(), 0);
      for (long i = wanted - 1; i > 0; --i) std::swap(perm[static_cast<size_t>(i)], perm[static_cast<size_t>(rng() % static_cast<std::uint64_t>(i + 1))]);
      for (long i = 0; i < wanted; ++i)
        lhs(i, k) = (static_cast<double>(perm[static_cast<size_t>(i)]) + uniform01(rng)) / static_cast<double>(wanted);
    }
    for (size_t i = 0; i < starts.size(); ++i)
      lhs.row(static_cast<Eigen::Index>(i)) = space.to_unit(Eigen::Map<const Eigen::VectorXd>(starts[i]->data(), d))
                                                  .cwiseMax(0.0).cwiseMin(1.0).transpose();
    // Known runs stand in for the design points they lie near (within half the design's spacing,
    // 0.5 n^(-1/d)), not for a count of them: runs clustered at one set (a diagnosis's probes
    // around its base fit) leave the rest of the box to the design, an earlier campaign's spread
    // runs replace most of it.
    const double radius = 0.5 * std::pow(static_cast<double>(wanted), -1.0 / std::max(1, d));
    std::vector<long> kept;
    for (long i = 0; i < wanted; ++i) {
      const bool covered = std::any_of(warm_.begin(), warm_.end(), [&](const TrainingRow& r) {
        return (r.unit - lhs.row(i).transpose()).norm() <= radius;  // a failed run is known too
      });
      if (!covered) kept.push_back(i);
    }
    design_ = Eigen::MatrixXd(static_cast<Eigen::Index>(kept.size()), d);
    for (size_t i = 0; i < kept.size(); ++i) design_.row(static_cast<Eigen::Index>(i)) = lhs.row(kept[i]);
  }

  std::vector<Eigen::VectorXd> ask() override {
    if (!pending_) {
      if (done()) return {};
      const long remaining = options_.evaluation_budget() - evaluations_;
      pending_units_.clear();
      pending_predictions_.clear();
      const long told = static_cast<long>(told_f_.size());
      if (told < design_.rows()) {
        for (long i = told; i < design_.rows() && static_cast<long>(pending_units_.size()) < remaining; ++i)
          pending_units_.push_back(design_.row(i).transpose());
        pending_predictions_.assign(pending_units_.size(), nlohmann::json(nullptr));
      } else {
        propose(std::min<long>(batch_, remaining));
      }
      pending_ = true;
    }
    std::vector<Eigen::VectorXd> batch;
    for (const auto& u : pending_units_) batch.push_back(physical(u));
    return batch;
  }

  void tell(const std::vector<double>& fitness) override {
    if (!pending_) throw std::logic_error("bo: tell() without a pending ask()");
    if (fitness.size() != pending_units_.size())
      throw std::invalid_argument("bo: tell() got " + std::to_string(fitness.size()) + " values for " +
                                  std::to_string(pending_units_.size()) + " candidates");
    for (size_t i = 0; i < fitness.size(); ++i) {
      record(pending_units_[i], fitness[i]);
      told_x_.push_back(pending_units_[i]);
      told_f_.push_back(fitness[i]);
      told_predictions_.push_back(pending_predictions_[i]);
    }
    pending_ = false;
    ++iteration_;
    update_status_after_tell();
  }

  nlohmann::json save_state() const override {
    nlohmann::json s = save_common();
    nlohmann::json x = nlohmann::json::array(), f = nlohmann::json::array(), pending = nlohmann::json::array();
    for (const auto& u : told_x_) x.push_back(vector_json(u));
    for (double v : told_f_) f.push_back(std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr));
    for (const auto& u : pending_units_) pending.push_back(vector_json(u));
    nlohmann::json fits = nlohmann::json::array();
    for (const auto& [told, full] : fits_) fits.push_back({told, full});
    s["told_x"] = x;
    s["told_f"] = f;
    s["told_predictions"] = told_predictions_;
    s["pending"] = pending_;
    s["pending_units"] = pending;
    s["pending_predictions"] = pending_predictions_;
    s["fits"] = fits;
    s["batch"] = batch_;
    s["batch_reason"] = batch_reason_;
    s["overlap"] = overlap_;
    s["prefitted"] = prefitted_ || next_model_.pending();
    return s;
  }

  void load_state(const nlohmann::json& state) override {
    load_common(state);
    try {
      told_x_.clear();
      told_f_.clear();
      told_outputs_.clear();
      pending_units_.clear();
      fits_.clear();
      for (const auto& u : state.at("told_x")) told_x_.push_back(vector_from(u));
      for (const auto& v : state.at("told_f"))
        told_f_.push_back(v.is_null() ? std::numeric_limits<double>::quiet_NaN() : v.get<double>());
      for (const auto& u : state.at("pending_units")) pending_units_.push_back(vector_from(u));
      pending_ = state.at("pending").get<bool>();
      told_predictions_ = state.at("told_predictions").get<std::vector<nlohmann::json>>();
      pending_predictions_ = state.at("pending_predictions").get<std::vector<nlohmann::json>>();
      for (const auto& fit : state.at("fits")) fits_.push_back({fit.at(0).get<long>(), fit.at(1).get<bool>()});
      batch_ = state.at("batch").get<int>();
      batch_reason_ = state.at("batch_reason").get<std::string>();
      overlap_ = state.value("overlap", false);
      prefitted_ = state.value("prefitted", false);
    } catch (const nlohmann::json::exception& e) {
      throw std::invalid_argument(std::string("bo state: ") + e.what());
    }
    if (told_x_.size() != told_f_.size() || told_predictions_.size() != told_f_.size())
      throw std::invalid_argument("bo state: told_x, told_f and told_predictions differ in length");
    if (pending_predictions_.size() != pending_units_.size())
      throw std::invalid_argument("bo state: pending_units and pending_predictions differ in length");
    next_model_.discard();
    model_ = SurrogateModel();
    replayed_ = false;
  }

 private:
  // The rows of the first `told` told points (and the warm rows); a told point's curves are read
  // once (its archived runs do not change).
  std::vector<TrainingRow> rows_until(size_t told) {
    const bool curves = surrogate_.kind == "mlp" && hooks_.outputs_at;
    while (told_outputs_.size() < told)
      told_outputs_.push_back(curves ? hooks_.outputs_at(told_x_[told_outputs_.size()]) : Eigen::VectorXd());
    std::vector<TrainingRow> rows = warm_;
    for (size_t i = 0; i < told; ++i) rows.push_back({told_x_[i], told_f_[i], told_outputs_[i]});
    return rows;
  }

  // One fit: an update of the previous model, unless `full` or the update cannot take the rows.
  // Returns whether it was a full fit.
  bool fit_model(const std::vector<TrainingRow>& rows, bool full) {
    if (!full && model_.update(rows)) return false;
    model_ = SurrogateModel(surrogate_, hooks_);
    model_.fit(rows);
    return true;
  }

  // A restored optimiser replays the recorded fits, so that it proposes what an uninterrupted one would.
  void replay_fits() {
    if (replayed_) return;
    for (const auto& [told, full] : fits_) fit_model(rows_until(static_cast<size_t>(told)), full);
    replayed_ = true;
  }

  // The model for the next proposal: a full refit when there is no model yet or the rows grew by
  // refit_growth since the last full one, else an update; recorded in the state. False: unusable.
  bool refresh_model(const std::vector<TrainingRow>& rows) {
    fits_.push_back({static_cast<long>(told_x_.size()), fit_model(rows, full_refit_due())});
    return model_.usable();
  }

  // Whether the next fit is a full one: no model yet, or the rows grew by refit_growth since the
  // last full fit.
  bool full_refit_due() const {
    long last_full = 0;
    for (const auto& [told, full] : fits_)
      if (full) last_full = told;
    const double rows_now = static_cast<double>(warm_.size() + told_x_.size());
    return !model_.usable() || rows_now >= surrogate_.refit_growth * static_cast<double>(warm_.size() + last_full);
  }

  // The model for the round after this one (if any), fitted on `rows` on another thread while this
  // round's `count` points are simulated (overlap_). Recorded in fits_ as requested, so that a replay, which takes
  // the same update-or-refit path, ends with the same model.
  void start_next_fit(const std::vector<TrainingRow>& rows, long count) {
    if (!overlap_ || options_.evaluation_budget() - evaluations_ - count <= 0) return;  // no round after this one
    const bool full = full_refit_due();
    fits_.push_back({static_cast<long>(told_x_.size()), full});
    next_model_.start([this, model = model_, rows, full]() mutable {
      if (full || !model.update(rows)) {
        model = SurrogateModel(surrogate_, hooks_);
        model.fit(rows);
      }
      return model;
    });
  }

  // The model this round proposes with: the one fitted while the last round ran (overlap_, or the
  // replayed last fit of a restored optimiser), else a fit now. The points told since its rows are
  // returned in `unseen`.
  bool model_for_round(const std::vector<TrainingRow>& rows, std::vector<Eigen::VectorXd>& unseen) {
    if (next_model_.pending()) {
      model_ = next_model_.take();
    } else if (!prefitted_) {
      refresh_model(rows);
    }
    prefitted_ = false;
    for (size_t i = static_cast<size_t>(fits_.back().first); i < told_x_.size(); ++i) unseen.push_back(told_x_[i]);
    return model_.usable();
  }

  // The model's score of every point, on `threads` threads (each score on its own: the same
  // values whatever the thread count).
  std::vector<double> score_all(const std::vector<Eigen::VectorXd>& points) const {
    std::vector<double> score(points.size());
    const size_t threads = std::min<size_t>(static_cast<size_t>(std::max(1, surrogate_.threads)), points.size());
    auto work = [&](size_t part) {
      for (size_t i = part; i < points.size(); i += threads) score[i] = model_.score(points[i]);
    };
    std::vector<std::thread> pool;
    for (size_t part = 1; part < threads; ++part) pool.emplace_back(work, part);
    work(0);
    for (auto& t : pool) t.join();
    return score;
  }

  // The batch's points: each the penalised acquisition's maximum over 2000 random points and 100
  // Gaussian steps around the 5 best rows, polished by NLopt BOBYQA from the best 3.
  void propose(long count) {
    replay_fits();
    const auto start = std::chrono::steady_clock::now();
    const int d = space_.dimension();
    std::mt19937_64 rng = seeded_rng(options_.seed, iteration_ + 1);
    Eigen::VectorXd random_point(d);
    for (int k = 0; k < d; ++k) random_point[k] = uniform01(rng);
    const auto rows = rows_until(told_x_.size());
    std::vector<Eigen::VectorXd> unseen;
    if (!model_for_round(rows, unseen)) {
      start_next_fit(rows, count);
      for (long i = 0; i < count; ++i) {
        if (i > 0)
          for (int k = 0; k < d; ++k) random_point[k] = uniform01(rng);
        pending_units_.push_back(random_point);
        pending_predictions_.push_back(nullptr);
      }
      return;
    }
    std::vector<Eigen::VectorXd> searched = {random_point};
    for (int c = 1; c < 2000; ++c) {
      Eigen::VectorXd u(d);
      for (int k = 0; k < d; ++k) u[k] = uniform01(rng);
      searched.push_back(u);
    }
    std::vector<size_t> order;
    for (size_t i = 0; i < rows.size(); ++i)
      if (std::isfinite(rows[i].fitness)) order.push_back(i);
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return rows[a].fitness < rows[b].fitness; });
    for (size_t r = 0; r < std::min<size_t>(5, order.size()); ++r)
      for (int c = 0; c < 20; ++c) {
        Eigen::VectorXd u = rows[order[r]].unit;
        for (int k = 0; k < d; ++k) u[k] += normal(rng, 0.05);
        searched.push_back(u.cwiseMax(0.0).cwiseMin(1.0));
      }
    const std::vector<double> score = score_all(searched);
    // Penalty radius: half the typical spacing of the finite rows, 0.5 n^(-1/d).
    const double radius = 0.5 * std::pow(std::max<double>(1.0, static_cast<double>(order.size())), -1.0 / d);
    // Points the model has not seen yet (told since its rows) are penalised like the round's own.
    std::vector<Eigen::VectorXd> picked = unseen;
    PenalisedScore acquisition{&model_, *std::min_element(score.begin(), score.end()), radius, &picked};
    std::vector<double> lower(static_cast<size_t>(d), 0.0), upper(static_cast<size_t>(d), 1.0), step(static_cast<size_t>(d), 0.05);
    for (long b = 0; b < count; ++b) {
      std::vector<std::pair<double, size_t>> ranked;
      for (size_t i = 0; i < searched.size(); ++i) ranked.push_back({acquisition.penalised(searched[i], score[i]), i});
      std::stable_sort(ranked.begin(), ranked.end(), [](const auto& x, const auto& y) { return x.first > y.first; });
      double best_value = ranked.front().first;
      Eigen::VectorXd best = searched[ranked.front().second];
      for (size_t s = 0; s < std::min<size_t>(3, ranked.size()); ++s) {
        const Eigen::VectorXd& from = searched[ranked[s].second];
        std::vector<double> x(from.data(), from.data() + d);
        nlopt_opt opt = nlopt_create(NLOPT_LN_BOBYQA, static_cast<unsigned>(d));
        nlopt_set_lower_bounds(opt, lower.data());
        nlopt_set_upper_bounds(opt, upper.data());
        nlopt_set_min_objective(opt, negative_penalised, &acquisition);
        nlopt_set_maxeval(opt, 60);
        nlopt_set_initial_step(opt, step.data());
        double value = 0;
        nlopt_optimize(opt, x.data(), &value);
        nlopt_destroy(opt);
        Eigen::VectorXd u = Eigen::Map<Eigen::VectorXd>(x.data(), d).cwiseMax(0.0).cwiseMin(1.0);
        const double v = acquisition(u);
        if (v > best_value) {
          best_value = v;
          best = u;
        }
      }
      picked.push_back(best);
      const Prediction p = model_.predict(best);
      const auto [lo, hi] = model_.interval(best, 0.9);
      pending_units_.push_back(best);
      pending_predictions_.push_back({{"fitness", p.fitness}, {"low90", lo}, {"high90", hi}});
    }
    adapt_batch(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    start_next_fit(rows, count);
  }

  // Cost-aware rounds, decided once, after the third proposal round (a full fit and two updates,
  // as later rounds mix them): when a round's mean model time exceeds cost_ratio x the wall time of
  // a round of simulations (one simulation per worker, hooks_.seconds_per_simulation), later
  // rounds propose up to kMaxBatchFactor x as many points; otherwise the model fits while the
  // simulations run (overlap_), and each round proposes with the model of the rows before the last
  // round, its points penalised as the round's own.
  void adapt_batch(double round_seconds) {
    if (!batch_reason_.empty() || !hooks_.seconds_per_simulation || !std::isfinite(surrogate_.cost_ratio)) return;
    model_seconds_ += round_seconds;
    if (++model_rounds_ < 3) return;
    const double model_seconds = model_seconds_ / model_rounds_;
    const double simulation = hooks_.seconds_per_simulation();
    if (!(simulation > 0)) return;
    const double ratio = model_seconds / (surrogate_.cost_ratio * simulation);
    const int factor = static_cast<int>(std::clamp(std::ceil(ratio), 1.0, static_cast<double>(kMaxBatchFactor)));
    overlap_ = factor == 1 || surrogate_.overlap == "always";
    batch_reason_ = (factor > 1 ? "batches of " + std::to_string(batch_ * factor)
                                : std::string("batches kept, the model fitted while the simulations run")) +
                    ": a proposal round took " + format_number(model_seconds, 3) + " s of model time, a simulation " +
                    format_number(simulation, 3) + " s";
    batch_ *= factor;
  }

  SurrogateOptions surrogate_;
  std::vector<TrainingRow> warm_;
  CurveHooks hooks_;
  Eigen::MatrixXd design_;
  int batch_ = 1;                   // points per round after the design
  std::string batch_reason_;        // the cost-aware decision, once made
  double model_seconds_ = 0;        // model time of the proposal rounds before the decision
  int model_rounds_ = 0;
  std::vector<Eigen::VectorXd> told_x_;
  std::vector<double> told_f_;
  std::vector<nlohmann::json> told_predictions_;    // the model's prediction when proposed (null: design)
  std::vector<Eigen::VectorXd> told_outputs_;       // the "mlp" kind's curves of told_x_, read once
  std::vector<Eigen::VectorXd> pending_units_;
  std::vector<nlohmann::json> pending_predictions_;
  std::vector<std::pair<long, bool>> fits_;         // per proposal round: told points fitted, full refit
  bool pending_ = false;
  bool overlap_ = false;    // the next round's model fits while this round's points are simulated
  bool prefitted_ = false;  // restored: the replayed last fit is the next round's model
  bool replayed_ = true;
  SurrogateModel model_;
  BackgroundFit next_model_;  // the overlapping fit; last, so destroyed (joined) first
};

}  // namespace

BayesSummary summarise_bayes_state(const nlohmann::json& state) {
  BayesSummary summary;
  std::vector<double> errors, observed;
  long covered = 0;
  try {
    const auto& predictions = state.at("told_predictions");
    const auto& told = state.at("told_f");
    for (size_t i = 0; i < predictions.size() && i < told.size(); ++i) {
      if (predictions[i].is_null()) continue;
      ++summary.predicted;
      if (told[i].is_null()) continue;  // a failed run: the classifier's business, not the fitness model's
      const double y = told[i].get<double>();
      errors.push_back(std::abs(predictions[i].at("fitness").get<double>() - y));
      observed.push_back(y);
      if (y >= predictions[i].at("low90").get<double>() && y <= predictions[i].at("high90").get<double>()) ++covered;
    }
    summary.batch = state.at("batch").get<int>();
    summary.batch_reason = state.at("batch_reason").get<std::string>();
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(std::string("bo state: ") + e.what());
  }
  if (observed.size() >= 2) {
    summary.prequential_error = detail::relative_error(errors, observed);
    summary.prequential_coverage90 = static_cast<double>(covered) / static_cast<double>(observed.size());
  }
  return summary;
}

std::unique_ptr<optimise::Optimiser> make_bayes_optimiser(const optimise::ParameterSpace& space,
                                                          const optimise::OptimiserOptions& options,
                                                          const SurrogateOptions& surrogate,
                                                          std::vector<TrainingRow> warm_rows, CurveHooks hooks) {
  space.Validate();
  if (options.population < 1) throw std::invalid_argument("bo: population must be >= 1");
  if (options.evaluation_budget() < 1) throw std::invalid_argument("bo: the evaluation budget must be >= 1");
  if (surrogate.kind == "mlp" && (!hooks.fitness || !hooks.outputs_at))
    throw std::invalid_argument("bo: the mlp surrogate needs the campaign's curves (fitness and outputs hooks)");
  return std::make_unique<BayesOptimiser>(space, options, surrogate, std::move(warm_rows), std::move(hooks));
}

}  // namespace demcal::surrogate
