// Fuzz target: campaign JSON (pipelines::campaign_from_json + CampaignConfig::Validate). Text that
// is not JSON is skipped; for JSON the only accepted failure is a CampaignError. Relative paths
// resolve under a folder that does not exist, so nothing is read from disk.
#include "demcal/pipelines/campaign.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace demcal::pipelines;
  const auto j = nlohmann::json::parse(data, data + size, nullptr, false);
  if (j.is_discarded()) return 0;
  try {
    const CampaignConfig config = campaign_from_json(j, "/nonexistent-fuzz-dir", "fuzz.json");
    config.Validate();
    (void)config.result_defining_json().dump();
  } catch (const CampaignError&) {
  }
  return 0;
}
