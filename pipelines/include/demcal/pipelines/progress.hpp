// Progress of a campaign on the terminal: iteration, simulations done and total, best fitness and
// an estimate of the time left. On a terminal one status line is rewritten in place after every
// simulation; otherwise (a log file, a pipe) one plain line is written per iteration.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace demcal::pipelines {

struct ProgressState {
  int iteration = 0;          // 1-based, the iteration being evaluated
  int iterations = 0;         // planned; 0 = not known in advance (`bo`): printed without "/N"
  long done = 0;              // simulations done (simulated or read from the archive)
  long total = 0;             // simulations planned
  double best = 0;            // best fitness so far (NaN/inf before any)
  double elapsed_s = 0;       // this session
  long done_this_session = 0; // simulations finished in this session (for the rate)
  double model_s = 0;         // this session: choosing candidates (surrogate fits and search)
  double simulation_s = 0;    // this session: waiting for simulations
};

// "iteration 3/20  simulations 30/200  best 123.4  elapsed 12 s (simulations 9 s, model 2 s)
// left ~1 min 08 s"; the "/20" only while the plan is known and not passed.
std::string format_progress(const ProgressState& state);
// "1 h 02 min", "3 min 05 s", "42 s"
std::string format_duration(double seconds);

class ProgressPrinter {
 public:
  // enabled = false prints nothing; the stream's TTY-ness picks the style.
  ProgressPrinter(bool enabled, std::FILE* stream = stderr);
  void simulation_done(const ProgressState& state);  // TTY: rewrite the status line
  void iteration_done(const ProgressState& state);   // a full line in both styles
  void finish();                                      // ends a pending TTY line
  bool is_terminal() const { return terminal_; }

 private:
  bool enabled_;
  std::FILE* stream_;
  bool terminal_ = false;
  bool pending_line_ = false;
};

}  // namespace demcal::pipelines
