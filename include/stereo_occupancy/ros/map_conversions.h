#pragma once
/// @file
/// The maps and their messages: a drawn grid as an OccupancyUpdate (and the
/// update read in place), the accumulated map as octomap_server's outputs
/// (Octomap, block markers, the occupied cells' cloud, projected_map), a
/// local grid as a cloud.

#include <nav_msgs/OccupancyGrid.h>
#include <octomap/OcTree.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/Header.h>
#include <visualization_msgs/MarkerArray.h>

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "stereo_occupancy/OccupancyUpdate.h"
#include "stereo_occupancy/Octomap.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/projected_map.h"
#include "stereo_occupancy/store/map_snapshot.h"

namespace stereo_occupancy {

/// The update as a message: its arrays move into the message (no copy of the cells).
void toMsg(GridUpdate&& update, const std_msgs::Header& header, OccupancyUpdate* msg);
/// A view of the message's cells in place (no copy); @p msg must outlive it.
/// False (with the reason) if the sizes do not fit an int; whether runs and
/// values fit together is GridUpdateView::isConsistent(), which
/// MapAccumulator::integrate() checks.
bool viewOf(const OccupancyUpdate& msg, GridUpdateView* view, std::string* why);

/// The tree as an octomap_msgs/Octomap-compatible message: binary (.bt
/// content) or full (.ot content, log-odds).
void toMsg(const octomap::OcTree& tree, bool binary, const std_msgs::Header& header, Octomap* msg);

/// The same message from a MapSnapshot of the tree, byte for byte.
/// @throws std::logic_error for a full message of a snapshot without full data.
void toMsg(const MapSnapshot& snapshot, bool binary, const std_msgs::Header& header, Octomap* msg);

/// The tree a toMsg() message carries (binary or full), or null if it is not
/// an OcTree's or its data cannot be read.
std::unique_ptr<octomap::OcTree> treeFromMsg(const Octomap& msg);

/// The occupied cells of @p blocks (MapAccumulator's change-tracking blocks)
/// as one cube list each, coloured by height over the map's height: a block
/// is marker (namespace "occupied_cells_z<bz>", id from bx, by) that rviz
/// replaces when the block changes; a block without occupied cells is a
/// DELETE. With @p all (the whole map) a DELETEALL comes first, so that
/// blocks that went away go from rviz too.
void blockMarkers(const octomap::OcTree& tree, const std::vector<Eigen::Vector3i>& blocks, bool all,
                  const std_msgs::Header& header, visualization_msgs::MarkerArray* markers);

/// The free leaves of @p blocks as cube lists, a translucent green as
/// octomap_server draws them: per block one marker per leaf size of 1, 2, 4, 8
/// and 16 cells (namespace "free_cells_z<bz>_s<side>", id from bx, by; a leaf
/// larger than a block is drawn as the block), a DELETE where a block has no
/// free leaf of that size. With @p all a DELETEALL comes first and the empty
/// markers are left out.
void freeBlockMarkers(const octomap::OcTree& tree, const std::vector<Eigen::Vector3i>& blocks, bool all,
                      const std_msgs::Header& header, visualization_msgs::MarkerArray* markers);

/// The projected map as a nav_msgs/OccupancyGrid in the header's frame (z = 0).
void toMsg(const ProjectedMap& map, const std_msgs::Header& header, nav_msgs::OccupancyGrid* msg);

/// Centres of the map's occupied leaves as an XYZ cloud.
void occupiedCellCloud(const MapSnapshot& snapshot, const std_msgs::Header& header, sensor_msgs::PointCloud2* cloud);

/// Centres of a local grid's cells with positive log-odds as an XYZ + intensity (log-odds) cloud.
void occupiedCellCloud(const LocalGrid& grid, const std_msgs::Header& header, sensor_msgs::PointCloud2* cloud);

}  // namespace stereo_occupancy
