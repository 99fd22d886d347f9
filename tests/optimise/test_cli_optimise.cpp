// `demcal optimise` end to end.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cstdio>
#include <string>

namespace {

struct Result {
  int status;
  std::string output;
};

Result run(const std::string& arguments) {
  const std::string command = std::string(DEMCAL_BINARY) + " " + arguments + " 2>&1";
  std::string output;
  FILE* pipe = popen(command.c_str(), "r");
  std::array<char, 4096> buffer{};
  while (pipe && fgets(buffer.data(), buffer.size(), pipe)) output += buffer.data();
  const int status = pipe ? pclose(pipe) : -1;
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
}

}  // namespace

TEST(CliOptimise, PrintsJsonAndIsDeterministic) {
  const std::string args = "optimise --function rosenbrock --dim 3 --evals 300 --algorithm tbpso --seed 4 --batch 12";
  const Result a = run(args), b = run(args);
  ASSERT_EQ(a.status, 0) << a.output;
  EXPECT_EQ(a.output, b.output);
  const auto json = nlohmann::json::parse(a.output);
  EXPECT_EQ(json["evaluations"].get<long>(), 300);
  EXPECT_EQ(json["best_x"].size(), 3u);
  EXPECT_EQ(json["algorithm"], "tbpso");
  EXPECT_EQ(json["batch"], 12);
  EXPECT_TRUE(json["best_value"].is_number());
  const Result other_seed = run("optimise --function rosenbrock --dim 3 --evals 300 --algorithm tbpso --seed 5 --batch 12");
  EXPECT_NE(nlohmann::json::parse(other_seed.output)["best_value"], json["best_value"]);
}

TEST(CliOptimise, NloptAndPolish) {
  const Result r = run("optimise --function sphere --dim 2 --evals 100 --algorithm nlopt:LN_SBPLX --seed 1");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_LT(nlohmann::json::parse(r.output)["best_value"].get<double>(), 1e-6);
  // The polish takes its 200 evaluations out of the 250: 50 for PSO, then LN_BOBYQA from its best.
  const Result p = run("optimise --function sphere --dim 3 --evals 250 --algorithm pso --polish 200 --seed 1");
  ASSERT_EQ(p.status, 0) << p.output;
  const auto json = nlohmann::json::parse(p.output);
  EXPECT_EQ(json["algorithm"], "pso+polish:LN_BOBYQA");
  EXPECT_EQ(json["before_polish"]["evaluations"].get<long>(), 50);
  EXPECT_LT(json["best_value"].get<double>(), 1e-6);
  EXPECT_LT(json["best_value"].get<double>(), json["before_polish"]["best_value"].get<double>());
  EXPECT_LE(json["evaluations"].get<long>(), 250);
  EXPECT_EQ(json["evaluations"].get<long>(),
            json["before_polish"]["evaluations"].get<long>() + json["polish"]["evaluations"].get<long>());
  const Result too_much = run("optimise --evals 100 --polish 100");
  EXPECT_EQ(too_much.status, 1);
  EXPECT_NE(too_much.output.find("--polish 100"), std::string::npos) << too_much.output;
}

TEST(CliOptimise, BadInputIsReported) {
  const Result f = run("optimise --function himmelblau");
  EXPECT_EQ(f.status, 1);
  EXPECT_NE(f.output.find("'himmelblau'"), std::string::npos) << f.output;
  const Result a = run("optimise --algorithm nlopt:XX");
  EXPECT_EQ(a.status, 1);
  EXPECT_NE(a.output.find("'nlopt:XX'"), std::string::npos) << a.output;
  const Result e = run("optimise --evals 0");
  EXPECT_EQ(e.status, 1);
  EXPECT_NE(e.output.find("--evals 0"), std::string::npos) << e.output;
  const Result d = run("optimise --dim 0");
  EXPECT_EQ(d.status, 1);
  EXPECT_NE(d.output.find("dimension 0"), std::string::npos) << d.output;
}
