// Subcommand registry of the `demcal` program. Each cli/cmd_*.cpp file registers its own
// subcommand with a static DEMCAL_REGISTER_COMMAND, so modules add commands without editing main.
// Each file keeps its code in a namespace of its own (demcal::cli::<name>_command), so that the
// unity build, which compiles several files as one, joins them without a clash.
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

namespace demcal::cli {

// Adds one subcommand (with its options and callback) to the top-level app. The callback reports
// bad input by throwing (std::runtime_error or a module error type); main prints the message and
// exits with status 1. A callback may also set exit_code() for a non-zero exit without a message.
using CommandSetup = std::function<void(CLI::App& app)>;

struct CommandEntry {
  std::string name;    // subcommand name, used only to order --help output
  CommandSetup setup;
};

std::vector<CommandEntry>& command_registry();
int& exit_code();

struct CommandRegistrar {
  CommandRegistrar(std::string name, CommandSetup setup) {
    command_registry().push_back({std::move(name), std::move(setup)});
  }
};

}  // namespace demcal::cli

#define DEMCAL_CONCAT_INNER(a, b) a##b
#define DEMCAL_CONCAT(a, b) DEMCAL_CONCAT_INNER(a, b)
#define DEMCAL_REGISTER_COMMAND(name, setup_function) \
  static const ::demcal::cli::CommandRegistrar DEMCAL_CONCAT(demcal_command_, __COUNTER__)(name, setup_function)
