// The bad-input catalogue (docs/bad-input.md), entries for the measured CSV, the scene, the
// campaign file, the command line and the archive: each runs the real `demcal calibrate` on one
// bad input and checks the exit status and that the message names the file, line or key and the
// value. (Simulator outputs: test_simulator_faults.cpp; more CSV and scene entries:
// tests/smoothing/cli_test.cpp, tests/dem/test_scene.cpp.) The message of each entry is recorded
// as the test property "message" (--gtest_output=xml:FILE shows it).
#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/process.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <fstream>
#include <functional>
#include <sstream>

namespace fs = std::filesystem;
using namespace demcal::pipelines;
using nlohmann::json;

namespace {

using test_support::read_text;
using test_support::write_text;

void sql(const fs::path& path, const std::string& statements) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, statements.c_str(), nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  sqlite3_close(db);
}

using test_support::toy_measured_text;

// A valid, tiny campaign through the toy simulator; each entry breaks one thing.
json good_campaign(const fs::path& dir) { return test_support::toy_campaign(dir, "bad-input"); }

struct Entry {
  std::string id;
  // Writes what the entry needs into dir (campaign.json is the good campaign, already written)
  // and returns the arguments after `demcal calibrate`.
  std::function<std::vector<std::string>(const fs::path& dir)> setup;
  std::vector<std::string> needles;  // each must be in stderr ("{dir}" = the entry's folder)
  int exit_code = 1;
};

void PrintTo(const Entry& e, std::ostream* os) { *os << e.id; }

std::vector<std::string> with_campaign(const fs::path& dir, const json& campaign, std::vector<std::string> extra = {}) {
  write_text(dir / "campaign.json", campaign.dump(2));
  std::vector<std::string> args{(dir / "campaign.json").string(), "--out", (dir / "out").string()};
  args.insert(args.end(), extra.begin(), extra.end());
  return args;
}

// The good campaign with one change made by `edit`.
std::function<std::vector<std::string>(const fs::path&)> campaign_edit(std::function<void(json&, const fs::path&)> edit) {
  return [edit](const fs::path& dir) {
    json c = good_campaign(dir);
    edit(c, dir);
    return with_campaign(dir, c);
  };
}

// The good campaign with a different measured file.
std::function<std::vector<std::string>(const fs::path&)> measured_file(const std::string& text) {
  return [text](const fs::path& dir) {
    write_text(dir / "bad.csv", text);
    json c = good_campaign(dir);
    c["measured"] = (dir / "bad.csv").string();
    return with_campaign(dir, c);
  };
}

// The good campaign plus command-line flags.
std::function<std::vector<std::string>(const fs::path&)> flags(std::vector<std::string> extra) {
  return [extra](const fs::path& dir) { return with_campaign(dir, good_campaign(dir), extra); };
}

const std::vector<Entry>& catalogue() {
  static const std::vector<Entry> entries = {
      // ---- measured curve (CSV) ----
      {"csv_missing_file", campaign_edit([](json& c, const fs::path& d) { c["measured"] = (d / "nope.csv").string(); }),
       {"campaign.json", "cases[0].measured.file", "no such file", "{dir}/nope.csv"}},
      {"csv_non_numeric_cell", measured_file("top_horizontal,force\n0,0\n0.001,abc\n0.002,5\n"),
       {"bad.csv", "line 3", "column 'force'", "'abc'"}},
      {"csv_ragged_row", measured_file("top_horizontal,force\n0,0\n0.001\n0.002,5\n"), {"bad.csv", "line 3"}},
      {"csv_duplicate_column", measured_file("force,force\n0,0\n1,1\n"), {"bad.csv", "'force'", "duplicate"}},
      {"csv_no_data_rows", measured_file("top_horizontal,force\n"), {"bad.csv"}},
      // a gauge that only moves backwards: one loading point, which no run can be scored against
      {"csv_channel_without_loading_points", measured_file("top_horizontal,force\n0,0\n-0.001,5\n-0.002,7\n"),
       {"bad.csv", "channel 'top_horizontal'", "fewer than 2 loading points"}},
      {"csv_mapped_column_missing",
       campaign_edit([](json& c, const fs::path&) {
         c["measured"] = {{"file", c["measured"]}, {"columns", {{"force", {{"column", "shear"}}}}}};
       }),
       {"measured.csv", "'shear'", "top_horizontal, force"}},
      {"csv_unknown_unit",
       campaign_edit([](json& c, const fs::path&) {
         c["measured"] = {{"file", c["measured"]}, {"columns", {{"force", {{"column", "force"}, {"unit", "furlong"}}}}}};
       }),
       {"furlong", "mm", "kN"}},
      // ---- scene ----
      {"scene_missing_file",
       campaign_edit([](json& c, const fs::path& d) {
         c["scene"] = {{"file", (d / "nope.json").string()}};
         c["backend"] = "threads";
       }),
       {"{dir}/nope.json"}},
      {"scene_invalid_json",
       campaign_edit([](json& c, const fs::path& d) {
         write_text(d / "scene.json", "{\n  \"blocks\": [\n    {\"name\": \"a\",, }\n  ]\n}\n");
         c["scene"] = {{"file", (d / "scene.json").string()}};
         c["backend"] = "threads";
       }),
       {"scene.json", "line 3"}},
      {"scene_generator_unknown_option",
       campaign_edit([](json& c, const fs::path&) {
         c["scene"] = {{"generator", "arch"}, {"options", {{"voussoir_count", 12}}}};
         c["backend"] = "threads";
       }),
       {"voussoir_count"}},
      {"scene_unknown_parameter",
       campaign_edit([](json& c, const fs::path&) {
         c["scene"] = {{"generator", "arch"}, {"options", {{"contacts_per_joint", 3}}}};
         c["backend"] = "threads";
       }),
       {"parameter 'k'", "known:", "kn"}},
      // ---- campaign file ----
      {"campaign_invalid_json",
       [](const fs::path& dir) {
         write_text(dir / "campaign.json", "{\n  \"name\": \"x\",\n  \"objective\": 1,,\n}\n");
         return std::vector<std::string>{(dir / "campaign.json").string(), "--out", (dir / "out").string()};
       },
       {"campaign.json", "not valid JSON", "line 3"}},
      {"campaign_unknown_key", campaign_edit([](json& c, const fs::path&) { c["optimiser"]["swarm"] = 3; }),
       {"campaign.json", "optimiser", "'swarm'"}},
      {"campaign_wrong_type", campaign_edit([](json& c, const fs::path&) { c["optimiser"]["population"] = "ten"; }),
       {"campaign.json", "optimiser.population", "expected an integer", "\"ten\""}},
      {"campaign_inverted_bounds",
       campaign_edit([](json& c, const fs::path&) {
         c["parameters"][1]["lower"] = 45;
         c["parameters"][1]["upper"] = 25;
       }),
       {"friction_deg", "45", "25"}},
      {"campaign_objective_3", campaign_edit([](json& c, const fs::path&) { c["objective"] = 3; }),
       {"campaign.json", "objective", "3"}},
      {"campaign_unknown_algorithm", campaign_edit([](json& c, const fs::path&) { c["optimiser"]["algorithm"] = "annealing"; }),
       {"campaign.json", "annealing"}},
      {"campaign_surrogate_one_member",
       campaign_edit([](json& c, const fs::path&) { c["surrogate"] = {{"kind", "mlp"}, {"mlp", {{"members", 1}}}}; }),
       {"campaign.json", "surrogate.mlp", "members = 1", ">= 2"}},
      {"campaign_surrogate_unknown_kind", campaign_edit([](json& c, const fs::path&) { c["surrogate"] = {{"kind", "forest"}}; }),
       {"campaign.json", "surrogate", "forest", "gp or mlp"}},
      {"campaign_surrogate_unknown_overlap", campaign_edit([](json& c, const fs::path&) { c["surrogate"] = {{"overlap", "often"}}; }),
       {"campaign.json", "surrogate", "overlap = 'often'", "auto or always"}},
      {"campaign_command_without_output",
       campaign_edit([](json& c, const fs::path&) { c["backend"]["command"] = "sim {k} {friction_deg}"; }),
       {"campaign.json", "backend.command", "{output}"}},
      {"campaign_unknown_placeholder",
       campaign_edit([](json& c, const fs::path&) { c["backend"]["command"] = "sim {kn} {output}"; }),
       {"campaign.json", "backend.command", "{kn}", "known:"}},
      {"campaign_negative_timeout", campaign_edit([](json& c, const fs::path&) { c["backend"]["timeout_s"] = -1; }),
       {"campaign.json", "backend.timeout_s", "must be >= 0, got -1"}},
      {"campaign_zero_max_output", campaign_edit([](json& c, const fs::path&) { c["backend"]["max_output_mb"] = 0; }),
       {"campaign.json", "backend.max_output_mb", "must be > 0 and <= 1048576 (1 TiB), got 0"}},
      // a simulator that fails every run: the campaign fails with the reason the runs share
      {"campaign_every_run_fails",
       campaign_edit([](json& c, const fs::path&) {
         c["backend"]["command"] = test_support::python() + " -c \"import sys; sys.exit(3)\" {k} {friction_deg} {output}";
       }),
       {"no run gave a finite fitness (2 failed)", "2 of the 2 failed runs: case 'main', failed: external command exit code 3"},
       2},
      {"campaign_unknown_backend", campaign_edit([](json& c, const fs::path&) { c["backend"]["type"] = "cloud"; }),
       {"campaign.json", "backend.type", "'cloud'"}},
      // ---- command line ----
      {"cli_param_without_bounds", flags({"--param", "kn=1e8"}), {"--param kn=1e8", "NAME=LOWER:UPPER"}},
      {"cli_param_not_a_number", flags({"--param", "k=abc:1e9:log"}), {"--param k=abc:1e9:log", "'abc'", "not a finite number"}},
      {"cli_map_unknown_unit", flags({"--map", "force=force:furlong"}), {"furlong"}},
      {"cli_unknown_flag", flags({"--swarmsize", "3"}), {"--swarmsize"}, 109},
      {"cli_negative_timeout", flags({"--timeout", "-1"}), {"--timeout -1: must be a number of seconds >= 0"}},
      {"cli_unknown_backend", flags({"--backend", "cloud"}), {"--backend cloud", "'cloud'", "threads, command, mpi"}},
      {"cli_no_campaign", [](const fs::path& dir) { return std::vector<std::string>{"--out", (dir / "out").string()}; },
       {"no campaign", "campaign file", "--scene"}},
      // ---- archive ----
      {"archive_not_sqlite",
       flags({"--archive", "{dir}/junk.sqlite"}),
       {"{dir}/junk.sqlite", "not a demcal run archive", "not an SQLite database"}},
      {"archive_foreign_sqlite", flags({"--archive", "{dir}/foreign.sqlite"}),
       {"{dir}/foreign.sqlite", "not a demcal run archive", "tables people", "no demcal schema version"}},
      {"archive_newer_schema", flags({"--archive", "{dir}/future.sqlite"}),
       {"{dir}/future.sqlite", "archive schema version 99", "this demcal reads 1"}},
      {"archive_folder_missing", flags({"--archive", "/no/such/folder/archive.sqlite"}),
       {"/no/such/folder/archive.sqlite", "cannot open the run archive", "the folder /no/such/folder does not exist"}},
      {"archive_read_only_folder", flags({"--archive", "{dir}/locked/archive.sqlite"}),
       {"{dir}/locked/archive.sqlite", "cannot open the run archive", "the folder {dir}/locked is not writable"}},
      {"archive_other_configuration", flags({"--archive", "{dir}/other.sqlite", "--resume"}),
       {"note: --resume: {dir}/other.sqlite holds no campaign with this configuration"}, 0},
  };
  return entries;
}

class BadInput : public ::testing::TestWithParam<Entry> {};

using test_support::replace_dir;

}  // namespace

TEST_P(BadInput, MessageNamesWhereAndWhat) {
  const Entry& entry = GetParam();
  const auto dir = test_support::fresh_dir("bad-input", entry.id);
  write_text(dir / "measured.csv", toy_measured_text());
  if (entry.id.rfind("archive_", 0) == 0) {
    // Archives the entries point at.
    write_text(dir / "junk.sqlite", "this is a text file, not an SQLite database\n" + std::string(2000, 'x'));
    sql(dir / "foreign.sqlite", "CREATE TABLE people(name TEXT); INSERT INTO people VALUES('ada');");
    { RunArchive future((dir / "future.sqlite").string()); }
    sql(dir / "future.sqlite", "UPDATE meta SET value='99' WHERE key='schema_version'");
  }
  if (entry.id == "archive_other_configuration") {
    // An archive of another configuration (another seed) for the --resume entry.
    json other = good_campaign(dir);
    other["optimiser"]["seed"] = 2;
    write_text(dir / "other.json", other.dump());
    ProcessOptions o;
    o.argv = {DEMCAL_BINARY, "calibrate", (dir / "other.json").string(), "--out", (dir / "other-out").string(),
              "--archive", (dir / "other.sqlite").string(), "--quiet"};
    o.timeout_s = 120;
    ASSERT_TRUE(run_process(o).ok());
  }
  fs::create_directories(dir / "locked");
  fs::permissions(dir / "locked", fs::perms::owner_read | fs::perms::owner_exec | fs::perms::group_read |
                                      fs::perms::group_exec | fs::perms::others_read | fs::perms::others_exec);

  std::vector<std::string> args = entry.setup(dir);
  ProcessOptions o;
  // Root writes into read-only folders: that entry runs demcal as the unprivileged user "nobody"
  // (65534). The others run as the caller, whose checkout (and toy simulator) nobody may not read.
  const bool as_nobody = ::geteuid() == 0 && entry.id == "archive_read_only_folder";
  if (as_nobody) o.argv = {"setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"};
  o.argv.insert(o.argv.end(), {DEMCAL_BINARY, "calibrate"});
  for (auto& a : args) o.argv.push_back(replace_dir(a, dir));
  o.argv.push_back("--quiet");
  o.timeout_s = 120;
  o.stderr_path = (dir / "stderr.txt").string();
  if (as_nobody) fs::permissions(dir, fs::perms::all, fs::perm_options::add);
  if (as_nobody)
    for (const auto& f : fs::directory_iterator(dir))
      if (f.is_regular_file()) fs::permissions(f.path(), fs::perms::all, fs::perm_options::add);
  const ProcessResult r = run_process(o);
  const std::string message = read_text(dir / "stderr.txt");
  RecordProperty("message", message);
  EXPECT_EQ(r.status, ProcessStatus::exited) << r.message;
  EXPECT_EQ(r.exit_code, entry.exit_code) << message;
  if (entry.exit_code == 1) {
    EXPECT_NE(message.find("demcal: error: "), std::string::npos) << message;
  }
  for (const auto& needle : entry.needles) {
    const std::string expected = replace_dir(needle, dir);
    EXPECT_NE(message.find(expected), std::string::npos) << "'" << expected << "' not in: " << message;
  }
}

INSTANTIATE_TEST_SUITE_P(Catalogue, BadInput, ::testing::ValuesIn(catalogue()),
                         [](const ::testing::TestParamInfo<Entry>& info) { return info.param.id; });
