// Crash safety of the run archive: several writers at once (threads with their own connections,
// and two `demcal calibrate` processes sharing one archive file) keep every run.
#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/process.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <set>
#include <thread>

namespace fs = std::filesystem;
using namespace demcal::pipelines;
using nlohmann::json;

namespace {

RunRecord small_run(const std::string& model, double k) {
  RunRecord run;
  run.model_hash = model;
  run.params = {{"k", k}};
  run.code_version = "test";
  run.backend = "threads";
  run.status = "completed";
  run.curves.columns = {{"force", "N", {0, k, 2 * k}}, {"top_horizontal", "m", {0, 1e-3, 2e-3}}};
  return run;
}

}  // namespace

// Four connections (one per thread) insert runs, fitness rows and iterations into one file as
// fast as they can; each writer's rows all arrive and the file stays consistent.
TEST(CrashSafety, ConcurrentWritersKeepEveryRow) {
  const auto dir = test_support::fresh_dir("crash", "writers");
  const std::string path = (dir / "shared.sqlite").string();
  constexpr int kWriters = 4, kRuns = 150;
  std::vector<std::thread> writers;
  std::vector<std::string> errors(kWriters);
  for (int w = 0; w < kWriters; ++w)
    writers.emplace_back([&, w] {
      try {
        RunArchive archive(path);
        CampaignRecord c;
        c.name = "writer" + std::to_string(w);
        c.config_key = c.name;
        const auto campaign = archive.create_campaign(c);
        for (int i = 0; i < kRuns; ++i) {
          // Half of the runs are shared by all writers: the archive keeps one row for each.
          const std::string model = i % 2 ? "own" + std::to_string(w) : "shared";
          const auto id = archive.insert_run(small_run(model, 1e6 + i));
          FitnessRecord f;
          f.run_id = id;
          f.objective_key = c.name;
          f.fitness = i;
          archive.put_fitness(f);
          IterationRecord it;
          it.campaign_id = campaign;
          it.iteration = i;
          it.optimiser_state = "{}";
          EvaluationRecord e;
          e.params = {{"k", 1e6 + i}};
          e.run_ids = {id};
          e.fitness = i;
          archive.commit_iteration(it, {e});
        }
      } catch (const std::exception& e) {
        errors[w] = e.what();
      }
    });
  for (auto& t : writers) t.join();
  for (const auto& e : errors) EXPECT_EQ(e, "");
  RunArchive archive(path);
  EXPECT_EQ(archive.integrity_check(), "ok");
  EXPECT_EQ(archive.run_count(), kRuns / 2 + kWriters * kRuns / 2);
  for (int w = 0; w < kWriters; ++w) {
    const auto campaign = archive.latest_campaign("writer" + std::to_string(w));
    ASSERT_TRUE(campaign.has_value());
    const auto evaluations = archive.evaluations(campaign->id);
    ASSERT_EQ(evaluations.size(), static_cast<size_t>(kRuns));
    for (const auto& e : evaluations) {
      const auto run = archive.run(e.run_ids.at(0));
      ASSERT_TRUE(run.has_value());
      EXPECT_EQ(run->params, e.params);
      EXPECT_EQ(archive.find_fitness(run->id, "writer" + std::to_string(w))->fitness, e.fitness);
    }
  }
}

// Two `demcal calibrate` processes (different seeds) write one archive at the same time: both
// finish, every run of both is kept, and each result equals that of the campaign run alone.
TEST(CrashSafety, TwoCampaignProcessesShareOneArchive) {
  const auto dir = test_support::fresh_dir("crash", "two-processes");
  const std::string measured = (dir / "measured.csv").string();
  {
    ProcessOptions o;
    o.argv = {test_support::python(), test_support::kToySimulator, "2e7", "32", measured, "--noise", "20", "--seed", "7"};
    o.timeout_s = 30;
    ASSERT_TRUE(run_process(o).ok());
  }
  auto campaign = [&](int seed) {
    const json c = {
        {"name", "share-" + std::to_string(seed)},
        {"measured", measured},
        {"parameters", {{{"name", "k"}, {"lower", 1e6}, {"upper", 1e8}, {"scale", "log"}},
                        {{"name", "friction_deg"}, {"lower", 25}, {"upper", 45}}}},
        {"objective", 1},
        {"optimiser", {{"algorithm", "pso"}, {"population", 6}, {"iterations", 6}, {"seed", seed}}},
        {"backend", {{"type", "command"},
                     {"command", test_support::python() + " " + test_support::kToySimulator + " {k} {friction_deg} {output}"},
                     {"parallel", 2}}},
        {"report", false}};
    const fs::path file = dir / ("campaign-" + std::to_string(seed) + ".json");
    std::ofstream(file) << c.dump(2);
    return file.string();
  };
  const std::string a = campaign(3), b = campaign(4);
  auto demcal = [&](const std::string& file, const std::string& out, const std::string& archive) {
    ProcessOptions o;
    o.argv = {DEMCAL_BINARY, "calibrate", file, "--out", (dir / out).string(), "--quiet"};
    if (!archive.empty()) o.argv.insert(o.argv.end(), {"--archive", archive});
    o.timeout_s = 300;
    o.stderr_path = (dir / (out + ".stderr")).string();
    return run_process(o);
  };
  // Alone, each with its own archive.
  ASSERT_TRUE(demcal(a, "alone-a", "").ok());
  ASSERT_TRUE(demcal(b, "alone-b", "").ok());
  // At once, one archive.
  const std::string shared = (dir / "shared.sqlite").string();
  ProcessResult ra, rb;
  std::thread other([&] { rb = demcal(b, "shared-b", shared); });
  ra = demcal(a, "shared-a", shared);
  other.join();
  ASSERT_TRUE(ra.ok()) << ra.message;
  ASSERT_TRUE(rb.ok()) << rb.message;

  auto comparable = [](json j) {
    j.erase("wall_time_s");
    j.erase("timing");
    j.erase("session");
    j.erase("archive");
    return j;
  };
  RunArchive archive(shared);
  EXPECT_EQ(archive.integrity_check(), "ok");
  std::set<std::string> distinct;
  for (const std::string side : {"a", "b"}) {
    const json alone = test_support::read_json(dir / ("alone-" + side) / "result.json");
    const json together = test_support::read_json(dir / ("shared-" + side) / "result.json");
    EXPECT_EQ(comparable(alone).dump(), comparable(together).dump()) << side;
    const auto evaluations = archive.evaluations(together["session"]["campaign_id"].get<std::int64_t>());
    EXPECT_EQ(evaluations.size(), 36u) << side;
    for (const auto& e : evaluations) {
      const auto run = archive.run(e.run_ids.at(0));
      ASSERT_TRUE(run.has_value()) << side << " lost a run";
      EXPECT_EQ(run->params, e.params);
      EXPECT_EQ(run->status, "completed");
      distinct.insert(parameter_key(e.params));
    }
  }
  EXPECT_EQ(archive.run_count(), static_cast<std::int64_t>(distinct.size()));
}
