// The campaign report: <output>/report.md with PNG figures drawn by gnuplot (pngcairo terminal,
// png as fallback). Sections: the best parameters; best-fit curves over the measured ones for each
// case and channel (raw, and smoothed with objective 2); convergence (best fitness against
// simulations); the five best parameter sets in the layout of the paper's Tables 1-4; the evaluated
// and the five best sets in parameter space (the paper's Figures 14, 17, 20, 23); the failure mode
// of the best run (deformed blocks coloured by displacement magnitude, hinges and sliding joints
// marked); the runs that failed and why (first 100). A figure gnuplot cannot draw is replaced by a line saying why; the report is still
// written.
#pragma once

#include "demcal/pipelines/archive.hpp"
#include "demcal/pipelines/campaign.hpp"

#include <map>
#include <string>
#include <vector>

namespace demcal::pipelines {

struct ReportInputs {
  const CampaignConfig* config = nullptr;
  const CampaignResult* result = nullptr;
  std::vector<smoothing::Curve> measured;  // per case, SI (force + gauges)
  std::vector<RunRecord> best_runs;        // per case: the best candidate's run
  // Objective 2 only: smoothed measured and best simulated channels per case.
  std::vector<std::map<std::string, smoothing::XYSeries>> smoothed_measured;
  std::vector<std::map<std::string, smoothing::XYSeries>> smoothed_best;
  // Candidates without a finite fitness, in evaluation order: listed under "Failed runs" with the
  // reason archived for their run (a crash, a timeout, a bad output, no common window, ...).
  struct Failure {
    int iteration = 0, position = 0;
    std::string case_name;
    std::map<std::string, double> params;
    std::string status;   // the run's status ("failed", "unstable", ... or "completed")
    std::string reason;   // the run's message, or why its fitness is not finite
  };
  std::vector<Failure> failures;
};

// Writes report.md and figures/ under out_dir; returns the report's path. Throws std::runtime_error
// only when report.md itself cannot be written.
std::string write_report(const ReportInputs& inputs, const std::string& out_dir);

// Runs gnuplot on a script (written next to the PNG as <png>.gp). Returns "" on success, else the
// reason (gnuplot missing, its error output).
std::string run_gnuplot(const std::string& script, const std::string& png_path);

// "pngcairo" when this gnuplot has it, else "png" (checked once).
std::string png_terminal();

}  // namespace demcal::pipelines
