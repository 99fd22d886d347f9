// Scene generators over their flag ranges: every scene they write validates, survives the JSON
// round trip that `demcal scene` + `demcal simulate` make, and runs its first steps sanely; what
// they cannot build is refused at generation time with the flag named.
#include "demcal/dem/generators.hpp"
#include "demcal/dem/joints.hpp"
#include "demcal/dem/simulation.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <unistd.h>

namespace {

using namespace demcal::dem;
namespace fs = std::filesystem;

// Validates the scene and its JSON round trip, then runs about `steps` time steps (a first run of
// one step gives the automatic time step). Returns the recording of the short run.
Recording validate_and_step(const Scene& generated, const std::string& what, int steps = 60) {
  generated.Validate(what);
  const Scene scene = scene_from_json(scene_to_json(generated), what);
  scene.Validate(what);
  EXPECT_EQ(scene_hash(scene), scene_hash(generated)) << what;
  Scene probe = scene;
  probe.solver.max_equilibrium_time = 1e-12;
  probe.solver.max_time = 1e-12;
  const Recording first = simulate(probe);
  EXPECT_GT(first.time_step, 0) << what;
  Scene shortened = scene;
  shortened.solver.max_equilibrium_time = steps * first.time_step;
  shortened.solver.max_time = steps * first.time_step;
  const Recording r = simulate(shortened);
  EXPECT_TRUE(r.status == RunStatus::completed || r.status == RunStatus::step_limit)
      << what << ": " << to_string(r.status) << " " << r.message;
  EXPECT_GE(r.steps, 1) << what;
  EXPECT_TRUE(std::isfinite(r.max_block_displacement)) << what;
  return r;
}

std::string describe(const ArchOptions& o) {
  std::ostringstream s;
  s << "arch span " << o.span << " rise " << o.rise << " thickness " << o.thickness << " voussoirs " << o.voussoirs
    << " load " << o.load << " load-voussoir " << o.load_voussoir;
  return s.str();
}

std::string describe(const WallOptions& o) {
  std::ostringstream s;
  s << "wall height " << o.height << " length " << o.length << " unit " << o.unit_length << " x " << o.unit_height
    << " precompression " << o.precompression_mpa << " beam-rotation " << o.beam_rotation << " load-height "
    << o.load_height;
  return s.str();
}

// Runs the CLI, returns its exit status and puts stdout + stderr into `output`.
int run_cli(const std::string& args, std::string& output) {
  const fs::path log = fs::temp_directory_path() / ("demcal_generators_" + std::to_string(::getpid()) + ".log");
  const int rc = std::system((std::string(DEMCAL_BINARY) + " " + args + " > " + log.string() + " 2>&1").c_str());
  std::ifstream in(log);
  std::stringstream text;
  text << in.rdbuf();
  output = text.str();
  fs::remove(log);
  return rc;
}

}  // namespace

TEST(ArchGenerator, WholeRiseRangeUpToTheSemicircleValidatesAndRuns) {
  int scenes = 0;
  for (const double span : {0.5, 1.885, 12.0})
    for (const double rise_ratio : {0.02, 0.15, 1.0 / 3, 0.4, 0.45, 0.49, 0.499, 0.5})
      for (const double thickness_ratio : {0.02, 0.061, 0.3})
        for (const int voussoirs : {3, 13, 40}) {
          ArchOptions o;
          o.span = span;
          o.rise = rise_ratio * span;
          o.thickness = thickness_ratio * span;
          o.voussoirs = voussoirs;
          o.load_voussoir = 1 + (scenes % voussoirs);
          o.load = scenes % 2 ? "none" : "point";
          const Scene scene = make_arch(o);
          ASSERT_EQ(scene.blocks.size(), static_cast<std::size_t>(voussoirs + 2));
          const Recording r = validate_and_step(scene, describe(o));
          // A few steps under gravity move a block far less than a thousandth of the span.
          EXPECT_LT(r.max_block_displacement, 1e-3 * span) << describe(o);
          ++scenes;
        }
  EXPECT_EQ(scenes, 216);
}

TEST(ArchGenerator, SemicircleFromTheCommandLineIsAcceptedBySimulate) {
  // rise = span / 2 with 40 voussoirs: the springing joints are horizontal.
  const fs::path dir = fs::temp_directory_path() / ("demcal_semicircle_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::string out;
  ASSERT_EQ(run_cli("scene arch --span 1.885 --rise 0.9425 --thickness 0.115 --voussoirs 40 --load none -o " +
                        (dir / "arch.json").string(),
                    out),
            0)
      << out;
  const Scene s = load_scene((dir / "arch.json").string());
  ASSERT_EQ(s.blocks.size(), 42u);
  // The left abutment's top face is the springing joint, level with the intrados springing point.
  for (const Vec2& v : s.blocks[0].vertices) EXPECT_LE(v.y(), 1e-12);
  // The semicircle on bases (Milankovitch) is offered too, and both scenes simulate.
  ASSERT_EQ(run_cli("scene semicircle --voussoirs 21 --thickness-ratio 0.2 -o " + (dir / "semi.json").string(), out),
            0)
      << out;
  EXPECT_EQ(load_scene((dir / "semi.json").string()).blocks.size(), 23u);
  EXPECT_EQ(run_cli("simulate " + (dir / "semi.json").string() + " --out " + (dir / "semi-out").string(), out), 0)
      << out;
  fs::remove_all(dir);
}

TEST(ArchGenerator, RefusesWhatItCannotBuildNamingTheFlag) {
  std::string out;
  const struct {
    std::string args, fragment;
  } cases[] = {
      {"--span 1.885 --rise 0.95", "--rise"},             // beyond the semicircle
      {"--rise 0", "--rise"},
      {"--span -1", "--span"},
      {"--thickness nan", "--thickness"},
      {"--voussoirs 2", "--voussoirs"},
      {"--voussoirs 4", "--load-voussoir"},               // default loaded voussoir 5 does not exist
      {"--contacts-per-joint 500", "--contacts-per-joint"},  // the engine takes 2..200
      {"--friction-deg 90", "--friction-deg"},
      {"--load line", "--load"},
      {"--record-interval 0.02", "--record-interval"},     // beyond the travel (default 12 mm)
      {"--record-interval -1e-5", "--record-interval"},
  };
  for (const auto& c : cases) {
    EXPECT_NE(run_cli("scene arch " + c.args + " -o /dev/null", out), 0) << c.args;
    EXPECT_NE(out.find(c.fragment), std::string::npos) << c.args << ": " << out;
  }
  EXPECT_NE(run_cli("scene semicircle --thickness-ratio 1.5 -o /dev/null", out), 0);
  EXPECT_NE(out.find("--thickness-ratio"), std::string::npos) << out;
  EXPECT_NE(run_cli("scene wall --unit-height 2 -o /dev/null", out), 0);
  EXPECT_NE(out.find("--unit-height"), std::string::npos) << out;
  EXPECT_NE(run_cli("scene wall --beam-height inf -o /dev/null", out), 0);
  EXPECT_NE(out.find("--beam-height"), std::string::npos) << out;
}

TEST(ArchGenerator, RecordIntervalSetsTheRowsOfTheRecording) {
  // The default: 1200 rows over the travel; a given interval (a measurement's sampling) is kept.
  ArchOptions o;
  o.max_displacement = 2e-4;
  o.velocity = 0.01;
  o.contacts_per_joint = 3;
  EXPECT_DOUBLE_EQ(make_arch(o).loading.record_interval, 2e-4 / 1200);
  o.record_interval = 5e-5;
  const Scene scene = make_arch(o);
  EXPECT_DOUBLE_EQ(scene.loading.record_interval, 5e-5);
  EXPECT_DOUBLE_EQ(scene_from_json(scene_to_json(scene), "arch").loading.record_interval, 5e-5);
  const Recording r = simulate(scene);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  EXPECT_EQ(r.force.size(), 5u);  // travel 0, 50, 100, 150 and 200 um
  WallOptions w;
  EXPECT_DOUBLE_EQ(make_wall(w).loading.record_interval, w.max_displacement / 1000);
  w.record_interval = 1e-3;
  EXPECT_DOUBLE_EQ(make_wall(w).loading.record_interval, 1e-3);
}

TEST(SemicircleGenerator, ThicknessAndVoussoirRangeValidatesAndRuns) {
  for (const double ratio : {0.05, 0.1075, 0.3, 0.9})
    for (const int voussoirs : {3, 8, 31, 60}) {
      SemicircularArchOptions o;
      o.thickness_ratio = ratio;
      o.voussoirs = voussoirs;
      validate_and_step(make_semicircular_arch(o),
                        "semicircle t/R " + std::to_string(ratio) + " voussoirs " + std::to_string(voussoirs));
    }
}

TEST(WallGenerator, CourseAndUnitRangeValidatesAndRuns) {
  int scenes = 0;
  for (const double height : {0.1, 0.25, 0.9, 1.0})
    for (const double length : {0.2, 1.0, 2.35})
      for (const double unit_length : {0.2, 0.333333, 0.45})
        for (const double precompression : {0.0, 1.25}) {
          WallOptions o;
          o.height = height;
          o.length = length;
          o.unit_length = std::min(unit_length, length);
          o.precompression_mpa = precompression;
          o.beam_rotation = scenes % 2;
          o.load_height = scenes % 3 ? 0.1 : 0.0;
          const Scene scene = make_wall(o);
          // No sliver units: every unit is at least a quarter unit long.
          for (const Block& b : scene.blocks) {
            if (b.label != "unit") continue;
            EXPECT_GE(b.vertices[1].x() - b.vertices[0].x(), o.unit_length / 4 - 1e-12) << describe(o);
          }
          const Recording r = validate_and_step(scene, describe(o));
          // Bounded by the joints' elastic closure under the full vertical stress (twice the static
          // value for a suddenly applied load), courses + 1 bed joints in series, plus 1e-3 height.
          const int courses = static_cast<int>(std::lround(height / o.unit_height));
          const double stress = o.precompression_mpa * 1e6 + o.density * 9.81 * height;
          EXPECT_LT(r.max_block_displacement, 2 * (courses + 1) * stress / o.kn + 1e-3 * height) << describe(o);
          ++scenes;
        }
  EXPECT_EQ(scenes, 72);
}

// The joints beside a joint share one of its blocks, and are named as a run reports its joints.
TEST(Joints, TheJointsBesideAJointShareOneOfItsBlocks) {
  const Scene arch = make_arch(ArchOptions{});
  const std::vector<std::string> beside = {"voussoir_4/voussoir_5", "voussoir_6/voussoir_7"};
  EXPECT_EQ(joints_beside(arch, "voussoir_5/voussoir_6"), beside);
  EXPECT_EQ(joints_beside(arch, "voussoir_6/voussoir_5"), beside);  // either order
  EXPECT_EQ(joints_beside(arch, "abutment_left/voussoir_1"), std::vector<std::string>{"voussoir_1/voussoir_2"});
  EXPECT_TRUE(joints_beside(arch, "voussoir_5/pier").empty());
  EXPECT_TRUE(joints_beside(arch, "voussoir_5").empty());
  // The names a run reports: each has joints beside it, none reported with its blocks the other way round.
  const Recording r = validate_and_step(arch, "arch");
  std::vector<std::string> reported;
  for (const auto& j : r.joints) reported.push_back(j.name);
  ASSERT_GE(reported.size(), 2u);
  const auto reversed = [](const std::string& j) { return j.substr(j.find('/') + 1) + "/" + j.substr(0, j.find('/')); };
  for (const auto& joint : reported) {
    const auto around = joints_beside(arch, joint);
    EXPECT_FALSE(around.empty()) << joint;
    for (const auto& other : around)
      EXPECT_EQ(std::find(reported.begin(), reported.end(), reversed(other)), reported.end()) << other << " beside " << joint;
  }
  // A wall's unit touches several: every joint beside shares a block with the joint and no joint twice.
  const Scene wall = make_wall(WallOptions{});
  const Recording w = validate_and_step(wall, "wall");
  ASSERT_FALSE(w.joints.empty());
  const std::string joint = w.joints.front().name;
  const auto around = joints_beside(wall, joint);
  EXPECT_GE(around.size(), 2u);
  const auto blocks_of = [](const std::string& j) {
    return std::make_pair(j.substr(0, j.find('/')), j.substr(j.find('/') + 1));
  };
  const auto [a, b] = blocks_of(joint);
  for (const auto& other : around) {
    const auto [c, d] = blocks_of(other);
    EXPECT_TRUE(c == a || c == b || d == a || d == b) << other << " beside " << joint;
    EXPECT_EQ(std::count(around.begin(), around.end(), other), 1) << other;
  }
}
