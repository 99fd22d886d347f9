// Synthetic force–displacement curves with a known smooth truth, for testing and benchmarking
// smoothers: the truth is a softening curve with a peak, and the "simulated" curve adds what explicit
// DEM integration adds (paper Figure 9): a sinusoidal oscillation and sudden stick-slip drops that
// recover over a short distance.
#pragma once

#include "demcal/smoothing/curve.hpp"

#include <cstdint>
#include <vector>

namespace demcal::smoothing {

struct SyntheticCurveOptions {
  int samples = 200;                    // recorded points, evenly spaced in displacement
  double max_displacement = 12e-3;      // m
  double peak_force = 2700;             // N, peak of the smooth truth
  double peak_displacement = 3e-3;      // m, where the truth peaks
  double residual_fraction = 0.65;      // truth at max_displacement / peak_force, in (0, 1]
  double oscillation_amplitude = 0.05;  // times peak_force
  double oscillation_cycles = 12;       // full sine cycles over the displacement range
  int stick_slip_drops = 3;             // drops at random displacements (after 10 % of the range)
  double drop_depth = 0.15;             // times the truth at the drop
  double drop_recovery = 0.01;          // recovery length, times max_displacement
  std::uint64_t seed = 1;               // drop positions and oscillation phase
};

struct SyntheticCurve {
  SyntheticCurveOptions options;  // what made it
  XYSeries truth;                 // smooth truth at the same x as `noisy`
  XYSeries noisy;                 // truth + oscillation + drops
};

// The smooth truth at a displacement (N): a parabolic rise to the peak (zero slope there), then a
// softening branch ~ (distance past the peak)^1.5 down to residual_fraction * peak_force.
double synthetic_truth(const SyntheticCurveOptions& options, double displacement);

SyntheticCurve make_synthetic_curve(const SyntheticCurveOptions& options);

// The benchmark family used in the tests, the docs table and bench/smoothing.cpp: `count` curves
// with amplitude and frequency varied over a fixed grid, seeds seed, seed+1, ...
std::vector<SyntheticCurve> synthetic_family(int count, std::uint64_t seed = 1);

}  // namespace demcal::smoothing
