// The bundled Lourenco 2005 wall campaigns (data/walls/): every file parses and validates against
// its measured curve and scene, a tiny-budget campaign on one wall runs end to end, and
// predict_cases (the worth test's prediction step) agrees with the campaign's own fitness.
#include "demcal/dem/scene.hpp"
#include "demcal/pipelines/campaign.hpp"
#include "test_support.hpp"
#include "demcal/pipelines/predict.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>

namespace fs = std::filesystem;
using namespace demcal::pipelines;
using nlohmann::json;

namespace {

fs::path walls_dir(const std::string& name) { return test_support::fresh_dir("walls", name); }
using test_support::read_json;

const fs::path kWalls = fs::path(DEMCAL_SOURCE_DIR) / "data" / "walls";

// Applied vertical stress of each test (the database's sigma_0,pc, MPa), by test name prefix.
const std::map<std::string, double> kPrecompression = {
    {"SW.30.", 0.15}, {"SW.100.", 0.50}, {"SW.200.", 1.00}, {"SW.250.", 1.25}};

std::vector<fs::path> campaign_files() {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(kWalls))
    if (entry.path().extension() == ".json") files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  return files;
}



// The SW.30.1 campaign cut down to a test budget: 2 iterations x 3 particles, 3 contact points
// per joint, 3 mm of travel (the measured curve is compared over the shared 0-3 mm window).
CampaignConfig tiny_wall_campaign(const fs::path& out) {
  json j = read_json(kWalls / "SW.30.1.json");
  j["cases"][0]["scene"]["options"]["contacts_per_joint"] = 3;
  j["cases"][0]["scene"]["options"]["max_displacement"] = 0.003;
  j["optimiser"]["iterations"] = 2;
  j["optimiser"]["population"] = 3;
  j["backend"] = {{"type", "threads"}, {"threads", 2}};
  j["output"] = out.string();
  j["report"] = false;
  return campaign_from_json(j, kWalls.string(), "SW.30.1.json (tiny)");
}

}  // namespace

TEST(Walls, EveryBundledCampaignParsesValidatesAndMatchesItsTest) {
  const auto files = campaign_files();
  // 7 walls, the beam-rotation and 10-course trials, SW.200.1 with the crushing cap, the worth test,
  // its prediction and the diagnosis fitted on the worth test's walls with the other two held out.
  ASSERT_EQ(files.size(), 13u);
  EXPECT_TRUE(fs::exists(kWalls / "LICENSE"));
  EXPECT_TRUE(fs::exists(kWalls / "README.md"));
  std::set<std::string> walls_seen;
  for (const auto& file : files) {
    SCOPED_TRACE(file.filename().string());
    CampaignConfig config;
    ASSERT_NO_THROW(config = load_campaign(file.string()));
    ASSERT_NO_THROW(config.Validate());
    EXPECT_EQ(config.objective, 1);
    std::vector<std::string> free = {"kn", "ks", "friction_deg"};
    if (file.filename() == "SW.200.1-crushing-cap.json")
      free.insert(free.end(), {"compressive_strength", "crushing_softening"});
    EXPECT_EQ(config.space.free_names(), free);
    for (const auto& c : config.cases) {
      SCOPED_TRACE(c.name);
      walls_seen.insert(c.name);
      // The measured file reads, in SI, with the engine's column names.
      const auto measured = load_measured(c.measured);
      ASSERT_TRUE(measured.has_column("force"));
      ASSERT_TRUE(measured.has_column("top_horizontal"));
      const auto& d = measured.column("top_horizontal").values;
      const auto& f = measured.column("force").values;
      const double max_displacement = *std::max_element(d.begin(), d.end());
      const double peak = *std::max_element(f.begin(), f.end());
      EXPECT_GT(max_displacement, 0.015);  // metres: the tests ran to 21-30 mm
      EXPECT_LT(max_displacement, 0.035);
      EXPECT_GT(peak, 15e3);  // newtons: peaks 21-103 kN
      EXPECT_LT(peak, 110e3);
      // The scene builds, carries the test's pre-compression and travels past the measured curve.
      ASSERT_EQ(c.scene.generator, "wall");
      double precompression = -1;
      for (const auto& [prefix, value] : kPrecompression)
        if (c.name.rfind(prefix, 0) == 0) precompression = value;
      EXPECT_EQ(c.scene.options.at("precompression_mpa").get<double>(), precompression);
      const double travel = c.scene.options.at("max_displacement").get<double>();
      EXPECT_GE(travel, 1.1 * max_displacement - 1e-12);
      EXPECT_LE(travel, 1.1 * max_displacement + 1e-3);
      demcal::dem::Scene scene;
      ASSERT_NO_THROW(scene = build_scene(c.scene, file.string()));
      EXPECT_GE(scene.block_index("beam"), 0);
      // Every calibrated parameter is known to the scene.
      for (const auto& name : config.space.free_names()) {
        demcal::dem::Scene probe = scene;
        EXPECT_NO_THROW(demcal::dem::set_parameter(probe, name, demcal::dem::get_parameter(scene, name))) << name;
      }
    }
  }
  EXPECT_EQ(walls_seen, (std::set<std::string>{"SW.30.1", "SW.30.2", "SW.100.1", "SW.100.2", "SW.200.1",
                                                "SW.200.2", "SW.250.1"}));
  // The worth test calibrates on the two lower pre-compressions and predicts the two higher ones.
  const auto worth = load_campaign((kWalls / "worth-SW30-SW100.json").string());
  ASSERT_EQ(worth.cases.size(), 2u);
  EXPECT_EQ(worth.cases[0].name, "SW.30.1");
  EXPECT_EQ(worth.cases[1].name, "SW.100.1");
  const auto predict = load_campaign((kWalls / "predict-SW200-SW250.json").string());
  ASSERT_EQ(predict.cases.size(), 2u);
  EXPECT_EQ(predict.cases[0].name, "SW.200.1");
  EXPECT_EQ(predict.cases[1].name, "SW.250.1");
}

TEST(Walls, TinyCampaignOnOneWallRunsEndToEndAndPredictReproducesItsBestFitness) {
  const auto dir = walls_dir("tiny");
  const CampaignConfig config = tiny_wall_campaign(dir / "out");
  RunOptions options;
  options.progress = false;
  const CampaignResult result = run_campaign(config, options);
  ASSERT_EQ(result.status, CampaignStatus::completed) << result.message;
  EXPECT_EQ(result.simulations, 6);
  EXPECT_EQ(result.failed_runs, 0);
  ASSERT_TRUE(std::isfinite(result.best.fitness));
  EXPECT_GT(result.best.fitness, 0);
  ASSERT_TRUE(fs::exists(dir / "out" / "result.json"));
  const auto params = read_result_parameters((dir / "out" / "result.json").string());
  EXPECT_EQ(params.size(), 3u);
  for (const auto& name : {"kn", "ks", "friction_deg"}) EXPECT_DOUBLE_EQ(params.at(name), result.best.params.at(name));

  // Predicting the same case with the best parameters simulates the same run: the same fitness.
  PredictionOptions predict_options;
  predict_options.threads = 1;
  const auto cases = predict_cases(config, params, predict_options);
  ASSERT_EQ(cases.size(), 1u);
  const auto& p = cases[0];
  ASSERT_TRUE(p.ok()) << p.message;
  EXPECT_EQ(p.name, "SW.30.1");
  EXPECT_NEAR(p.fitness, result.best.fitness, 1e-9 * result.best.fitness);
  // One channel: the RMS error is objective 1 over sqrt(200 points).
  EXPECT_NEAR(p.rms_error, p.fitness / std::sqrt(200.0), 1e-9 * p.fitness);
  // The window is the 3 mm the scene travels (less the actuator's lag), starting at the origin.
  EXPECT_NEAR(p.window_lower, 0.0, 1e-9);
  EXPECT_GT(p.window_upper, 0.0025);
  EXPECT_LE(p.window_upper, 0.003 + 1e-6);
  // Inside the window SW.30.1 reaches 14.8-15.5 kN (at 2.8-3.0 mm), well below its 21.5 kN peak at
  // 25 mm; the simulated peak lies in the window too, and the error is signed.
  EXPECT_GE(p.measured_peak, 14.8e3);
  EXPECT_LE(p.measured_peak, 15.5e3);
  EXPECT_LE(p.measured_peak_displacement, p.window_upper);
  EXPECT_LE(p.simulated_peak_displacement, p.window_upper);
  EXPECT_NEAR(p.peak_error, (p.simulated_peak - p.measured_peak) / p.measured_peak, 1e-12);
  // Each curve first reaches 80 % of its peak inside the window, before (or at) the peak.
  for (const auto& [rise, at] : {std::pair{p.measured_rise_displacement, p.measured_peak_displacement},
                                 std::pair{p.simulated_rise_displacement, p.simulated_peak_displacement}}) {
    EXPECT_GE(rise, p.window_lower);
    EXPECT_LE(rise, at);
  }
  EXPECT_TRUE(p.simulated.has_column("force"));
  const json j = prediction_json(params, cases);
  EXPECT_EQ(j["cases"][0]["name"], "SW.30.1");
  EXPECT_DOUBLE_EQ(j["cases"][0]["fitness"].get<double>(), p.fitness);
}

TEST(Walls, ACollapsedRunIsScoredOverTheWholeMeasuredCurve) {
  namespace smoothing = demcal::smoothing;
  // A run that collapsed after 1 mm of a 4 mm test, matching the test up to there: compared on the
  // shared millimetre alone it would score perfectly; it carries nothing after its collapse.
  auto curve = [](std::vector<double> x, std::vector<double> f) {
    smoothing::Curve c;
    c.columns = {{"time", "s", x}, {"force", "N", f}, {"top_horizontal", "m", x}};
    return c;
  };
  const smoothing::Curve measured = curve({0, 1e-3, 2e-3, 3e-3, 4e-3}, {0, 1e3, 1e3, 1e3, 1e3});
  const smoothing::Curve run = curve({0, 1e-3}, {0, 1e3});
  smoothing::ObjectiveOptions options;
  options.points = 5;
  EXPECT_EQ(smoothing::objective1(measured, scored_curve("completed", run, measured, options), options).fitness, 0.0);
  EXPECT_DOUBLE_EQ(smoothing::objective1(measured, scored_curve("collapsed", run, measured, options), options).fitness, 2e3);
  EXPECT_EQ(scored_curve("step_limit", run, measured, options).rows(), 2u);
}

TEST(Walls, PredictRejectsUnknownParametersAndMalformedResults) {
  const auto dir = walls_dir("bad");
  const CampaignConfig config = tiny_wall_campaign(dir / "out");
  try {
    predict_cases(config, {{"kn", 1e9}, {"ks", 1e9}, {"friction_degrees", 30}});
    FAIL() << "an unknown parameter name was accepted";
  } catch (const CampaignError& e) {
    EXPECT_NE(std::string(e.what()).find("friction_degrees"), std::string::npos) << e.what();
  }
  try {
    predict_cases(config, {{"kn", std::nan("")}});
    FAIL() << "a NaN parameter was accepted";
  } catch (const CampaignError& e) {
    EXPECT_NE(std::string(e.what()).find("'kn'"), std::string::npos) << e.what();
  }
  const auto bad = dir / "result.json";
  std::ofstream(bad) << R"({"best": {"params": {"kn": "fast"}}})";
  try {
    read_result_parameters(bad.string());
    FAIL() << "a non-numeric parameter was accepted";
  } catch (const CampaignError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("best.params.kn"), std::string::npos) << what;
    EXPECT_NE(what.find("result.json"), std::string::npos) << what;
  }
  std::ofstream(bad) << R"({"simulations": 3})";
  EXPECT_THROW(read_result_parameters(bad.string()), CampaignError);
}
