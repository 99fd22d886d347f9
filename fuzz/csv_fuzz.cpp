// Fuzz target: the curve reader (smoothing::parse_curve) on arbitrary bytes. A CurveError is the
// only accepted failure. A curve that reads and formats (format_curve refuses names holding a
// separator, quote or newline) must read back to the same names, units and values.
#include "demcal/smoothing/curve.hpp"

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

namespace {

bool same(double a, double b) { return (std::isnan(a) && std::isnan(b)) || a == b; }

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace demcal::smoothing;
  const std::string text(reinterpret_cast<const char*>(data), size);
  Curve curve;
  try {
    curve = parse_curve(text, "fuzz.csv");
  } catch (const CurveError&) {
    return 0;
  }
  std::string written;
  try {
    written = format_curve(curve);
  } catch (const CurveError&) {
    return 0;
  }
  const Curve again = parse_curve(written, "round-trip.csv");  // any error here is a finding
  if (again.column_names() != curve.column_names() || again.rows() != curve.rows()) std::abort();
  for (std::size_t c = 0; c < curve.columns.size(); ++c) {
    if (again.columns[c].unit != curve.columns[c].unit) std::abort();
    for (std::size_t r = 0; r < curve.rows(); ++r)
      if (!same(again.columns[c].values[r], curve.columns[c].values[r])) std::abort();
  }
  return 0;
}
