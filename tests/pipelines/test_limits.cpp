// Limits on counts and sizes (demcal/limits, docs/bad-input.md "Limits"): each entry runs the real
// `demcal` on an input over one limit and checks that it stops at once (exit status 1, well within
// the process time-out, so nothing was allocated or run first) with a message that names the
// option, the value and the limit and says how to raise it. Entries over a default limit use the
// default; the rest lower the limit through DEMCAL_LIMITS so that a small input reaches it by the
// same check. The message of each entry is recorded as the test property "message".
#include "demcal/limits/limits.hpp"
#include "demcal/pipelines/process.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <sstream>

namespace fs = std::filesystem;
using namespace demcal::pipelines;
using nlohmann::json;

namespace {

using test_support::read_text;
using test_support::write_text;

using test_support::toy_measured_text;

json limits_campaign(const fs::path& dir) { return test_support::toy_campaign(dir, "limits"); }

// A valid scene file (the default arch, 15 blocks) made by the CLI.
fs::path arch_scene(const fs::path& dir) {
  ProcessOptions o;
  o.argv = {DEMCAL_BINARY, "scene", "arch", "-o", (dir / "arch.json").string()};
  o.timeout_s = 60;
  EXPECT_TRUE(run_process(o).ok());
  return dir / "arch.json";
}

struct LimitCase {
  std::string id;
  // Writes what the entry needs into dir and returns the arguments after `demcal`.
  std::function<std::vector<std::string>(const fs::path& dir)> setup;
  std::vector<std::string> needles;  // each must be in stderr ("{dir}" = the entry's folder)
  std::string environment = {};      // DEMCAL_LIMITS for the run ("" = the defaults)
};

void PrintTo(const LimitCase& e, std::ostream* os) { *os << e.id; }

// The default arch scene file with `edit` applied to its JSON.
std::function<std::vector<std::string>(const fs::path&)> simulate_edited(std::function<void(json&)> edit) {
  return [edit](const fs::path& dir) {
    json scene = test_support::read_json(arch_scene(dir));
    edit(scene);
    write_text(dir / "scene.json", scene.dump());
    return std::vector<std::string>{"simulate", (dir / "scene.json").string(), "--out", (dir / "run").string()};
  };
}

// `demcal calibrate` on the toy campaign with `edit` applied and `extra` flags.
std::function<std::vector<std::string>(const fs::path&)> calibrate_edited(std::function<void(json&)> edit,
                                                                          std::vector<std::string> extra = {}) {
  return [edit, extra](const fs::path& dir) {
    json campaign = limits_campaign(dir);
    edit(campaign);
    write_text(dir / "campaign.json", campaign.dump(2));
    std::vector<std::string> args{"calibrate", (dir / "campaign.json").string(), "--out", (dir / "out").string(), "--quiet"};
    args.insert(args.end(), extra.begin(), extra.end());
    return args;
  };
}

std::function<std::vector<std::string>(const fs::path&)> command(std::vector<std::string> args) {
  return [args](const fs::path&) { return args; };
}

const char* kRaise = "raise it with --limit ";

std::vector<LimitCase> limit_catalogue() {
  return {
      // ---- scenes: generators (flags) ----
      {"arch_voussoirs", command({"scene", "arch", "--voussoirs", "2000000000", "-o", "{dir}/a.json"}),
       {"--voussoirs", "2000000000 voussoirs", "2000000002 blocks exceed the limit of 100000", "--limit blocks=N"}},
      {"semicircle_voussoirs", command({"scene", "semicircle", "--voussoirs", "1000000", "-o", "{dir}/a.json"}),
       {"--voussoirs", "1000002 blocks exceed the limit of 100000", "--limit blocks=N"}},
      {"wall_courses_by_units",
       command({"scene", "wall", "--height", "1000", "--unit-height", "0.001", "--length", "1000", "--unit-length",
                "0.001", "-o", "{dir}/w.json"}),
       {"--height/--unit-height/--length/--unit-length", "1000000 courses of up to 1000001 units",
        "exceed the limit of 100000", "--limit blocks=N"}},
      {"arch_record_interval", command({"scene", "arch", "--record-interval", "1e-12", "-o", "{dir}/a.json"}),
       {"--record-interval", "1e-12 m over 0.012 m of travel", "recorded rows exceed the limit of 1000000",
        "--limit recorded_rows=N"}},
      // ---- scenes: files ----
      {"scene_record_interval", simulate_edited([](json& s) { s["loading"]["record_interval"] = 1e-13; }),
       {"loading.record_interval", "1e-13 m over 0.012 m of travel", "recorded rows exceed the limit of 1000000"}},
      {"scene_max_time", simulate_edited([](json& s) { s["solver"]["max_time"] = 1e9; }),
       {"solver.max_time", "1000000000 s", "time steps exceed the limit of 1000000000", "--limit time_steps=N"}},
      {"scene_vertices", simulate_edited([](json& s) {
         json circle = json::array();  // a convex block of 1001 vertices
         for (int k = 0; k < 1001; ++k)
           circle.push_back({5 + 0.1 * std::cos(2 * M_PI * k / 1001), 5 + 0.1 * std::sin(2 * M_PI * k / 1001)});
         s["blocks"].push_back({{"name", "round"}, {"vertices", circle}});
       }),
       {"blocks[15].vertices", "1001 vertices in one block exceed the limit of 1000", "--limit vertices_per_block=N"}},
      {"scene_blocks", simulate_edited([](json&) {}), {"blocks", "15 blocks exceed the limit of 10"}, "blocks=10"},
      {"scene_file_bytes",
       [](const fs::path& dir) {
         fs::resize_file(arch_scene(dir), 300ll << 20);  // sparse: 300 MiB without writing them
         return std::vector<std::string>{"simulate", (dir / "arch.json").string(), "--out", (dir / "run").string()};
       },
       {"{dir}/arch.json", "the file is too large", "314572800 bytes exceed the limit of 268435456", "--limit file_bytes=N"}},
      // ---- curves ----
      {"csv_file_bytes",
       [](const fs::path& dir) {
         write_text(dir / "big.csv", toy_measured_text());
         fs::resize_file(dir / "big.csv", 1ll << 30);
         return std::vector<std::string>{"smooth", (dir / "big.csv").string(), "--out", (dir / "s.csv").string()};
       },
       {"{dir}/big.csv", "1073741824 bytes exceed the limit of 268435456"}},
      {"csv_rows",
       [](const fs::path& dir) {
         write_text(dir / "m.csv", toy_measured_text());
         return std::vector<std::string>{"smooth", (dir / "m.csv").string(), "--out", (dir / "s.csv").string()};
       },
       {"{dir}/m.csv: line 2 on", "21 data rows exceed the limit of 10", "--limit curve_rows=N"}, "curve_rows=10"},
      // ---- optimiser and campaign ----
      {"population", calibrate_edited([](json& c) { c["optimiser"]["population"] = 20000; }),
       {"option population", "20000 members of the population exceed the limit of 10000", "--limit population=N"}},
      {"iterations", calibrate_edited([](json& c) { c["optimiser"]["iterations"] = 2000000; }),
       {"option iterations", "2000000 iterations exceed the limit of 1000000"}},
      {"population_x_iterations",
       calibrate_edited([](json& c) { c["optimiser"]["population"] = 5000, c["optimiser"]["iterations"] = 5000; }),
       {"option population x iterations", "25000000 evaluations exceed the limit of 10000000"}},
      {"max_simulations_flag", calibrate_edited([](json&) {}, {"--max-simulations", "100000000"}),
       {"option max_evaluations", "100000000 evaluations exceed the limit of 10000000", "--limit evaluations=N"}},
      {"backend_parallel", calibrate_edited([](json& c) { c["backend"]["parallel"] = 5000; }),
       {"backend.parallel", "5000 workers exceed the limit of 1024", "--limit workers=N"}},
      {"threads_flag", calibrate_edited([](json&) {}, {"--threads", "100000"}),
       {"backend.threads", "100000 workers exceed the limit of 1024"}},
      {"smoother_epochs",
       calibrate_edited([](json& c) { c["objective"] = {{"type", 2}, {"smoother", {{"epochs", 100000000}}}}; }),
       {"SmootherOptions.epochs", "100000000 epochs exceed the limit of 10000000", "--limit epochs=N"}},
      {"surrogate_network",
       calibrate_edited([](json& c) { c["surrogate"] = {{"kind", "mlp"}, {"mlp", {{"hidden_width", 100000}}}}; }),
       {"surrogate mlp.members x hidden_layers x hidden_width^2", "network weights exceed the limit of 10000000",
        "--limit network_weights=N"}},
      {"diagnose_candidate_simulations",
       [](const fs::path& dir) {
         write_text(dir / "campaign.json", limits_campaign(dir).dump());
         return std::vector<std::string>{"diagnose", (dir / "campaign.json").string(), "--out", (dir / "d").string(),
                                         "--candidate-simulations", "2000000000"};
       },
       {"--candidate-simulations 2000000000", "evaluations exceed the limit of 10000000"}},
      {"study_campaigns",
       [](const fs::path& dir) {
         write_text(dir / "campaign.json", limits_campaign(dir).dump());
         write_text(dir / "study.json", json{{"campaign", "campaign.json"},
                                             {"algorithms", {{{"algorithm", "pso"}}, {{"algorithm", "ga"}}}},
                                             {"seeds", {1, 2}}}.dump());
         return std::vector<std::string>{"study", (dir / "study.json").string(), "--out", (dir / "s").string()};
       },
       {"2 methods x 2 seeds", "4 campaigns exceed the limit of 3", "--limit campaigns=N"}, "campaigns=3"},
      {"campaign_file_bytes",
       [](const fs::path& dir) {
         write_text(dir / "measured.csv", toy_measured_text());
         write_text(dir / "campaign.json", limits_campaign(dir).dump());
         fs::resize_file(dir / "campaign.json", 1ll << 30);
         return std::vector<std::string>{"calibrate", (dir / "campaign.json").string(), "--out", (dir / "out").string()};
       },
       {"{dir}/campaign.json", "the file is too large", "exceed the limit of 268435456"}},
      {"optimise_dimension", command({"optimise", "--function", "sphere", "--dim", "2000000000"}),
       {"test function dimension", "2000000000 parameters exceed the limit of 1000", "--limit parameters=N"}},
      {"optimise_evaluations", command({"optimise", "--function", "sphere", "--evals", "1000000000"}),
       {"1000000000 evaluations exceed the limit of 10000000"}},
      // ---- the --limit flag and DEMCAL_LIMITS themselves ----
      {"limit_unknown_key", command({"--limit", "blok=5", "scene", "arch", "-o", "{dir}/a.json"}),
       {"--limit 'blok=5'", "unknown limit 'blok'", "known: blocks, vertices_per_block"}},
      {"limit_not_a_number", command({"scene", "arch", "-o", "{dir}/a.json", "--limit", "blocks=many"}),
       {"--limit 'blocks=many'", "'many' is not a number >= 1"}},
      {"environment_not_a_number", command({"scene", "arch", "-o", "{dir}/a.json"}),
       {"DEMCAL_LIMITS 'blocks=0'", "'0' is not a number >= 1"}, "blocks=0"},
  };
}

class Limits : public ::testing::TestWithParam<LimitCase> {};

using test_support::replace_dir;

ProcessResult run_demcal(const std::vector<std::string>& args, const std::string& environment, const fs::path& dir) {
  ProcessOptions o;
  o.argv = {"env", "-u", "DEMCAL_LIMITS"};
  if (!environment.empty()) o.argv.push_back("DEMCAL_LIMITS=" + environment);
  o.argv.push_back(DEMCAL_BINARY);
  for (const auto& a : args) o.argv.push_back(replace_dir(a, dir));
  o.timeout_s = 60;  // a refused input returns at once; an input that is not refused may run for ever
  o.stderr_path = (dir / "stderr.txt").string();
  o.stdout_path = (dir / "stdout.txt").string();
  return run_process(o);
}

}  // namespace

TEST_P(Limits, InputOverALimitIsRefusedAtOnceNamingTheOptionValueAndLimit) {
  const LimitCase& entry = GetParam();
  const auto dir = test_support::fresh_dir("limits", entry.id);
  write_text(dir / "measured.csv", toy_measured_text());
  const ProcessResult r = run_demcal(entry.setup(dir), entry.environment, dir);
  const std::string message = read_text(dir / "stderr.txt");
  RecordProperty("message", message);
  ASSERT_EQ(r.status, ProcessStatus::exited) << r.message;
  EXPECT_EQ(r.exit_code, 1) << message;
  EXPECT_NE(message.find("demcal: error: "), std::string::npos) << message;
  for (const auto& needle : entry.needles) {
    const std::string expected = replace_dir(needle, dir);
    EXPECT_NE(message.find(expected), std::string::npos) << "'" << expected << "' not in: " << message;
  }
  const bool about_a_setting = entry.id.rfind("limit_", 0) == 0 || entry.id.rfind("environment_", 0) == 0;
  if (!about_a_setting) {
    EXPECT_NE(message.find(kRaise), std::string::npos) << message;
  }
}

INSTANTIATE_TEST_SUITE_P(Catalogue, Limits, ::testing::ValuesIn(limit_catalogue()),
                         [](const ::testing::TestParamInfo<LimitCase>& info) { return info.param.id; });

// A limit raised (or lowered) by --limit or DEMCAL_LIMITS moves the line between refused and
// accepted by exactly that much: 40 voussoirs and 2 abutments are 42 blocks.
TEST(Limits, RaisedByTheFlagOrTheEnvironmentTheLineMovesExactly) {
  const auto dir = test_support::fresh_dir("limits", "raised");
  const std::vector<std::string> arch = {"scene", "arch", "--voussoirs", "40", "-o", "{dir}/a.json"};
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> args = arch;
    args.insert(args.end(), extra.begin(), extra.end());
    return args;
  };
  EXPECT_EQ(run_demcal(with({"--limit", "blocks=41"}), "", dir).exit_code, 1);
  EXPECT_NE(read_text(dir / "stderr.txt").find("42 blocks exceed the limit of 41"), std::string::npos);
  EXPECT_TRUE(run_demcal(with({"--limit", "blocks=42"}), "", dir).ok()) << read_text(dir / "stderr.txt");
  EXPECT_EQ(run_demcal(arch, "blocks=41", dir).exit_code, 1);
  EXPECT_TRUE(run_demcal(arch, "blocks=42", dir).ok()) << read_text(dir / "stderr.txt");
  // The flag wins over the environment, before or after the subcommand.
  EXPECT_TRUE(run_demcal(with({"--limit", "blocks=1e5"}), "blocks=41", dir).ok()) << read_text(dir / "stderr.txt");
  std::vector<std::string> before = {"--limit", "blocks=42"};
  before.insert(before.end(), arch.begin(), arch.end());
  EXPECT_TRUE(run_demcal(before, "blocks=41", dir).ok()) << read_text(dir / "stderr.txt");
}

// The module itself: every key is distinct, a setting from text is read back, the exported
// environment holds what is not at its default, and reset() restores the defaults.
TEST(Limits, SettingsReadBackAndExportWhatDiffersFromTheDefaults) {
  using namespace demcal::limits;
  ::unsetenv("DEMCAL_LIMITS");
  reset();
  std::set<std::string_view> keys;
  for (const auto& i : all_limits()) {
    EXPECT_TRUE(keys.insert(i.key).second) << i.key;
    EXPECT_EQ(&info(i.limit), &i);
    EXPECT_EQ(value(i.limit), i.default_value);
    EXPECT_FALSE(exceeds(i.limit, i.default_value));
    EXPECT_TRUE(exceeds(i.limit, i.default_value + 1));
    EXPECT_TRUE(exceeds(i.limit, std::nan("")));
  }
  set_from_text("blocks=2e5", true);
  set_from_text("blocks=300000", true);
  set_from_text("epochs=7", true);
  EXPECT_EQ(value(Limit::blocks), 3e5);
  EXPECT_EQ(std::string(std::getenv("DEMCAL_LIMITS")), "blocks=300000,epochs=7");
  EXPECT_THROW(set_from_text("blocks", false), std::invalid_argument);
  EXPECT_THROW(set_from_text("blocks=inf", false), std::invalid_argument);
  EXPECT_THROW(set_from_text("nothing=5", false), std::invalid_argument);
  EXPECT_EQ(message(Limit::epochs, 8), "8 epochs exceed the limit of 7 (limit 'epochs'; raise it with --limit epochs=N or "
                                       "DEMCAL_LIMITS=epochs=N)");
  ::unsetenv("DEMCAL_LIMITS");
  reset();
  EXPECT_EQ(value(Limit::blocks), 1e5);
  EXPECT_EQ(value(Limit::epochs), 1e7);
  EXPECT_EQ(number_text(1e-12), "1e-12");
  EXPECT_EQ(number_text(2000000002), "2000000002");
}
