// Synthetic curves with a known truth (see synthetic.hpp).
#include "demcal/smoothing/synthetic.hpp"

#include <algorithm>
#include <cmath>
#include <random>

namespace demcal::smoothing {

double synthetic_truth(const SyntheticCurveOptions& o, double w) {
  const double wp = o.peak_displacement, wm = o.max_displacement;
  if (w <= 0) return 0;
  if (w <= wp) {
    const double s = 1 - w / wp;
    return o.peak_force * (1 - s * s);
  }
  const double s = std::min(1.0, (w - wp) / (wm - wp));
  return o.peak_force * (1 - (1 - o.residual_fraction) * std::pow(s, 1.5));
}

SyntheticCurve make_synthetic_curve(const SyntheticCurveOptions& o) {
  SyntheticCurve c;
  c.options = o;
  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double phase = 2 * M_PI * unit(rng);
  std::vector<double> drops;
  for (int j = 0; j < o.stick_slip_drops; ++j) drops.push_back((0.1 + 0.85 * unit(rng)) * o.max_displacement);
  std::sort(drops.begin(), drops.end());
  for (int i = 0; i < o.samples; ++i) {
    const double w = o.max_displacement * i / (o.samples - 1);
    const double truth = synthetic_truth(o, w);
    double noisy = truth + o.oscillation_amplitude * o.peak_force *
                               std::sin(2 * M_PI * o.oscillation_cycles * w / o.max_displacement + phase);
    for (double d : drops)
      if (w >= d)
        noisy -= o.drop_depth * synthetic_truth(o, d) * std::exp(-(w - d) / (o.drop_recovery * o.max_displacement));
    c.truth.x.push_back(w);
    c.truth.y.push_back(truth);
    c.noisy.x.push_back(w);
    c.noisy.y.push_back(noisy);
  }
  return c;
}

std::vector<SyntheticCurve> synthetic_family(int count, std::uint64_t seed) {
  const double amplitudes[] = {0.03, 0.06, 0.10};
  const double cycles[] = {16, 24, 40};
  const double peaks[] = {0.2, 0.3, 0.4};
  std::vector<SyntheticCurve> out;
  for (int i = 0; i < count; ++i) {
    SyntheticCurveOptions o;
    o.oscillation_amplitude = amplitudes[i % 3];
    o.oscillation_cycles = cycles[(i / 3) % 3];
    o.peak_displacement = peaks[(i / 9) % 3] * o.max_displacement;
    o.stick_slip_drops = 1 + i % 4;
    o.samples = i % 2 == 0 ? 200 : 1000;
    o.seed = seed + static_cast<std::uint64_t>(i);
    out.push_back(make_synthetic_curve(o));
  }
  return out;
}

}  // namespace demcal::smoothing
