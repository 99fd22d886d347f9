#include "demcal/dem/joints.hpp"

#include "geometry.hpp"

#include <algorithm>

namespace demcal::dem {

std::vector<std::string> joints_beside(const Scene& scene, const std::string& joint) {
  const auto slash = joint.find('/');
  if (slash == std::string::npos) return {};
  const auto index_of = [&](const std::string& name) {
    const auto it = std::find_if(scene.blocks.begin(), scene.blocks.end(), [&](const Block& b) { return b.name == name; });
    return it == scene.blocks.end() ? -1L : static_cast<long>(it - scene.blocks.begin());
  };
  const long ends[2] = {index_of(joint.substr(0, slash)), index_of(joint.substr(slash + 1))};
  if (ends[0] < 0 || ends[1] < 0) return {};
  std::vector<std::string> out;
  for (long k = 0; k < static_cast<long>(scene.blocks.size()); ++k) {
    if (k == ends[0] || k == ends[1]) continue;
    for (const long e : ends) {
      Vec2 p, q;
      const auto& a = scene.blocks[static_cast<std::size_t>(std::min(e, k))];
      const auto& b = scene.blocks[static_cast<std::size_t>(std::max(e, k))];
      if (!geometry::shared_edge(a.vertices, b.vertices, p, q)) continue;
      const std::string name = a.name + "/" + b.name;
      if (std::find(out.begin(), out.end(), name) == out.end()) out.push_back(name);
    }
  }
  return out;
}

}  // namespace demcal::dem
