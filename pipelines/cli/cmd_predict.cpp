// `demcal predict campaign.json (--result result.json | --param NAME=VALUE ...) [--out DIR]`:
// simulate every case of a campaign with one parameter set and compare with the measured curves
// (objective 1, RMS force error, peak loads). Writes DIR/prediction.json and DIR/<case>.csv.
#include "command_registry.hpp"

#include "demcal/pipelines/predict.hpp"

#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>

namespace demcal::cli::predict_command {

struct PredictFlags {
  std::string campaign_file, result_file, out;
  std::vector<std::string> params;  // NAME=VALUE
  int threads = 0;
};

double parse_value(const std::string& flag, const std::string& text) {
  try {
    std::size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == text.size()) return v;
  } catch (const std::exception&) {
  }
  throw demcal::pipelines::CampaignError("--param '" + flag + "': the value '" + text + "' is not a number");
}

void run(const PredictFlags& f) {
  using namespace demcal::pipelines;
  namespace fs = std::filesystem;
  const CampaignConfig config = load_campaign(f.campaign_file);
  std::map<std::string, double> params;
  if (!f.result_file.empty()) params = read_result_parameters(f.result_file);
  for (const auto& p : f.params) {
    const auto eq = p.find('=');
    if (eq == std::string::npos || eq == 0) throw CampaignError("--param '" + p + "': expected NAME=VALUE");
    params[p.substr(0, eq)] = parse_value(p, p.substr(eq + 1));
  }
  if (params.empty()) throw CampaignError("no parameters: give --result result.json or --param NAME=VALUE");
  PredictionOptions options;
  options.threads = f.threads;
  options.work_folder = f.out;  // an external command's run folders: DIR/runs
  const auto cases = predict_cases(config, params, options);

  std::cout << "case            status     peak measured  peak simulated  peak error  RMS error  objective 1\n";
  bool all_ok = true;
  for (const auto& c : cases) {
    all_ok = all_ok && c.ok();
    std::cout << std::left << std::setw(16) << c.name << std::setw(11) << c.status << std::right << std::fixed
              << std::setprecision(2) << std::setw(10) << c.measured_peak / 1e3 << " kN" << std::setw(13)
              << c.simulated_peak / 1e3 << " kN" << std::setw(10) << 100 * c.peak_error << " %" << std::setw(8)
              << c.rms_error / 1e3 << " kN" << std::setw(11) << std::setprecision(0) << c.fitness << " N\n";
    if (!c.ok()) std::cout << "  " << c.message << "\n";
  }
  std::cout.unsetf(std::ios::floatfield);
  if (!f.out.empty()) {
    fs::create_directories(f.out);
    const auto used = complete_parameters(config, params);
    std::ofstream(fs::path(f.out) / "prediction.json") << prediction_json(used, cases).dump(2) << "\n";
    for (const auto& c : cases)
      if (c.simulated.rows() > 0) demcal::smoothing::write_curve(c.simulated, (fs::path(f.out) / (c.name + ".csv")).string());
    std::cout << "wrote " << (fs::path(f.out) / "prediction.json").string() << " and one CSV per case\n";
  }
  if (!all_ok) demcal::cli::exit_code() = 2;
}

void setup(CLI::App& app) {
  auto flags = std::make_shared<PredictFlags>();
  auto* sub = app.add_subcommand(
      "predict", "Simulate a campaign's cases with one parameter set; compare with the measured curves");
  sub->add_option("campaign", flags->campaign_file, "Campaign JSON file whose cases are predicted")
      ->required()
      ->check(CLI::ExistingFile);
  sub->add_option("--result", flags->result_file, "result.json of demcal calibrate: its best.params are used")
      ->check(CLI::ExistingFile);
  sub->add_option("--param", flags->params, "NAME=VALUE (SI, friction_deg in degrees); overrides --result");
  sub->add_option("--out", flags->out, "Folder for prediction.json and the simulated curves (<case>.csv)");
  sub->add_option("--threads", flags->threads,
                  "Simulations at once (0 = every core, or the campaign's backend.parallel for an external command)");
  sub->callback([flags] { run(*flags); });
}

}  // namespace demcal::cli::predict_command

DEMCAL_REGISTER_COMMAND("predict", demcal::cli::predict_command::setup);
