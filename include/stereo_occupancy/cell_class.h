#pragma once
/// @file
/// The class of a map cell (unknown, free, occupied) and a change of it: what
/// the accumulator's fusion reports (MapAccumulator::takeClassChanges()) and
/// the distance field (distance_field.h) takes. Apart from distance_field.h so
/// that the fusion does not depend on the field.

#include <Eigen/Core>
#include <Eigen/Geometry>  // AlignedBox3i

#include <cstdint>

namespace stereo_occupancy {

/// What a cell of the map is, as the field sees it.
enum class CellClass : uint8_t {
  kUnknown = 0,   ///< no node in the map
  kFree = 1,      ///< log-odds below the map's occupancy threshold
  kOccupied = 2,  ///< log-odds at or above it (octomap's isNodeOccupied())
};

/// The class of a cell of log-odds @p log_odds, with @p occupied_log_odds the
/// map's occupancy threshold (OcTree::getOccupancyThresLog()): as
/// OcTree::isNodeOccupied() decides, so the field and the published map agree.
inline CellClass classOfLogOdds(float log_odds, float occupied_log_odds) {
  return log_odds >= occupied_log_odds ? CellClass::kOccupied : CellClass::kFree;
}

/// A cell whose class an update changed. @p cell is the global cell index:
/// the OctoMap key minus 32768 on each axis (floor(p / resolution)).
struct CellClassChange {
  Eigen::Vector3i cell;
  CellClass now = CellClass::kUnknown;
};

/// A box of cells whose classes may have changed in any way (a tile dropped
/// or loaded, the part of the map a prune dropped, a cleared box): global
/// cell indices as CellClassChange's, both corners inside the box.
using CellBox = Eigen::AlignedBox3i;

}  // namespace stereo_occupancy
