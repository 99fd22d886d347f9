// Surrogate pre-screening in campaigns: the archive adapter, "never a prediction" in the archive and
// the optimiser, a warm second campaign, and kill -9 / --resume with the surrogate on. Campaigns run
// the toy external simulator (tests/pipelines/toy_simulator.py) through the demcal program.
#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/campaign.hpp"
#include "demcal/pipelines/process.hpp"
#include "demcal/pipelines/surrogate_data.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <random>
#include <set>
#include <thread>

namespace fs = std::filesystem;
using namespace demcal;
using namespace demcal::pipelines;
using nlohmann::json;
using test_support::python;
using test_support::read_json;

namespace {

fs::path surrogate_dir(const std::string& name) { return test_support::fresh_dir("surrogate", name); }

// The toy wall's measurement (k 2e7, friction 32°, 20 N of noise drawn with `seed`) in dir/NAME.
std::string toy_measurement(const fs::path& dir, const std::string& name = "measured.csv", int seed = 7) {
  const std::string path = (dir / name).string();
  ProcessOptions o;
  o.argv = {python(), test_support::kToySimulator, "2e7", "32", path, "--noise", "20", "--seed", std::to_string(seed)};
  o.timeout_s = 30;
  EXPECT_TRUE(run_process(o).ok());
  return path;
}

// The toy wall: failures (a crashed program) above 42 degrees, a surrogate that screens 8 -> 4.
json surrogate_toy_campaign(const fs::path& dir, std::uint64_t seed = 3, const std::string& kind = "gp") {
  return {{"name", "toy-surrogate"},
          {"measured", toy_measurement(dir)},
          {"parameters", {{{"name", "k"}, {"lower", 1e6}, {"upper", 1e8}, {"scale", "log"}},
                          {{"name", "friction_deg"}, {"lower", 25}, {"upper", 45}}}},
          {"objective", 1},
          {"optimiser", {{"algorithm", "tbpso"}, {"population", 8}, {"max_evaluations", 36}, {"seed", seed}}},
          {"surrogate", {{"k", 4}, {"pool_factor", 4}, {"min_runs", 8}, {"kind", kind}}},
          {"backend", {{"type", "command"},
                       {"command", python() + " " + test_support::kToySimulator +
                                       " {k} {friction_deg} {output} --crash-above 42"},
                       {"parallel", 2}}},
          {"report", false}};
}

ProcessResult calibrate(const fs::path& campaign, const fs::path& out, bool resume, const std::atomic<bool>* kill = nullptr,
                        const std::string& archive = "") {
  ProcessOptions o;
  o.argv = {DEMCAL_BINARY, "calibrate", campaign.string(), "--out", out.string(), "--quiet"};
  if (!archive.empty()) {
    o.argv.push_back("--archive");
    o.argv.push_back(archive);
  }
  if (resume) o.argv.push_back("--resume");
  o.timeout_s = 300;
  o.cancel = kill;
  o.stderr_path = out.string() + ".stderr";
  return run_process(o);
}

}  // namespace

TEST(SurrogateData, ReadsExactlyTheFinishedRunsOfOneSceneHash) {
  const auto dir = surrogate_dir("adapter");
  RunArchive archive((dir / "a.sqlite").string());
  optimise::ParameterSpace space;
  space.add("kn", 1e8, 1e10, optimise::ParameterSpec::Scale::log10).add("friction_deg", 25, 45).tie("ks", "kn", 2.0);
  auto insert = [&](const std::string& model, double kn, double friction, const std::string& status, double ks_ratio = 2.0) {
    RunRecord r;
    r.model_hash = model;
    r.params = {{"kn", kn}, {"friction_deg", friction}, {"ks", kn / ks_ratio}};
    r.code_version = "test";
    r.backend = "threads";
    r.status = status;
    return archive.insert_run(r);
  };
  auto score = [&](std::int64_t id, const std::string& key, double fitness) {
    FitnessRecord f;
    f.run_id = id;
    f.objective_key = key;
    f.fitness = fitness;
    archive.put_fitness(f);
  };
  const std::int64_t a = insert("sceneA", 1e9, 30, "completed");
  score(a, "obj", 10.0);
  score(a, "other-objective", 99.0);
  const std::int64_t b = insert("sceneA", 2e9, 35, "unstable");
  score(b, "obj", NAN);                                   // a failed run: kept, NaN
  const std::int64_t c = insert("sceneA", 3e9, 40, "completed");  // not scored yet: left out
  (void)c;
  const std::int64_t d = insert("sceneB", 1e9, 30, "completed");  // another scene
  score(d, "obj", 5.0);
  const std::int64_t e = insert("sceneA", 4e9, 50, "completed");  // outside the bounds
  score(e, "obj", 7.0);
  const std::int64_t f = insert("sceneA", 5e9, 33, "completed", 3.0);  // another tie: another calibration
  score(f, "obj", 8.0);
  const std::int64_t g = insert("sceneA", 6e9, 31, "cancelled");
  score(g, "obj", NAN);
  const std::int64_t h = insert("sceneA", 7e9, 29, "collapsed");
  score(h, "obj", 12.0);

  const auto rows = archive_training_rows(archive, space, {{"sceneA", "obj", 1.0}});
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[0].fitness, 10.0);
  EXPECT_TRUE(std::isnan(rows[1].fitness));
  EXPECT_EQ(rows[2].fitness, 12.0);
  EXPECT_TRUE(rows[0].unit.isApprox(space.to_unit(Eigen::Vector2d(1e9, 30))));
  // The horizon cuts later runs; a second case joins by parameter set and weights the sum.
  EXPECT_EQ(archive_training_rows(archive, space, {{"sceneA", "obj", 1.0}}, b).size(), 2u);
  const auto joined = archive_training_rows(archive, space, {{"sceneA", "obj", 1.0}, {"sceneB", "obj", 2.0}});
  ASSERT_EQ(joined.size(), 1u);
  EXPECT_EQ(joined[0].fitness, 10.0 + 2.0 * 5.0);
}

// Parallel runs are archived in the order they finish; the rows (and every model fitted to them) must
// not depend on that order.
TEST(SurrogateData, RowsDoNotDependOnTheOrderRunsFinished) {
  const auto dir = surrogate_dir("finish-order");
  optimise::ParameterSpace space;
  space.add("kn", 1e8, 1e10, optimise::ParameterSpec::Scale::log10).add("friction_deg", 25, 45);
  const std::vector<std::pair<double, double>> points = {{3e9, 30}, {1e9, 41}, {5e8, 27}, {1e9, 33}};
  auto rows_in_order = [&](const std::string& name, const std::vector<size_t>& order) {
    RunArchive archive((dir / name).string());
    for (size_t i : order) {
      RunRecord r;
      r.model_hash = "scene";
      r.params = {{"kn", points[i].first}, {"friction_deg", points[i].second}};
      r.code_version = "test";
      r.backend = "threads";
      r.status = "completed";
      FitnessRecord f;
      f.run_id = archive.insert_run(r);
      f.objective_key = "obj";
      f.fitness = static_cast<double>(i) + 1.0;
      archive.put_fitness(f);
    }
    return archive_training_rows(archive, space, {{"scene", "obj", 1.0}});
  };
  const auto forward = rows_in_order("forward.sqlite", {0, 1, 2, 3});
  const auto shuffled = rows_in_order("shuffled.sqlite", {2, 0, 3, 1});
  ASSERT_EQ(forward.size(), points.size());
  ASSERT_EQ(shuffled.size(), points.size());
  for (size_t i = 0; i < forward.size(); ++i) {
    EXPECT_EQ(forward[i].unit, shuffled[i].unit) << "row " << i;
    EXPECT_EQ(forward[i].fitness, shuffled[i].fitness) << "row " << i;
  }
}

// The archive and the optimiser hold simulated values only; the budget counts simulations; a second
// campaign on the same archive starts warm (its first iteration is already screened).
// The "mlp" kind's outputs: a run's curves resampled on the measurement's grid score (through
// curve_fitness) as the objective scores the run itself, a shorter run included.
TEST(SurrogateData, CurveOutputsScoreAsTheObjectiveScoresTheRun) {
  auto toy_curve = [](double capacity, double stiffness, double end, double noise) {
    smoothing::Curve c;
    c.source = "toy";
    c.columns = {{"top_horizontal", "m", {}}, {"force", "N", {}}};
    std::mt19937_64 rng(11);
    for (int i = 0; i <= 400; ++i) {
      const double d = end * i / 400.0;
      c.columns[0].values.push_back(d);
      c.columns[1].values.push_back(capacity * (1 - std::exp(-stiffness * d / capacity)) +
                                    noise * (static_cast<double>(rng() % 2001) / 1000.0 - 1.0));
    }
    return c;
  };
  const auto measured = toy_curve(7000, 2e7, 0.010, 50);
  smoothing::ObjectiveOptions objective;
  auto grid = std::make_shared<const CurveGrid>(make_curve_grid(measured, objective, nullptr, 2.0, 40));
  ASSERT_EQ(grid->channels.size(), 1u);
  EXPECT_EQ(grid->size(), 41);
  // The grid's own error, against the scale of the fitness (that of a curve of zero force): 0.1 %.
  smoothing::Curve zero = toy_curve(1e-9, 1, 0.010, 0);
  const double scale = 2.0 * smoothing::objective1(measured, zero, objective).fitness;
  for (const auto& run : {toy_curve(6000, 1e7, 0.010, 0), toy_curve(8000, 4e7, 0.006, 0), toy_curve(7000, 2e7, 0.012, 0)}) {
    const Eigen::VectorXd outputs = curve_outputs(run, *grid);
    ASSERT_EQ(outputs.size(), 41);
    EXPECT_DOUBLE_EQ(outputs[40], run.columns[0].values.back()) << "the last output is the run's end displacement";
    const double expected = 2.0 * smoothing::objective1(measured, run, objective).fitness;
    EXPECT_NEAR(curve_fitness(outputs, {grid}), expected, 0.02 * expected + 0.001 * scale);
    // to the bit, the objective's channel misfit of the measured series and the grid's curve
    EXPECT_EQ(curve_fitness(outputs, {grid}),
              2.0 * smoothing::channel_misfit(smoothing::series(measured, "top_horizontal", "force"),
                                              output_channel(outputs, 0, *grid, 0), objective.points, "top_horizontal",
                                              objective.window));
  }
  smoothing::Curve other = toy_curve(6000, 1e7, 0.010, 0);
  other.columns[0].name = "other_gauge";
  EXPECT_EQ(curve_outputs(other, *grid).size(), 0) << "a run without the measured channel has no outputs";
}

// Both kinds: the Gaussian process on the fitness, the MLP ensemble on the curves.
class SurrogateKinds : public ::testing::TestWithParam<std::string> {};
INSTANTIATE_TEST_SUITE_P(SurrogateCampaign, SurrogateKinds, ::testing::Values("gp", "mlp"));

TEST_P(SurrogateKinds, ArchiveAndOptimiserNeverHoldAPrediction) {
  const auto dir = surrogate_dir("never-predicted-" + GetParam());
  std::ofstream(dir / "campaign.json") << surrogate_toy_campaign(dir, 3, GetParam()).dump(2);
  const auto r = calibrate(dir / "campaign.json", dir / "out", false);
  ASSERT_TRUE(r.ok()) << r.message;
  const json result = read_json(dir / "out" / "result.json");
  ASSERT_TRUE(result.contains("surrogate"));
  EXPECT_EQ(result["surrogate"]["kind"], GetParam());
  EXPECT_EQ(result["simulations"], 36) << "--max-simulations counts simulations";
  EXPECT_GT(result["surrogate"]["screened_out"].get<long>(), 0);
  // Screening starts once 8 runs have a finite fitness; the unscreened batches before are whole.
  EXPECT_EQ((36 - result["surrogate"]["simulated"].get<long>()) % 8, 0);
  EXPECT_TRUE(result["surrogate"]["cv_error"].is_number());

  RunArchive archive((dir / "out" / "archive.sqlite").string());
  const auto campaign = archive.latest_campaign(archive.campaigns().back().config_key);
  ASSERT_TRUE(campaign);
  const auto evaluations = archive.evaluations(campaign->id);
  EXPECT_EQ(evaluations.size(), 36u);
  std::set<double> simulated;
  for (const auto& e : evaluations) {
    ASSERT_EQ(e.run_ids.size(), 1u);
    const auto run = archive.run(e.run_ids[0]);
    ASSERT_TRUE(run) << "every evaluation is a simulated run";
    const auto fitness = archive.find_fitness(run->id, archive.model_objectives().front().objective_key);
    ASSERT_TRUE(fitness);
    if (std::isnan(e.fitness)) {
      EXPECT_TRUE(std::isnan(fitness->fitness));
    } else {
      EXPECT_EQ(e.fitness, fitness->fitness) << "the evaluation's value is its run's";
      simulated.insert(e.fitness);
    }
  }
  std::set<std::string> distinct;
  for (const auto& e : evaluations) distinct.insert(parameter_key(e.params));
  EXPECT_EQ(archive.run_count(), static_cast<std::int64_t>(distinct.size())) << "no run but the simulated ones";
  // Every value in every saved optimiser state is simulated (or the +inf of "nothing yet").
  for (const auto& it : archive.iterations(campaign->id)) {
    const json state = json::parse(it.optimiser_state).at("optimiser");
    for (const char* key : {"fx", "fp"}) {
      for (const auto& v : state.at(key)) {
        if (v.is_number()) {
          EXPECT_TRUE(simulated.count(v.get<double>())) << key << " holds " << v;
        }
      }
    }
    if (state.at("best_value").is_number()) {
      EXPECT_TRUE(simulated.count(state.at("best_value").get<double>()));
    }
  }

  // A second campaign (another seed) on the same archive: warm from the first one's 36 runs.
  json second = surrogate_toy_campaign(dir, 4, GetParam());
  std::ofstream(dir / "second.json") << second.dump(2);
  const auto r2 = calibrate(dir / "second.json", dir / "second", false, nullptr, (dir / "out" / "archive.sqlite").string());
  ASSERT_TRUE(r2.ok()) << r2.message;
  const json warm = read_json(dir / "second" / "result.json");
  EXPECT_EQ(warm["surrogate"]["simulated"], 36) << "screened from the first iteration on";
}

// "bo" on a backend of 2 parallel programs proposes 2 points per round, so both simulate; the
// result says how the time divided between the simulations and the model, and how well the model
// predicted each point before it was simulated. With the default cost ratio the batch may grow,
// and the result says why.
TEST_P(SurrogateKinds, BayesRoundsFillTheWorkersAndReportTheirTime) {
  const auto dir = surrogate_dir("bo-batches-" + GetParam());
  json campaign = surrogate_toy_campaign(dir, 3, GetParam());
  campaign["optimiser"] = {{"algorithm", "bo"}, {"population", 8}, {"max_evaluations", 20}, {"seed", 3}};
  campaign["surrogate"] = {{"kind", GetParam()}, {"min_runs", 8}, {"cost_ratio", "inf"}};
  std::ofstream(dir / "campaign.json") << campaign.dump(2);
  const auto r = calibrate(dir / "campaign.json", dir / "fixed", false);
  ASSERT_TRUE(r.ok()) << r.message;
  const json fixed = read_json(dir / "fixed" / "result.json");
  EXPECT_EQ(fixed["simulations"], 20);
  EXPECT_EQ(fixed["surrogate"]["batch"], 2) << "one point per parallel program";
  EXPECT_EQ(fixed["surrogate"]["batch_reason"], "");
  EXPECT_EQ(fixed["iterations"], 1 + (20 - 8) / 2) << "the design, then rounds of 2";
  EXPECT_EQ(fixed["surrogate"]["predicted"], 12) << "every proposed point was predicted before it ran";
  EXPECT_TRUE(fixed["surrogate"]["prequential_error"].is_number());
  const double coverage = fixed["surrogate"]["prequential_coverage90"].get<double>();
  EXPECT_TRUE(coverage >= 0 && coverage <= 1);
  const json& t = fixed["timing"];
  EXPECT_GT(t["model_s"].get<double>(), 0);
  EXPECT_GT(t["simulations_s"].get<double>(), 0);
  EXPECT_LE(t["model_s"].get<double>() + t["simulations_s"].get<double>(), t["wall_s"].get<double>());

  campaign["surrogate"].erase("cost_ratio");
  std::ofstream(dir / "adaptive.json") << campaign.dump(2);
  const auto a = calibrate(dir / "adaptive.json", dir / "adaptive", false);
  ASSERT_TRUE(a.ok()) << a.message;
  const json adaptive = read_json(dir / "adaptive" / "result.json");
  const int batch = adaptive["surrogate"]["batch"].get<int>();
  EXPECT_TRUE(batch == 2 || batch == 4) << batch;
  const std::string reason = adaptive["surrogate"]["batch_reason"].get<std::string>();
  EXPECT_NE(reason.find(batch > 2 ? "batches of " + std::to_string(batch) : "batches kept"), std::string::npos) << reason;
  EXPECT_NE(reason.find("s of model time, a simulation"), std::string::npos) << reason;
}

// Runs archived without a fitness for a campaign's objective (scored against another measurement of
// the same model) are scored when a "bo" campaign starts, and its model trains on them: the design
// they replace is not simulated.
TEST(SurrogateCampaign, EarlierRunsOfAnotherObjectiveAreScoredAndTrainTheModel) {
  const auto dir = surrogate_dir("scored-earlier");
  json campaign = surrogate_toy_campaign(dir, 3, "gp");
  campaign["optimiser"] = {{"algorithm", "bo"}, {"population", 8}, {"max_evaluations", 20}, {"seed", 3}};
  campaign["surrogate"] = {{"kind", "gp"}, {"min_runs", 8}, {"cost_ratio", "inf"}};
  std::ofstream(dir / "first.json") << campaign.dump(2);
  const std::string archive = (dir / "shared.sqlite").string();
  const auto first = calibrate(dir / "first.json", dir / "first", false, nullptr, archive);
  ASSERT_TRUE(first.ok()) << first.message;
  EXPECT_EQ(read_json(dir / "first" / "result.json")["iterations"], 1 + (20 - 8) / 2) << "the design, then rounds of 2";

  // Another measurement of the same wall: another objective key, the same runs.
  campaign["measured"] = toy_measurement(dir, "other.csv", 8);
  std::ofstream(dir / "second.json") << campaign.dump(2);
  const auto second = calibrate(dir / "second.json", dir / "second", false, nullptr, archive);
  ASSERT_TRUE(second.ok()) << second.message;
  const json result = read_json(dir / "second" / "result.json");
  EXPECT_EQ(result["simulations"], 20);
  EXPECT_EQ(result["iterations"], 20 / 2) << "no design: the first campaign's runs, scored again, replace it";

  // The second objective has a fitness row for every run, the first only for its own 20.
  RunArchive a(archive);
  const auto pairs = a.model_objectives();  // most rows first
  ASSERT_EQ(pairs.size(), 2u);
  EXPECT_EQ(pairs[0].rows, a.run_count());
  EXPECT_TRUE(a.unscored_runs(pairs[0].model_hash, pairs[0].objective_key).empty());
  EXPECT_EQ(pairs[1].rows, 20);
  EXPECT_EQ(static_cast<std::int64_t>(a.unscored_runs(pairs[1].model_hash, pairs[1].objective_key).size()),
            a.run_count() - 20);
}

// kill -9 during a screened campaign, then --resume: the result is the uninterrupted one.
TEST_P(SurrogateKinds, KilledAndResumedEndsWithTheUninterruptedResult) {
  const auto dir = surrogate_dir("resume-" + GetParam());
  std::ofstream(dir / "campaign.json") << surrogate_toy_campaign(dir, 5, GetParam()).dump(2);
  const std::string log = (dir / "simulator.log").string();
  ::setenv("TOY_SIMULATOR_LOG", log.c_str(), 1);
  auto logged_runs = [&] {
    std::ifstream in(log);
    size_t lines = 0;
    for (std::string line; std::getline(in, line);) ++lines;
    return lines;
  };
  const auto reference = calibrate(dir / "campaign.json", dir / "uninterrupted", false);
  ASSERT_TRUE(reference.ok()) << reference.message;
  fs::remove(log);
  std::mt19937 rng(77);
  // Kills after 10..14 runs (inside the screened iterations), then after 4..6 more.
  for (int attempt = 0; attempt < 2; ++attempt) {
    const size_t target = logged_runs() + static_cast<size_t>(attempt == 0 ? 10 + rng() % 5 : 4 + rng() % 3);
    std::atomic<bool> kill{false}, ended{false};
    std::thread watcher([&] {
      while (!ended.load() && logged_runs() < target) std::this_thread::sleep_for(std::chrono::milliseconds(10));
      std::this_thread::sleep_for(std::chrono::milliseconds(static_cast<int>(rng() % 40)));
      kill.store(true);
    });
    const auto r = calibrate(dir / "campaign.json", dir / "killed", attempt > 0, &kill);
    ended.store(true);
    watcher.join();
    ASSERT_EQ(r.status, ProcessStatus::cancelled) << "attempt " << attempt << " was not killed: " << r.message;
  }
  const auto last = calibrate(dir / "campaign.json", dir / "killed", true);
  ::unsetenv("TOY_SIMULATOR_LOG");
  ASSERT_TRUE(last.ok()) << last.message;
  auto comparable = [](json j) {
    j.erase("wall_time_s");
    j.erase("timing");
    j.erase("session");
    j.erase("archive");
    return j;
  };
  const json a = comparable(read_json(dir / "uninterrupted" / "result.json"));
  const json b = comparable(read_json(dir / "killed" / "result.json"));
  EXPECT_EQ(a.dump(), b.dump());
  EXPECT_GT(a["surrogate"]["screened_out"].get<long>(), 0);
}

// `demcal surrogate check` and `train` on a campaign's archive, and a trained model used by
// `demcal calibrate --surrogate MODEL` (it screens from the first iteration on).
TEST(SurrogateCli, CheckTrainAndCalibrateWithAModel) {
  const auto dir = surrogate_dir("cli");
  json campaign = surrogate_toy_campaign(dir);
  campaign.erase("surrogate");
  campaign["optimiser"]["max_evaluations"] = 40;
  std::ofstream(dir / "campaign.json") << campaign.dump(2);
  ASSERT_TRUE(calibrate(dir / "campaign.json", dir / "plain", false).ok());
  const std::string archive = (dir / "plain" / "archive.sqlite").string();
  auto demcal = [&](const std::vector<std::string>& args, const std::string& out) {
    ProcessOptions o;
    o.argv = {DEMCAL_BINARY};
    o.argv.insert(o.argv.end(), args.begin(), args.end());
    o.stdout_path = (dir / out).string();
    o.stderr_path = (dir / (out + ".stderr")).string();
    o.timeout_s = 120;
    return run_process(o);
  };
  ASSERT_TRUE(demcal({"surrogate", "check", "--archive", archive, "--kind", "gp"}, "check.json").ok());
  const json check = read_json(dir / "check.json");
  RunArchive a(archive);
  EXPECT_EQ(check["rows"].get<std::int64_t>(), a.run_count());
  const json& cv = check["cross_validation"];
  EXPECT_EQ(cv["finite_rows"].get<long>() + cv["failed_rows"].get<long>(), check["rows"].get<long>());
  EXPECT_GE(cv["coverage90"].get<double>(), 0.0);
  EXPECT_LE(cv["coverage90"].get<double>(), 1.0);
  EXPECT_LT(cv["relative_error"].get<double>(), 1.0) << "better than predicting the mean";

  ASSERT_TRUE(demcal({"surrogate", "train", "--archive", archive, "--kind", "gp", "--out", (dir / "model.json").string()},
                     "train.json").ok());
  EXPECT_EQ(read_json(dir / "model.json")["format"], "demcal-surrogate");
  EXPECT_EQ(read_json(dir / "train.json")["rows"], check["rows"]);

  const auto wrong = demcal({"surrogate", "train", "--archive", archive, "--scene-hash", "0123", "--out",
                             (dir / "x.json").string()}, "wrong.json");
  EXPECT_FALSE(wrong.ok());
  std::ifstream err(dir / "wrong.json.stderr");
  const std::string message((std::istreambuf_iterator<char>(err)), std::istreambuf_iterator<char>());
  EXPECT_NE(message.find("0123"), std::string::npos) << message;

  // A fresh archive, the trained model: screened from the first batch.
  json with_model = surrogate_toy_campaign(dir, 9);
  with_model["surrogate"]["model"] = (dir / "model.json").string();
  with_model["optimiser"]["max_evaluations"] = 12;
  std::ofstream(dir / "with-model.json") << with_model.dump(2);
  ASSERT_TRUE(calibrate(dir / "with-model.json", dir / "with-model", false).ok());
  const json result = read_json(dir / "with-model" / "result.json");
  EXPECT_EQ(result["surrogate"]["simulated"], 12);
  // 8 proposed -> 4 simulated, twice; the last batch is cut to the 4 simulations left.
  EXPECT_EQ(result["surrogate"]["screened_out"], 8);

  // The mlp kind scores predicted curves against a measurement: it needs the campaign that names it.
  const std::string campaign_file = (dir / "campaign.json").string();
  EXPECT_FALSE(demcal({"surrogate", "check", "--archive", archive, "--kind", "mlp"}, "mlp-alone.json").ok());
  ASSERT_TRUE(demcal({"surrogate", "check", "--archive", archive, "--kind", "mlp", "--campaign", campaign_file},
                     "mlp-check.json").ok());
  const json mlp = read_json(dir / "mlp-check.json");
  EXPECT_EQ(mlp["kind"], "mlp");
  EXPECT_EQ(mlp["cross_validation"]["finite_rows"], cv["finite_rows"]) << "every scored run has its curves";
  EXPECT_LT(mlp["cross_validation"]["relative_error"].get<double>(), 0.5);
  ASSERT_TRUE(demcal({"surrogate", "train", "--archive", archive, "--kind", "mlp", "--campaign", campaign_file, "--out",
                      (dir / "mlp-model.json").string()}, "mlp-train.json").ok());
  EXPECT_EQ(read_json(dir / "mlp-model.json")["kind"], "mlp");
  // A campaign given the mlp model takes its kind and screens from the first batch.
  json with_mlp = surrogate_toy_campaign(dir, 9);
  with_mlp["surrogate"].erase("kind");
  with_mlp["surrogate"]["model"] = (dir / "mlp-model.json").string();
  with_mlp["optimiser"]["max_evaluations"] = 12;
  std::ofstream(dir / "with-mlp.json") << with_mlp.dump(2);
  ASSERT_TRUE(calibrate(dir / "with-mlp.json", dir / "with-mlp", false).ok());
  const json mlp_result = read_json(dir / "with-mlp" / "result.json");
  EXPECT_EQ(mlp_result["surrogate"]["kind"], "mlp");
  EXPECT_EQ(mlp_result["surrogate"]["screened_out"], 8);
}
