#include "demcal/pipelines/version.hpp"

namespace demcal::pipelines {

std::string version() { return DEMCAL_VERSION_STRING; }

}  // namespace demcal::pipelines
