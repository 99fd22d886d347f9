// External simulator faults: every way a simulator can misbehave (tests/pipelines/
// faulty_simulator.sh) gives a failed run with a reason, the other runs go on, and no process the
// simulator started survives its run (checked by pid, with no grace period: the runner reaps
// everything before it reports).
#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/backend.hpp"
#include "demcal/pipelines/campaign.hpp"
#include "demcal/pipelines/process.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <thread>

namespace fs = std::filesystem;
using namespace demcal::pipelines;
using nlohmann::json;

namespace {

const std::string kFaulty = std::string(DEMCAL_SOURCE_DIR) + "/tests/pipelines/faulty_simulator.sh";

std::vector<long> pids_in(const fs::path& file) {
  std::vector<long> pids;
  std::ifstream in(file);
  for (long pid = 0; in >> pid;) pids.push_back(pid);
  return pids;
}

// A process that still exists (running, stopped or a zombie nobody reaped).
bool exists(long pid) { return fs::exists("/proc/" + std::to_string(pid)); }

std::string leftovers(const std::vector<long>& pids) {
  std::string alive;
  for (long pid : pids)
    if (exists(pid)) alive += " " + std::to_string(pid);
  return alive;
}

CommandBackendOptions faulty_backend(const std::string& fault, const fs::path& dir) {
  CommandBackendOptions o;
  o.command = "sh " + kFaulty + " " + fault + " {k} {friction_deg} {output}";
  o.timeout_s = 1.5;
  o.parallel = 4;
  o.work_root = (dir / "runs").string();
  o.case_names = {"main"};
  o.parameter_names = {"k", "friction_deg"};
  o.max_output_bytes = 1 << 20;
  return o;
}

struct Fault {
  std::string name;
  std::vector<std::string> needles;  // every one must be in the failed run's message
  size_t processes = 1;              // processes a faulty run starts (all recorded in ./pids)
};

void PrintTo(const Fault& f, std::ostream* os) { *os << f.name; }

class SimulatorFault : public ::testing::TestWithParam<Fault> {};

}  // namespace

// Two good runs (friction < 35 deg) and two faulty ones (>= 35) in one batch, four at once.
TEST_P(SimulatorFault, RunFailsWithItsReasonAndNothingSurvives) {
  const Fault& fault = GetParam();
  const auto dir = test_support::fresh_dir("faults", fault.name);
  CommandBackend backend(faulty_backend(fault.name, dir));
  const std::vector<SimulationTask> tasks{{0, {{"k", 2e7}, {"friction_deg", 30}}},
                                          {0, {{"k", 2e7}, {"friction_deg", 40}}},
                                          {0, {{"k", 3e7}, {"friction_deg", 31}}},
                                          {0, {{"k", 3e7}, {"friction_deg", 41}}}};
  std::vector<SimulationOutcome> outcomes(tasks.size());
  backend.run(tasks, [&](size_t i, SimulationOutcome&& o) { outcomes[i] = std::move(o); });
  for (size_t i = 0; i < tasks.size(); ++i) {
    const auto& o = outcomes[i];
    const fs::path workdir = o.details.at("workdir").get<std::string>();
    const auto pids = pids_in(workdir / "pids");
    EXPECT_GE(pids.size(), i % 2 ? fault.processes : 1) << "the simulator did not run in " << workdir;
    EXPECT_EQ(leftovers(pids), "") << fault.name << ": processes still there after run " << i;
    if (i % 2 == 0) {
      EXPECT_EQ(o.status, "completed") << o.message;
      EXPECT_EQ(o.curves.column("force").values.size(), 21u);
      continue;
    }
    EXPECT_EQ(o.status, "failed") << fault.name;
    EXPECT_EQ(o.curves.rows(), 0u);
    if (i == 1) RecordProperty("message", o.message);  // quoted in docs/bad-input.md
    for (const auto& needle : fault.needles)
      EXPECT_NE(o.message.find(needle), std::string::npos) << "'" << needle << "' not in: " << o.message;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Faults, SimulatorFault,
    ::testing::Values(Fault{"exit-code", {"exit code 3", "stderr: solver diverged at step 12"}},
                      Fault{"crash", {"killed by signal 11"}},
                      Fault{"empty", {"output.csv is empty"}},
                      Fault{"no-output", {"wrote no output file", "output.csv"}},
                      Fault{"huge-output", {"signal 25", "reached the limit of 1048576 bytes", "max_output_mb"}},
                      Fault{"huge-stdout", {"signal 25", "reached the limit of 1048576 bytes"}},
                      Fault{"nan", {"output.csv: line 9, column 'force': non-finite value 'nan'"}},
                      Fault{"inf", {"output.csv", "line 9", "column 'force'", "'inf'"}},
                      Fault{"malformed", {"output unreadable", "output.csv"}},
                      Fault{"ragged", {"output unreadable", "output.csv", "line 23"}},
                      Fault{"no-force", {"output unreadable", "no column 'force'", "shear"}},
                      Fault{"one-row", {"output unreadable", "output.csv"}},
                      Fault{"hang", {"killed after the 1.5 s timeout"}, 3},
                      Fault{"hang-setsid", {"killed after the 1.5 s timeout"}, 2},
                      Fault{"hang-double-fork", {"killed after the 1.5 s timeout"}, 2}),
    [](const ::testing::TestParamInfo<Fault>& info) {
      std::string name = info.param.name;
      for (auto& c : name)
        if (c == '-') c = '_';
      return name;
    });

// A simulator that finishes well but leaves a detached (setsid, double-forked) process behind: the
// run counts, says so, and the process is gone.
TEST(SimulatorFaults, DetachedLeftoverOfAGoodRunIsKilled) {
  const auto dir = test_support::fresh_dir("faults", "leave-daemon");
  CommandBackend backend(faulty_backend("leave-daemon", dir));
  const auto o = backend.run_one({0, {{"k", 2e7}, {"friction_deg", 40}}});
  EXPECT_EQ(o.status, "completed") << o.message;
  RecordProperty("message", o.message);
  EXPECT_NE(o.message.find("left 1 process(es) running after it exited; killed"), std::string::npos) << o.message;
  const auto pids = pids_in(fs::path(o.details.at("workdir").get<std::string>()) / "pids");
  EXPECT_EQ(pids.size(), 2u);
  EXPECT_EQ(leftovers(pids), "");
}

TEST(SimulatorFaults, MissingProgramIsAFailedRun) {
  const auto dir = test_support::fresh_dir("faults", "missing");
  auto options = faulty_backend("none", dir);
  options.command = "/no/such/simulator {k} {output}";
  CommandBackend backend(options);
  const auto o = backend.run_one({0, {{"k", 2e7}, {"friction_deg", 40}}});
  EXPECT_EQ(o.status, "failed");
  RecordProperty("message", o.message);
  EXPECT_NE(o.message.find("cannot run '/no/such/simulator'"), std::string::npos) << o.message;
  EXPECT_NE(o.message.find("No such file"), std::string::npos) << o.message;
}

// The caller itself dies by SIGKILL while a simulator (with a setsid child and a double-forked
// grandchild) hangs: the supervisor sees its lifeline close and kills them all.
TEST(SimulatorFaults, CallerKilledWithSigkillTakesTheSimulatorTreeAlong) {
  const auto dir = test_support::fresh_dir("faults", "caller-killed");
  const fs::path pids_file = dir / "pids";
  // Orphaned supervisors come to this process (not to init, which may not reap in a container).
  ASSERT_EQ(::prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0), 0);
  const pid_t caller = ::fork();
  ASSERT_GE(caller, 0);
  if (caller == 0) {
    ProcessOptions o;
    o.argv = {"sh", "-c",
              "echo $$ >> pids; setsid sh -c 'echo $$ >> pids; exec sleep 1000' & "
              "( sh -c 'echo $$ >> pids; exec sleep 1000' & ) ; exec sleep 1000"};
    o.working_directory = dir.string();
    run_process(o);
    ::_exit(0);
  }
  for (int i = 0; i < 500 && pids_in(pids_file).size() < 3; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const auto pids = pids_in(pids_file);
  ASSERT_EQ(pids.size(), 3u);
  for (long pid : pids) EXPECT_TRUE(exists(pid)) << pid << " ended before the caller was killed";
  ::kill(caller, SIGKILL);
  int status = 0;
  ::waitpid(caller, &status, 0);
  // The supervisor cleans up on its own; reap it (and anything else) as it ends.
  std::string alive;
  for (int i = 0; i < 500; ++i) {
    while (::waitpid(-1, &status, WNOHANG) > 0) {
    }
    alive = leftovers(pids);
    if (alive.empty()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ::prctl(PR_SET_CHILD_SUBREAPER, 0, 0, 0, 0);
  EXPECT_EQ(alive, "") << "survived the caller's SIGKILL";
}

// A whole campaign through a simulator that fails in three ways by friction band: the campaign
// ends, each failed run's reason is archived and listed in the report, and no process survives.
TEST(SimulatorFaults, CampaignGoesOnAndTheReportListsEveryFailure) {
  const auto dir = test_support::fresh_dir("faults", "campaign");
  const std::string measured = (dir / "measured.csv").string();
  {
    ProcessOptions o;
    o.argv = {"sh", kFaulty, "none", "2e7", "32", measured};
    o.working_directory = dir.string();
    ASSERT_TRUE(run_process(o).ok());
  }
  const json campaign = {
      {"name", "faults"},
      {"measured", measured},
      {"parameters", {{{"name", "k"}, {"lower", 1e6}, {"upper", 1e8}, {"scale", "log"}},
                      {{"name", "friction_deg"}, {"lower", 25}, {"upper", 45}}}},
      {"objective", 1},
      {"optimiser", {{"algorithm", "pso"}, {"population", 10}, {"iterations", 2}, {"seed", 4}}},
      {"backend", {{"type", "command"}, {"command", "sh " + kFaulty + " mixed {k} {friction_deg} {output}"},
                   {"timeout_s", 1.0}, {"parallel", 4}}},
      {"output", (dir / "out").string()},
      {"report", true}};
  const CampaignConfig config = campaign_from_json(campaign, dir.string(), "faults.json");
  RunOptions options;
  options.progress = false;
  const CampaignResult result = run_campaign(config, options);
  EXPECT_EQ(result.status, CampaignStatus::completed);
  EXPECT_EQ(result.simulations, 20);
  int fine = 0, nan = 0, hung = 0, exited = 0;
  for (const auto& s : result.all) {
    const double phi = s.params.at("friction_deg");
    (phi < 32 ? fine : phi < 36 ? nan : phi < 39 ? hung : exited) += 1;
    EXPECT_EQ(std::isfinite(s.fitness), phi < 32) << phi;
  }
  EXPECT_GT(fine, 0);
  EXPECT_GT(nan, 0);
  EXPECT_GT(hung, 0);
  EXPECT_GT(exited, 0);
  EXPECT_EQ(result.failed_runs, nan + hung + exited);

  // Reasons in the archive and in the report.
  RunArchive archive((dir / "out" / "archive.sqlite").string());
  const auto failed = archive.runs_with_status("failed");
  EXPECT_EQ(static_cast<int>(failed.size()), result.failed_runs);
  std::ifstream report_file(dir / "out" / "report.md");
  const std::string report((std::istreambuf_iterator<char>(report_file)), std::istreambuf_iterator<char>());
  EXPECT_NE(report.find("## Failed runs"), std::string::npos);
  for (const auto& run : failed) {
    EXPECT_EQ(run.status, "failed");
    const double phi = run.params.at("friction_deg");
    const std::string expected = phi < 36 ? "non-finite value 'nan'" : phi < 39 ? "timeout" : "exit code 3";
    EXPECT_NE(run.message.find(expected), std::string::npos) << run.message;
    EXPECT_NE(report.find(run.message.substr(0, 60)), std::string::npos) << "not in the report: " << run.message;
  }

  // No process of any run is left.
  for (const auto& entry : fs::directory_iterator(dir / "out" / "runs"))
    EXPECT_EQ(leftovers(pids_in(entry.path() / "pids")), "") << entry.path();
}
