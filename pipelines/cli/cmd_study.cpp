// `demcal study study.json`: algorithms x seeds on one calibration problem (study.hpp).
#include "command_registry.hpp"

#include "demcal/pipelines/study.hpp"

#include <iostream>
#include <memory>

namespace demcal::cli::study_command {

void setup(CLI::App& app) {
  struct Flags {
    std::string file, out;
    bool quiet = false, fresh = false;
  };
  auto flags = std::make_shared<Flags>();
  auto* sub = app.add_subcommand("study", "Compare algorithms x seeds on one calibration problem (paper-style tables)");
  sub->add_option("study", flags->file, "Study JSON file")->required()->check(CLI::ExistingFile);
  sub->add_option("--out", flags->out, "Output folder (overrides the file's)");
  sub->add_flag("--quiet", flags->quiet, "No progress lines");
  sub->add_flag("--fresh", flags->fresh,
                "Start every campaign anew instead of continuing those already in the study's archive "
                "(runs are still read back from the archive)");
  sub->callback([flags] {
    auto config = demcal::pipelines::load_study(flags->file);
    if (!flags->out.empty()) config.output = flags->out;
    config.resume = !flags->fresh;
    const auto result = demcal::pipelines::run_study(config, !flags->quiet);
    if (!flags->quiet) std::cout << "study: " << result.markdown_path << "\n";
  });
}

}  // namespace demcal::cli::study_command

DEMCAL_REGISTER_COMMAND("study", demcal::cli::study_command::setup);
