// The library of physical effects the engine can add to the plain model (dry Mohr-Coulomb joints on
// rigid supports), described for programs that try them in turn: each effect's name, its physical
// meaning, its parameters with SI units, physical bounds and a default search range, and a switch
// that turns it on in a Scene. Every effect is off in a scene until switched on. Each effect also
// declares its values in a scene (SceneField: file keys, limits) and its generator options and
// flags (EffectFlag), which the scene files, set_parameter, the generators and `demcal scene` read
// from here. The values live in scene.hpp (JointMaterial, Block, JointGap); the physics is in
// docs/engine.md.
#pragma once

#include "demcal/dem/scene.hpp"

#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace demcal::dem {

// What a parameter's search range is relative to. A material strength only matters against the
// stresses the structure reaches: a compressive strength above the largest contact stress never
// acts, whatever the structure, so its range is written as fractions of that stress.
enum class SearchScale {
  absolute,            // search_min..search_max as written
  peak_normal_stress,  // scaled_min..scaled_max x the largest normal stress at a contact node (Pa),
                       // never below the largest one at the start of loading (a strength below it
                       // crushes the structure under its weight and pre-compression before the test)
  stress_level,        // the same multiples of that stress, with no floor: a stress a law's response
                       // is measured against, not a strength (shear stiffening's doubling stress)
};

// One numeric parameter of an effect, named as set_parameter's field ("closure_max").
struct EffectParameter {
  std::string name;
  std::string unit;           // SI ("m", "Pa", "N/m", "N m/rad"), "deg" for the friction angle, "1" for a ratio
  std::string meaning;        // one line
  double lower_bound = 0;     // physical bounds Scene::Validate enforces (upper may be +infinity)
  double upper_bound = 0;
  double search_min = 0;      // a sensible default calibration range, inside the bounds
  double search_max = 0;
  bool log_scale = false;     // search on log10 (ranges spanning decades)
  double default_value = 0;   // the value enable_effect sets
  // Optional structure-relative range (see SearchScale); search_min..search_max stay the fallback
  // where the scale is unknown.
  SearchScale search_scale = SearchScale::absolute;
  double scaled_min = 0;
  double scaled_max = 0;
  // True where the top of the search range is the nearest the search comes to the effect's simplest
  // form, which the range itself cannot hold: crushing_softening, whose limit past any length is
  // the scene's 0, a perfectly plastic cap. Programs that probe an effect before searching it
  // also search that form, at search_max, along the effect's other parameters (demcal diagnose,
  // pipelines::search_simplest_form), so that a search can start from it.
  bool simplest_form_at_max = false;
  // The base parameter whose value bounds this one above, as a set_parameter field ("friction_deg"
  // for friction_loss_deg, whose residual friction_deg - loss stays >= 0); "" = none. Programs
  // that search the effect beside the base parameters cap its range there, in the same joint group.
  std::string capped_by{};
};

// The response of a structure, from a run of its model, that scaled search ranges refer to; 0 = unknown.
struct ResponseScales {
  double peak_normal_stress = 0;   // Pa, Recording::max_normal_stress
  double start_normal_stress = 0;  // Pa, Recording::start_normal_stress
};

// `p` with its search range resolved for a structure (see SearchScale) when the parameter has a
// scale and the scale is known (> 0), clipped to the physical bounds; else `p` unchanged.
EffectParameter scaled_search_range(const EffectParameter& p, const ResponseScales& scales);
// How scaled_search_range resolved `p`'s range, in words for a report ("0.03 to 3 x the largest
// contact stress of the base fit, 8.2e+05 Pa, and not below ..."); "" for an absolute range or an
// unknown scale.
std::string scaled_range_words(const EffectParameter& p, const ResponseScales& scales);

// What an effect attaches to, and so what enable_effect's `targets` name.
enum class EffectTarget {
  joint_groups,    // joint-group names; empty = every group
  support_blocks,  // fixed blocks; empty = every fixed block
  joint,           // exactly one joint "blockA/blockB" (two blocks sharing an edge at the start)
  beam_block,      // one free block; empty = the loaded block (scene.loading.block)
};
std::string to_string(EffectTarget target);

// A fit of an effect, as its finding reads it: the calibrated set of base + effect.
struct FittedEffect {
  std::map<std::string, double> params;       // the fit's set_parameter names -> values, base ones included
  std::map<std::string, double> base_params;  // the base model's, whose names are not the effect's
  std::string target;                         // what the effect was switched on for ("" = its default)
  // The first value, in name order, of a field ("closure_max" of "arch_joints.closure_max") among
  // the effect's own parameters (names not in base_params) / among every fitted parameter.
  std::optional<double> effect_value(const std::string& field) const;
  std::optional<double> fitted_value(const std::string& field) const;
};

// One numeric value an effect adds to a scene, declared once in the effect's file. Scene files
// (scene_from_json, scene_to_json), Scene::Validate, set_parameter / get_parameter /
// parameter_names, the generators' EffectOptions and `demcal scene` all loop over these
// declarations, and name none of them. The value lives in one of three hosts, told by which of the
// pointers below is set:
//   a joint group's JointMaterial: key in the group's object; set_parameter "<name>" sets every
//     group, "<group>.<name>" one;
//   a Block: key in the block's object; "<block>.<name>", or bare for the effect's default blocks
//     (EffectTarget::support_blocks: every fixed block; beam_block: the loaded block);
//   the scene's JointGap: key in the object "joint_gap"; bare names only.
struct SceneField {
  std::string name;        // set_parameter's field and the generator option ("closure_max", "gap_opening")
  std::string json_key{};  // key in the host's JSON object where it differs from `name` ("opening")
  std::string unit;        // SI, "deg", "1": as EffectParameter::unit
  double JointMaterial::*material = nullptr;
  double Block::*block = nullptr;
  double JointGap::*gap = nullptr;
  // A value derived from the stored ones (the gap's ends from its opening and taper): an alternative
  // way to give them. set_parameter sets it through `set_gap`, a scene file may give it instead of
  // the stored keys (never beside them), and it is never written.
  double (*get_gap)(const JointGap&) = nullptr;
  void (*set_gap)(JointGap&, double) = nullptr;
  bool degrees = false;  // given in degrees (file, set_parameter), held in radians
  // Limits that Scene::Validate enforces, naming the key (a derived value: where it is given):
  // finite, then with a lower bound of 0 "must not be negative" and, under a finite upper bound,
  // "must be at most <upper> (<reason>)"; with another lower bound "must be in [<lower>, <upper>]
  // (<reason>)".
  double lower = 0;
  double upper = std::numeric_limits<double>::infinity();
  std::string reason{};
  // Where the bounds depend on other values (the residual friction on friction_deg), Effect::
  // check_material enforces them instead, and lower/upper only describe the range.
  bool bounded_by_rule = false;
  // Joint-group values only: the field zeroed when this one is set (two forms of one value, the
  // residual friction as an angle or as a loss), and when scene_to_json writes the key (null: when
  // the value is not 0, so that a scene with the effect off keeps its text and its hash).
  double JointMaterial::*clears = nullptr;
  bool (*written)(const JointMaterial&) = nullptr;

  const std::string& key() const { return json_key.empty() ? name : json_key; }
  bool derived() const { return set_gap != nullptr; }
};

// One option of the scene generators (EffectOptions) and its `demcal scene arch|wall` flag.
struct EffectFlag {
  std::string option;  // the SceneField it sets ("closure_max"), or with `names_target` the target option
  std::string flag;    // "--closure-max"
  std::string help;    // "{fixed blocks}" stands for the generator's fixed blocks ("abutment_left,abutment_right")
  std::string help_if_rotation_held{};  // appended where the generator's loaded block is held in rotation
  // Text naming where the effect's values go: support blocks, comma-separated (none: every fixed
  // block), or the one joint "blockA/blockB", which the effect's values then need.
  bool names_target = false;
};

// What set_parameter and Scene::Validate say about an effect on blocks (EffectTarget::support_blocks
// or beam_block, whose values need fixed or free blocks).
struct BlockTargetTexts {
  std::string misplaced;   // Validate: a value on a block of the other kind (at the block, or at the
                           // value where the effect has one)
  std::string needs;       // set_parameter "<block>.<name>" for a block of the other kind, before
                           // "; '<block>' is free" (or "fixed")
  std::string no_default;  // set_parameter "<name>" where the scene has no default block
};

// One effect: one file each (dem/src/effect_<name>.cpp) declares all of this, and nothing else in
// the library or in programs that try effects (demcal diagnose) branches on its name.
struct Effect {
  std::string name;       // "joint-closure", "friction-softening", "cohesion", "crushing-cap",
                          // "support-compliance", "joint-gap", "boundary-restraint"
  std::string meaning;    // one line of physics
  EffectTarget target = EffectTarget::joint_groups;
  std::vector<EffectParameter> parameters;
  const EffectParameter* parameter(const std::string& field) const;  // the one of that field; null if none
  std::function<bool(const Scene&)> enabled{};  // on anywhere in the scene
  // What a fit means in a structural engineer's words ("the supports yield elastically ...: horizontal
  // stiffness about 1.1 MN/m ..."); "" when the fit lacks a value the sentence needs.
  std::function<std::string(const FittedEffect&)> finding{};

  // Its values in a scene (a superset of `parameters`: other forms of them, such as the residual
  // friction as an angle or the gap's ends), in the order of scene files and set_parameter's list.
  std::vector<SceneField> scene_fields{};
  // Its generator options and `demcal scene` flags, in the order `--help` prints them.
  std::vector<EffectFlag> flags{};
  // Rules across a joint group's values, run by Scene::Validate after the limits of this effect's
  // joint-group fields; throws SceneError at `where` + "." + the key.
  void (*check_material)(const JointMaterial& material, const std::string& where) = nullptr;
  BlockTargetTexts block_texts{};  // effects on blocks only
};

// The effect's finding for a fit (Effect::finding), or "effect <name>" when it has none.
std::string describe_fit(const Effect& effect, const FittedEffect& fit);

// Every effect, in a fixed order.
const std::vector<Effect>& effect_registry();
// The effect of that name; throws SceneError listing the known names.
const Effect& find_effect(const std::string& name);

// Switches `name` on in `scene` at its parameters' default values, for the given targets (see
// EffectTarget), and returns the set_parameter names that now control it in this scene, in the
// order of Effect::parameters (per target): "closure_max" when every group is meant,
// "arch_joints.closure_max" for one group, "abutment_right.support_kx", "gap_intrados", "beam_kr".
// A default above its cap (EffectParameter::capped_by) in a group is lowered to the group's value
// of the cap, and the parameter then named per group when the scene has several. Throws
// SceneError for unknown names or targets, and validates the scene afterwards.
std::vector<std::string> enable_effect(Scene& scene, const std::string& name,
                                       const std::vector<std::string>& targets = {});

// True when the effect is on anywhere in the scene.
bool effect_enabled(const Scene& scene, const std::string& name);

}  // namespace demcal::dem
