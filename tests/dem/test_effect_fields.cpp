// The effects' declarations drive the scene layer: every value an effect declares (SceneField)
// round-trips through scene files, is taken by set_parameter and the generators' options, and is
// refused outside its limits naming its key; and the scene, generator and `demcal scene` sources
// name no effect value, so that a new effect is one file in dem/src plus its tests.
#include "demcal/dem/effects.hpp"
#include "demcal/dem/generators.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

namespace {

using namespace demcal::dem;
using nlohmann::json;

constexpr const char* kGapJoint = "voussoir_9/voussoir_10";

// The reference arch with its gap joint named, so that every host of an effect value is there.
Scene arch_with_gap_joint() {
  Scene s = make_arch(ArchOptions{});
  s.joint_gap.joint = kGapJoint;
  return s;
}

// The block of the arch that holds an effect's block values: a support, or the loaded voussoir.
std::string block_of(const Effect& effect) {
  return effect.target == EffectTarget::support_blocks ? "abutment_right" : "voussoir_5";
}

// The set_parameter name of a field at one place of the arch: one joint group, one block, the gap.
std::string parameter_at_one_place(const Effect& effect, const SceneField& f) {
  if (f.material) return "arch_joints." + f.name;
  if (f.block) return block_of(effect) + "." + f.name;
  return f.name;
}

// The field's host object in the arch's scene file; for a derived value, a gap object holding
// only the joint (the stored values and the derived ones are never given together).
json& host_object(json& scene, const Effect& effect, const SceneField& f) {
  if (f.material) return scene["joint_groups"]["arch_joints"];
  if (f.block) {
    for (json& block : scene["blocks"])
      if (block["name"] == block_of(effect)) return block;
  }
  if (f.derived()) scene["joint_gap"] = {{"joint", kGapJoint}};
  return scene["joint_gap"];
}

// A value within the field's limits, not 0.
double inside(const SceneField& f) { return std::isfinite(f.upper) ? f.upper / 4 : 1e-3; }

template <class F>
void for_each_field(F f) {
  for (const Effect& effect : effect_registry())
    for (const SceneField& field : effect.scene_fields) f(effect, field);
}

TEST(EffectFields, EveryFieldRoundTripsThroughSceneFilesAndSetParameter) {
  const Scene plain = arch_with_gap_joint();
  int fields = 0;
  for_each_field([&](const Effect& effect, const SceneField& f) {
    ++fields;
    const std::string name = parameter_at_one_place(effect, f);
    SCOPED_TRACE(effect.name + ": " + name);
    Scene s = plain;
    set_parameter(s, name, inside(f));
    EXPECT_NEAR(get_parameter(s, name), inside(f), 1e-12 * inside(f));
    EXPECT_NE(scene_hash(s), scene_hash(plain));
    const json written = scene_to_json(s);
    const Scene back = scene_from_json(written, "roundtrip");
    EXPECT_EQ(scene_hash(back), scene_hash(s));
    EXPECT_EQ(get_parameter(back, name), get_parameter(s, name));
    // The file's own key: written for a stored value, read for either
    json file = scene_to_json(plain);
    json& host = host_object(file, effect, f);
    if (!f.derived()) {
      json copy = written;
      EXPECT_NEAR(host_object(copy, effect, f).at(f.key()).get<double>(), inside(f), 1e-12 * inside(f));
    }
    host[f.key()] = inside(f);
    EXPECT_NEAR(get_parameter(scene_from_json(file, "file"), name), inside(f), 1e-12 * inside(f));
  });
  EXPECT_GE(fields, 15);
}

TEST(EffectFields, OutOfItsLimitsAFieldIsRefusedNamingItsKey) {
  const Scene plain = arch_with_gap_joint();
  for_each_field([&](const Effect& effect, const SceneField& f) {
    const std::string name = parameter_at_one_place(effect, f);
    std::vector<double> outside = {f.lower - 1};
    if (std::isfinite(f.upper) && !f.bounded_by_rule) outside.push_back(2 * f.upper);
    for (const double v : outside) {
      SCOPED_TRACE(name + " = " + std::to_string(v));
      const std::string at_key = "." + f.key() + ": must";
      // set_parameter takes a stored value for Validate to refuse; a derived one it refuses itself
      Scene s = plain;
      try {
        set_parameter(s, name, v);
        EXPECT_FALSE(f.derived());
        s.Validate("scene");
        ADD_FAILURE() << "accepted";
      } catch (const SceneError& e) {
        const std::string expected = f.derived() ? "parameter '" + name + "': must" : at_key;
        EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
      }
      // a scene file with the value
      json file = scene_to_json(plain);
      host_object(file, effect, f)[f.key()] = v;
      try {
        scene_from_json(file, "bad.json");
        ADD_FAILURE() << "accepted";
      } catch (const SceneError& e) {
        EXPECT_NE(std::string(e.what()).find(at_key), std::string::npos) << e.what();
      }
    }
  });
}

TEST(EffectFields, EveryFieldIsAParameterNameAndInTheListOfNames) {
  Scene s = arch_with_gap_joint();
  set_parameter(s, "voussoir_5.beam_kr", 1e6);
  const std::vector<std::string> names = parameter_names(s);
  std::string unknown;
  try {
    get_parameter(s, "moss");
  } catch (const SceneError& e) {
    unknown = e.what();
  }
  for_each_field([&](const Effect& effect, const SceneField& f) {
    EXPECT_NE(std::find(names.begin(), names.end(), f.name), names.end()) << f.name;
    EXPECT_NE(std::find(names.begin(), names.end(), parameter_at_one_place(effect, f)), names.end()) << f.name;
    EXPECT_NE(unknown.find(f.name), std::string::npos) << unknown;
  });
}

// Each effect's parameters (what a calibration searches) are some of its scene values, with their
// physical bounds.
TEST(EffectFields, EveryParameterIsAFieldWithItsBounds) {
  for (const Effect& effect : effect_registry())
    for (const EffectParameter& p : effect.parameters) {
      const auto f = std::find_if(effect.scene_fields.begin(), effect.scene_fields.end(),
                                  [&](const SceneField& field) { return field.name == p.name; });
      ASSERT_NE(f, effect.scene_fields.end()) << p.name;
      EXPECT_EQ(f->lower, p.lower_bound) << p.name;
      EXPECT_EQ(f->upper, p.upper_bound) << p.name;
      EXPECT_EQ(f->unit, p.unit) << p.name;
    }
}

// Every flag sets its field through the generators' options ("--closure-max" is option
// closure_max), an effect on one joint with its target.
TEST(EffectFields, EveryGeneratorOptionSetsItsField) {
  for (const Effect& effect : effect_registry())
    for (const EffectFlag& flag : effect.flags) {
      std::string expected_flag = "--" + flag.option;
      std::replace(expected_flag.begin(), expected_flag.end(), '_', '-');
      EXPECT_EQ(flag.flag, expected_flag);
      if (flag.names_target) continue;
      const auto f = std::find_if(effect.scene_fields.begin(), effect.scene_fields.end(),
                                  [&](const SceneField& field) { return field.name == flag.option; });
      ASSERT_NE(f, effect.scene_fields.end()) << flag.option;
      ArchOptions o;
      o.effects.values[flag.option] = inside(*f);
      for (const EffectFlag& other : effect.flags)
        if (other.names_target && effect.target == EffectTarget::joint) o.effects.targets[other.option] = kGapJoint;
      const Scene s = make_arch(o);
      EXPECT_NEAR(get_parameter(s, parameter_at_one_place(effect, *f)), inside(*f), 1e-12 * inside(*f)) << flag.flag;
    }
  ArchOptions misspelt;
  misspelt.effects.values["closure_maximum"] = 1e-4;
  try {
    make_arch(misspelt);
    ADD_FAILURE() << "accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("closure_maximum"), std::string::npos) << e.what();
  }
}

// Like Diagnose.NoStageNamesAnEffect: the scene layer, the generators and `demcal scene` take every
// effect value from the registry, so their sources name none (as a quoted key, option or flag).
TEST(EffectFields, SceneGeneratorsAndSceneCommandNameNoEffectValue) {
  const std::filesystem::path root(DEMCAL_SOURCE_DIR);
  for (const char* file : {"dem/src/scene.cpp", "dem/src/generators.cpp", "pipelines/cli/cmd_scene.cpp"}) {
    std::ifstream in(root / file);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_FALSE(text.empty()) << file;
    const auto expect_absent = [&](const std::string& needle) {
      EXPECT_EQ(text.find(needle), std::string::npos) << file << " names " << needle;
    };
    for (const Effect& effect : effect_registry()) {
      expect_absent("\"" + effect.name + "\"");
      for (const SceneField& f : effect.scene_fields) {
        expect_absent("\"" + f.name + "\"");
        expect_absent("\"" + f.key() + "\"");
      }
      for (const EffectFlag& flag : effect.flags) {
        expect_absent("\"" + flag.option + "\"");
        expect_absent(flag.flag);
      }
    }
  }
}

}  // namespace
