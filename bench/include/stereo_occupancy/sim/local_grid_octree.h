#pragma once
/// @file
/// A local grid as an octomap::OcTree: to look at one drawn image in
/// octovis, or to compare it with a map (tools and tests).

#include <octomap/OcTree.h>

#include <memory>

#include "stereo_occupancy/local_grid.h"

namespace stereo_occupancy {

/// An OcTree at the grid's resolution holding every known, non-zero cell of
/// @p grid with its log-odds unchanged (setNodeValue, no clamping).
std::unique_ptr<octomap::OcTree> localGridToOcTree(const LocalGrid& grid);

}  // namespace stereo_occupancy
