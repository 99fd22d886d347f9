// `demcal simulate scene.json --out DIR`: run one scene; write summary.json, curves.csv, final.vtk.
#include "command_registry.hpp"

#include "demcal/dem/simulation.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <iostream>

namespace demcal::cli::simulate_command {

namespace fs = std::filesystem;
using namespace demcal::dem;

void setup_simulate(CLI::App& app) {
  static std::string scene_path, out_dir;
  auto* sub = app.add_subcommand("simulate", "Run a scene; write DIR/summary.json, DIR/curves.csv, DIR/final.vtk");
  sub->add_option("scene", scene_path, "Scene JSON")->required();
  sub->add_option("--out", out_dir, "Output folder")->required();
  sub->callback([] {
    const Scene scene = load_scene(scene_path);  // validates before anything is written
    const Recording rec = simulate(scene);
    // Write into a temporary folder and rename, so no partial output is ever left behind.
    const fs::path target(out_dir), staging = fs::path(out_dir + ".partial");
    fs::remove_all(staging);
    fs::create_directories(staging);
    try {
      std::ofstream(staging / "summary.json") << summary_json(rec).dump(2) << "\n";
      write_curves_csv(rec, (staging / "curves.csv").string());
      write_vtk(rec, (staging / "final.vtk").string());
    } catch (...) {
      fs::remove_all(staging);
      throw;
    }
    fs::remove_all(target);
    fs::rename(staging, target);
    std::cout << "status " << to_string(rec.status) << ": " << rec.message << "\n"
              << "peak force " << rec.peak_force << " N, " << rec.steps << " steps, " << rec.wall_time_s << " s\n"
              << "hinges:";
    for (const auto& h : rec.hinges) std::cout << " " << h;
    std::cout << "\nsliding joints:";
    for (const auto& s : rec.sliding_joints) std::cout << " " << s;
    std::cout << "\nwrote " << out_dir << "/summary.json, curves.csv, final.vtk\n";
  });
}

DEMCAL_REGISTER_COMMAND("simulate", setup_simulate);

}  // namespace demcal::cli::simulate_command
