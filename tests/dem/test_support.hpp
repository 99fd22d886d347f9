// Helpers shared by the engine's tests: blocks, recorded blocks by name, the `demcal` program.
#pragma once

#include "demcal/common/units.hpp"
#include "demcal/dem/scene.hpp"
#include "demcal/dem/simulation.hpp"

#include <cstdio>
#include <stdexcept>
#include <string>
#include <sys/wait.h>

namespace demcal::dem::test_support {

inline constexpr double kDeg = demcal::kDegree;

// An axis-aligned rectangular block [x0, x1] x [y0, y1], m.
inline Block box(const std::string& name, double x0, double y0, double x1, double y1, bool fixed, double density = 2000) {
  Block b;
  b.name = name;
  b.density = density;
  b.fixed = fixed;
  b.vertices = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
  return b;
}

inline const BlockState& block_named(const Recording& r, const std::string& name) {
  for (const auto& b : r.final_blocks)
    if (b.name == name) return b;
  throw std::runtime_error("no block " + name);
}

struct CommandResult {
  int exit_code;
  std::string output;  // stdout and stderr
};

// Runs `demcal ARGS` (a shell command line) and returns its exit status and output.
inline CommandResult run_demcal(const std::string& args) {
  const std::string command = std::string(DEMCAL_BINARY) + " " + args + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  std::string output;
  char buffer[4096];
  while (std::fgets(buffer, sizeof buffer, pipe)) output += buffer;
  const int status = pclose(pipe);
  return {WEXITSTATUS(status), output};
}

}  // namespace demcal::dem::test_support
