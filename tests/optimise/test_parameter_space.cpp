#include <demcal/optimise/parameter_space.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

using demcal::optimise::ParameterSpace;
using demcal::optimise::ParameterSpec;

namespace {

ParameterSpace arch_space() {
  ParameterSpace space;
  space.add("kn", 1e8, 1e10, ParameterSpec::Scale::log10).add("friction_angle", 25.0, 45.0);
  return space;
}

// Runs f, expects std::invalid_argument whose message contains every fragment.
template <class F>
void expect_error(F&& f, std::initializer_list<std::string> fragments) {
  try {
    f();
    FAIL() << "no exception thrown";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    for (const auto& fragment : fragments) EXPECT_NE(what.find(fragment), std::string::npos) << what;
  }
}

}  // namespace

TEST(ParameterSpace, LogScaleMapsExponentsLinearly) {
  const auto space = arch_space();
  space.Validate();
  Eigen::VectorXd unit(2);
  unit << 0.5, 0.25;
  const Eigen::VectorXd x = space.to_physical(unit);
  EXPECT_NEAR(x[0], 1e9, 1e9 * 1e-14);  // half way in the exponent 8..10
  EXPECT_DOUBLE_EQ(x[1], 30.0);
  const Eigen::VectorXd back = space.to_unit(x);
  EXPECT_NEAR(back[0], 0.5, 1e-15);
  EXPECT_NEAR(back[1], 0.25, 1e-15);
}

TEST(ParameterSpace, CubeCornersMapExactlyOntoBounds) {
  const auto space = arch_space();
  EXPECT_EQ(space.to_physical(Eigen::Vector2d(0.0, 0.0)), Eigen::Vector2d(1e8, 25.0));
  EXPECT_EQ(space.to_physical(Eigen::Vector2d(1.0, 1.0)), Eigen::Vector2d(1e10, 45.0));
  EXPECT_EQ(space.to_unit(Eigen::Vector2d(1e10, 25.0)), Eigen::Vector2d(1.0, 0.0));
}

TEST(ParameterSpace, ValuesIncludeFixedAndTiedParameters) {
  auto space = arch_space();
  space.fix("damping", 0.8).tie("ks", "kn", 2.5);
  space.Validate();
  const auto values = space.values(Eigen::Vector2d(4e9, 32.0));
  ASSERT_EQ(values.size(), 4u);
  EXPECT_DOUBLE_EQ(values.at("kn"), 4e9);
  EXPECT_DOUBLE_EQ(values.at("ks"), 4e9 / 2.5);
  EXPECT_DOUBLE_EQ(values.at("friction_angle"), 32.0);
  EXPECT_DOUBLE_EQ(values.at("damping"), 0.8);
  EXPECT_EQ(space.dimension(), 2);
}

TEST(ParameterSpace, JsonRoundTrip) {
  auto space = arch_space();
  space.fix("damping", 0.8).tie("ks", "kn", 2.0);
  const auto copy = ParameterSpace::from_json(nlohmann::json::parse(space.to_json().dump()));
  EXPECT_EQ(copy.to_json(), space.to_json());
  EXPECT_EQ(copy.free_parameters()[0].scale, ParameterSpec::Scale::log10);
}

TEST(ParameterSpace, ValidateNamesTheBadParameterAndValue) {
  expect_error([] { ParameterSpace().add("kn", 5.0, 1.0).Validate(); }, {"kn", "5", "1"});
  expect_error([] { ParameterSpace().add("ks", 0.0, 1e10, ParameterSpec::Scale::log10).Validate(); },
               {"ks", "0", "log10"});
  expect_error([] { ParameterSpace().add("phi", std::nan(""), 45.0).Validate(); }, {"phi", "nan"});
  expect_error([] { ParameterSpace().add("a", 0, 1).add("a", 0, 2).Validate(); }, {"'a'", "twice"});
  expect_error([] { ParameterSpace().add("a", 0, 1).fix("b", std::numeric_limits<double>::infinity()).Validate(); },
               {"'b'", "inf"});
  expect_error([] { ParameterSpace().add("kn", 1, 2).tie("ks", "kx", 2.0).Validate(); }, {"ks", "kx"});
  expect_error([] { ParameterSpace().add("kn", 1, 2).tie("ks", "kn", -1.0).Validate(); }, {"ks", "-1"});
  expect_error([] { ParameterSpace().Validate(); }, {"no free parameters"});
  expect_error([] { arch_space().to_physical(Eigen::VectorXd::Zero(3)); }, {"length 3", "dimension 2"});
}

TEST(ParameterSpace, FromJsonNamesWhereAndKey) {
  const auto bad_number = nlohmann::json::parse(R"({"parameters":[{"name":"kn","lower":"x","upper":2}]})");
  expect_error([&] { ParameterSpace::from_json(bad_number, "campaign.json"); },
               {"campaign.json", "parameters[0]", "'lower'", "\"x\""});
  const auto inverted = nlohmann::json::parse(R"({"parameters":[{"name":"kn","lower":3,"upper":2}]})");
  expect_error([&] { ParameterSpace::from_json(inverted, "campaign.json"); }, {"campaign.json", "kn", "3", "2"});
  const auto bad_scale = nlohmann::json::parse(R"({"parameters":[{"name":"kn","lower":1,"upper":2,"scale":"ln"}]})");
  expect_error([&] { ParameterSpace::from_json(bad_scale, "c.json"); }, {"c.json", "kn", "'ln'"});
  expect_error([&] { ParameterSpace::from_json(nlohmann::json::parse(R"({"params":[]})"), "c.json"); },
               {"c.json", "'parameters'"});
}
