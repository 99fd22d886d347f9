// Fuzz target: scene JSON (dem::scene_from_json + Scene::Validate). Text that is not JSON is
// skipped; for JSON the only accepted failure is a SceneError. A scene that validates must
// serialise and parse back to the same hash.
#include "demcal/dem/scene.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace demcal::dem;
  const auto j = nlohmann::json::parse(data, data + size, nullptr, false);
  if (j.is_discarded()) return 0;
  try {
    const Scene scene = scene_from_json(j, "fuzz.json");
    scene.Validate("fuzz.json");
    const Scene again = scene_from_json(scene_to_json(scene), "round-trip");
    if (scene_hash(again) != scene_hash(scene)) std::abort();
  } catch (const SceneError&) {
  }
  return 0;
}
