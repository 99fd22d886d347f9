// `demcal study`: algorithms x seeds on one problem, through the external-command backend and the
// small Python simulator in this folder (tiny budgets; objective 1). Checks study.json and study.md
// against the campaigns' own result.json files, the rerun from the archive, and bad input.
#include "demcal/pipelines/process.hpp"
#include "test_support.hpp"
#include "demcal/pipelines/study.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;
using namespace demcal::pipelines;
using nlohmann::json;

namespace {

fs::path study_dir(const std::string& name) { return test_support::fresh_dir("study", name); }
using test_support::read_json;

using test_support::kToySimulator;
using test_support::python;



using test_support::read_text;

// A toy problem: k = 2e7 N/m, friction 32 deg, 20 N of noise; population 4.
json toy_study(const fs::path& dir) {
  const std::string measured = (dir / "measured.csv").string();
  ProcessOptions o;
  o.argv = {python(), kToySimulator, "2e7", "32", measured, "--noise", "20", "--seed", "7"};
  o.timeout_s = 30;
  EXPECT_TRUE(run_process(o).ok());
  const json campaign = {
      {"name", "toy"},
      {"measured", "measured.csv"},
      {"parameters", {{{"name", "k"}, {"lower", 1e6}, {"upper", 1e8}, {"scale", "log"}},
                      {{"name", "friction_deg"}, {"lower", 25}, {"upper", 45}}}},
      {"objective", 1},
      {"optimiser", {{"algorithm", "tbpso"}, {"population", 4}, {"iterations", 9}, {"seed", 1}}},
      {"backend", {{"type", "command"}, {"command", python() + " " + kToySimulator + " {k} {friction_deg} {output}"}, {"parallel", 2}}},
      {"output", "unused"}};
  return {{"campaign", campaign},
          {"algorithms", json::array({"pso", json{{"algorithm", "tbpso"}, {"iterations", 2}},
                                      json{{"algorithm", "pso"}, {"iterations", 2}, {"label", "pso-short"}}})},
          {"iterations", {{"pso", 3}}},
          {"seeds", {{"first", 1}, {"count", 6}}},
          {"output", "study"}};
}

StudyConfig study_config(const json& j, const fs::path& dir) { return study_from_json(j, dir.string(), "study.json"); }

}  // namespace

TEST(Study, WritesTheFiveBestPerMethodStatisticsAndSimulations) {
  const auto dir = study_dir("tables");
  const StudyConfig config = study_config(toy_study(dir), dir);
  ASSERT_EQ(config.methods.size(), 3u);
  EXPECT_EQ(config.methods[0].iterations, 3);  // from the "iterations" map
  EXPECT_EQ(config.seeds, (std::vector<std::uint64_t>{1, 2, 3, 4, 5, 6}));
  const StudyResult result = run_study(config, false);

  const fs::path out = dir / "study";
  const json study = read_json(out / "study.json");
  const std::vector<std::string> labels = {"pso-3", "tbpso-2", "pso-short"};
  const std::vector<long> budgets = {12, 8, 8};
  ASSERT_EQ(study["methods"].size(), 3u);
  EXPECT_EQ(study["common_budget"], 8);
  for (size_t m = 0; m < labels.size(); ++m) {
    const json& method = study["methods"][m];
    SCOPED_TRACE(labels[m]);
    EXPECT_EQ(method["label"], labels[m]);
    EXPECT_EQ(method["simulations_per_campaign"], budgets[m]);
    EXPECT_EQ(method["simulations_total"], 6 * budgets[m]);
    ASSERT_EQ(method["campaigns"].size(), 6u);

    // Every seed's best is that campaign's own result.json; the statistics are those of the six.
    std::vector<double> bests, at_budget;
    for (size_t s = 0; s < 6; ++s) {
      const json campaign = read_json(out / labels[m] / ("seed-" + std::to_string(s + 1)) / "result.json");
      EXPECT_EQ(campaign["seed"], s + 1);
      EXPECT_EQ(campaign["simulations"], budgets[m]);
      EXPECT_EQ(method["campaigns"][s]["seed"], s + 1);
      EXPECT_EQ(method["campaigns"][s]["fitness"].get<double>(), campaign["best"]["fitness"].get<double>());
      EXPECT_EQ(method["campaigns"][s]["params"], campaign["best"]["params"]);
      bests.push_back(campaign["best"]["fitness"].get<double>());
      at_budget.push_back(campaign["convergence"][7].get<double>());  // best after 8 candidates
      EXPECT_EQ(method["campaigns"][s]["fitness_at_common_budget"].get<double>(), at_budget.back());
    }
    std::vector<double> sorted = bests;
    std::sort(sorted.begin(), sorted.end());
    double mean = 0;
    for (double b : bests) mean += b / 6;
    double sq = 0;
    for (double b : bests) sq += (b - mean) * (b - mean);
    const auto& stats = method["fitness"];
    EXPECT_EQ(stats["count"], 6);
    EXPECT_NEAR(stats["mean"].get<double>(), mean, 1e-9 * mean);
    EXPECT_NEAR(stats["stddev"].get<double>(), std::sqrt(sq / 5), 1e-9 * mean);
    EXPECT_EQ(stats["min"].get<double>(), sorted.front());
    EXPECT_EQ(stats["max"].get<double>(), sorted.back());
    EXPECT_EQ(stats["median"].get<double>(), 0.5 * (sorted[2] + sorted[3]));
    EXPECT_EQ(method["fitness_at_common_budget"]["min"].get<double>(), *std::min_element(at_budget.begin(), at_budget.end()));

    // Five best: the five lowest per-seed bests, ascending, without the worst seed.
    ASSERT_EQ(method["five_best"].size(), 5u);
    for (size_t i = 0; i < 5; ++i) EXPECT_EQ(method["five_best"][i]["fitness"].get<double>(), sorted[i]);
    EXPECT_EQ(result.methods[m].five_best.size(), 5u);
  }
  // pso-short and pso-3 start from the same seeded swarm (their inertia schedules differ after that):
  // the first iteration's runs are read back from the shared archive, not simulated again.
  for (size_t s = 0; s < 6; ++s)
    EXPECT_LT(study["methods"][2]["campaigns"][s]["simulated_this_session"].get<long>(), 8);

  // study.md: the paper's table layout, one block of five rows per method, and the other sections.
  const std::string md = read_text(out / "study.md");
  EXPECT_NE(md.find("| Calibration process | Number of iterations | Run ID | k | friction_deg (deg) | Fitness (-) |"),
            std::string::npos)
      << md;
  for (size_t m = 0; m < labels.size(); ++m) {
    char best_cell[64];
    std::snprintf(best_cell, sizeof best_cell, "| %.1f |", study["methods"][m]["five_best"][0]["fitness"].get<double>());
    EXPECT_NE(md.find("| " + labels[m] + " | "), std::string::npos) << labels[m];
    EXPECT_NE(md.find(best_cell), std::string::npos) << best_cell;
  }
  size_t rows = 0;
  for (size_t pos = 0; (pos = md.find("\n|  |  | ", pos)) != std::string::npos; ++pos) ++rows;
  EXPECT_EQ(rows, 3u * 4u);  // ranks 2-5 of each method
  for (const char* section : {"## Fitness of the best set per seed", "## At equal cost: best fitness after 8 simulations",
                              "## Simulations used", "## Convergence", "## Calibrated sets in parameter space"})
    EXPECT_NE(md.find(section), std::string::npos) << section;
  EXPECT_TRUE(fs::exists(out / "figures" / "convergence.png"));
  EXPECT_TRUE(fs::exists(out / "figures" / "positions_k_friction_deg.png"));

  // Run again: every campaign continues from the archive, nothing is simulated, same tables.
  const StudyResult again = run_study(config, false);
  for (size_t m = 0; m < 3; ++m)
    for (size_t s = 0; s < 6; ++s) {
      EXPECT_EQ(again.methods[m].campaigns[s].simulated, 0);
      EXPECT_EQ(again.methods[m].campaigns[s].best.fitness, result.methods[m].campaigns[s].best.fitness);
      EXPECT_EQ(again.methods[m].campaigns[s].best.params, result.methods[m].campaigns[s].best.params);
    }
  EXPECT_EQ(read_json(out / "study.json")["methods"][0]["fitness"], study["methods"][0]["fitness"]);
}

TEST(Study, BadStudyFilesGiveMessagesNamingTheKey) {
  const auto dir = study_dir("bad");
  const json good = toy_study(dir);
  auto expect_error = [&](json j, const std::string& needle) {
    try {
      study_config(j, dir);
      ADD_FAILURE() << "no error for " << needle;
    } catch (const CampaignError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("study.json"), std::string::npos) << e.what();
    }
  };
  json j = good;
  j["algorithms"] = json::array({"pso", "psoo"});
  expect_error(j, "algorithms[1] ('psoo'): unknown algorithm 'psoo'");
  j = good;
  j["algorithms"] = json::array({"pso", json{{"algorithm", "pso"}, {"iterations", 3}}});
  expect_error(j, "label 'pso-3' is used twice");
  j = good;
  j["algorithms"][1]["iterations"] = "many";
  expect_error(j, "algorithms[1].iterations must be an integer, not \"many\"");
  j = good;
  j["algorithms"][1]["iterations"] = -2;
  expect_error(j, "iterations = -2 must be >= 1");
  j = good;
  j["seeds"] = {{"first", 1}, {"count", 0}};
  expect_error(j, "seeds.count = 0 must be >= 1");
  j = good;
  j["seeds"] = json::array({1, 2, 1});
  expect_error(j, "seed 1 is listed twice");
  j = good;
  j["seed"] = 3;
  expect_error(j, "unknown key 'seed'");
  j = good;
  j["algorithms"] = json::array();
  expect_error(j, "'algorithms' must be a non-empty array");
  j = good;
  j["campaign"]["parameters"][1]["lower"] = 50;
  expect_error(j, "friction_deg");
}

TEST(Study, CommandLineRunsTheStudyFileAndReportsBadInput) {
  const auto dir = study_dir("cli");
  json j = toy_study(dir);
  j["algorithms"] = json::array({json{{"algorithm", "tbpso"}, {"iterations", 2}}});
  j["seeds"] = json::array({4, 9});
  std::ofstream(dir / "study.json") << j.dump(2);
  ProcessOptions o;
  o.argv = {DEMCAL_BINARY, "study", (dir / "study.json").string(), "--out", (dir / "elsewhere").string(), "--quiet"};
  o.stderr_path = (dir / "stderr.txt").string();
  o.timeout_s = 120;
  const ProcessResult ok = run_process(o);
  ASSERT_TRUE(ok.ok()) << ok.message << read_text(dir / "stderr.txt");
  const json study = read_json(dir / "elsewhere" / "study.json");
  EXPECT_EQ(study["seeds"], json::array({4, 9}));
  EXPECT_EQ(study["methods"][0]["label"], "tbpso-2");
  EXPECT_TRUE(fs::exists(dir / "elsewhere" / "tbpso-2" / "seed-9" / "result.json"));
  EXPECT_TRUE(fs::exists(dir / "elsewhere" / "study.md"));

  j["algorithms"] = json::array({"ga", "annealing"});
  std::ofstream(dir / "bad.json") << j.dump(2);
  o.argv = {DEMCAL_BINARY, "study", (dir / "bad.json").string(), "--quiet"};
  const ProcessResult bad = run_process(o);
  EXPECT_EQ(bad.status, ProcessStatus::exited);
  EXPECT_EQ(bad.exit_code, 1);
  const std::string err = read_text(dir / "stderr.txt");
  EXPECT_NE(err.find("demcal: error: "), std::string::npos) << err;
  EXPECT_NE(err.find("algorithms[1] ('annealing')"), std::string::npos) << err;
}
