// PNG plots of raw and smoothed curves through gnuplot (the `gnuplot` program must be on PATH).
#pragma once

#include "demcal/smoothing/curve.hpp"

#include <string>
#include <vector>

namespace demcal::smoothing {

struct PlotSeries {
  XYSeries data;
  std::string label;
  bool points = false;  // markers instead of a line
};

struct PlotOptions {
  std::string title;
  std::string x_label;
  std::string y_label;
  int width = 900;   // pixels
  int height = 600;  // pixels
};

// Writes a PNG with every series; throws std::runtime_error if gnuplot fails or is missing.
void plot_png(const std::vector<PlotSeries>& series, const std::string& png_path,
              const PlotOptions& options = {});

}  // namespace demcal::smoothing
