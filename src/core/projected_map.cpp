#include "stereo_occupancy/projected_map.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stereo_occupancy {

ProjectedMap projectOccupancy(const octomap::OcTree& tree, double min_z_m, double max_z_m) {
  ProjectedMap map;
  map.resolution_m = tree.getResolution();
  auto inBand = [&](const octomap::OcTree::leaf_iterator& it) {
    const double half = 0.5 * it.getSize();
    return it.getZ() + half > min_z_m && it.getZ() - half < max_z_m;
  };
  // The band's leaves' extent, in cell indices (a leaf spans 2^k cells).
  const double c = map.resolution_m;
  long x0 = std::numeric_limits<long>::max(), y0 = x0, x1 = std::numeric_limits<long>::min(), y1 = x1;
  auto cellRange = [&](const octomap::OcTree::leaf_iterator& it, long* lo_x, long* lo_y, long* cells) {
    const double half = 0.5 * it.getSize();
    *cells = std::lround(it.getSize() / c);
    *lo_x = std::lround((it.getX() - half) / c);
    *lo_y = std::lround((it.getY() - half) / c);
  };
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (!inBand(it)) continue;
    long lx, ly, n;
    cellRange(it, &lx, &ly, &n);
    x0 = std::min(x0, lx), y0 = std::min(y0, ly);
    x1 = std::max(x1, lx + n), y1 = std::max(y1, ly + n);
  }
  if (x0 >= x1) return map;
  map.width = static_cast<int>(x1 - x0);
  map.height = static_cast<int>(y1 - y0);
  map.origin_x_m = static_cast<double>(x0) * c;
  map.origin_y_m = static_cast<double>(y0) * c;
  map.cells.assign(static_cast<size_t>(map.width) * map.height, ProjectedMap::kUnknown);
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (!inBand(it)) continue;
    const int8_t value = tree.isNodeOccupied(*it) ? ProjectedMap::kOccupied : ProjectedMap::kFree;
    long lx, ly, n;
    cellRange(it, &lx, &ly, &n);
    for (long y = ly; y < ly + n; ++y)
      for (long x = lx; x < lx + n; ++x) {
        int8_t& cell = map.cells[static_cast<size_t>(y - y0) * map.width + static_cast<size_t>(x - x0)];
        cell = std::max(cell, value);  // occupied over free over unknown
      }
  }
  return map;
}

}  // namespace stereo_occupancy
