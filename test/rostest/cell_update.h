#pragma once
/// @file
/// What the accumulator's parts' rostests share: an occupancy update of a few
/// cells, built as the mapper builds one (a local grid, encoded).

#include <Eigen/Core>
#include <vector>

#include "stereo_occupancy/OccupancyUpdate.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/ros/map_conversions.h"

namespace stereo_occupancy {

/// An update in frame "map" stamped @p stamp_s that gives each of @p cells
/// (global cell indices of a 0.25 m grid) the log-odds @p log_odds.
inline OccupancyUpdate cellUpdate(const std::vector<Eigen::Vector3i>& cells, float log_odds, double stamp_s) {
  Eigen::Vector3i lo = cells.front(), hi = cells.front();
  for (const Eigen::Vector3i& c : cells) lo = lo.cwiseMin(c), hi = hi.cwiseMax(c);
  LocalGrid grid;
  grid.reset(lo, hi - lo + Eigen::Vector3i::Ones(), 0.25);
  for (const Eigen::Vector3i& c : cells) grid.at(c.x() - lo.x(), c.y() - lo.y(), c.z() - lo.z()) = log_odds;
  GridUpdate update;
  // The sensor in the update's box (the map refuses an update far from its sensor).
  const Eigen::Vector3d W_sensor_origin = (lo.cast<double>().array() + 0.5).matrix() * 0.25;
  encodeGridUpdate(grid, W_sensor_origin, &update);
  std_msgs::Header header;
  header.frame_id = "map";
  header.stamp = ros::Time(stamp_s);
  OccupancyUpdate msg;
  toMsg(std::move(update), header, &msg);
  return msg;
}

}  // namespace stereo_occupancy
