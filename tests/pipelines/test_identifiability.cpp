// The identifiability block (campaign.hpp, compute_identifiability): evaluated ranges widened by
// the profile on an emulator, in physical units (a log-scaled parameter's grid uniform in its
// logarithm), and its place in result.json and report.md of a short campaign.
#include "test_support.hpp"
#include "demcal/pipelines/campaign.hpp"

#include "../test_random.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace fs = std::filesystem;
using namespace demcal::pipelines;
using nlohmann::json;
namespace optimise = demcal::optimise;

namespace {

using demcal::test_random::uniform;

// kn in [1e8, 1e10] (log10), friction in [25, 45] degrees; in unit coordinates (a, b) the fitness
// is the valley a = b: 1 + 50 (a - b)^2 + 0.02 (a - 0.75)^2, within a 5 % band all along its floor.
optimise::ParameterSpace valley_space() {
  optimise::ParameterSpace space;
  space.add("kn", 1e8, 1e10, optimise::ParameterSpec::Scale::log10).add("friction_deg", 25, 45).fix("ks", 1e9);
  return space;
}

ParameterSet valley_set(const optimise::ParameterSpace& space, double a, double b) {
  Eigen::VectorXd unit(2);
  unit << a, b;
  ParameterSet s;
  s.params = space.values(space.to_physical(unit));
  s.fitness = 1 + 50 * (a - b) * (a - b) + 0.02 * (a - 0.75) * (a - 0.75);
  return s;
}

// A design without a set in the band, sets on the valley's flanks, and a cluster at a in [0.7, 0.8]
// (the only sets in the band), as a converged swarm leaves them.
std::vector<ParameterSet> valley_sets(const optimise::ParameterSpace& space, int spread, int flank, int cluster) {
  std::mt19937_64 rng(5);
  std::vector<ParameterSet> sets;
  while (static_cast<int>(sets.size()) < spread) {
    const auto s = valley_set(space, uniform(rng), uniform(rng));
    if (s.fitness > 1.06) sets.push_back(s);
  }
  while (static_cast<int>(sets.size()) < spread + flank) {
    const double a = uniform(rng), b = a + (uniform(rng) < 0.5 ? -1 : 1) * (0.05 + 0.1 * uniform(rng));
    if (b >= 0 && b <= 1) sets.push_back(valley_set(space, a, b));
  }
  for (int i = 0; i < cluster; ++i) {
    const double a = 0.7 + 0.1 * uniform(rng);
    sets.push_back(valley_set(space, a, a + 0.04 * (uniform(rng) - 0.5)));
  }
  return sets;
}

}  // namespace

TEST(Identifiability, ProfileWidensTheEvaluatedRangeInPhysicalUnits) {
  const auto space = valley_space();
  const Identifiability id = compute_identifiability(valley_sets(space, 40, 20, 25), space, 0.05, {});
  ASSERT_EQ(id.method, "profile") << id.method_note;
  EXPECT_EQ(id.emulator_kind, "gp");
  EXPECT_EQ(id.profile.training_rows, 85);
  const auto& kn = id.parameters.at("kn");
  const auto& friction = id.parameters.at("friction_deg");
  EXPECT_FALSE(id.parameters.contains("ks")) << "fixed parameters have no range";
  // the evaluated range is the cluster's: unit a in [0.7, 0.8] = kn in [10^9.4, 10^9.6]
  EXPECT_GE(kn.evaluated_min, std::pow(10.0, 9.4) * (1 - 1e-12));
  EXPECT_LE(kn.evaluated_max, std::pow(10.0, 9.6) * (1 + 1e-12));
  // the reported one follows the valley: unit [0.3, 0.9] = kn [10^8.6, 10^9.8], friction [31, 43]
  EXPECT_LE(kn.min, std::pow(10.0, 8.6));
  EXPECT_GE(kn.max, std::pow(10.0, 9.8));
  EXPECT_LE(friction.min, 31.0);
  EXPECT_GE(friction.max, 43.0);
  for (const auto& [name, r] : id.parameters) {
    EXPECT_LE(r.min, r.evaluated_min) << name;
    EXPECT_GE(r.max, r.evaluated_max) << name;
    EXPECT_LE(r.min, r.profile_min) << name;
    EXPECT_GE(r.max, r.profile_max) << name;
  }
  // kn's grid is uniform in log10 kn: 41 values from 1e8 to 1e10, 1e9 in the middle
  ASSERT_EQ(kn.profile_values.size(), 41u);
  EXPECT_DOUBLE_EQ(kn.profile_values.front(), 1e8);
  EXPECT_DOUBLE_EQ(kn.profile_values.back(), 1e10);
  EXPECT_NEAR(kn.profile_values[20], 1e9, 1e9 * 1e-12);
  EXPECT_DOUBLE_EQ(friction.profile_values[20], 35.0);
  ASSERT_EQ(kn.profile_others.at("friction_deg").size(), 41u);
  EXPECT_NEAR(kn.profile_others.at("friction_deg")[20], 35.0, 1.0) << "on the valley's floor at a = 0.5";

  const json j = id.to_json();
  EXPECT_EQ(j["method"], "profile");
  EXPECT_EQ(j["emulator"]["training_runs"], 85);
  EXPECT_TRUE(j["emulator"]["length_scales"].contains("kn"));
  EXPECT_EQ(j["parameters"]["kn"]["min"].get<double>(), kn.min);
  EXPECT_EQ(j["parameters"]["kn"]["evaluated_min"].get<double>(), kn.evaluated_min);
  EXPECT_EQ(j["parameters"]["kn"]["profile"]["fitness"].size(), 41u);
}

TEST(Identifiability, FewSetsGiveTheEvaluatedRange) {
  const auto space = valley_space();
  const Identifiability id = compute_identifiability(valley_sets(space, 5, 2, 2), space, 0.05, {});
  EXPECT_EQ(id.method, "evaluated");
  EXPECT_NE(id.method_note.find("needed to train an emulator"), std::string::npos) << id.method_note;
  for (const auto& [name, r] : id.parameters) {
    EXPECT_EQ(r.min, r.evaluated_min) << name;
    EXPECT_EQ(r.max, r.evaluated_max) << name;
    EXPECT_TRUE(std::isnan(r.profile_min)) << name;
  }
  const json j = id.to_json();
  EXPECT_EQ(j["method"], "evaluated");
  EXPECT_FALSE(j.contains("emulator"));
  EXPECT_TRUE(j["parameters"]["kn"]["profile_min"].is_null());
}

// A short campaign through the toy external simulator (64 runs, a few seconds): result.json and
// report.md carry the profile ranges; "profile": {"enabled": false} gives the evaluated ones.
TEST(Identifiability, CampaignWritesTheProfileRangesToResultAndReport) {
  const fs::path dir = test_support::fresh_dir("identifiability", "campaign");
  test_support::write_text(dir / "measured.csv", test_support::toy_measured_text());
  json config_json = test_support::toy_campaign(dir, "toy-identifiability");
  config_json["optimiser"] = {{"algorithm", "tbpso"}, {"population", 8}, {"iterations", 8}, {"seed", 3}};
  config_json["backend"]["parallel"] = 2;
  config_json["output"] = (dir / "out").string();
  config_json["report"] = true;
  RunOptions options;
  options.progress = false;
  const CampaignResult result = run_campaign(campaign_from_json(config_json, dir.string(), "toy.json"), options);
  ASSERT_EQ(result.status, CampaignStatus::completed) << result.message;
  const json written = test_support::read_json(dir / "out" / "result.json");
  const json& id = written["identifiability"];
  ASSERT_EQ(id["method"], "profile") << id.dump();
  EXPECT_EQ(id["emulator"]["kind"], "gp");
  EXPECT_GE(id["emulator"]["training_runs"].get<long>(), 10);
  EXPECT_GT(written["timing"]["identifiability_fit_s"].get<double>(), 0.0);  // wall times: with the others
  EXPECT_GT(written["timing"]["identifiability_profile_s"].get<double>(), 0.0);
  EXPECT_EQ(id["emulator"]["options"]["grid_points"], 41);
  for (const std::string name : {"k", "friction_deg"}) {
    const json& p = id["parameters"][name];
    for (const char* key : {"best", "min", "max", "evaluated_min", "evaluated_max", "profile_min", "profile_max", "profile"})
      EXPECT_TRUE(p.contains(key)) << name << " lacks " << key << ": " << p.dump();
    EXPECT_LE(p["min"].get<double>(), p["evaluated_min"].get<double>());
    EXPECT_GE(p["max"].get<double>(), p["evaluated_max"].get<double>());
    EXPECT_EQ(p["profile"]["values"].size(), 41u);
  }
  const std::string report = test_support::read_text(dir / "out" / "report.md");
  EXPECT_NE(report.find("## Identifiability"), std::string::npos);
  EXPECT_NE(report.find("| friction_deg (°) |"), std::string::npos);

  config_json["identifiability"] = {{"profile", {{"enabled", false}}}};
  config_json["output"] = (dir / "out-evaluated").string();
  config_json["report"] = false;
  config_json["archive"] = (dir / "out" / "archive.sqlite").string();  // the same runs, from the archive
  const CampaignResult again = run_campaign(campaign_from_json(config_json, dir.string(), "toy.json"), options);
  EXPECT_EQ(again.simulated_this_session, 0);
  EXPECT_EQ(again.identifiability.method, "evaluated");
  for (const auto& [name, r] : again.identifiability.parameters) {
    EXPECT_EQ(r.min, result.identifiability.parameters.at(name).evaluated_min) << name;
    EXPECT_EQ(r.max, result.identifiability.parameters.at(name).evaluated_max) << name;
  }

  config_json["identifiability"] = {{"profile", {{"grid_points", 1}}}};
  EXPECT_THROW(campaign_from_json(config_json, dir.string(), "toy.json"), CampaignError);
}
