// Process runner (no shell, timeouts kill the group) and the SQLite run archive.
#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/process.hpp"
#include "demcal/pipelines/progress.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <thread>
#include <filesystem>
#include <fstream>

namespace fs = std::filesystem;
using namespace demcal::pipelines;

namespace {
fs::path process_archive_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("demcal-test-pipelines-" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}
}  // namespace

TEST(CommandTemplate, SplitsWithoutAShellAndExpandsPlaceholders) {
  const auto words = split_command_line("python3 'my sim.py' --k {kn} \"{output}\" a\\ b x={friction_deg}deg");
  ASSERT_EQ(words.size(), 7u);
  EXPECT_EQ(words[1], "my sim.py");
  EXPECT_EQ(words[5], "a b");
  EXPECT_EQ(placeholder_names(words), (std::vector<std::string>{"kn", "output", "friction_deg"}));
  const auto expanded = expand_placeholders(words, {{"kn", "1e9"}, {"output", "/o.csv"}, {"friction_deg", "30"}});
  EXPECT_EQ(expanded[3], "1e9");
  EXPECT_EQ(expanded[4], "/o.csv");
  EXPECT_EQ(expanded[6], "x=30deg");
  EXPECT_THROW(expand_placeholders(words, {{"kn", "1"}}), std::invalid_argument);
  EXPECT_THROW(split_command_line("a 'b"), std::invalid_argument);
  EXPECT_THROW(split_command_line("   "), std::invalid_argument);
  try {
    expand_placeholders({"{nope}"}, {{"kn", "1"}});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("{nope}"), std::string::npos);
  }
}

TEST(Process, ReportsExitCodeSignalAndMissingProgram) {
  const auto dir = process_archive_dir("process");
  ProcessOptions o;
  o.argv = {"sh", "-c", "echo hello; echo oops >&2; exit 3"};
  o.stdout_path = (dir / "out.txt").string();
  o.stderr_path = (dir / "err.txt").string();
  auto r = run_process(o);
  EXPECT_EQ(r.status, ProcessStatus::exited);
  EXPECT_EQ(r.exit_code, 3);
  std::ifstream out(o.stdout_path);
  std::string line;
  std::getline(out, line);
  EXPECT_EQ(line, "hello");

  o.argv = {"sh", "-c", "kill -SEGV $$"};
  r = run_process(o);
  EXPECT_EQ(r.status, ProcessStatus::signalled);
  EXPECT_EQ(r.signal, 11);

  o.argv = {"/no/such/program"};
  r = run_process(o);
  EXPECT_EQ(r.status, ProcessStatus::failed_to_start);
  EXPECT_NE(r.message.find("/no/such/program"), std::string::npos);

  o.argv = {"true"};
  o.working_directory = (dir / "missing").string();
  r = run_process(o);
  EXPECT_EQ(r.status, ProcessStatus::failed_to_start);
}

TEST(Process, TimeoutKillsTheWholeProcessGroup) {
  const auto dir = process_archive_dir("timeout");
  const auto marker = dir / "child.pid";
  ProcessOptions o;
  // The shell starts a grandchild that would outlive a kill of the shell alone.
  o.argv = {"sh", "-c", "sleep 30 & echo $! > " + marker.string() + "; wait"};
  o.timeout_s = 0.5;
  const auto r = run_process(o);
  EXPECT_EQ(r.status, ProcessStatus::timed_out);
  EXPECT_GE(r.wall_time_s, 0.5);
  EXPECT_LT(r.wall_time_s, 5.0);
  std::ifstream in(marker);
  long pid = 0;
  in >> pid;
  ASSERT_GT(pid, 0);
  // The grandchild is gone, not even a zombie, when run_process returns: the supervisor killed and
  // reaped it before reporting.
  const bool alive = fs::exists("/proc/" + std::to_string(pid));
  EXPECT_FALSE(alive) << "grandchild " << pid << " survived the timeout";
}

TEST(Archive, ParameterKeyIsExactAndOrderFree) {
  EXPECT_EQ(parameter_key({{"kn", 4e9}, {"friction_deg", 30.5}}), parameter_key({{"friction_deg", 30.5}, {"kn", 4e9}}));
  EXPECT_NE(parameter_key({{"kn", 4e9}}), parameter_key({{"kn", std::nextafter(4e9, 5e9)}}));
  EXPECT_EQ(hash_text("abc"), hash_text("abc"));
  EXPECT_NE(hash_text("abc"), hash_text("abd"));
}

TEST(Archive, RunsFitnessAndIterationsSurviveReopening) {
  const auto dir = process_archive_dir("archive");
  const std::string path = (dir / "a.sqlite").string();
  RunRecord run;
  run.model_hash = "scene1";
  run.params = {{"kn", 3.123456789012345e9}, {"friction_deg", 30.1}};
  run.code_version = "test";
  run.backend = "threads";
  run.status = "completed";
  run.curves.columns = {{"time", "s", {0, 0.1, 0.2}}, {"force", "N", {0, 1.0 / 3.0, std::nan("")}},
                        {"load_vertical", "m", {0, 1e-4, 2e-4}}};
  run.details = {{"hinges", {"a/b"}}};
  std::int64_t id = 0;
  {
    RunArchive archive(path);
    id = archive.insert_run(run);
    EXPECT_EQ(archive.insert_run(run), id);  // never twice
    EXPECT_EQ(archive.run_count(), 1);
    FitnessRecord f;
    f.run_id = id;
    f.objective_key = "obj";
    f.objective = 2;
    f.objective1 = 12.5;
    f.objective2 = 10.25;
    f.fitness = 10.25;
    archive.put_fitness(f);
    FitnessRecord failed = f;
    failed.objective_key = "other";
    failed.fitness = std::nan("");
    archive.put_fitness(failed);
    CampaignRecord c;
    c.name = "c";
    c.config_key = "key";
    const auto cid = archive.create_campaign(c);
    IterationRecord it;
    it.campaign_id = cid;
    it.iteration = 0;
    it.optimiser_state = "{\"x\":1}";
    it.best_fitness = 10.25;
    it.evaluations = 1;
    EvaluationRecord e;
    e.params = run.params;
    e.run_ids = {id};
    e.fitness = 10.25;
    archive.commit_iteration(it, {e});
  }
  RunArchive archive(path);
  const auto back = archive.find_run("scene1", {{"friction_deg", 30.1}, {"kn", 3.123456789012345e9}});
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(back->id, id);
  EXPECT_EQ(back->params, run.params);
  ASSERT_EQ(back->curves.columns.size(), 3u);
  EXPECT_EQ(back->curves.column("force").values[1], 1.0 / 3.0);  // bit-identical
  EXPECT_TRUE(std::isnan(back->curves.column("force").values[2]));
  EXPECT_EQ(back->curves.column("load_vertical").unit, "m");
  EXPECT_EQ(back->details["hinges"][0], "a/b");
  EXPECT_FALSE(archive.find_run("scene2", run.params).has_value());
  EXPECT_EQ(archive.find_fitness(id, "obj")->objective2, 10.25);
  EXPECT_TRUE(std::isnan(archive.find_fitness(id, "other")->fitness));
  const auto campaign = archive.latest_campaign("key");
  ASSERT_TRUE(campaign.has_value());
  EXPECT_EQ(archive.last_iteration(campaign->id)->optimiser_state, "{\"x\":1}");
  const auto evaluations = archive.evaluations(campaign->id);
  ASSERT_EQ(evaluations.size(), 1u);
  EXPECT_EQ(evaluations[0].params, run.params);
  EXPECT_EQ(evaluations[0].run_ids, std::vector<std::int64_t>{id});
}

TEST(Archive, UnwritablePathIsAClearError) {
  try {
    RunArchive archive("/no/such/folder/a.sqlite");
    FAIL();
  } catch (const ArchiveError& e) {
    EXPECT_NE(std::string(e.what()).find("/no/such/folder/a.sqlite"), std::string::npos);
  }
}

TEST(Progress, FormatsAPlainLine) {
  ProgressState s;
  s.iteration = 3;
  s.iterations = 20;
  s.done = 30;
  s.total = 200;
  s.best = 123.4;
  s.elapsed_s = 12;
  s.simulation_s = 9;
  s.model_s = 2;
  s.done_this_session = 30;
  EXPECT_EQ(format_progress(s),
            "iteration 3/20  simulations 30/200  best 123.4  elapsed 12 s (simulations 9 s, model 2 s)  left ~1 min 08 s");
  s.iterations = 0;  // not known in advance
  EXPECT_EQ(format_progress(s),
            "iteration 3  simulations 30/200  best 123.4  elapsed 12 s (simulations 9 s, model 2 s)  left ~1 min 08 s");
  s.iterations = 2;  // never "3/2"
  EXPECT_EQ(format_progress(s).rfind("iteration 3  simulations", 0), 0u);
  EXPECT_EQ(format_duration(3725), "1 h 02 min");
}
