// Helpers shared by the pipelines tests: scratch folders, JSON files, the toy external simulator.
#pragma once

#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <string>

namespace demcal::pipelines::test_support {

namespace fs = std::filesystem;

// The small simulator script the external-command backend is tested with (not demcal code).
inline const std::string kToySimulator = std::string(DEMCAL_SOURCE_DIR) + "/tests/pipelines/toy_simulator.py";

inline std::string python() { return fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3"; }

// An empty folder under the temporary directory, named after the suite and the case.
inline fs::path fresh_dir(const std::string& suite, const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("demcal-test-" + suite + "-" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

inline nlohmann::json read_json(const fs::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

}  // namespace demcal::pipelines::test_support
