// Recovery (issue 5, "Must show"): a synthetic measurement of the arch made by the engine with known
// parameters and known noise, at the campaign's own loading velocity (no hidden effect), is
// calibrated back (TBPSO 20 x 10 with objective 2, then a 30-simulation local polish): friction
// within 1 degree, kn and ks reported with their identifiability, and the misfit compared with the
// spread the noise alone gives the truth's misfit ("within the noise", not met yet: see below).
//
// The scene is the reference arch (13 voussoirs, same geometry, loading and velocity) with 5
// contact points per joint instead of 15, to keep the test short: the joints still open and slide
// at their ends, so hinging and sliding compete as in the reference scene; only the stiffness of a
// partly open joint is resolved more coarsely.
#include "demcal/dem/generators.hpp"
#include "demcal/pipelines/backend.hpp"
#include "demcal/pipelines/campaign.hpp"
#include "demcal/smoothing/objective.hpp"
#include "test_support.hpp"

#include "../test_random.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <vector>

namespace fs = std::filesystem;
using namespace demcal;
using namespace demcal::pipelines;
using nlohmann::json;
using test_support::Realisation;

namespace {

constexpr double kTrueKn = 3.2e9, kTrueKs = 2.1e9, kTrueFriction = 30.2;
constexpr double kForceNoise = 20, kDisplacementNoise = 2e-6;  // N, m (one standard deviation)
// The search: TBPSO 20 x 10, then a Sbplx polish from the swarm's best (docs/pipelines.md, "Recovery").
constexpr int kPolishEvaluations = 30;
constexpr double kPolishInitialStep = 0.05;  // unit-cube lengths

dem::ArchOptions coarse_arch() {
  dem::ArchOptions o;
  o.contacts_per_joint = 5;
  return o;
}

// Standard normal deviate from a 64-bit engine (Box-Muller on the top 53 bits: portable).
using demcal::test_random::normal;

// The truth's recording thinned to one row in 10 with Gaussian noise on every column (SI units);
// `noise_seed` picks the draw (2024: the measurement that is calibrated).
smoothing::Curve noisy_measurement(const smoothing::Curve& truth, std::uint64_t noise_seed = 2024) {
  std::mt19937_64 rng(noise_seed);
  smoothing::Curve m;
  m.source = "synthetic";
  for (const char* name : {"load_vertical", "abutment_horizontal", "force"}) m.columns.push_back({name, "", {}});
  const auto& v = truth.column("load_vertical").values;
  const auto& h = truth.column("abutment_horizontal").values;
  const auto& f = truth.column("force").values;
  for (size_t i = 0; i < truth.rows(); i += 10) {
    m.columns[0].values.push_back(v[i] + kDisplacementNoise * normal(rng));
    m.columns[1].values.push_back(h[i] + kDisplacementNoise * normal(rng));
    m.columns[2].values.push_back(f[i] + kForceNoise * normal(rng));
  }
  return m;
}

}  // namespace

class Recovery : public ::testing::TestWithParam<Realisation> {};

TEST_P(Recovery, SyntheticArchMeasurementIsCalibratedBack) {
  const fs::path dir = test_support::fresh_dir("recovery", GetParam().name());

  dem::Scene scene = dem::make_arch(coarse_arch());
  GetParam().apply(scene);
  const SimulationOutcome truth =
      simulate_with_parameters(scene, {{"kn", kTrueKn}, {"ks", kTrueKs}, {"friction_deg", kTrueFriction}});
  ASSERT_EQ(truth.status, "completed") << truth.message;
  const smoothing::Curve measured = noisy_measurement(truth.curves);
  smoothing::write_curve(measured, (dir / "measured.csv").string());

  const json campaign = {
      {"name", "recovery"},
      {"scene", {{"generator", "arch"}, {"options", {{"contacts_per_joint", 5}}}, {"solver", GetParam().solver()}}},
      {"measured", (dir / "measured.csv").string()},
      {"parameters", {{{"name", "kn"}, {"lower", 1e8}, {"upper", 1e10}, {"scale", "log10"}},
                      {{"name", "ks"}, {"lower", 1e8}, {"upper", 1e10}, {"scale", "log10"}},
                      {{"name", "friction_deg"}, {"lower", 25}, {"upper", 45}}}},
      {"objective", 2},
      {"optimiser", {{"algorithm", "tbpso"}, {"population", 10}, {"iterations", 20}, {"seed", 1}}},
      {"polish", {{"algorithm", "LN_SBPLX"}, {"max_evaluations", kPolishEvaluations}, {"initial_step", kPolishInitialStep}}},
      {"output", (dir / "out").string()},
      {"report", false}};
  const CampaignConfig config = campaign_from_json(campaign, dir.string(), "recovery.json");
  RunOptions options;
  options.progress = false;
  const CampaignResult result = run_campaign(config, options);
  ASSERT_EQ(result.status, CampaignStatus::completed) << result.message;

  // "Within the noise" (docs/pipelines.md, "Recovery"): the calibrated set fits the measurement
  // as well as the TRUE parameters fit measurements that differ from it only by their noise draw.
  // The truth's misfit over kNoiseDraws draws (draw 0 is the calibrated measurement) gives the
  // spread that noise alone causes; the calibrated misfit must not exceed its mean + 2 sd.
  constexpr int kNoiseDraws = 8;
  std::vector<double> truth_misfit;
  for (int k = 0; k < kNoiseDraws; ++k)
    truth_misfit.push_back(smoothing::Objective2(noisy_measurement(truth.curves, 2024 + k), config.objective_options,
                                                 config.smoother)
                               .evaluate(truth.curves)
                               .fitness);
  double mean = 0, sq = 0;
  for (double f : truth_misfit) mean += f / kNoiseDraws;
  for (double f : truth_misfit) sq += (f - mean) * (f - mean);
  const double sd = std::sqrt(sq / (kNoiseDraws - 1));
  const double at_truth = truth_misfit.front();
  const double within_noise = mean + 2 * sd;
  std::cout << "recovery: misfit of the truth over " << kNoiseDraws << " noise draws:";
  for (double f : truth_misfit) std::cout << " " << f;
  std::cout << "\n  mean " << mean << " sd " << sd << " -> within the noise: <= " << within_noise << "\n";
  // "Within the noise" is recorded, not asserted: the search meets it on some realisations of the
  // round-off and not on others (docs/pipelines.md, "Recovery"). Asserted: the polish ran and never
  // loses the swarm's best, and improves on it unless that already fits within the noise; the
  // misfit is within 1.5x the truth's, so that a search that leaves the basin of the truth fails.
  RecordProperty("within_noise", result.best.fitness <= within_noise ? "yes" : "no");
  EXPECT_GT(result.polish_evaluations, 0);
  EXPECT_LE(result.best.fitness, result.swarm_best_fitness);
  if (result.swarm_best_fitness > within_noise) {
    EXPECT_LT(result.best.fitness, result.swarm_best_fitness) << "within the noise: <= " << within_noise;
  }
  EXPECT_LE(result.best.fitness, 1.5 * at_truth) << "truth " << at_truth << ", within the noise: <= " << within_noise;
  EXPECT_NEAR(result.best.params.at("friction_deg"), kTrueFriction, 1.0);

  // Identifiability is reported for every free parameter, and the band holds the best set.
  const auto& id = result.identifiability;
  EXPECT_GE(id.sets_in_band, 1);
  for (const char* name : {"kn", "ks", "friction_deg"}) {
    ASSERT_TRUE(id.parameters.count(name)) << name;
    const auto& r = id.parameters.at(name);
    EXPECT_LE(r.min, r.best);
    EXPECT_GE(r.max, r.best);
    EXPECT_EQ(r.best, result.best.params.at(name));
  }
  std::ifstream in(dir / "out" / "result.json");
  const json written = json::parse(in);
  EXPECT_TRUE(written.contains("identifiability"));
  EXPECT_EQ(written["identifiability"]["parameters"]["kn"]["best"].get<double>(), result.best.params.at("kn"));
  EXPECT_EQ(written["polish"]["evaluations"].get<long>(), result.polish_evaluations);
  RecordProperty("best_fitness", std::to_string(result.best.fitness));
  RecordProperty("fitness_at_truth", std::to_string(at_truth));
  RecordProperty("within_noise_bound", std::to_string(within_noise));
  std::cout << "recovery: best " << written["best"].dump() << "\n  fitness at truth " << at_truth
            << "\n  identifiability " << written["identifiability"].dump() << "\n  polish " << written["polish"].dump()
            << "\n";
}

INSTANTIATE_TEST_SUITE_P(Synthetic, Recovery, ::testing::Values(test_support::realisation_from_environment()),
                         test_support::realisation_name);
