// Scene generators: the reference segmental arch (Birhane's test), semicircular verification
// arches and dry-joint running-bond walls. Defaults reproduce the reference set-ups; lengths in m.
#pragma once

#include "demcal/dem/scene.hpp"

#include <map>
#include <string>

namespace demcal::dem {

// The effects of docs/engine.md as generator options (`demcal scene arch|wall` flags), by the names
// the effects declare (Effect::flags, effects.hpp): `values` by option ("closure_max", "support_kx",
// "gap_intrados"), `targets` by target option ("support_blocks": comma-separated fixed blocks, none
// = every fixed block; "gap_joint": "blockA/blockB"). An absent or 0 value leaves its effect off;
// joint-group options apply to every joint group of the scene.
struct EffectOptions {
  std::map<std::string, double> values;
  std::map<std::string, std::string> targets;
};
// Writes the options into the scene and validates it (SceneError naming the option's key, or the
// flags where an effect's values lack their target). Throws for option names no effect declares.
void apply_effects(Scene& scene, const EffectOptions& effects);

// Segmental arch of equal voussoirs with radial joints between two fixed abutment blocks.
// The geometry follows from the clear span and rise at the intrados: for the defaults an intrados
// radius of 0.65 m and an opening half-angle of 67.38 deg. Any rise in (0, span/2] is built, up to
// the semicircle: where the springing joint is within 20 deg of horizontal the abutment's top is the
// springing face extended by abutment_depth instead of a level top beside it.
struct ArchOptions {
  double span = 1.2;                 // clear span at the intrados (m)
  double rise = 0.4;                 // clear rise at the intrados (m)
  double thickness = 0.16;           // radial thickness of the ring (m)
  double width = 0.2;                // out-of-plane width (m)
  int voussoirs = 13;                // blocks in the ring, keystone included
  double density = 2650;             // kg/m^3
  double kn = 4e9;                   // Pa/m
  double ks = 1.6e9;                 // Pa/m
  double friction_deg = 30.5;        // degrees (converted to rad in the scene)
  int contacts_per_joint = 15;
  int load_voussoir = 5;             // counted from the left, 1-based
  double interface_height = 0.05;    // wooden interface above the voussoir's extrados middle (m)
  double interface_length = 0.11;    // its horizontal length (m), sets the actuator's contact area
  double velocity = 0.01;            // m/s (10 mm/s)
  double max_displacement = 0.012;   // m
  // m of actuator travel between recorded rows; 0 = max_displacement / 1200. Set it to the
  // measurement's sampling so that both curves are read at the same instants (docs/diagnose.md).
  double record_interval = 0;
  std::string load = "point";        // "point" | "none"
  double max_time = 0;               // s; 0 = travel time x 1.5 + 5 s
  double abutment_depth = 0.3;       // extent of each abutment block below and beside the springing (m)
  EffectOptions effects;             // all off: the published model

  void Validate() const;  // throws SceneError naming the flag
};
Scene make_arch(const ArchOptions& options);

// Semicircular arch with radial joints on two fixed bases, self-weight only (verification against
// Milankovitch's minimum thickness, t/R = 0.1075 for radial joints). `radius` is the centre-line
// radius. `demcal scene semicircle` writes it. (make_arch with rise = span/2 builds a loaded
// semicircle on abutments instead.)
struct SemicircularArchOptions {
  double radius = 1.0;             // centre-line radius (m)
  double thickness_ratio = 0.115;  // t / R, in (0, 1)
  int voussoirs = 31;
  double width = 1.0;              // out-of-plane width (m)
  double density = 2000;           // kg/m^3
  double kn = 1e11;                // Pa/m
  double ks = 1e11;                // Pa/m
  double friction_deg = 70;        // degrees
  int contacts_per_joint = 15;

  void Validate() const;  // throws SceneError naming the flag
};
Scene make_semicircular_arch(const SemicircularArchOptions& options);

// Dry-joint running-bond wall on a fixed base, with a rigid top beam carrying a constant vertical
// force and pushed horizontally at `load_height` above the top of the wall (cantilever).
struct WallOptions {
  double height = 0.9;             // m (courses = round(height / unit_height))
  double length = 1.0;             // m
  double thickness = 0.2;          // m, out-of-plane width
  double unit_height = 0.1;        // m
  double unit_length = 0.2;        // m
  double density = 2400;           // kg/m^3
  double precompression_mpa = 0.15;  // vertical stress on the top (MPa), beam weight included
  double kn = 2e10;
  double ks = 8e9;
  double friction_deg = 32;
  int contacts_per_joint = 15;
  double velocity = 0.002;         // m/s
  double max_displacement = 0.02;  // m
  double record_interval = 0;      // m of travel between recorded rows; 0 = max_displacement / 1000
  bool beam_rotation = false;      // true: the top beam may rotate
  double beam_height = 0.1;        // m
  double load_height = 0.1;        // m above the top of the wall where the actuator pushes
  // N/m of the actuator spring. Independent of the joints' kn (calibration changes kn, not the
  // rig); stiff against the walls (15-50 kN/mm measured) without ringing at the time step.
  double actuator_stiffness = 2e8;
  double max_time = 0;             // s; 0 = travel time x 1.5 + 5 s
  EffectOptions effects;           // all off: the plain model

  void Validate() const;
};
Scene make_wall(const WallOptions& options);

}  // namespace demcal::dem
