// The `demcal` program: subcommands are registered by the cli/cmd_*.cpp files.
#include "command_registry.hpp"

#include "demcal/limits/limits.hpp"

#include <algorithm>
#include <exception>
#include <iostream>

namespace demcal::cli {

std::vector<CommandEntry>& command_registry() {
  static std::vector<CommandEntry> registry;
  return registry;
}

int& exit_code() {
  static int code = 0;
  return code;
}

}  // namespace demcal::cli

int main(int argc, char** argv) {
  using namespace demcal::cli;
  CLI::App app{"demcal: calibrate discrete element models of masonry against measured curves"};
  app.set_version_flag("--version", DEMCAL_VERSION_STRING);
  app.require_subcommand(1);
  // Raising a limit on counts and sizes (demcal/limits): applied as it is parsed, before any
  // subcommand runs, and exported to DEMCAL_LIMITS for the processes a command starts. Accepted
  // before or after the subcommand (fallthrough).
  app.add_option_function<std::string>(
         "--limit", [](const std::string& setting) { demcal::limits::set_from_text(setting, true); },
         "Raise a limit on a count or size, KEY=N (repeatable; keys and defaults in docs/bad-input.md)")
      ->trigger_on_parse()
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast)
      ->type_name("KEY=N");
  app.fallthrough();
  auto& registry = command_registry();
  std::sort(registry.begin(), registry.end(),
            [](const CommandEntry& a, const CommandEntry& b) { return a.name < b.name; });
  for (const auto& entry : registry) entry.setup(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const std::exception& e) {
    std::cerr << "demcal: error: " << e.what() << "\n";
    return 1;
  }
  return exit_code();
}
