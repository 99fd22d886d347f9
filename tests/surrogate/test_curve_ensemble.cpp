// The "mlp" kind: an ensemble of MLPs (trained by the native loops, or with LibTorch in the plugin)
// that predicts curves, scored by its owner's fitness of a curve, on synthetic problems with a known
// answer.
#include "demcal/surrogate/curve_ensemble.hpp"
#include "demcal/surrogate/surrogate.hpp"

#include "../test_random.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

using namespace demcal::surrogate;

namespace {

using demcal::test_random::uniform;

// A family of softening force-displacement curves on 16 points: stiffness a, strength b.
constexpr int kPoints = 16;
Eigen::VectorXd curve(const Eigen::VectorXd& unit) {
  const double stiffness = 1 + 4 * unit[0], strength = 1 + unit[1];
  Eigen::VectorXd f(kPoints);
  for (int k = 0; k < kPoints; ++k) {
    const double w = static_cast<double>(k) / (kPoints - 1);
    f[k] = strength * std::tanh(stiffness * w / strength);
  }
  return f;
}

// The "measurement": the curve at (0.3, 0.6).
const Eigen::VectorXd kMeasured = curve((Eigen::VectorXd(2) << 0.3, 0.6).finished());
double fitness_of(const Eigen::VectorXd& outputs) { return (outputs - kMeasured).norm(); }

std::vector<TrainingRow> rows_of(int n, std::uint64_t seed, double extent = 1.0) {
  std::mt19937_64 rng(seed);
  std::vector<TrainingRow> rows;
  for (int i = 0; i < n; ++i) {
    Eigen::VectorXd u(2);
    u << extent * uniform(rng), extent * uniform(rng);
    const Eigen::VectorXd c = curve(u);
    rows.push_back({u, fitness_of(c), c});
  }
  return rows;
}

SurrogateOptions mlp_options() {
  SurrogateOptions o;
  o.kind = "mlp";
  o.gp.log_transform = LogTransform::never;
  return o;
}

}  // namespace

TEST(CurveEnsemble, ReproducesAKnownFamilyOfCurvesDeterministically) {
  const auto train = rows_of(60, 1), test = rows_of(40, 2);
  Eigen::MatrixXd X(60, 2), Y(60, kPoints);
  for (int i = 0; i < 60; ++i) {
    X.row(i) = train[static_cast<size_t>(i)].unit.transpose();
    Y.row(i) = train[static_cast<size_t>(i)].outputs.transpose();
  }
  CurveEnsemble a, b;
  ASSERT_TRUE(a.fit(X, Y, MlpOptions{}));
  ASSERT_TRUE(b.fit(X, Y, MlpOptions{}));
  EXPECT_EQ(a.members(), 5);
  EXPECT_EQ(a.outputs(), kPoints);
  double squares = 0;
  for (const auto& r : test) {
    Eigen::VectorXd mean = Eigen::VectorXd::Zero(kPoints);
    for (int m = 0; m < a.members(); ++m) {
      const Eigen::VectorXd p = a.predict(m, r.unit);
      EXPECT_EQ((p - b.predict(m, r.unit)).norm(), 0.0) << "the same rows and options give the same model";
      mean += p / a.members();
    }
    squares += (mean - r.outputs).squaredNorm() / kPoints;
  }
  // The forces span 0..2: an RMS error of 1 % of that on held-out points.
  EXPECT_LT(std::sqrt(squares / static_cast<double>(test.size())), 0.02);
  // A model file predicts what the model does.
  const CurveEnsemble c = CurveEnsemble::from_json(a.to_json(), "test");
  EXPECT_LT((c.predict(2, test[0].unit) - a.predict(2, test[0].unit)).norm(), 1e-12);
}

namespace {

void to_matrices(const std::vector<TrainingRow>& rows, Eigen::MatrixXd& X, Eigen::MatrixXd& Y) {
  X.resize(static_cast<Eigen::Index>(rows.size()), 2);
  Y.resize(static_cast<Eigen::Index>(rows.size()), kPoints);
  for (size_t i = 0; i < rows.size(); ++i) {
    X.row(static_cast<Eigen::Index>(i)) = rows[i].unit.transpose();
    Y.row(static_cast<Eigen::Index>(i)) = rows[i].outputs.transpose();
  }
}

double held_out_rms(const CurveEnsemble& e, const std::vector<TrainingRow>& test) {
  double squares = 0;
  for (const auto& r : test) {
    Eigen::VectorXd mean = Eigen::VectorXd::Zero(kPoints);
    for (int m = 0; m < e.members(); ++m) mean += e.predict(m, r.unit) / e.members();
    squares += (mean - r.outputs).squaredNorm() / kPoints;
  }
  return std::sqrt(squares / static_cast<double>(test.size()));
}

}  // namespace

// refine(): a model trained on 30 rows continues on 60 in a sixth of a full fit's steps and
// predicts held-out curves as well as a fresh fit on the 60 (within 50 %), better than before.
TEST(CurveEnsemble, RefineOnMoreRowsMatchesAFreshFit) {
  const auto rows = rows_of(60, 1), test = rows_of(40, 2);
  Eigen::MatrixXd X30, Y30, X60, Y60;
  to_matrices(std::vector<TrainingRow>(rows.begin(), rows.begin() + 30), X30, Y30);
  to_matrices(rows, X60, Y60);
  const MlpOptions o;
  ASSERT_LE(6 * o.refit_epochs, o.epochs);
  CurveEnsemble refined, fresh;
  EXPECT_FALSE(refined.refine(X60, Y60, o)) << "nothing to continue from";
  ASSERT_TRUE(refined.fit(X30, Y30, o));
  const double before = held_out_rms(refined, test);
  ASSERT_TRUE(refined.refine(X60, Y60, o));
  ASSERT_TRUE(fresh.fit(X60, Y60, o));
  const double after = held_out_rms(refined, test), full = held_out_rms(fresh, test);
  EXPECT_LT(after, before);
  EXPECT_LT(after, 1.5 * full) << "fresh fit " << full;
  MlpOptions other = o;
  other.members = 3;
  EXPECT_FALSE(refined.refine(X60, Y60, other)) << "another ensemble's shape";
}

// The two training backends train the same networks: after a few steps (before the training's own
// sensitivity amplifies round-off) their members agree to float round-off; after a full fit both
// predict held-out curves well. The native one gives the same members on any thread count.
TEST(CurveEnsemble, NativeAndLibtorchBackendsTrainTheSameNetworks) {
  const auto rows = rows_of(60, 1), test = rows_of(40, 2);
  Eigen::MatrixXd X, Y;
  to_matrices(rows, X, Y);
  MlpOptions few;
  few.epochs = 20;
  MlpOptions torch = few;
  torch.backend = demcal::smoothing::RegressionBackend::libtorch;
  CurveEnsemble native, libtorch;
  ASSERT_TRUE(native.fit(X, Y, few));
  ASSERT_TRUE(libtorch.fit(X, Y, torch));
  for (const auto& r : test)
    for (int m = 0; m < native.members(); ++m) {
      const Eigen::VectorXd a = native.predict(m, r.unit), b = libtorch.predict(m, r.unit);
      EXPECT_LT((a - b).cwiseAbs().maxCoeff(), 1e-4 * (1 + b.cwiseAbs().maxCoeff())) << "member " << m;
    }
  MlpOptions threads = few;
  threads.threads = 3;
  CurveEnsemble side_by_side;
  ASSERT_TRUE(side_by_side.fit(X, Y, threads));
  for (int m = 0; m < native.members(); ++m)
    EXPECT_EQ((side_by_side.predict(m, test[0].unit) - native.predict(m, test[0].unit)).norm(), 0.0) << "member " << m;
  MlpOptions full;
  torch = full;
  torch.backend = demcal::smoothing::RegressionBackend::libtorch;
  ASSERT_TRUE(native.fit(X, Y, full));
  ASSERT_TRUE(libtorch.fit(X, Y, torch));
  const double native_rms = held_out_rms(native, test), libtorch_rms = held_out_rms(libtorch, test);
  EXPECT_LT(native_rms, 0.02);
  EXPECT_LT(libtorch_rms, 0.02);
  // the backend is part of the options' JSON (a campaign's key), the thread count is not
  EXPECT_EQ(torch.to_json().at("backend"), "libtorch");
  EXPECT_FALSE(threads.to_json().contains("threads"));
  EXPECT_EQ(MlpOptions::from_json(torch.to_json(), "test").backend, torch.backend);
  nlohmann::json bad = full.to_json();
  bad["backend"] = "cuda";
  try {
    MlpOptions::from_json(bad, "campaign.json: surrogate.mlp");
    ADD_FAILURE() << "an unknown backend was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("cuda"), std::string::npos) << e.what();
  }
}

TEST(SurrogateModel, MlpKindScoresPredictedCurvesWithItsOwnersFitness) {
  SurrogateModel unhooked(mlp_options());
  EXPECT_THROW(unhooked.fit(rows_of(30, 3)), std::invalid_argument) << "an mlp model needs the fitness of a curve";

  CurveHooks hooks;
  hooks.fitness = fitness_of;
  SurrogateModel model(mlp_options(), hooks);
  ASSERT_TRUE(model.fit(rows_of(60, 3)));
  EXPECT_FALSE(model.log_transformed());
  EXPECT_EQ(model.dimension(), 2);
  // The predicted fitness follows the true one, and is smallest near the measurement's parameters.
  const auto test = rows_of(40, 4);
  double error = 0, spread = 0, mean = 0;
  for (const auto& r : test) mean += r.fitness / static_cast<double>(test.size());
  for (const auto& r : test) {
    error += std::abs(model.predict(r.unit).fitness - r.fitness);
    spread += std::abs(r.fitness - mean);
  }
  EXPECT_LT(error / spread, 0.05) << "relative error (1 = no better than the mean)";
  const Eigen::VectorXd truth = (Eigen::VectorXd(2) << 0.3, 0.6).finished();
  const Eigen::VectorXd far = (Eigen::VectorXd(2) << 0.9, 0.1).finished();
  EXPECT_LT(model.predict(truth).fitness, 0.2 * model.predict(far).fitness);
  EXPECT_GT(model.score(truth), model.score(far)) << "expected improvement prefers the basin";

  // The members disagree more where there are no data: trained on [0, 0.5]², asked at (0.95, 0.95).
  SurrogateModel corner(mlp_options(), hooks);
  ASSERT_TRUE(corner.fit(rows_of(40, 5, 0.5)));
  double inside = 0;
  const auto near_rows = rows_of(20, 6, 0.5);
  for (const auto& r : near_rows) inside += corner.predict(r.unit).sd / static_cast<double>(near_rows.size());
  EXPECT_GT(corner.predict((Eigen::VectorXd(2) << 0.95, 0.95).finished()).sd, 4 * inside);

  // A model file, given its hooks again, predicts what the model does.
  SurrogateModel loaded = SurrogateModel::from_json(model.to_json(), "test");
  loaded.set_hooks(hooks);
  EXPECT_DOUBLE_EQ(loaded.predict(truth).fitness, model.predict(truth).fitness);
  EXPECT_DOUBLE_EQ(loaded.score(far), model.score(far));
}

TEST(CrossValidation, MlpKindReportsErrorAndCoverage) {
  CurveHooks hooks;
  hooks.fitness = fitness_of;
  auto rows = rows_of(50, 7);
  rows.push_back({(Eigen::VectorXd(2) << 0.5, 0.5).finished(), NAN, Eigen::VectorXd()});  // a failed run
  const auto cv = cross_validate(rows, mlp_options(), 5, hooks);
  EXPECT_EQ(cv.finite_rows, 50);
  EXPECT_EQ(cv.failed_rows, 1);
  EXPECT_LT(cv.relative_error, 0.1);
  EXPECT_GE(cv.coverage90, 0.75);
}

namespace {

// The curve family's two parameters, a and b, each on [0, 1].
demcal::optimise::ParameterSpace unit_square() {
  demcal::optimise::ParameterSpace space;
  space.add("a", 0, 1);
  space.add("b", 0, 1);
  return space;
}

demcal::optimise::OptimiserOptions bayes_options(long simulations, std::uint64_t seed) {
  demcal::optimise::OptimiserOptions o;
  o.population = 8;
  o.max_evaluations = simulations;
  o.seed = seed;
  return o;
}

// Rounds of `batch` points, with shorter full fits.
SurrogateOptions batched_mlp(int batch) {
  SurrogateOptions s = mlp_options();
  s.batch = batch;
  s.mlp.epochs = 600;
  return s;
}

// One round: the optimiser's points simulated on the curve family and told.
void simulate_round(demcal::optimise::Optimiser& opt, const demcal::optimise::ParameterSpace& space) {
  std::vector<double> values;
  for (const auto& x : opt.ask()) values.push_back(fitness_of(curve(space.to_unit(x))));
  opt.tell(values);
}

// The curve family's hooks: the fitness of predicted curves, and a told point's curves.
CurveHooks curve_hooks() {
  CurveHooks hooks;
  hooks.fitness = fitness_of;
  hooks.outputs_at = [](const Eigen::VectorXd& unit) { return curve(unit); };
  return hooks;
}

// A "bo" run on the curve family (unit square, 26 simulations), the best after each round; at round
// `stop_after` its state is saved, checked by `check_saved`, and a fresh optimiser continues from
// it. `check_batch` sees each round's points (rounds from 1) with the evaluations before them; the
// finished state goes into `last`, if given.
std::vector<double> resumed_rounds(const SurrogateOptions& s, const CurveHooks& hooks, int stop_after,
                                   const std::function<void(const nlohmann::json&)>& check_saved,
                                   const std::function<void(int, const std::vector<Eigen::VectorXd>&, long)>& check_batch = {},
                                   nlohmann::json* last = nullptr) {
  const auto space = unit_square();
  const auto o = bayes_options(26, 4);
  auto opt = make_bayes_optimiser(space, o, s, {}, hooks);
  std::vector<double> history;
  int round = 0;
  while (!opt->done()) {
    if (round++ == stop_after) {
      const nlohmann::json state = nlohmann::json::parse(opt->save_state().dump());
      check_saved(state);
      opt = make_bayes_optimiser(space, o, s, {}, hooks);
      opt->load_state(state);
    }
    const auto batch = opt->ask();
    if (check_batch) check_batch(round, batch, opt->evaluations());
    std::vector<double> values;
    for (const auto& x : batch) values.push_back(fitness_of(curve(space.to_unit(x))));
    opt->tell(values);
    history.push_back(opt->best_value());
  }
  if (last) *last = opt->save_state();
  return history;
}

// Overlapping rounds: the state is saved with the overlap decided and the next round's fit in
// flight; the finished state's summary into `summary`, if given.
std::vector<double> overlapping_rounds(const SurrogateOptions& s, const CurveHooks& hooks, int stop_after,
                                       BayesSummary* summary = nullptr) {
  nlohmann::json last;
  const auto history = resumed_rounds(
      s, hooks, stop_after,
      [](const nlohmann::json& state) {
        EXPECT_TRUE(state.at("overlap").get<bool>()) << "saved after the decision";
        EXPECT_TRUE(state.at("prefitted").get<bool>()) << "saved with the next round's fit started";
      },
      {}, &last);
  if (summary) *summary = summarise_bayes_state(last);
  return history;
}

}  // namespace

// "bo" with the mlp kind: the optimiser is told fitness values only and finds each told point's
// curves through CurveHooks::outputs_at; it reaches the measurement's basin and resumes exactly.
TEST(BayesOptimiser, MlpKindFindsTheBasinAndResumesExactly) {
  const auto space = unit_square();
  const auto o = bayes_options(20, 3);
  CurveHooks hooks;
  hooks.fitness = fitness_of;
  EXPECT_THROW(make_bayes_optimiser(space, o, mlp_options(), {}, hooks), std::invalid_argument)
      << "without outputs_at, bo cannot train on curves";
  hooks.outputs_at = [](const Eigen::VectorXd& unit) { return curve(unit); };
  auto run = [&](int stop_after) {
    auto opt = make_bayes_optimiser(space, o, mlp_options(), {}, hooks);
    std::vector<double> history;
    int round = 0;
    while (!opt->done()) {
      if (round++ == stop_after) {
        const nlohmann::json state = nlohmann::json::parse(opt->save_state().dump());
        opt = make_bayes_optimiser(space, o, mlp_options(), {}, hooks);
        opt->load_state(state);
      }
      simulate_round(*opt, space);
      history.push_back(opt->best_value());
    }
    EXPECT_EQ(opt->evaluations(), 20);
    return history;
  };
  const auto straight = run(-1);
  // The 12 model-driven points after the design improve its best by more than an order of magnitude.
  EXPECT_LT(straight.back(), straight.front() / 20) << "design best " << straight.front();
  EXPECT_EQ(run(4), straight);
}

// "bo" in rounds of 3 (one point per worker of a 3-worker backend): the points of a round are
// distinct, the model is updated between full refits, and a resumed run (state saved after
// updates) replays the refits and ends with the uninterrupted run's history.
TEST(BayesOptimiser, ProposesDistinctBatchesAndResumesAfterUpdatesExactly) {
  const SurrogateOptions s = batched_mlp(3);
  const auto check_saved = [](const nlohmann::json& state) {
    EXPECT_GE(state.at("fits").size(), 3u) << "saved after a full fit and updates";
  };
  const auto check_batch = [](int round, const std::vector<Eigen::VectorXd>& batch, long evaluations) {
    if (round <= 1) return;
    EXPECT_EQ(batch.size(), std::min<size_t>(3, static_cast<size_t>(26 - evaluations)));
    for (size_t i = 0; i < batch.size(); ++i)
      for (size_t j = 0; j < i; ++j) EXPECT_GT((batch[i] - batch[j]).norm(), 1e-3) << "round " << round;
  };
  auto run = [&](int stop_after) {
    nlohmann::json state;
    const auto history = resumed_rounds(s, curve_hooks(), stop_after, check_saved, check_batch, &state);
    long full = 0, updates = 0;
    for (const auto& fit : state.at("fits")) (fit.at(1).get<bool>() ? full : updates) += 1;
    EXPECT_GE(full, 1);
    EXPECT_GE(updates, 2);
    EXPECT_EQ(state.at("told_predictions").size(), 26u);
    return history;
  };
  const auto straight = run(-1);
  EXPECT_LT(straight.back(), straight.front() / 10) << "design best " << straight.front();
  EXPECT_EQ(run(4), straight);
}

// Simulations slower than the model (an external code): after the third round the cost rule keeps
// the batch and fits each round's model while the round before is simulated. The rounds then
// propose with a model one round old, which still reaches the basin; the history differs from the
// rounds that wait for their model, and a run resumed after overlapping rounds (a fit in flight
// when the state was saved) ends with the uninterrupted history.
TEST(BayesOptimiser, SlowSimulationsOverlapTheFitsAndResumeExactly) {
  const SurrogateOptions s = batched_mlp(2);
  const CurveHooks hooks = curve_hooks();
  CurveHooks slow = hooks;
  slow.seconds_per_simulation = [] { return 1000.0; };
  BayesSummary summary;
  const auto overlapped = overlapping_rounds(s, slow, -1, &summary);
  EXPECT_NE(summary.batch_reason.find("batches kept, the model fitted while the simulations run"), std::string::npos)
      << summary.batch_reason;
  EXPECT_LT(overlapped.back(), overlapped.front() / 10) << "design best " << overlapped.front();
  EXPECT_NE(overlapping_rounds(s, hooks, -1), overlapped) << "the rounds waiting for their model propose otherwise";
  EXPECT_EQ(overlapping_rounds(s, slow, 6), overlapped);
}

// overlap "always" (the diagnosis's searches): no clock is read, every round after the first
// model proposes with the model fitted while the round before ran, from the first model on; the
// same history on every run, resumed or not, and it still reaches the basin.
TEST(BayesOptimiser, AlwaysOverlappingRoundsNeedNoClockAndResumeExactly) {
  SurrogateOptions s = batched_mlp(2);
  s.cost_ratio = HUGE_VAL;
  s.overlap = "always";
  const CurveHooks hooks = curve_hooks();  // no seconds_per_simulation
  BayesSummary summary;
  const auto overlapped = overlapping_rounds(s, hooks, -1, &summary);
  EXPECT_EQ(summary.batch, 2) << "the batch never grows";
  EXPECT_LT(overlapped.back(), overlapped.front() / 10) << "design best " << overlapped.front();
  EXPECT_EQ(overlapping_rounds(s, hooks, -1), overlapped);
  EXPECT_EQ(overlapping_rounds(s, hooks, 3), overlapped) << "resumed after the first overlapping round";
  s.overlap = "auto";
  EXPECT_NE(overlapping_rounds(s, hooks, -1), overlapped) << "without a clock, auto rounds wait for their model";
}
