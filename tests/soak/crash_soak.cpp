// Crash-safety soak: kills a calibration campaign with SIGKILL at seeded random moments, some of
// them inside an archive write, resumes it each time, and checks that the final result equals an
// uninterrupted run and that the archive passes PRAGMA integrity_check.
//
//   build/tests/crash_soak [--kills 20] [--seed 1] [--surrogate] [--out build/soak] [--demcal build/demcal]
//
// `make soak` runs 20 kills (seconds; minutes with --surrogate); the ctest
// Soak.FiveKillsWithTheSurrogateResumeToTheSameResult runs 5 with --surrogate in `make test`.
//
// The campaign: the reference arch (3 contact points per joint, 4 mm of loading), kn and friction
// free, objective 2, TBPSO 6 x 8, threads backend. --surrogate turns on pre-screening
// (docs/surrogate.md): from the 8th finished run on, each iteration ranks a pool of 4 x 6
// candidates with the surrogate model refitted to the archive and simulates the best 3.
// Every demcal process runs with DEMCAL_ARCHIVE_WRITE_PAUSE_MS set, so each archive write
// announces itself on stderr. Odd-numbered kills (1st, 3rd, ...) set it to 40: every write holds
// its transaction open 40 ms before COMMIT; the kill waits for a random 1st..12th write of the
// attempt to begin and lands inside it (confirmed afterwards: the attempt's last stderr line is
// that write's "begins"). Even-numbered kills set it to 0 (no pause) and land after a random delay
// between 0.1 s and the uninterrupted run's wall time, wherever the campaign is. When an attempt
// finishes before its kill, its result is checked and the next kill starts a fresh campaign
// folder (a new cycle). Exit status 0 when every check passed.
#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/process.hpp"

#include <nlohmann/json.hpp>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>
#include <string>
#include <thread>

namespace fs = std::filesystem;
using namespace demcal::pipelines;
using nlohmann::json;

namespace {

std::string read_text(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

json comparable(const fs::path& result) {
  json j = json::parse(read_text(result));
  j.erase("wall_time_s");
  j.erase("timing");
  j.erase("session");
  j.erase("archive");
  return j;
}

// Highest write number whose "begins" line is in the stderr text, and whether it also ended.
std::pair<long, bool> last_write(const std::string& text) {
  long last = 0;
  bool ended = true;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    long n = 0;
    char what[16] = {0};
    if (std::sscanf(line.c_str(), "demcal-archive: write %ld %15s", &n, what) != 2) continue;
    if (std::string(what) == "begins") {
      last = n;
      ended = false;
    } else if (n == last) {
      ended = true;
    }
  }
  return {last, ended};
}

// The last `lines` lines of a demcal process's stderr, indented: what a failed run said (a
// sanitizer's report, an exception), printed with the failure.
std::string stderr_tail(const fs::path& path, std::size_t lines = 40) {
  std::deque<std::string> kept;
  std::istringstream text(read_text(path));
  for (std::string line; std::getline(text, line);) {
    if (line.rfind("demcal-archive: write ", 0) == 0) continue;  // the write announcements
    kept.push_back(line);
    if (kept.size() > lines) kept.pop_front();
  }
  std::string tail = "  " + path.string() + (kept.empty() ? " is empty\n" : " ends:\n");
  for (const auto& line : kept) tail += "    " + line + "\n";
  return tail;
}

}  // namespace

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  int kills = 20;
  unsigned seed = 1;
  fs::path out = "build/soak";
  bool surrogate = false;
  fs::path demcal = DEMCAL_BINARY;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--surrogate") {
      surrogate = true;
      continue;
    }
    if (i + 1 >= argc) {
      std::cerr << "crash_soak: " << flag << " needs a value\n";
      return 1;
    }
    const std::string value = argv[++i];
    if (flag == "--kills") kills = std::stoi(value);
    else if (flag == "--seed") seed = static_cast<unsigned>(std::stoul(value));
    else if (flag == "--out") out = value;
    else if (flag == "--demcal") demcal = value;
    else {
      std::cerr << "crash_soak: unknown flag " << flag << "\n";
      return 1;
    }
  }
  if (!fs::exists(demcal)) {
    std::cerr << "crash_soak: no demcal program at " << demcal << " (use --demcal)\n";
    return 1;
  }
  fs::remove_all(out);
  fs::create_directories(out);
  out = fs::absolute(out);
  json campaign = {
      {"name", "soak"},
      {"scene", {{"generator", "arch"},
                 {"options", {{"contacts_per_joint", 3}, {"velocity", 0.05}, {"max_displacement", 0.004}}}}},
      {"measured", {{"file", std::string(DEMCAL_SOURCE_DIR) + "/data/arch/measured.csv"},
                    {"columns", {{"force", {{"column", "force"}, {"unit", "kN"}}},
                                 {"load_vertical", {{"column", "load_vertical"}, {"unit", "mm"}}},
                                 {"abutment_horizontal", {{"column", "abutment_horizontal"}, {"unit", "mm"}}}}}}},
      {"parameters", {{{"name", "kn"}, {"lower", 1e9}, {"upper", 1e10}, {"scale", "log10"}},
                      {{"name", "friction_deg"}, {"lower", 28}, {"upper", 34}}}},
      {"fixed", {{"ks", 2e9}}},
      {"objective", {{"type", 2}, {"smoother", {{"epochs", 60}}}}},
      {"optimiser", {{"algorithm", "tbpso"}, {"population", 6}, {"iterations", 8}, {"seed", 1}}},
      {"backend", {{"type", "threads"}, {"threads", 2}}},
      {"report", false}};
  if (surrogate) campaign["surrogate"] = {{"min_runs", 8}, {"pool_factor", 4}, {"k", 3}};
  std::ofstream(out / "campaign.json") << campaign.dump(2);

  // pause_ms: DEMCAL_ARCHIVE_WRITE_PAUSE_MS of the demcal process (writes announced on stderr).
  auto run = [&](const fs::path& dir, bool resume, const std::atomic<bool>* kill, const std::string& log,
                 int pause_ms) {
    ProcessOptions o;
    o.argv = {"env", "DEMCAL_ARCHIVE_WRITE_PAUSE_MS=" + std::to_string(pause_ms), demcal.string(), "calibrate", (out / "campaign.json").string(), "--out", dir.string(), "--quiet"};
    if (resume) o.argv.push_back("--resume");
    o.timeout_s = 600;
    o.cancel = kill;  // raised: SIGKILL to demcal's process group
    o.stderr_path = log;
    return run_process(o);
  };

  const auto t0 = std::chrono::steady_clock::now();
  const ProcessResult reference = run(out / "uninterrupted", false, nullptr, (out / "uninterrupted.stderr").string(), 0);
  if (!reference.ok()) {
    std::cerr << "crash_soak: the uninterrupted campaign failed: " << reference.message << "\n"
              << stderr_tail(out / "uninterrupted.stderr");
    return 1;
  }
  const json expected = comparable(out / "uninterrupted" / "result.json");
  const auto expected_runs = RunArchive((out / "uninterrupted" / "archive.sqlite").string()).run_count();
  std::printf("uninterrupted campaign: %.1f s, %lld runs\n", reference.wall_time_s,
              static_cast<long long>(expected_runs));

  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> write_target(1, 12);
  std::uniform_real_distribution<double> delay_s(0.1, reference.wall_time_s);
  int cycle = 0, attempts = 0, done_kills = 0, in_write = 0, checks = 0, failures = 0;
  bool resume = false;
  auto check = [&](const fs::path& dir, const std::string& when) {
    ++checks;
    RunArchive archive((dir / "archive.sqlite").string());
    const std::string integrity = archive.integrity_check();
    const json got = comparable(dir / "result.json");
    const bool same = got == expected;
    const bool runs = archive.run_count() == expected_runs;
    if (integrity != "ok" || !same || !runs) {
      ++failures;
      std::printf("FAILED %s: integrity %s, result %s, runs %lld of %lld\n", when.c_str(), integrity.c_str(),
                  same ? "equal" : "DIFFERENT", static_cast<long long>(archive.run_count()),
                  static_cast<long long>(expected_runs));
      if (!same)
        for (const auto& change : json::diff(expected, got))
          std::printf("  differs from the uninterrupted result at %s\n", change.at("path").get<std::string>().c_str());
    }
  };
  while (done_kills < kills) {
    const fs::path dir = out / ("cycle-" + std::to_string(cycle));
    const std::string log = (out / ("attempt-" + std::to_string(attempts) + ".stderr")).string();
    const bool aim_at_write = done_kills % 2 == 0;
    const int target = write_target(rng);
    const double delay = delay_s(rng);
    std::atomic<bool> kill{false}, ended{false};
    std::thread killer([&] {
      const auto start = std::chrono::steady_clock::now();
      while (!ended.load()) {
        if (aim_at_write) {
          const auto [last, finished] = last_write(read_text(log));
          if (last >= target && !finished) break;
        } else if (std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >= delay) {
          break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(aim_at_write ? 2 : 5));
      }
      kill.store(true);
    });
    const ProcessResult r = run(dir, resume, &kill, log, aim_at_write ? 40 : 0);
    ended.store(true);
    killer.join();
    ++attempts;
    if (r.status == ProcessStatus::cancelled) {
      ++done_kills;
      const auto [last, finished] = last_write(read_text(log));
      const bool inside = last > 0 && !finished;
      in_write += inside;
      // The archive a kill -9 leaves is consistent before any resume touches it (a kill before
      // demcal created it leaves none). Its run count says how far the campaign had got (with
      // --surrogate, screening starts at 8 runs).
      const fs::path archive = dir / "archive.sqlite";
      std::string integrity = "ok";
      long long runs = 0;
      if (fs::exists(archive)) {
        RunArchive opened(archive.string());
        integrity = opened.integrity_check();
        runs = opened.run_count();
      }
      std::printf("kill %2d (cycle %d, %s): after %.2f s, %lld runs archived%s\n", done_kills, cycle,
                  aim_at_write ? ("at write " + std::to_string(target)).c_str() : "at a random time", r.wall_time_s,
                  runs, inside ? ", inside an archive write" : "");
      if (integrity != "ok") {
        ++failures;
        std::printf("FAILED: integrity after kill %d: %s\n", done_kills, integrity.c_str());
      }
      resume = true;
    } else if (r.ok()) {
      std::printf("cycle %d finished before its kill; checking and starting a fresh cycle\n", cycle);
      check(dir, "cycle " + std::to_string(cycle));
      ++cycle;
      resume = false;
    } else {
      ++failures;
      std::printf("FAILED: attempt %d ended with %s\n%s", attempts, r.message.c_str(), stderr_tail(log).c_str());
      break;
    }
  }
  // The last cycle runs to its end.
  const fs::path dir = out / ("cycle-" + std::to_string(cycle));
  const ProcessResult last = run(dir, resume, nullptr, (out / "final.stderr").string(), 0);
  if (!last.ok()) {
    ++failures;
    std::printf("FAILED: the final resume ended with %s\n%s", last.message.c_str(), stderr_tail(out / "final.stderr").c_str());
  } else {
    check(dir, "final cycle " + std::to_string(cycle));
  }
  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("soak: %d kills (%d inside an archive write), %d cycles, %d attempts, %d result checks, "
              "%d failures, %.0f s in all\n",
              done_kills, in_write, cycle + 1, attempts + 1, checks, failures, total);
  return failures == 0 ? 0 : 1;
}
