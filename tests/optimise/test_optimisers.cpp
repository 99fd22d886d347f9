// Every optimiser: convergence on Sphere 3-D, exact resume, determinism, failed evaluations, bad input.
#include <demcal/optimise/optimise.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

using namespace demcal::optimise;

namespace {

ParameterSpace space_of(const TestFunction& f) {
  ParameterSpace space;
  for (int k = 0; k < f.dimension; ++k) space.add(std::string("x").append(std::to_string(k)), f.lower[k], f.upper[k]);
  return space;
}

struct Case {
  std::string label;
  OptimiserOptions options;
};

OptimiserOptions with(std::string algorithm, long evaluations, std::uint64_t seed = 1) {
  OptimiserOptions o;
  o.algorithm = std::move(algorithm);
  o.max_evaluations = evaluations;
  o.seed = seed;
  return o;
}

std::vector<Case> all_algorithms(long evaluations) {
  std::vector<Case> cases = {{"pso", with("pso", evaluations)},
                             {"tbpso_toward", with("tbpso", evaluations)},
                             {"tbpso_paper", with("tbpso", evaluations)},
                             {"ga_paper", with("ga", evaluations)},
                             {"ga_gaussian_elitist", with("ga", evaluations)}};
  cases[1].options.trust_direction = "toward";
  cases[2].options.trust_direction = "paper";
  cases[4].options.ga_mutation = GaMutation::gaussian;
  cases[4].options.elitism = 1;
  for (const char* n : {"GN_DIRECT_L", "GN_CRS2_LM", "GN_ISRES", "GN_ESCH", "LN_BOBYQA", "LN_NELDERMEAD", "LN_SBPLX"})
    cases.push_back({std::string("nlopt_") + n, with(std::string("nlopt:") + n, evaluations)});
  return cases;
}

}  // namespace

// ---- Sphere 3-D within 2000 evaluations -------------------------------------------------------

// Every algorithm reaches < 1e-6 within 2000 evaluations in total. Those that cannot refine an
// optimum on their own (the paper's GA, ISRES, ESCH; TBPSO, erratic in long runs with either
// reading of Δx, see docs/optimise.md) get the polish: the last 200 of the 2000 evaluations go to
// LN_BOBYQA from the best point. The test checks that the main algorithm really spent its 1800.
struct SphereCase {
  std::string label;
  long polish_evaluations;
};

class SphereConvergence : public ::testing::TestWithParam<SphereCase> {};

TEST_P(SphereConvergence, ReachesOneInAMillionWithin2000Evaluations) {
  const auto& [label, polish_evaluations] = GetParam();
  const TestFunction sphere = make_test_function("sphere", 3);
  for (const auto& c : all_algorithms(2000)) {
    if (c.label != label) continue;
    for (std::uint64_t seed : {1, 2, 3}) {
      OptimiserOptions options = c.options;
      options.seed = seed;
      options.polish_evaluations = polish_evaluations;
      auto opt = make_optimiser(space_of(sphere), options);
      const auto summary = minimise(*opt, sphere.evaluate);
      EXPECT_LE(summary.evaluations, 2000) << label << " seed " << seed;
      EXPECT_LT(summary.best_value, 1e-6) << label << " seed " << seed;
      EXPECT_NE(summary.status, OptimiserStatus::failed) << summary.message;
      EXPECT_DOUBLE_EQ(sphere.evaluate(summary.best_x), summary.best_value);
      const auto report = opt->polish_report();
      ASSERT_EQ(report.has_value(), polish_evaluations > 0);
      if (report) {
        EXPECT_TRUE(report->polishing) << label;
        EXPECT_EQ(report->main_evaluations, 2000 - polish_evaluations) << label << " seed " << seed;
        EXPECT_EQ(report->main_evaluations + report->polish_evaluations, summary.evaluations);
        EXPECT_LE(summary.best_value, report->main_best_value);
      }
    }
    return;
  }
  FAIL() << "no case " << label;
}

INSTANTIATE_TEST_SUITE_P(
    Optimise, SphereConvergence,
    ::testing::Values(
        // On their own.
        SphereCase{"pso", 0}, SphereCase{"ga_gaussian_elitist", 0}, SphereCase{"nlopt_GN_DIRECT_L", 0},
        SphereCase{"nlopt_GN_CRS2_LM", 0}, SphereCase{"nlopt_LN_BOBYQA", 0}, SphereCase{"nlopt_LN_NELDERMEAD", 0},
        SphereCase{"nlopt_LN_SBPLX", 0},
        // With the polish (200 of the 2000 evaluations): every global algorithm.
        SphereCase{"pso", 200}, SphereCase{"tbpso_paper", 200}, SphereCase{"tbpso_toward", 200},
        SphereCase{"ga_paper", 200}, SphereCase{"ga_gaussian_elitist", 200}, SphereCase{"nlopt_GN_DIRECT_L", 200},
        SphereCase{"nlopt_GN_CRS2_LM", 200}, SphereCase{"nlopt_GN_ISRES", 200}, SphereCase{"nlopt_GN_ESCH", 200}),
    [](const auto& info) {
      return info.param.label + (info.param.polish_evaluations > 0 ? "_polished" : "");
    });

// Without the polish, the paper's GA, ISRES and ESCH stay far from 1e-6 at 2000 evaluations: the
// polish is what gets them there (this guards the statement in docs/optimise.md).
TEST(Optimiser, PaperGaIsresEschNeedThePolish) {
  const TestFunction sphere = make_test_function("sphere", 3);
  for (const auto& c : all_algorithms(2000)) {
    if (c.label != "ga_paper" && c.label != "nlopt_GN_ISRES" && c.label != "nlopt_GN_ESCH") continue;
    auto opt = make_optimiser(space_of(sphere), c.options);
    EXPECT_GT(minimise(*opt, sphere.evaluate).best_value, 1e-5) << c.label;
  }
}

// ---- exact resume -----------------------------------------------------------------------------

class Resume : public ::testing::TestWithParam<std::string> {};

namespace {

// Runs to the end; returns every asked batch, flattened.
std::vector<double> run_recording(Optimiser& opt, const TestFunction& f, int stop_after_rounds = -1) {
  std::vector<double> trace;
  int rounds = 0;
  while (!opt.done() && rounds != stop_after_rounds) {
    const auto batch = opt.ask();
    if (batch.empty()) break;
    std::vector<double> values;
    for (const auto& x : batch) {
      for (Eigen::Index k = 0; k < x.size(); ++k) trace.push_back(x[k]);
      // A failed evaluation now and then, to check its resume too.
      values.push_back(x[0] > 4.5 ? std::numeric_limits<double>::quiet_NaN() : f.evaluate(x));
    }
    opt.tell(values);
    ++rounds;
  }
  return trace;
}

}  // namespace

TEST_P(Resume, SaveRestoreContinueEqualsUninterruptedRun) {
  const TestFunction f = make_test_function("rastrigin", 3);
  for (const auto& c : all_algorithms(120)) {
    if (c.label != GetParam()) continue;
    for (bool pending : {false, true}) {
      auto uninterrupted = make_optimiser(space_of(f), c.options);
      const auto full = run_recording(*uninterrupted, f);

      auto first = make_optimiser(space_of(f), c.options);
      auto trace = run_recording(*first, f, 5);
      if (pending) first->ask();  // a batch asked but not told when the state is saved
      const std::string saved = first->save_state().dump();
      first.reset();

      auto resumed = make_optimiser(space_of(f), c.options);
      resumed->load_state(nlohmann::json::parse(saved));
      const auto rest = run_recording(*resumed, f);
      trace.insert(trace.end(), rest.begin(), rest.end());

      ASSERT_EQ(trace.size(), full.size()) << c.label << " pending=" << pending;
      for (std::size_t k = 0; k < full.size(); ++k) ASSERT_EQ(trace[k], full[k]) << c.label << " at " << k;
      EXPECT_EQ(resumed->best_value(), uninterrupted->best_value());
      EXPECT_EQ(resumed->evaluations(), uninterrupted->evaluations());
      EXPECT_EQ(resumed->best_x(), uninterrupted->best_x());
    }
    return;
  }
  FAIL() << "no case " << GetParam();
}

INSTANTIATE_TEST_SUITE_P(Optimise, Resume,
                         ::testing::Values("pso", "tbpso_toward", "tbpso_paper", "ga_paper", "ga_gaussian_elitist",
                                           "nlopt_GN_DIRECT_L", "nlopt_GN_CRS2_LM", "nlopt_GN_ISRES", "nlopt_GN_ESCH",
                                           "nlopt_LN_BOBYQA", "nlopt_LN_NELDERMEAD", "nlopt_LN_SBPLX"));

// Resume with the polish: saved in the main phase, right at the switch, and during the polish.
TEST(Optimiser, PolishedRunResumesExactlyInEveryPhase) {
  const TestFunction f = make_test_function("rastrigin", 3);
  for (const auto& c : all_algorithms(120)) {
    if (c.label != "pso" && c.label != "tbpso_paper" && c.label != "ga_paper" && c.label != "nlopt_GN_ESCH") continue;
    OptimiserOptions options = c.options;
    options.polish_evaluations = 60;
    const bool nlopt_main = c.label.rfind("nlopt_", 0) == 0;
    // PSO/TBPSO/GA: 6 rounds of 10 then polish points; ESCH: 60 rounds of 1 then polish points.
    const std::vector<int> stops = nlopt_main ? std::vector<int>{3, 60, 75} : std::vector<int>{3, 6, 20};
    auto uninterrupted = make_optimiser(space_of(f), options);
    const auto full = run_recording(*uninterrupted, f);
    ASSERT_TRUE(uninterrupted->polish_report()->polishing) << c.label;
    for (int stop : stops)
      for (bool pending : {false, true}) {
        auto first = make_optimiser(space_of(f), options);
        auto trace = run_recording(*first, f, stop);
        if (pending) first->ask();
        const std::string saved = first->save_state().dump();
        first.reset();
        auto resumed = make_optimiser(space_of(f), options);
        resumed->load_state(nlohmann::json::parse(saved));
        const auto rest = run_recording(*resumed, f);
        trace.insert(trace.end(), rest.begin(), rest.end());
        ASSERT_EQ(trace, full) << c.label << " stop " << stop << " pending " << pending;
        EXPECT_EQ(resumed->best_value(), uninterrupted->best_value());
        EXPECT_EQ(resumed->evaluations(), uninterrupted->evaluations());
        EXPECT_LE(resumed->evaluations(), 120);
        EXPECT_EQ(resumed->status(), uninterrupted->status());
      }
  }
}

TEST(Optimiser, PolishPhaseBehaviour) {
  const TestFunction f = make_test_function("sphere", 3);
  OptimiserOptions o = with("pso", 100);
  o.polish_evaluations = 40;
  auto opt = make_optimiser(space_of(f), o);
  EXPECT_EQ(opt->name(), "pso+polish:LN_BOBYQA");
  EXPECT_FALSE(opt->polish_report()->polishing);
  // Main phase: whole swarms, substitution allowed.
  for (int round = 0; round < 6; ++round) {
    const auto batch = opt->ask();
    ASSERT_EQ(batch.size(), 10u) << round;
    EXPECT_TRUE(opt->can_substitute());
    std::vector<double> values;
    for (const auto& x : batch) values.push_back(f.evaluate(x));
    opt->tell(values);
  }
  const auto report = opt->polish_report();
  EXPECT_TRUE(report->polishing);
  EXPECT_EQ(report->main_evaluations, 60);
  // Polish: single points, the first one is the main phase's best; no substitution.
  const auto first = opt->ask();
  ASSERT_EQ(first.size(), 1u);
  EXPECT_TRUE(first[0].isApprox(report->main_best_x, 1e-12));
  EXPECT_FALSE(opt->can_substitute());
  EXPECT_THROW(opt->substitute(0, f.optimum), std::logic_error);
  opt->tell({f.evaluate(first[0])});
  const auto summary = minimise(*opt, f.evaluate);
  EXPECT_EQ(summary.evaluations, 100);
  EXPECT_LT(summary.best_value, 1e-3 * report->main_best_value);
  EXPECT_TRUE(opt->ask().empty());
  EXPECT_THROW(opt->tell({1.0}), std::logic_error);
  EXPECT_FALSE(make_optimiser(space_of(f), with("pso", 100))->polish_report().has_value());
}

TEST(Optimiser, PolishStartsAtTheCentreWhenTheMainPhaseFoundNothing) {
  const TestFunction f = make_test_function("sphere", 2);
  OptimiserOptions o = with("ga", 50);
  o.polish_evaluations = 30;
  auto opt = make_optimiser(space_of(f), o);
  for (int round = 0; round < 2; ++round) {
    const auto batch = opt->ask();
    opt->tell(std::vector<double>(batch.size(), std::nan("")));
  }
  EXPECT_TRUE(std::isinf(opt->polish_report()->main_best_value));
  const auto first = opt->ask();
  ASSERT_EQ(first.size(), 1u);
  EXPECT_TRUE(first[0].isApprox(0.5 * (f.lower + f.upper), 1e-12));
  const auto summary = minimise(*opt, f.evaluate);
  EXPECT_EQ(summary.evaluations, 50);
  EXPECT_TRUE(std::isfinite(summary.best_value));
}

TEST(Optimiser, PolishIsSkippedWhenTheTargetIsReached) {
  const TestFunction f = make_test_function("sphere", 3);
  OptimiserOptions o = with("pso", 2000);
  o.polish_evaluations = 200;
  o.target_value = 1e-2;
  auto opt = make_optimiser(space_of(f), o);
  const auto summary = minimise(*opt, f.evaluate);
  EXPECT_EQ(summary.status, OptimiserStatus::target_reached);
  EXPECT_FALSE(opt->polish_report()->polishing);
  EXPECT_LT(summary.evaluations, 1800);
}

// ---- behaviour ----------------------------------------------------------------------------------

TEST(Optimiser, SameSeedSameRunOtherSeedOtherRun) {
  const TestFunction f = make_test_function("ackley", 3);
  for (const char* algorithm : {"pso", "tbpso", "ga", "nlopt:GN_CRS2_LM", "nlopt:GN_ISRES", "nlopt:GN_ESCH"}) {
    auto a = make_optimiser(space_of(f), with(algorithm, 100, 7));
    auto b = make_optimiser(space_of(f), with(algorithm, 100, 7));
    auto c = make_optimiser(space_of(f), with(algorithm, 100, 8));
    const auto ta = run_recording(*a, f), tb = run_recording(*b, f), tc = run_recording(*c, f);
    EXPECT_EQ(ta, tb) << algorithm;
    EXPECT_NE(ta, tc) << algorithm;
  }
}

TEST(Optimiser, BatchesAreThePopulationAndStayInBounds) {
  const TestFunction f = make_test_function("rastrigin", 4);
  for (const char* algorithm : {"pso", "tbpso", "ga"}) {
    OptimiserOptions o = with(algorithm, 95);
    o.population = 10;
    o.bounds = BoundHandling::reflect;
    auto opt = make_optimiser(space_of(f), o);
    std::vector<std::size_t> sizes;
    while (!opt->done()) {
      const auto batch = opt->ask();
      EXPECT_EQ(opt->ask().size(), batch.size()) << "ask() must be idempotent while pending";
      sizes.push_back(batch.size());
      std::vector<double> values;
      for (const auto& x : batch) {
        EXPECT_TRUE((x.array() >= f.lower.array()).all() && (x.array() <= f.upper.array()).all()) << algorithm;
        values.push_back(f.evaluate(x));
      }
      opt->tell(values);
    }
    ASSERT_EQ(sizes.size(), 10u) << algorithm;
    EXPECT_EQ(sizes.back(), 5u) << algorithm << ": the last batch is cut to the budget";
    EXPECT_EQ(opt->evaluations(), 95);
    EXPECT_EQ(opt->status(), OptimiserStatus::budget_exhausted);
    EXPECT_TRUE(opt->ask().empty());
  }
}

TEST(Optimiser, FailedEvaluationsAreWorstAndNeverBest) {
  const TestFunction f = make_test_function("sphere", 2);
  for (const auto& c : all_algorithms(60)) {
    auto opt = make_optimiser(space_of(f), c.options);
    bool first = true;
    while (!opt->done()) {
      const auto batch = opt->ask();
      std::vector<double> values;
      for (const auto& x : batch) {
        // The first batch fails entirely; afterwards points with x0 > 0 fail (NaN or inf).
        if (first || x[0] > 0.0)
          values.push_back(values.size() % 2 ? std::numeric_limits<double>::infinity() : std::nan(""));
        else
          values.push_back(f.evaluate(x));
      }
      if (first) {
        opt->tell(values);
        EXPECT_EQ(opt->best_value(), std::numeric_limits<double>::infinity()) << c.label;
        EXPECT_EQ(opt->best_x().size(), 0) << c.label;
        first = false;
        continue;
      }
      opt->tell(values);
    }
    EXPECT_TRUE(std::isfinite(opt->best_value())) << c.label;
    EXPECT_LE(opt->best_x()[0], 0.0) << c.label;
  }
}

TEST(Optimiser, SubstituteReplacesACandidate) {
  const TestFunction f = make_test_function("sphere", 3);
  for (const char* algorithm : {"pso", "tbpso", "ga"}) {
    auto opt = make_optimiser(space_of(f), with(algorithm, 100));
    ASSERT_TRUE(opt->can_substitute());
    auto batch = opt->ask();
    opt->substitute(2, f.optimum);
    batch = opt->ask();
    EXPECT_TRUE(batch[2].isApprox(f.optimum, 1e-12)) << algorithm;
    std::vector<double> values;
    for (const auto& x : batch) values.push_back(f.evaluate(x));
    opt->tell(values);
    EXPECT_LT(opt->best_value(), 1e-20) << algorithm;
    EXPECT_THROW(opt->substitute(0, f.optimum), std::logic_error) << "no batch pending";
    opt->ask();
    EXPECT_THROW(opt->substitute(0, f.upper * 2.0), std::invalid_argument);
    EXPECT_THROW(opt->substitute(99, f.optimum), std::invalid_argument);
  }
  auto nlopt = make_optimiser(space_of(f), with("nlopt:LN_BOBYQA", 10));
  nlopt->ask();
  EXPECT_FALSE(nlopt->can_substitute());
  EXPECT_THROW(nlopt->substitute(0, f.optimum), std::logic_error);
}

TEST(Optimiser, LogScaleCandidatesSpreadOverDecades) {
  ParameterSpace space;
  space.add("kn", 1e8, 1e10, ParameterSpec::Scale::log10);
  OptimiserOptions o = with("pso", 1000);
  o.population = 1000;
  auto opt = make_optimiser(space, o);
  int below_1e9 = 0;
  for (const auto& x : opt->ask()) below_1e9 += x[0] < 1e9;
  EXPECT_NEAR(below_1e9, 500, 60);  // half of the exponent range lies below 1e9
}

TEST(Optimiser, PolishImprovesASwarmBest) {
  const TestFunction f = make_test_function("rosenbrock", 3);
  auto swarm = make_optimiser(space_of(f), with("tbpso", 200));
  const auto coarse = minimise(*swarm, f.evaluate);
  PolishOptions polish;
  polish.max_evaluations = 300;
  auto polisher = make_polisher(space_of(f), coarse.best_x, polish);
  EXPECT_EQ(polisher->name(), "nlopt:LN_BOBYQA");
  const auto first = polisher->ask();
  ASSERT_EQ(first.size(), 1u);
  EXPECT_TRUE(first[0].isApprox(coarse.best_x, 1e-12)) << "the polish starts at the given point";
  polisher->tell({f.evaluate(first[0])});
  const auto fine = minimise(*polisher, f.evaluate);
  EXPECT_LT(fine.best_value, 1e-3 * coarse.best_value);
  EXPECT_LE(fine.evaluations, 300);
}

TEST(Optimiser, TargetValueStopsEarly) {
  const TestFunction f = make_test_function("sphere", 3);
  for (const char* algorithm : {"pso", "nlopt:LN_NELDERMEAD"}) {
    OptimiserOptions o = with(algorithm, 5000);
    o.target_value = 1e-2;
    auto opt = make_optimiser(space_of(f), o);
    const auto s = minimise(*opt, f.evaluate);
    EXPECT_EQ(s.status, OptimiserStatus::target_reached) << algorithm << " " << s.message;
    EXPECT_LE(s.best_value, 1e-2);
    EXPECT_LT(s.evaluations, 5000);
  }
}

// ---- bad input ------------------------------------------------------------------------------------

namespace {
template <class F>
void expect_invalid(F&& f, const std::string& fragment) {
  try {
    f();
    FAIL() << "no exception for " << fragment;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}
}  // namespace

TEST(Optimiser, BadOptionsAreNamed) {
  ParameterSpace space;
  space.add("kn", 1e8, 1e10, ParameterSpec::Scale::log10);
  auto make = [&](auto change) {
    OptimiserOptions o;
    change(o);
    make_optimiser(space, o);
  };
  expect_invalid([&] { make([](auto& o) { o.algorithm = "cmaes"; }); }, "'cmaes'");
  expect_invalid([&] { make([](auto& o) { o.algorithm = "nlopt:LN_FOO"; }); }, "'nlopt:LN_FOO'");
  expect_invalid([&] { make([](auto& o) { o.population = 1; }); }, "population = 1");
  expect_invalid([&] { make([](auto& o) { o.iterations = 0; }); }, "iterations = 0");
  expect_invalid([&] { make([](auto& o) { o.max_evaluations = -5; }); }, "max_evaluations = -5");
  expect_invalid([&] { make([](auto& o) { o.trust_direction = "away"; }); }, "'away'");
  expect_invalid([&] { make([](auto& o) { o.mutation_probability = 1.5; }); }, "mutation_probability = 1.5");
  expect_invalid([&] { make([](auto& o) { o.inertia_start = std::nan(""); }); }, "inertia_start = nan");
  expect_invalid([&] { make([](auto& o) { o.algorithm = "pso"; o.constriction = true; o.pso_cognitive = 1.0; }); }, "phi");
  expect_invalid([&] { make([](auto& o) { o.elitism = 10; }); }, "elitism = 10");
  expect_invalid([&] { make([](auto& o) { o.polish_evaluations = 200; }); }, "polish_evaluations = 200");
  expect_invalid([&] { make([](auto& o) { o.polish_evaluations = -1; }); }, "polish_evaluations = -1");
  expect_invalid([&] { make([](auto& o) { o.polish_evaluations = 50; o.polish_algorithm = "LN_FOO"; }); }, "'LN_FOO'");
  expect_invalid([&] { make([](auto& o) { o.polish_evaluations = 50; o.polish_initial_step = 0.0; }); },
                 "polish_initial_step = 0");
  expect_invalid([&] { make([](auto& o) { o.algorithm = "nlopt:LN_BOBYQA"; o.initial_point = {1e12}; }); }, "'kn'");
  expect_invalid([&] { make([](auto& o) { o.initial_point = {1e9, 2.0}; }); }, "initial_point");
  expect_invalid([&] { make([](auto& o) { o.further_starts = {{1e9}, {1e9, 2.0}}; }); }, "further_starts[1] has 2 values");
  expect_invalid([&] { make([](auto& o) { o.further_starts = {{std::nan("")}}; }); }, "further_starts[0][0] = nan");
  expect_invalid([&] { make_optimiser(ParameterSpace().add("kn", 2.0, 1.0), OptimiserOptions{}); }, "'kn'");
  expect_invalid([&] { make_polisher(space, Eigen::VectorXd::Constant(1, 1e9), PolishOptions{"GN_FOO"}); }, "GN_FOO");
}

TEST(Optimiser, MisuseOfAskTellAndStateIsRejected) {
  ParameterSpace space;
  space.add("a", 0.0, 1.0).add("b", 0.0, 1.0);
  auto pso = make_optimiser(space, with("pso", 100));
  EXPECT_THROW(pso->tell({1.0}), std::logic_error);
  pso->ask();
  expect_invalid([&] { pso->tell({1.0, 2.0}); }, "2 values for 10 candidates");
  auto ga = make_optimiser(space, with("ga", 100));
  expect_invalid([&] { ga->load_state(pso->save_state()); }, "'pso', not 'ga'");
  ParameterSpace other;
  other.add("a", 0.0, 1.0);
  auto pso1 = make_optimiser(other, with("pso", 100));
  expect_invalid([&] { pso1->load_state(pso->save_state()); }, "dimension 2");
  auto state = pso->save_state();
  state.erase("v");
  auto pso2 = make_optimiser(space, with("pso", 100));
  expect_invalid([&] { pso2->load_state(state); }, "'v'");
  OptimiserOptions polished = with("pso", 100);
  polished.polish_evaluations = 20;
  expect_invalid([&] { make_optimiser(space, polished)->load_state(pso->save_state()); }, "'pso', not 'pso+polish");
  auto bobyqa = make_optimiser(space, with("nlopt:LN_BOBYQA", 100));
  EXPECT_THROW(bobyqa->tell({1.0}), std::logic_error);
}

// Pre-screening support: alternatives are redraws of the optimiser's own proposal that leave its
// stream untouched, and a withdrawn candidate is never told a value nor counted.
TEST(Optimiser, AlternativesAndWithdrawalForPrescreening) {
  const TestFunction f = make_test_function("sphere", 3);
  for (const char* algorithm : {"pso", "tbpso", "ga"}) {
    auto plain = make_optimiser(space_of(f), with(algorithm, 60));
    auto screened = make_optimiser(space_of(f), with(algorithm, 60));
    for (int round = 0; round < 3; ++round) {
      const auto a = plain->ask();
      const auto b = screened->ask();
      ASSERT_EQ(a.size(), b.size());
      for (size_t i = 0; i < a.size(); ++i) EXPECT_TRUE(a[i] == b[i]) << algorithm << " alternatives moved the stream";
      const auto alt = screened->alternatives(1, 4);
      ASSERT_EQ(alt.size(), 4u);
      EXPECT_TRUE(alt == screened->alternatives(1, 4)) << algorithm << ": alternatives are deterministic";
      EXPECT_FALSE(alt[0] == alt[1]) << algorithm;
      for (const auto& x : alt)
        for (Eigen::Index k = 0; k < x.size(); ++k) EXPECT_TRUE(x[k] >= f.lower[k] && x[k] <= f.upper[k]);
      std::vector<double> values;
      for (const auto& x : a) values.push_back(f.evaluate(x));
      plain->tell(values);
      screened->tell(values);
    }
    // Withdrawing candidate 0: a finite value for it is refused, NaN is accepted and not counted.
    const auto batch = screened->ask();
    screened->withdraw(0);
    std::vector<double> values;
    for (const auto& x : batch) values.push_back(f.evaluate(x));
    const long before = screened->evaluations();
    EXPECT_THROW(screened->tell(values), std::invalid_argument) << algorithm;
    values[0] = std::numeric_limits<double>::quiet_NaN();
    screened->tell(values);
    EXPECT_EQ(screened->evaluations(), before + static_cast<long>(batch.size()) - 1) << algorithm;
    EXPECT_THROW(screened->withdraw(0), std::logic_error) << "no batch pending";
  }
  auto nlopt = make_optimiser(space_of(f), with("nlopt:LN_BOBYQA", 10));
  nlopt->ask();
  EXPECT_THROW(nlopt->alternatives(0, 2), std::logic_error);
  EXPECT_THROW(nlopt->withdraw(0), std::logic_error);
}
