// The diagnosis on records that another DEM code made (data/refdem-arch/, its README): another
// contact discretisation, damping and effect laws than the engine that calibrates them, as measured
// data are. The control and a friction softening below the noise need no effect; a compliant
// right abutment is named there, with its stiffness and its bounds, every stage of the loop checked
// on the way. Shortened searches (two candidates, no further search) keep each within three
// minutes; the full table over every record is a benchmark
// (scripts/refdem_table.py, docs/diagnose.md). Each runs on the round-off realisation
// DEMCAL_TEST_REALISATION names, the softening on the one after it.
#include "demcal/pipelines/diagnose.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

using namespace demcal;
using namespace demcal::pipelines;
using nlohmann::json;
namespace fs = std::filesystem;
using test_support::Realisation;

namespace {

const fs::path kRecords = fs::path(DEMCAL_SOURCE_DIR) / "data" / "refdem-arch";

// A-campaign.json on `record` on the given round-off realisation.
CampaignConfig record_campaign(const std::string& record, const fs::path& dir, const Realisation& realisation) {
  json j = test_support::read_json(kRecords / "A-campaign.json");
  j["measured"]["file"] = (kRecords / (record + ".csv")).string();
  j["output"] = (dir / "base-campaign").string();
  j["scene"]["solver"] = realisation.solver();
  return campaign_from_json(j, kRecords.string(), record);
}

// Shortened options: two candidates of 30 runs, no further search, one effect; the bounds' check
// with re-fits of at most 4 runs where `bounds`, and report.md where `report`.
DiagnoseOptions shortened(const fs::path& dir, const std::vector<std::string>& effects, bool bounds, bool report) {
  DiagnoseOptions o;
  o.out = (dir / "out").string();
  o.effects = effects;
  o.candidates = 2;
  o.candidate_simulations = 30;
  o.continued_simulations = 0;
  o.parameter_bounds = bounds;
  o.profile_simulations = 4;
  o.max_effects = 1;
  o.progress = false;
  o.report = report;
  return o;
}

// What a record that needs no effect gets: "no effect needed" with the numbers, whatever effects
// are on offer. Either the base fit is within the noise, or candidates are calibrated and the base
// model alone, re-fitted from the closest of their fits, does as well (the removal check of an
// undecided verdict): on some realisations the base calibration stops above the noise, and the
// candidates' searches, re-fitting the base parameters too, find what it missed.
void expect_no_effect_needed(const std::string& record, const Realisation& realisation,
                             long candidate_simulations = DiagnoseOptions{}.candidate_simulations) {
  const fs::path dir = test_support::fresh_dir("diagnose", "refdem-" + record + "-" + realisation.name());
  DiagnoseOptions options = shortened(dir, {}, false, false);
  options.candidate_simulations = candidate_simulations;
  const Diagnosis d = run_diagnosis(record_campaign(record, dir, realisation), options);
  EXPECT_EQ(d.outcome, DiagnosisOutcome::no_effect_needed) << d.verdict;
  EXPECT_TRUE(d.chosen.empty()) << d.verdict;
  EXPECT_NE(d.headline.find("No effect needed: "), std::string::npos) << d.headline;
  const double noise = d.noise.begin()->second;
  if (d.removal_checks.empty()) {
    EXPECT_EQ(d.error_after, d.error_before);
    for (const auto& c : d.candidates) EXPECT_NE(c.verdict, CandidateVerdict::accepted) << c.effect;
  } else {
    ASSERT_EQ(d.removal_checks.size(), 1u);
    const Diagnosis::RemovalCheck& check = d.removal_checks.front();
    EXPECT_TRUE(check.dropped) << check.effect;
    // no longer needed: its removal costs no evidence, or the base alone re-fitted is explained
    EXPECT_TRUE(check.criterion > -DiagnoseOptions{}.evidence || check.error_without <= check.explained_level)
        << check.criterion << ", " << check.error_without << " N against " << check.explained_level << " N";
    EXPECT_EQ(d.error_after, check.error_without);
    EXPECT_TRUE(fs::exists(fs::path(check.folder) / "result.json")) << check.folder;
    EXPECT_NE(d.headline.find("re-fitted from the " + check.effect + " fit"), std::string::npos) << d.headline;
    EXPECT_EQ(d.frequency.verdict, d.frequency.none);  // the share of the resamples choosing no effect
  }
  EXPECT_EQ(d.advised_candidate_simulations, 0);  // a settled verdict advises no longer search
  EXPECT_EQ(d.verdict.find("A longer search"), std::string::npos) << d.verdict;
  EXPECT_LT(d.error_after, 2 * noise) << d.headline;  // the two codes agree to about the noise
}

class RefdemRecord : public ::testing::TestWithParam<Realisation> {};
class RefdemNextRealisation : public ::testing::TestWithParam<Realisation> {};

// The realisation after the one DEMCAL_TEST_REALISATION names (in_contact:1 by default).
Realisation next_realisation() {
  Realisation next = test_support::realisation_from_environment();
  ++next.k;
  return next;
}

}  // namespace

// A candidate's search is not cut to the campaign's own budget (A-campaign.json: 40 runs of the
// base's three parameters) unless asked: it searches more parameters, away from the base fit.
TEST(CandidateBudget, IsItsOwnUnlessZeroAsksForTheCampaigns) {
  const CampaignConfig config =
      campaign_from_json(test_support::read_json(kRecords / "A-campaign.json"), kRecords.string(), "A-campaign.json");
  ASSERT_EQ(config.optimiser.evaluation_budget(), 40);
  DiagnoseOptions o;
  EXPECT_EQ(candidate_budget(o, config), 80);
  o.candidate_simulations = 0;
  EXPECT_EQ(candidate_budget(o, config), 40);
  o.candidate_simulations = 24;
  EXPECT_EQ(candidate_budget(o, config), 24);
}

// The other code's control (kn 2.9e9, ks 1.2e9, friction 32.5°, 1.5 % noise).
TEST_P(RefdemRecord, TheControlNeedsNoEffect) { expect_no_effect_needed("A-control-1", GetParam()); }

// The other code's friction softening, 34° -> 26° over 0.5 mm of slip (kn 3.0e9, ks 1.3e9): on the
// reference arch the base model fits it to within the noise (data/refdem-arch/README.md allows
// it), so no effect may be named; the false positive this guards against is a compliant support.
// It runs on the realisation after the environment's: on in_contact:1, after the default, the base
// calibration stops at 1.3 x the noise and the undecided candidates get the removal check (the
// control runs the path where the base fit is within the noise).
TEST_P(RefdemNextRealisation, ASofteningBelowTheNoiseIsNotTakenForAnEffect) {
  expect_no_effect_needed("A-softening-1", GetParam(), 40);
}

// The other code's right abutment on a 2 MN/m horizontal spring (kn 3.4e9, ks 1.3e9, friction 31.5°),
// with a joint gap on offer too (the rival whose fit comes closest): both effects probed, ranked,
// calibrated through the campaign machinery into the diagnosis's one archive, re-simulated on the
// base grid, judged and reported; support compliance is named at the right abutment (not the
// left), the truth of its horizontal stiffness inside what its bounds do not rule out, the error
// lowered, the choice reached by most resamples, and the base re-fitted from its fit without it
// clearly worse (the removal check). Its best kx is not compared with the truth: the record's
// horizontal spring is fitted by the three springs together, on some realisations by the
// rotational and vertical ones at their lower ends with kx left open (not pinned by the data).
// (The base friction is not compared with the other code's: the two codes' friction laws differ,
// and the fits end at 40-45°.) The base calibration has the campaign's budget, the candidates the
// default: with 30 base runs the verdict was undecided on all:-1 (a tapered gap beside the hinge
// within the noise of the support); at 30 or 40 runs per candidate the gap, its search started from
// other base fits too, ties the support (61 against 73 N, 73 against 76 N) and falls behind at 80.
TEST_P(RefdemRecord, ACompliantAbutmentIsNamedAndRecovered) {
  const fs::path dir = test_support::fresh_dir("diagnose", "refdem-support-" + GetParam().name());
  constexpr double kx_truth = 2e6;
  DiagnoseOptions options = shortened(dir, {"support-compliance", "joint-gap"}, true, true);
  options.candidate_simulations = DiagnoseOptions{}.candidate_simulations;
  const Diagnosis d = run_diagnosis(record_campaign("A-support-1", dir, GetParam()), options);
  ASSERT_EQ(d.candidates.size(), 2u);
  EXPECT_GE(d.candidates[0].signature_score, d.candidates[1].signature_score);  // ranked
  for (const auto& c : d.candidates) {
    EXPECT_TRUE(c.tried) << c.effect << ": " << c.reason;
    EXPECT_TRUE(std::isfinite(c.score)) << c.effect << ": " << c.reason;
    EXPECT_FALSE(c.reason.empty());
    EXPECT_EQ(c.residuals.size(), d.base_residuals.size());
    EXPECT_TRUE(fs::exists(dir / "out" / "candidates" / c.effect / "result.json")) << c.effect;
    EXPECT_GT(c.params.size(), d.base_params.size()) << c.effect;  // the effect's parameters calibrated too
  }
  ASSERT_EQ(d.outcome, DiagnosisOutcome::missing_effect) << d.verdict;
  ASSERT_EQ(d.chosen, std::vector<std::string>{"support-compliance"}) << d.verdict;
  const auto c = std::find_if(d.candidates.begin(), d.candidates.end(),
                              [](const EffectCandidate& x) { return x.effect == "support-compliance"; });
  EXPECT_EQ(c->target, "abutment_right");
  EXPECT_NE(d.headline.find("support_kx"), std::string::npos) << d.headline;  // with its range, or as not pinned
  EXPECT_LT(d.error_after, d.error_before);
  EXPECT_EQ(d.frequency.resamples, DiagnoseOptions{}.resamples);
  EXPECT_GE(d.frequency.verdict, DiagnoseOptions{}.verdict_share);
  // the removal check: the base alone, re-fitted from the support's fit, misses by far more
  ASSERT_EQ(d.removal_checks.size(), 1u);
  const Diagnosis::RemovalCheck& removal = d.removal_checks.front();
  EXPECT_EQ(removal.effect, "support-compliance");
  EXPECT_FALSE(removal.dropped);
  EXPECT_LT(removal.criterion, -DiagnoseOptions{}.evidence);
  EXPECT_GT(removal.error_without, d.error_after);
  EXPECT_GT(removal.error_without, removal.explained_level);  // the base alone is not explained
  EXPECT_TRUE(fs::exists(dir / "out" / "without-support-compliance" / "result.json"));
  // each of the effect's parameters checked, the truth inside what the check does not rule out
  ASSERT_EQ(c->bounds.size(), 3u);
  for (const ParameterBound& b : c->bounds) {
    // four values around the best, those beyond the search range left out: at least three, two
    // where the best is at an end of the range
    const auto [range_lower, range_upper] = c->search_ranges.at(b.name);
    EXPECT_GE(b.trials.size(), b.best == range_lower || b.best == range_upper ? 2u : 3u) << b.name;
    EXPECT_EQ(b.best, c->params.at(b.name));
    if (b.name != "abutment_right.support_kx") continue;
    if (std::isfinite(b.lower)) {
      EXPECT_LT(b.lower, kx_truth) << b.describe();
    }
    if (std::isfinite(b.upper)) {
      EXPECT_GT(b.upper, kx_truth) << b.describe();
    }
  }
  // every candidate counted with the same effective points: per channel, those of the closest fit
  ASSERT_EQ(d.effective_points.size(), d.base_residuals.size());
  std::vector<double> points;
  for (const auto& r : d.base_residuals) points.push_back(d.effective_points.at(r.case_name + "/" + r.channel));
  for (const auto& x : d.candidates)
    EXPECT_DOUBLE_EQ(x.score, information_criterion_change(d.base_residuals, x.residuals, x.effect_parameters, points));
  const json j = test_support::read_json(dir / "out" / "diagnosis.json");
  for (const char* key : {"base", "noise", "effective_points", "candidates", "chosen", "error_before", "error_after"})
    EXPECT_TRUE(j.contains(key)) << key;
  // the effect added carries its candidate's bounds, in diagnosis.json too
  ASSERT_EQ(d.added.size(), 1u);
  ASSERT_EQ(d.added.front().bounds.size(), c->bounds.size());
  for (std::size_t i = 0; i < c->bounds.size(); ++i) {
    const ParameterBound& b = d.added.front().bounds[i];
    EXPECT_EQ(b.name, c->bounds[i].name);
    EXPECT_EQ(j["added"][0]["bounds"][b.name]["best"].get<double>(), b.best) << b.name;
  }
  ASSERT_EQ(j["base"]["further_starts"].size(), d.further_starts.size());
  EXPECT_LE(d.further_starts.size(), static_cast<std::size_t>(DiagnoseOptions{}.candidate_starts - 1));
  EXPECT_EQ(j["frequency"]["verdict"].get<double>(), d.frequency.verdict);
  // the advice of a longer search in words and as a number, or neither
  ASSERT_TRUE(j.contains("advised_candidate_simulations"));
  if (j["advised_candidate_simulations"].is_null())
    EXPECT_EQ(d.verdict.find("A longer search"), std::string::npos) << d.verdict;
  else
    EXPECT_NE(d.verdict.find("--candidate-simulations " + std::to_string(j["advised_candidate_simulations"].get<long>())),
              std::string::npos)
        << d.verdict;
  EXPECT_TRUE(fs::exists(dir / "out" / "report.md"));
  EXPECT_TRUE(fs::exists(dir / "out" / "archive.sqlite"));  // one archive for every calibration
}

INSTANTIATE_TEST_SUITE_P(DiagnoseLoop, RefdemRecord, ::testing::Values(test_support::realisation_from_environment()),
                         test_support::realisation_name);
INSTANTIATE_TEST_SUITE_P(DiagnoseLoop, RefdemNextRealisation, ::testing::Values(next_realisation()),
                         test_support::realisation_name);
