#include "stereo_occupancy/projected_map.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stereo_occupancy {

std::vector<ProjectedLeaf> projectedLeaves(const octomap::OcTree& tree, double min_z_m, double max_z_m) {
  std::vector<ProjectedLeaf> leaves;
  const double c = tree.getResolution();
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const double half = 0.5 * it.getSize();
    if (it.getZ() + half <= min_z_m || it.getZ() - half >= max_z_m) continue;
    ProjectedLeaf leaf;  // a leaf spans 2^k cells
    leaf.cells = std::lround(it.getSize() / c);
    leaf.x = std::lround((it.getX() - half) / c);
    leaf.y = std::lround((it.getY() - half) / c);
    leaf.value = tree.isNodeOccupied(*it) ? ProjectedMap::kOccupied : ProjectedMap::kFree;
    leaves.push_back(leaf);
  }
  return leaves;
}

ProjectedMap composeProjection(double resolution_m, const std::vector<const std::vector<ProjectedLeaf>*>& sets) {
  ProjectedMap map;
  map.resolution_m = resolution_m;
  long x0 = std::numeric_limits<long>::max(), y0 = x0, x1 = std::numeric_limits<long>::min(), y1 = x1;
  for (const auto* set : sets)
    for (const ProjectedLeaf& leaf : *set) {
      x0 = std::min(x0, leaf.x), y0 = std::min(y0, leaf.y);
      x1 = std::max(x1, leaf.x + leaf.cells), y1 = std::max(y1, leaf.y + leaf.cells);
    }
  if (x0 >= x1) return map;
  map.width = static_cast<int>(x1 - x0);
  map.height = static_cast<int>(y1 - y0);
  map.origin_x_m = static_cast<double>(x0) * resolution_m;
  map.origin_y_m = static_cast<double>(y0) * resolution_m;
  map.cells.assign(static_cast<size_t>(map.width) * map.height, ProjectedMap::kUnknown);
  for (const auto* set : sets)
    for (const ProjectedLeaf& leaf : *set)
      for (long y = leaf.y; y < leaf.y + leaf.cells; ++y)
        for (long x = leaf.x; x < leaf.x + leaf.cells; ++x) {
          int8_t& cell = map.cells[static_cast<size_t>(y - y0) * map.width + static_cast<size_t>(x - x0)];
          cell = std::max(cell, leaf.value);  // occupied over free over unknown
        }
  return map;
}

ProjectedMap projectOccupancy(const octomap::OcTree& tree, double min_z_m, double max_z_m) {
  const std::vector<ProjectedLeaf> leaves = projectedLeaves(tree, min_z_m, max_z_m);
  return composeProjection(tree.getResolution(), {&leaves});
}

}  // namespace stereo_occupancy
