// `demcal smooth` and `demcal fitness` run as a user would: output files, JSON, bad input.
#include "demcal/smoothing/curve.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sys/wait.h>

using namespace demcal::smoothing;
namespace fs = std::filesystem;

namespace {

struct CommandRun {
  int status;
  std::string output;  // stdout and stderr
};

CommandRun run(const std::string& args) {
  const std::string command = std::string(DEMCAL_BINARY) + " " + args + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  std::string out;
  std::array<char, 4096> buf{};
  for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0;) out.append(buf.data(), n);
  const int status = pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("demcal_cli_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string file(const std::string& name, const std::string& text) {
    const auto p = dir_ / name;
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

// The bundled copy of a Lourenço 2005 curve (data/walls/, MIT licence beside it).
std::string lab_curve() { return std::string(DEMCAL_SOURCE_DIR) + "/data/walls/FD_SW301_Lourenco2005.csv"; }

void expect_failure(const CommandRun& r, const std::vector<std::string>& fragments) {
  EXPECT_NE(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("demcal: error:"), std::string::npos) << r.output;
  for (const auto& f : fragments) EXPECT_NE(r.output.find(f), std::string::npos) << r.output << " lacks " << f;
}

}  // namespace

TEST_F(Cli, SmoothWritesTheInputsColumnNamesAndAPlot) {
  const CommandRun r = run("smooth " + lab_curve() + " --out " + path("s.csv") + " --plot " + path("s.png") + " --epochs 100");
  ASSERT_EQ(r.status, 0) << r.output;
  const Curve c = read_curve(path("s.csv"));
  EXPECT_EQ(c.column_names(), (std::vector<std::string>{"top_displacement", "horizontal_force"}));
  EXPECT_EQ(c.column("horizontal_force").unit, "kN");
  EXPECT_EQ(c.rows(), 200u);
  EXPECT_GT(fs::file_size(path("s.png")), 1000u);

  const CommandRun ma = run("smooth " + lab_curve() + " --out " + path("m.csv") + " --x drift --y horizontal_force --method moving-average --points 50");
  ASSERT_EQ(ma.status, 0) << ma.output;
  const Curve m = read_curve(path("m.csv"));
  EXPECT_EQ(m.column_names(), (std::vector<std::string>{"drift", "horizontal_force"}));
  EXPECT_EQ(m.rows(), 50u);
}

TEST_F(Cli, SmoothStoppingRuleIsSelectable) {
  const CommandRun fixed = run("smooth " + lab_curve() + " --out " + path("f.csv") + " --epochs 60 --stopping fixed-budget");
  ASSERT_EQ(fixed.status, 0) << fixed.output;
  const CommandRun rule = run("smooth " + lab_curve() + " --out " + path("r.csv") + " --epochs 60 --stopping trend-spectrum");
  ASSERT_EQ(rule.status, 0) << rule.output;
  expect_failure(run("smooth " + lab_curve() + " --out " + path("x.csv") + " --stopping bogus"), {"bogus", "trend-spectrum"});
}

TEST_F(Cli, FitnessPrintsJson) {
  const std::string e = file("e.csv", "time,force,dv,dh\n0,0,0,0\n1,1,1,2\n2,2,2,4\n");
  const std::string s = file("s.csv", "dh;force;dv\n0;0;0\n2;2;1\n4;2;2\n");
  const CommandRun r = run("fitness --experiment " + e + " --simulation " + s + " --points 3 --weight dh=3");
  ASSERT_EQ(r.status, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  EXPECT_DOUBLE_EQ(j["fitness"].get<double>(), 4.0);
  EXPECT_DOUBLE_EQ(j["channels"]["dv"].get<double>(), 1.0);
  EXPECT_DOUBLE_EQ(j["channels"]["dh"].get<double>(), 1.0);
}

TEST_F(Cli, FitnessObjective2OnLabCurves) {
  const std::string args = "fitness -e " + lab_curve() + " -s " + lab_curve() + " --force-column horizontal_force --ignore drift";
  const CommandRun r1 = run(args);
  ASSERT_EQ(r1.status, 0) << r1.output;
  EXPECT_DOUBLE_EQ(nlohmann::json::parse(r1.output)["fitness"].get<double>(), 0.0);
  const CommandRun r2 = run(args + " --objective 2");
  ASSERT_EQ(r2.status, 0) << r2.output;
  EXPECT_NEAR(nlohmann::json::parse(r2.output)["channels"]["top_displacement"].get<double>(), 0.0, 1e-9);
}

TEST_F(Cli, BadInputGivesAClearErrorAndNonZeroExit) {
  const std::string good = file("good.csv", "force,dv\n0,0\n1,1\n2,2\n");
  expect_failure(run("smooth " + file("empty.csv", "") + " --out " + path("o.csv")), {"empty.csv", "empty"});
  expect_failure(run("smooth " + file("one.csv", "force,dv\n1,2\n") + " --out " + path("o.csv")), {"one.csv", "line 2", "1 data row"});
  expect_failure(run("fitness -e " + file("text.csv", "force,dv\n1,2\n3,x4\n") + " -s " + good), {"text.csv", "line 3", "column 'dv'", "'x4'"});
  expect_failure(run("fitness -e " + file("nan.csv", "force,dv\n1,nan\n3,nan\n") + " -s " + good), {"nan.csv", "column 'dv'", "NaN"});
  expect_failure(run("fitness -e " + good + " -s " + file("noforce.csv", "F,dv\n0,0\n1,1\n")), {"noforce.csv", "no force column 'force'", "F, dv"});
  expect_failure(run("fitness -e " + good + " -s " + file("dh.csv", "force,dh\n0,0\n1,1\n")), {"no displacement column in common", "good.csv", "(dv)", "dh.csv", "(dh)"});
  expect_failure(run("fitness -e " + good + " -s " + file("dh2.csv", "force,dh\n0,0\n1,1\n") + " --objective 2"), {"no displacement column in common"});
  expect_failure(run("smooth " + good + " --out " + path("o.csv") + " --y nothere"), {"good.csv", "no column 'nothere'"});
  expect_failure(run("smooth /nonexistent/x.csv --out " + path("o.csv")), {"/nonexistent/x.csv", "cannot open"});
}
