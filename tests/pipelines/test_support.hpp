// Helpers shared by the pipelines tests: scratch folders, JSON files, the toy external simulator.
#pragma once

#include "demcal/dem/scene.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace demcal::pipelines::test_support {

namespace fs = std::filesystem;

// The small simulator script the external-command backend is tested with (not demcal code).
inline const std::string kToySimulator = std::string(DEMCAL_SOURCE_DIR) + "/tests/pipelines/toy_simulator.py";

inline std::string python() { return fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3"; }

// One realisation of the engine's round-off: the automatic time step's face rule and its safety
// factor moved by k x 1e-14, the same physics. The tests on a chaotic curve run the one that
// DEMCAL_TEST_REALISATION names ("FACES:K", e.g. "all:1"; default: the engine's own, k = 0) and
// assert on it whatever it is; scripts/round_off_rates.sh runs them on eight and counts how often
// they pass, a benchmark's figure (docs/journal/diagnose-studies.md).
struct Realisation {
  std::string faces = dem::SolverSettings{}.time_step_faces;
  int k = 0;
  double safety() const { return dem::SolverSettings{}.time_step_safety * (1 + k * 1e-14); }
  // the campaign scene's "solver" (docs/pipelines.md)
  nlohmann::json solver() const { return {{"time_step_faces", faces}, {"time_step_safety", safety()}}; }
  void apply(dem::Scene& scene) const {
    scene.solver.time_step_faces = faces;
    scene.solver.time_step_safety = safety();
  }
  std::string name() const { return faces + "_k" + (k < 0 ? "m" + std::to_string(-k) : std::to_string(k)); }
};

inline void PrintTo(const Realisation& r, std::ostream* os) { *os << r.name(); }

inline std::string realisation_name(const ::testing::TestParamInfo<Realisation>& info) { return info.param.name(); }

// The realisation DEMCAL_TEST_REALISATION names, else the default. A malformed value throws.
inline Realisation realisation_from_environment() {
  Realisation r;
  const char* text = std::getenv("DEMCAL_TEST_REALISATION");
  if (text == nullptr || *text == 0) return r;
  const std::string value = text;
  const auto colon = value.find(':');
  if (colon == std::string::npos) throw std::invalid_argument("DEMCAL_TEST_REALISATION = '" + value + "' (expected FACES:K)");
  r.faces = value.substr(0, colon);
  r.k = std::stoi(value.substr(colon + 1));
  return r;
}

// An empty folder under the temporary directory, named after the suite and the case.
inline fs::path fresh_dir(const std::string& suite, const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("demcal-test-" + suite + "-" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// TEXT with every "{dir}" replaced by DIR.
inline std::string replace_dir(std::string text, const fs::path& dir) {
  for (size_t at; (at = text.find("{dir}")) != std::string::npos;) text.replace(at, 5, dir.string());
  return text;
}

inline std::string read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

inline void write_text(const fs::path& path, const std::string& text) { std::ofstream(path, std::ios::binary) << text; }

// A measured curve in the layout of the toy simulator (top_horizontal in m, force in N), rows + 1 rows.
inline std::string toy_measured_text(int rows = 20) {
  std::string text = "top_horizontal,force\n";
  for (int i = 0; i <= rows; ++i) text += std::to_string(0.0005 * i) + "," + std::to_string(6000.0 * i / (i + 2.0)) + "\n";
  return text;
}

// A valid, tiny campaign through the toy simulator, k and friction free, measured.csv in `dir`.
inline nlohmann::json toy_campaign(const fs::path& dir, const std::string& name) {
  return {{"name", name},
          {"measured", (dir / "measured.csv").string()},
          {"parameters", {{{"name", "k"}, {"lower", 1e6}, {"upper", 1e8}, {"scale", "log"}},
                          {{"name", "friction_deg"}, {"lower", 25}, {"upper", 45}}}},
          {"objective", 1},
          {"optimiser", {{"algorithm", "pso"}, {"population", 2}, {"iterations", 1}, {"seed", 1}}},
          {"backend", {{"type", "command"},
                       {"command", python() + " " + kToySimulator + " {k} {friction_deg} {output}"},
                       {"parallel", 1}}},
          {"report", false}};
}

inline nlohmann::json read_json(const fs::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

}  // namespace demcal::pipelines::test_support
