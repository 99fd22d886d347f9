// `demcal scene arch|semicircle|wall [flags] -o scene.json`: write a generated scene.
#include "command_registry.hpp"

#include "demcal/dem/effects.hpp"
#include "demcal/dem/generators.hpp"

#include <iostream>

namespace demcal::cli::scene_command {

using namespace demcal::dem;

// What the help of an effect's flag says about a generator's scene (EffectFlag::help).
struct GeneratorFacts {
  std::string fixed_blocks;    // comma-separated
  bool rotation_held = false;  // the loaded block is held in rotation (the wall's beam)
};

// Flags of the engine's effects, as each effect declares them (Effect::flags; docs/engine.md,
// docs/scene-format.md); 0 / empty = off.
void add_effect_flags(CLI::App* app, EffectOptions& options, const GeneratorFacts& facts) {
  const std::string group = "Effects (0 = off)", fixed_blocks = "{fixed blocks}";
  for (const Effect& effect : effect_registry())
    for (const EffectFlag& f : effect.flags) {
      std::string help = f.help;
      if (const auto at = help.find(fixed_blocks); at != std::string::npos)
        help.replace(at, fixed_blocks.size(), facts.fixed_blocks);
      if (facts.rotation_held) help += f.help_if_rotation_held;
      if (f.names_target)
        app->add_option(f.flag, options.targets[f.option], help)->group(group);
      else
        app->add_option(f.flag, options.values[f.option], help)->group(group)->capture_default_str();
    }
}

void setup_scene(CLI::App& app) {
  auto* scene = app.add_subcommand("scene", "Generate a scene JSON (reference arch, semicircular arch or dry-joint wall)");
  scene->require_subcommand(1);

  static ArchOptions arch;
  static std::string arch_out;
  auto* a = scene->add_subcommand("arch", "Segmental arch on fixed abutments, rise up to span/2 (defaults: the reference arch)");
  a->add_option("--span", arch.span, "Clear span at the intrados (m)")->capture_default_str();
  a->add_option("--rise", arch.rise, "Clear rise at the intrados (m)")->capture_default_str();
  a->add_option("--thickness", arch.thickness, "Radial thickness (m)")->capture_default_str();
  a->add_option("--width", arch.width, "Out-of-plane width (m)")->capture_default_str();
  a->add_option("--voussoirs", arch.voussoirs, "Blocks in the ring, keystone included")->capture_default_str();
  a->add_option("--density", arch.density, "Unit density (kg/m^3)")->capture_default_str();
  a->add_option("--kn", arch.kn, "Joint normal stiffness (Pa/m)")->capture_default_str();
  a->add_option("--ks", arch.ks, "Joint shear stiffness (Pa/m)")->capture_default_str();
  a->add_option("--friction-deg", arch.friction_deg, "Joint friction angle (degrees)")->capture_default_str();
  a->add_option("--contacts-per-joint", arch.contacts_per_joint, "Contact points along a joint")->capture_default_str();
  a->add_option("--load-voussoir", arch.load_voussoir, "Loaded voussoir, 1-based from the left")->capture_default_str();
  a->add_option("--velocity", arch.velocity, "Loading velocity (m/s)")->capture_default_str();
  a->add_option("--max-displacement", arch.max_displacement, "Actuator travel (m)")->capture_default_str();
  a->add_option("--record-interval", arch.record_interval,
                "Actuator travel between recorded rows (m); 0 = max-displacement / 1200")->capture_default_str();
  a->add_option("--load", arch.load, "point | none (self-weight only)")->capture_default_str();
  a->add_option("--max-time", arch.max_time, "Simulated time limit (s); 0 = automatic")->capture_default_str();
  add_effect_flags(a, arch.effects, {"abutment_left,abutment_right", false});
  a->add_option("-o,--output", arch_out, "Scene file to write")->required();
  a->callback([] {
    save_scene(make_arch(arch), arch_out);
    std::cout << "wrote " << arch_out << "\n";
  });

  static SemicircularArchOptions semi;
  static std::string semi_out;
  auto* c = scene->add_subcommand("semicircle",
                                  "Semicircular arch on fixed bases, self-weight only (Milankovitch verification)");
  c->add_option("--radius", semi.radius, "Centre-line radius (m)")->capture_default_str();
  c->add_option("--thickness-ratio", semi.thickness_ratio, "Thickness / centre-line radius")->capture_default_str();
  c->add_option("--voussoirs", semi.voussoirs, "Blocks in the ring")->capture_default_str();
  c->add_option("--width", semi.width, "Out-of-plane width (m)")->capture_default_str();
  c->add_option("--density", semi.density, "Unit density (kg/m^3)")->capture_default_str();
  c->add_option("--kn", semi.kn, "Joint normal stiffness (Pa/m)")->capture_default_str();
  c->add_option("--ks", semi.ks, "Joint shear stiffness (Pa/m)")->capture_default_str();
  c->add_option("--friction-deg", semi.friction_deg, "Joint friction angle (degrees)")->capture_default_str();
  c->add_option("--contacts-per-joint", semi.contacts_per_joint, "Contact points along a joint")->capture_default_str();
  c->add_option("-o,--output", semi_out, "Scene file to write")->required();
  c->callback([] {
    save_scene(make_semicircular_arch(semi), semi_out);
    std::cout << "wrote " << semi_out << "\n";
  });

  static WallOptions wall;
  static std::string wall_out;
  auto* w = scene->add_subcommand("wall", "Dry-joint running-bond wall under pre-compression and shear");
  w->add_option("--height", wall.height, "Wall height (m)")->capture_default_str();
  w->add_option("--length", wall.length, "Wall length (m)")->capture_default_str();
  w->add_option("--thickness", wall.thickness, "Wall thickness, out of plane (m)")->capture_default_str();
  w->add_option("--unit-height", wall.unit_height, "Unit height (m)")->capture_default_str();
  w->add_option("--unit-length", wall.unit_length, "Unit length (m)")->capture_default_str();
  w->add_option("--density", wall.density, "Unit density (kg/m^3)")->capture_default_str();
  w->add_option("--precompression", wall.precompression_mpa, "Vertical stress on the top (MPa)")->capture_default_str();
  w->add_option("--kn", wall.kn, "Joint normal stiffness (Pa/m)")->capture_default_str();
  w->add_option("--ks", wall.ks, "Joint shear stiffness (Pa/m)")->capture_default_str();
  w->add_option("--friction-deg", wall.friction_deg, "Joint friction angle (degrees)")->capture_default_str();
  w->add_option("--contacts-per-joint", wall.contacts_per_joint, "Contact points along a joint")->capture_default_str();
  w->add_option("--velocity", wall.velocity, "Horizontal loading velocity (m/s)")->capture_default_str();
  w->add_option("--max-displacement", wall.max_displacement, "Horizontal travel of the top (m)")->capture_default_str();
  w->add_option("--record-interval", wall.record_interval,
                "Travel between recorded rows (m); 0 = max-displacement / 1000")->capture_default_str();
  w->add_flag("--beam-rotation,!--no-beam-rotation", wall.beam_rotation, "Let the top beam rotate")->capture_default_str();
  w->add_option("--load-height", wall.load_height, "Height of the actuator above the wall top (m)")->capture_default_str();
  w->add_option("--actuator-stiffness", wall.actuator_stiffness, "Actuator spring stiffness (N/m)")->capture_default_str();
  w->add_option("--max-time", wall.max_time, "Simulated time limit (s); 0 = automatic")->capture_default_str();
  add_effect_flags(w, wall.effects, {"base", true});
  w->add_option("-o,--output", wall_out, "Scene file to write")->required();
  w->callback([] {
    save_scene(make_wall(wall), wall_out);
    std::cout << "wrote " << wall_out << "\n";
  });
}

DEMCAL_REGISTER_COMMAND("scene", setup_scene);

}  // namespace demcal::cli::scene_command
