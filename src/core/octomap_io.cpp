#include "stereo_occupancy/octomap_io.h"

#include <unistd.h>

#include <cstdio>
#include <stdexcept>

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
        if ((k.array() < 0).any() || (k.array() > 65535).any()) continue;  // outside OcTree's extent
        tree->setNodeValue(octomap::OcTreeKey(k.x(), k.y(), k.z()), value, /*lazy_eval=*/true);
      }
    }
  }
  tree->updateInnerOccupancy();
  return tree;
}

void writeOcTree(const octomap::OcTree& tree, const std::string& path) {
  const bool full = path.size() >= 3 && path.compare(path.size() - 3, 3, ".ot") == 0;
  const bool binary = path.size() >= 3 && path.compare(path.size() - 3, 3, ".bt") == 0;
  if (!full && !binary) throw std::runtime_error("'" + path + "': the map file must end in .ot or .bt");
  // Write a temporary file beside the target, then rename it into place: a
  // crash or kill during the write leaves the previous file intact.
  const std::string tmp = path + ".tmp" + std::to_string(::getpid());
  const bool ok = full ? tree.write(tmp) : tree.writeBinaryConst(tmp);
  if (!ok) {
    std::remove(tmp.c_str());
    throw std::runtime_error("cannot write '" + path + "'");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw std::runtime_error("cannot rename '" + tmp + "' to '" + path + "'");
  }
}

}  // namespace stereo_occupancy
