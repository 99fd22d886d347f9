// Scene JSON, parameters, and the `demcal scene` / `demcal simulate` commands on good and bad input.
#include "demcal/dem/generators.hpp"
#include "demcal/dem/simulation.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace {

namespace fs = std::filesystem;
using namespace demcal::dem;
using nlohmann::json;

using test_support::CommandResult;
using test_support::run_demcal;

class SceneFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("demcal_scene_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  // A small valid scene: one block on a fixed base.
  json small_scene() const {
    return json::parse(R"({
      "width": 0.2,
      "joint_groups": {"joint": {"kn": 1e9, "ks": 4e8, "friction_deg": 30}},
      "blocks": [
        {"name": "base", "fixed": true, "vertices": [[-0.5,-0.1],[0.5,-0.1],[0.5,0],[-0.5,0]]},
        {"name": "top", "vertices": [[-0.1,0],[0.1,0],[0.1,0.1],[-0.1,0.1]]}
      ]})");
  }
  // Runs `demcal simulate` on the scene text; expects failure, no output folder, and every needle.
  void expect_rejected(const std::string& text, const std::vector<std::string>& needles) {
    const std::string scene = write("bad.json", text);
    const std::string out = (dir_ / "out").string();
    const CommandResult r = run_demcal("simulate " + scene + " --out " + out);
    EXPECT_NE(r.exit_code, 0) << r.output;
    for (const auto& needle : needles) EXPECT_NE(r.output.find(needle), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(out)) << "partial output left behind";
    EXPECT_FALSE(fs::exists(out + ".partial")) << "partial output left behind";
  }
  fs::path dir_;
};

TEST_F(SceneFiles, MissingKeyIsNamed) {
  json j = small_scene();
  j.erase("joint_groups");
  expect_rejected(j.dump(), {"missing key 'joint_groups'"});
  j = small_scene();
  j["blocks"][1].erase("vertices");
  expect_rejected(j.dump(), {"blocks[1]", "missing key 'vertices'"});
}

TEST_F(SceneFiles, NegativeStiffnessIsNamed) {
  json j = small_scene();
  j["joint_groups"]["joint"]["kn"] = -1e9;
  expect_rejected(j.dump(), {"joint_groups.joint.kn", "must be positive", "-1000000000"});
}

TEST_F(SceneFiles, ZeroAreaBlockIsNamed) {
  json j = small_scene();
  j["blocks"][1]["vertices"] = json::parse("[[0,0.2],[0.1,0.2],[0.2,0.2]]");
  expect_rejected(j.dump(), {"'top'", "zero-area"});
}

TEST_F(SceneFiles, SelfIntersectingBlockIsNamed) {
  json j = small_scene();
  j["blocks"][1]["vertices"] = json::parse("[[-0.1,0],[0.1,0.1],[0.1,0],[-0.1,0.1]]");
  expect_rejected(j.dump(), {"'top'", "self-intersecting"});
}

TEST_F(SceneFiles, OverlappingBlocksAreNamed) {
  json j = small_scene();
  j["blocks"][1]["vertices"] = json::parse("[[-0.1,-0.01],[0.1,-0.01],[0.1,0.1],[-0.1,0.1]]");
  expect_rejected(j.dump(), {"'base'", "'top'", "overlap"});
}

TEST_F(SceneFiles, NanIsRejectedWithItsPlace) {
  // JSON has no NaN: a literal NaN is a syntax error reported with its line and column...
  std::string text = small_scene().dump(2);
  text.replace(text.find("1000000000.0"), 12, "NaN");
  expect_rejected(text, {"invalid JSON", "line"});
  // ...and a "nan" string where a number belongs names the key.
  json j = small_scene();
  j["joint_groups"]["joint"]["friction_deg"] = "nan";
  expect_rejected(j.dump(), {"joint_groups.joint.friction_deg", "expected a number"});
  // A NaN built in code (no file) is caught by Validate with the key.
  Scene s = scene_from_json(small_scene(), "code");
  s.blocks[1].density = std::nan("");
  EXPECT_THROW(
      {
        try {
          s.Validate("code");
        } catch (const SceneError& e) {
          EXPECT_NE(std::string(e.what()).find("density"), std::string::npos);
          throw;
        }
      },
      SceneError);
}

TEST_F(SceneFiles, UnknownLoadedBlockIsNamed) {
  json j = small_scene();
  j["loading"] = json::parse(R"({"type": "point", "block": "ghost", "point": [0, 0.1]})");
  expect_rejected(j.dump(), {"loading.block", "ghost"});
}

TEST_F(SceneFiles, UnknownTimeStepFacesAreNamed) {
  json j = small_scene();
  j["solver"] = json::parse(R"({"time_step_faces": "some"})");
  expect_rejected(j.dump(), {"solver.time_step_faces", "all or in_contact", "'some'"});
  // Both values round-trip and are always written, so that a scene's hash tells them apart; a scene
  // without the key takes the default, "in_contact".
  j["solver"]["time_step_faces"] = "all";
  const Scene all = scene_from_json(j, "all");
  EXPECT_EQ(all.solver.time_step_faces, "all");
  EXPECT_EQ(scene_to_json(all)["solver"]["time_step_faces"], "all");
  j["solver"].erase("time_step_faces");
  const Scene by_default = scene_from_json(j, "default");
  EXPECT_EQ(by_default.solver.time_step_faces, "in_contact");
  EXPECT_EQ(scene_to_json(by_default)["solver"]["time_step_faces"], "in_contact");
  EXPECT_NE(scene_hash(all), scene_hash(by_default));
}

TEST_F(SceneFiles, TimeStepStiffeningIsCheckedAndWrittenOnlyWhenNodes) {
  json j = small_scene();
  j["solver"] = {{"time_step_stiffening", "node"}};
  expect_rejected(j.dump(), {"solver.time_step_stiffening", "caps or nodes", "'node'"});
  // Written only when "nodes": the scenes (and archived runs) from before the key keep their hashes.
  const auto scene_with = [&](const char* value) {
    j["solver"]["time_step_stiffening"] = value;
    return scene_from_json(j, value);
  };
  const Scene nodes = scene_with("nodes"), caps = scene_with("caps");
  j["solver"].erase("time_step_stiffening");
  EXPECT_EQ(nodes.solver.time_step_stiffening, "nodes");
  EXPECT_EQ(scene_to_json(nodes)["solver"]["time_step_stiffening"], "nodes");
  EXPECT_FALSE(scene_to_json(caps)["solver"].contains("time_step_stiffening"));
  EXPECT_EQ(scene_hash(scene_from_json(j, "default")), scene_hash(caps));
  EXPECT_NE(scene_hash(nodes), scene_hash(caps));
}

TEST_F(SceneFiles, GeneratedSceneRoundTripsAndSimulates) {
  const std::string scene = (dir_ / "arch.json").string();
  CommandResult r = run_demcal("scene arch --voussoirs 9 --contacts-per-joint 5 --max-displacement 0.001 -o " + scene);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Scene loaded = load_scene(scene);
  ArchOptions o;
  o.voussoirs = 9;
  o.contacts_per_joint = 5;
  o.max_displacement = 0.001;
  EXPECT_EQ(scene_hash(loaded), scene_hash(make_arch(o)));
  const std::string out = (dir_ / "run").string();
  r = run_demcal("simulate " + scene + " --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  json summary;
  std::ifstream(out + "/summary.json") >> summary;
  EXPECT_EQ(summary["status"], "completed");
  for (const char* key : {"message", "peak_force", "steps", "wall_time_s", "max_block_displacement", "hinges",
                          "sliding_joints"})
    EXPECT_TRUE(summary.contains(key)) << key;
  std::ifstream csv(out + "/curves.csv");
  std::string header;
  std::getline(csv, header);
  EXPECT_EQ(header, "time,force,load_vertical,abutment_horizontal");
  std::ifstream vtk(out + "/final.vtk");
  std::string first;
  std::getline(vtk, first);
  EXPECT_EQ(first, "# vtk DataFile Version 3.0");
}

TEST_F(SceneFiles, BadGeneratorFlagIsNamed) {
  const CommandResult r = run_demcal("scene arch --rise -1 -o " + (dir_ / "a.json").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--rise"), std::string::npos) << r.output;
}

TEST(Parameters, SetEveryGroupOrOne) {
  Scene s = make_arch(ArchOptions{});
  set_parameter(s, "kn", 3e9);
  EXPECT_EQ(s.joint_groups.at("arch_joints").normal_stiffness, 3e9);
  EXPECT_EQ(s.joint_groups.at("abutment_joints").normal_stiffness, 3e9);
  set_parameter(s, "abutment_joints.friction_deg", 35);
  EXPECT_NEAR(get_parameter(s, "abutment_joints.friction_deg"), 35, 1e-12);
  EXPECT_NEAR(get_parameter(s, "arch_joints.friction_deg"), 30.5, 1e-12);
  EXPECT_THROW(set_parameter(s, "stiffness", 1), SceneError);
  EXPECT_THROW(set_parameter(s, "nogroup.kn", 1), SceneError);
  const std::string before = scene_hash(s);
  set_parameter(s, "ks", 1e9);
  EXPECT_NE(scene_hash(s), before);
}

TEST(Wall, RunningBondLayoutAndLoads) {
  WallOptions o;
  const Scene s = make_wall(o);
  int units = 0;
  double area = 0;
  for (const auto& b : s.blocks)
    if (b.label == "unit") {
      ++units;
      area += (b.vertices[1].x() - b.vertices[0].x()) * (b.vertices[2].y() - b.vertices[1].y());
    }
  EXPECT_EQ(units, 5 * 5 + 6 * 4);  // 9 courses: 5 of five full units, 4 of two halves and four full
  EXPECT_NEAR(area, o.height * o.length, 1e-12);
  ASSERT_EQ(s.loading.constant_forces.size(), 1u);
  EXPECT_NEAR(-s.loading.constant_forces[0].force.y(), 0.15e6 * 1.0 * 0.2, 1e-6);
}

}  // namespace
