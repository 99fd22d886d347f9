#include "demcal/pipelines/progress.hpp"

#include "demcal/common/format.hpp"

#include <unistd.h>

#include <cmath>

namespace demcal::pipelines {

std::string format_duration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  const long s = std::lround(seconds);
  char buffer[48];
  if (s >= 3600) std::snprintf(buffer, sizeof buffer, "%ld h %02ld min", s / 3600, (s % 3600) / 60);
  else if (s >= 60) std::snprintf(buffer, sizeof buffer, "%ld min %02ld s", s / 60, s % 60);
  else std::snprintf(buffer, sizeof buffer, "%ld s", s);
  return buffer;
}

std::string format_progress(const ProgressState& st) {
  const std::string best = format_number(st.best, {.significant_digits = 6, .non_finite = "-"});
  std::string left = "?";
  if (st.done_this_session > 0 && st.total >= st.done) {
    const double per_simulation = st.elapsed_s / static_cast<double>(st.done_this_session);
    left = "~";
    left += format_duration(per_simulation * static_cast<double>(st.total - st.done));
  }
  char iteration[48];
  if (st.iterations > 0 && st.iteration <= st.iterations)
    std::snprintf(iteration, sizeof iteration, "%d/%d", st.iteration, st.iterations);
  else
    std::snprintf(iteration, sizeof iteration, "%d", st.iteration);
  char line[320];
  std::snprintf(line, sizeof line, "iteration %s  simulations %ld/%ld  best %s  elapsed %s (simulations %s, model %s)  left %s",
                iteration, st.done, st.total, best.c_str(), format_duration(st.elapsed_s).c_str(),
                format_duration(st.simulation_s).c_str(), format_duration(st.model_s).c_str(), left.c_str());
  return line;
}

ProgressPrinter::ProgressPrinter(bool enabled, std::FILE* stream)
    : enabled_(enabled), stream_(stream), terminal_(enabled && ::isatty(::fileno(stream)) == 1) {}

void ProgressPrinter::simulation_done(const ProgressState& state) {
  if (!enabled_ || !terminal_) return;
  std::fprintf(stream_, "\r\033[K%s", format_progress(state).c_str());
  std::fflush(stream_);
  pending_line_ = true;
}

void ProgressPrinter::iteration_done(const ProgressState& state) {
  if (!enabled_) return;
  if (terminal_) std::fprintf(stream_, "\r\033[K");
  std::fprintf(stream_, "%s\n", format_progress(state).c_str());
  std::fflush(stream_);
  pending_line_ = false;
}

void ProgressPrinter::finish() {
  if (enabled_ && pending_line_) std::fprintf(stream_, "\n");
  pending_line_ = false;
}

}  // namespace demcal::pipelines
