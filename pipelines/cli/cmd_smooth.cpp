// `demcal smooth IN.csv --out OUT.csv`: smooths one force–displacement curve of a file (neural
// network, moving average or Savitzky–Golay) and writes it with the input's column names and units.
#include "command_registry.hpp"

#include "demcal/smoothing/smoothing.hpp"

#include <filesystem>
#include <iostream>
#include <stdexcept>

namespace demcal::cli::smooth_command {

struct SmoothArgs {
  std::string input, output, x_column, y_column, plot;
  std::string method = "dnn";
  int points = 200;
  std::uint64_t seed = 1;
  int epochs = demcal::smoothing::SmootherOptions{}.epochs;
  int window = 0;  // 0 = the method's default
  std::string backend = "native";
  std::string stopping = "trend-spectrum";
};

void run_smooth(const SmoothArgs& a) {
  using namespace demcal::smoothing;
  const Curve curve = read_curve(a.input);
  if (curve.columns.size() < 2)
    throw CurveError(a.input + ": needs at least two columns (x and y), found " + std::to_string(curve.columns.size()));
  const Column& xc = a.x_column.empty() ? curve.columns[0] : curve.column(a.x_column);
  const Column& yc = a.y_column.empty() ? curve.columns[1] : curve.column(a.y_column);
  if (xc.name == yc.name) throw std::runtime_error("--x and --y name the same column '" + xc.name + "'");
  const XYSeries input = series(curve, xc.name, yc.name);

  XYSeries smoothed;
  if (a.method == "dnn") {
    SmootherOptions options;
    options.points = a.points;
    options.seed = a.seed;
    options.epochs = a.epochs;
    options.backend = parse_smoother_backend(a.backend);
    options.stopping = parse_stopping_rule(a.stopping);
    smoothed = smooth_dnn(input, options);
  } else if (a.method == "moving-average") {
    smoothed = moving_average(input, a.window ? a.window : kDefaultMovingAverageWindow, a.points);
  } else if (a.method == "savitzky-golay") {
    smoothed = savitzky_golay(input, a.window ? a.window : kDefaultSavitzkyGolayWindow,
                              kDefaultSavitzkyGolayOrder, a.points);
  } else {
    throw std::runtime_error("--method '" + a.method + "': expected dnn, moving-average or savitzky-golay");
  }

  Curve out;
  out.source = a.output;
  out.columns.push_back({xc.name, xc.unit, smoothed.x});
  out.columns.push_back({yc.name, yc.unit, smoothed.y});
  write_curve(out, a.output);

  if (!a.plot.empty()) {
    PlotOptions plot;
    plot.title = std::filesystem::path(a.input).filename().string() + " (" + a.method + ")";
    plot.x_label = xc.name + (xc.unit.empty() ? "" : " [" + xc.unit + "]");
    plot.y_label = yc.name + (yc.unit.empty() ? "" : " [" + yc.unit + "]");
    plot_png({{input, "raw", true}, {smoothed, a.method, false}}, a.plot, plot);
  }
}

void setup(CLI::App& app) {
  auto args = std::make_shared<SmoothArgs>();
  auto* sub = app.add_subcommand("smooth", "Smooth a force-displacement curve (neural network or a baseline)");
  sub->add_option("input", args->input, "Input curve file (CSV: comma, semicolon or tab)")->required();
  sub->add_option("--out,-o", args->output, "Output CSV: the smoothed x and y columns")->required();
  sub->add_option("--x", args->x_column, "x column (default: the first column)");
  sub->add_option("--y", args->y_column, "y column (default: the second column)");
  sub->add_option("--method", args->method, "dnn | moving-average | savitzky-golay")
      ->check(CLI::IsMember({"dnn", "moving-average", "savitzky-golay"}));
  sub->add_option("--points", args->points, "Output points, evenly spaced in x")->check(CLI::Range(4, 1000000));
  sub->add_option("--seed", args->seed, "Seed of the network's initial weights");
  sub->add_option("--epochs", args->epochs, "Adam epoch budget of the network")->check(CLI::Range(1, 1000000));
  sub->add_option("--stopping", args->stopping,
                  "trend-spectrum (best checkpoint by the data-driven error estimate) | fixed-budget (all epochs)")
      ->capture_default_str();
  sub->add_option("--window", args->window, "Window (points, odd) of the baselines; 0 = default");
  sub->add_option("--backend", args->backend, "Network training: native (default) or libtorch")
      ->check(CLI::IsMember({"native", "libtorch"}));
  sub->add_option("--plot", args->plot, "Also write a PNG of the raw and smoothed curves (gnuplot)");
  sub->callback([args] { run_smooth(*args); });
}

DEMCAL_REGISTER_COMMAND("smooth", setup);

}  // namespace demcal::cli::smooth_command
