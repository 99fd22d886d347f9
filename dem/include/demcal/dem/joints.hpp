// The joints of a scene, named as the engine names them in a run's report (Recording::joints,
// hinges, sliding_joints): "blockA/blockB" for two blocks that share an edge at the start, A before
// B in the scene's block order.
#pragma once

#include "demcal/dem/scene.hpp"

#include <string>
#include <vector>

namespace demcal::dem {

// The joints that share a block with `joint` ("blockA/blockB", either order), by the scene's block
// order of the block they add; empty when a name is not one of the scene's blocks.
std::vector<std::string> joints_beside(const Scene& scene, const std::string& joint);

}  // namespace demcal::dem
