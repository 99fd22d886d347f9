// Shared by the diagnosis's sources (diagnose.cpp, residual.cpp, diagnose_report.cpp).
#pragma once

#include "demcal/pipelines/diagnose.hpp"

#include <string>

namespace demcal::pipelines::detail {

// A number in a verdict or report: `digits` significant digits, shortest form (3 -> "0.000139").
std::string format_number(double v, int digits = 3);

// The field of a set_parameter name without its group or block: "arch_joints.closure_max" ->
// "closure_max"; a bare name is its own field.
std::string parameter_field(const std::string& name);

// A residual's simulated_rows and simulated_in_gap from its simulated series and that series's
// loading envelope (its measured gap already set).
void note_simulated_sampling(ChannelResidual& residual, const smoothing::XYSeries& simulated,
                             const smoothing::XYSeries& simulated_envelope);

// `s` usable as a file or folder name: every character but letters, digits, '-' and '_' -> '_'.
std::string file_safe(std::string s);

// report.md and its figures (diagnose_report.cpp).
void write_diagnosis_report(const Diagnosis& diagnosis, const DiagnoseOptions& options);

}  // namespace demcal::pipelines::detail
