#pragma once
/// @file
/// The map as a 2D occupancy grid for planners on the ground plane (as
/// octomap_server's projected_map): each column of cells within a height
/// band, occupied if one of its cells is, free if one is known and none is
/// occupied, unknown otherwise.

#include <octomap/OcTree.h>

#include <cstdint>
#include <vector>

namespace stereo_occupancy {

/// A 2D grid over the x-y plane of the map's frame, row-major from its lower
/// corner (x fastest), with nav_msgs/OccupancyGrid's cell values.
struct ProjectedMap {
  static constexpr int8_t kUnknown = -1;
  static constexpr int8_t kFree = 0;
  static constexpr int8_t kOccupied = 100;

  double resolution_m = 0.0;  ///< cell edge [m]
  double origin_x_m = 0.0;    ///< lower corner of cell (0, 0) [m]
  double origin_y_m = 0.0;
  int width = 0;   ///< cells along x
  int height = 0;  ///< cells along y
  std::vector<int8_t> cells;

  int8_t at(int x, int y) const { return cells[static_cast<size_t>(y) * width + x]; }
};

/// One leaf's column in a projection: @p cells × @p cells map cells from
/// global cell index (x, y), occupied or free.
struct ProjectedLeaf {
  long x = 0, y = 0;
  long cells = 1;
  int8_t value = ProjectedMap::kFree;
};

/// The columns of @p tree's leaves that reach into [min_z_m, max_z_m].
std::vector<ProjectedLeaf> projectedLeaves(const octomap::OcTree& tree, double min_z_m, double max_z_m);

/// The grid of @p sets' columns (of maps of @p resolution_m cells) over their
/// bounding box, occupied over free over unknown (empty if there are none).
ProjectedMap composeProjection(double resolution_m, const std::vector<const std::vector<ProjectedLeaf>*>& sets);

/// composeProjection() of @p tree's projectedLeaves().
ProjectedMap projectOccupancy(const octomap::OcTree& tree, double min_z_m, double max_z_m);

}  // namespace stereo_occupancy
