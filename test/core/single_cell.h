#pragma once
/// @file
/// Test helper: an update of one cell.

#include <Eigen/Core>

#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/local_grid.h"

namespace stereo_occupancy {

/// An update of the one cell @p g with log-odds @p value, seen from the cell's centre.
inline GridUpdate singleCell(const Eigen::Vector3i& g, float value, double res = 0.25) {
  LocalGrid grid;
  grid.reset(g, Eigen::Vector3i(1, 1, 1), res);
  grid.at(0, 0, 0) = value;
  GridUpdate u;
  encodeGridUpdate(grid, grid.cellCentre(0, 0, 0), &u);
  return u;
}

}  // namespace stereo_occupancy
