// Version of the demcal build, stamped into every archived run and report.
#pragma once

#include <string>

namespace demcal::pipelines {

// "<project version>+<git describe>" of the build, e.g. "0.1.0+a1b2c3d".
std::string version();

}  // namespace demcal::pipelines
