// gnuplot PNG output.
#include "demcal/smoothing/plot.hpp"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

namespace demcal::smoothing {

namespace {

std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

}  // namespace

void plot_png(const std::vector<PlotSeries>& series, const std::string& png_path, const PlotOptions& options) {
  if (series.empty()) throw std::invalid_argument("plot_png: no series to plot");
  std::ostringstream script;
  script << "set terminal pngcairo size " << options.width << "," << options.height << " enhanced font 'Sans,10'\n"
         << "set output " << quoted(png_path) << "\n"
         << "set title " << quoted(options.title) << " noenhanced\n"
         << "set xlabel " << quoted(options.x_label) << " noenhanced\n"
         << "set ylabel " << quoted(options.y_label) << " noenhanced\n"
         << "set key left bottom noenhanced\nset grid\n"
         << "plot ";
  for (std::size_t i = 0; i < series.size(); ++i)
    script << (i ? ", " : "") << "'-' using 1:2 with " << (series[i].points ? "points pt 7 ps 0.5" : "lines lw 2")
           << " title " << quoted(series[i].label);
  script << "\n";
  script.precision(10);
  for (const auto& s : series) {
    for (std::size_t k = 0; k < s.data.x.size() && k < s.data.y.size(); ++k) {
      if (std::isnan(s.data.x[k]) || std::isnan(s.data.y[k])) {
        script << "\n";  // a gap
        continue;
      }
      script << s.data.x[k] << " " << s.data.y[k] << "\n";
    }
    script << "e\n";
  }
  FILE* pipe = popen("gnuplot 2>&1", "w");
  if (!pipe) throw std::runtime_error("plot_png: cannot start gnuplot");
  const std::string text = script.str();
  const bool written = std::fwrite(text.data(), 1, text.size(), pipe) == text.size();
  const int status = pclose(pipe);
  if (!written || status != 0)
    throw std::runtime_error("plot_png: gnuplot failed writing '" + png_path + "' (exit status " +
                             std::to_string(status) + "; is gnuplot installed?)");
}

}  // namespace demcal::smoothing
