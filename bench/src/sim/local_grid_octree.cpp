#include "stereo_occupancy/sim/local_grid_octree.h"

#include <limits>

namespace stereo_occupancy {

std::unique_ptr<octomap::OcTree> localGridToOcTree(const LocalGrid& grid) {
  auto tree = std::make_unique<octomap::OcTree>(grid.resolution());
  const Eigen::Vector3i& size = grid.size();
  const Eigen::Vector3i& origin = grid.originIndex();
  const int offset = static_cast<int>(tree->coordToKey(0.0));  // key of global index 0 (2^15)
  for (int z = 0; z < size.z(); ++z) {
    for (int y = 0; y < size.y(); ++y) {
      for (int x = 0; x < size.x(); ++x) {
        const float value = grid.at(x, y, z);
        if (value == LocalGrid::kUnknown || value == 0.0f) continue;
        const Eigen::Vector3i g = origin + Eigen::Vector3i(x, y, z);
        const Eigen::Vector3i k = g.array() + offset;
        constexpr int kMaxKey = std::numeric_limits<octomap::key_type>::max();  // OcTree's extent
        if ((k.array() < 0).any() || (k.array() > kMaxKey).any()) continue;
        tree->setNodeValue(octomap::OcTreeKey(k.x(), k.y(), k.z()), value, /*lazy_eval=*/true);
      }
    }
  }
  tree->updateInnerOccupancy();
  return tree;
}

}  // namespace stereo_occupancy
