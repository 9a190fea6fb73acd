// What octomap_server's users wire into planners and rviz, from a real
// manager: projected_map, octomap_full, free_cells_vis_array, the map on
// request (octomap_binary / octomap_full services), ~clear_bbx, and an
// accumulator that starts from a saved map (map_file).

#include <gtest/gtest.h>
#include <nav_msgs/OccupancyGrid.h>
#include <nodelet/NodeletLoad.h>
#include <nodelet/NodeletUnload.h>
#include <ros/ros.h>
#include <std_srvs/Empty.h>
#include <std_srvs/Trigger.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2_ros/transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>

#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "stereo_occupancy/BoundingBoxQuery.h"
#include "stereo_occupancy/GetOctomap.h"
#include "stereo_occupancy/OccupancyUpdate.h"
#include "stereo_occupancy/Octomap.h"
#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "stereo_occupancy/store/mission_map.h"
#include "wait_for.h"

using namespace stereo_occupancy;

namespace {

/// The map of a GetOctomap answer or an Octomap message (a readable OcTree, asserted).
std::unique_ptr<octomap::OcTree> treeOf(const Octomap& msg) {
  std::unique_ptr<octomap::OcTree> tree = treeFromMsg(msg);
  EXPECT_TRUE(tree) << "an Octomap message that is no readable OcTree";
  return tree ? std::move(tree) : std::make_unique<octomap::OcTree>(0.1);
}

/// True if @p msg's map holds the test wall (12 m ahead) as occupied.
bool holdsTheWall(const OctomapConstPtr& msg) {
  if (!msg) return false;
  const auto tree = treeOf(*msg);
  const octomap::OcTreeNode* n = tree->search(12.1, 0.1, 2.1);
  return n && tree->isNodeOccupied(n);
}

/// The projected map's cell at (x, y) [m]; -2 outside it.
int cellAt(const nav_msgs::OccupancyGrid& grid, double x, double y) {
  const int i = static_cast<int>(std::floor((x - grid.info.origin.position.x) / grid.info.resolution));
  const int j = static_cast<int>(std::floor((y - grid.info.origin.position.y) / grid.info.resolution));
  if (i < 0 || j < 0 || i >= static_cast<int>(grid.info.width) || j >= static_cast<int>(grid.info.height)) return -2;
  return grid.data[static_cast<size_t>(j) * grid.info.width + i];
}

/// A request to load a second OctomapAccumulator as @p name, its map outputs
/// (and the update input, if @p own_input) under @p name.
nodelet::NodeletLoad accumulatorLoad(const std::string& name, bool own_input) {
  nodelet::NodeletLoad load;
  load.request.name = name;
  load.request.type = "stereo_occupancy/OctomapAccumulator";
  std::vector<std::string> topics = {"octomap_binary",
                                     "octomap_full",
                                     "occupied_cells_vis_array",
                                     "free_cells_vis_array",
                                     "octomap_point_cloud_centers",
                                     "projected_map"};
  if (own_input) topics.push_back("occupancy_update");
  for (const std::string& topic : topics) {
    load.request.remap_source_args.push_back("/" + topic);
    load.request.remap_target_args.push_back(name + "/" + topic);
  }
  return load;
}

class OctomapServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    disparity_pub_ = nh_.advertise<stereo_msgs::DisparityImage>("/stereo/disparity", 10);
    const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(20.0);
    while (disparity_pub_.getNumSubscribers() == 0 && ros::WallTime::now() < until) ros::WallDuration(0.05).sleep();
    ASSERT_GT(disparity_pub_.getNumSubscribers(), 0u) << "DisparityMapper did not subscribe";
    // Each case from an emptied map (a case before may have cleared the wall's box).
    ASSERT_TRUE(ros::service::waitForService("/octomap_accumulator/reset", ros::Duration(10.0)));
    std_srvs::Empty reset;
    ASSERT_TRUE(ros::service::call("/octomap_accumulator/reset", reset));
    T_W_C_.setIdentity();
    T_W_C_.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;  // looking along +x
    T_W_C_.translation() = Eigen::Vector3d(0.0, 0.0, 2.0);
    SyntheticScene wall;  // 6 m wide, 4 m high, 12 m ahead
    wall.addBox(Eigen::Vector3d(12.0, -3.0, 0.0), Eigen::Vector3d(13.0, 3.0, 4.0));
    image_ = renderDisparity(wall, StereoCameraModel(StereoCameraConfig()), T_W_C_);
  }

  /// Maps the wall from a few frames and waits until the map holds it.
  void mapTheWall() {
    ros::Subscriber map_sub = nh_.subscribe<Octomap>("/octomap_binary", 1, [&](const OctomapConstPtr& msg) {
      std::lock_guard<std::mutex> lock(mutex_);
      latest_map_ = msg;
    });
    for (int i = 0; i < 3; ++i) {
      const ros::Time stamp = ros::Time::now();
      tf_.sendTransform(toTransformMsg(T_W_C_, stamp, "map", "camera_optical"));
      auto msg = boost::make_shared<stereo_msgs::DisparityImage>();
      std_msgs::Header header;
      header.stamp = stamp;
      header.frame_id = "camera_optical";
      toDisparityImageMsg(image_, header, StereoCameraConfig(), 128.0, 1.0 / 16.0, msg.get());
      disparity_pub_.publish(msg);
      ros::WallDuration(0.1).sleep();
    }
    ASSERT_TRUE(waitFor(
        mutex_, [&] { return holdsTheWall(latest_map_); }, 20.0))
        << "the wall never reached the map";
  }

  /// Saves through @p service (the save directory made first); fails the test if it does not.
  void saveTheMap(const std::string& service = "/octomap_accumulator/save_map") {
    ::mkdir("/tmp/stereo_occupancy_octomap_server", 0755);
    std_srvs::Trigger save;
    ASSERT_TRUE(ros::service::call(service, save)) << service;
    ASSERT_TRUE(save.response.success) << save.response.message;
  }

  /// The map as the octomap_binary or octomap_full service gives it.
  std::unique_ptr<octomap::OcTree> requestMap(const std::string& service, bool* binary = nullptr) {
    GetOctomap get;
    EXPECT_TRUE(ros::service::waitForService(service, ros::Duration(10.0))) << service;
    EXPECT_TRUE(ros::service::call(service, get)) << service;
    if (binary) *binary = get.response.map.binary;
    return treeOf(get.response.map);
  }

  ros::NodeHandle nh_;
  ros::Publisher disparity_pub_;
  tf2_ros::TransformBroadcaster tf_;
  Eigen::Isometry3d T_W_C_;
  cv::Mat image_;
  std::mutex mutex_;
  OctomapConstPtr latest_map_;
};

}  // namespace

TEST_F(OctomapServerTest, OutputsAndServicesAsOctomapServer) {
  // Latched outputs, subscribed before the wall is mapped.
  nav_msgs::OccupancyGridConstPtr projected;
  OctomapConstPtr full;
  visualization_msgs::MarkerArrayConstPtr free_markers;
  auto keep = [&](auto* slot) {
    return [this, slot](const auto& msg) {
      std::lock_guard<std::mutex> lock(mutex_);
      *slot = msg;
    };
  };
  ros::Subscriber projected_sub = nh_.subscribe<nav_msgs::OccupancyGrid>("/projected_map", 1, keep(&projected));
  ros::Subscriber full_sub = nh_.subscribe<Octomap>("/octomap_full", 1, keep(&full));
  ros::Subscriber free_sub =
      nh_.subscribe<visualization_msgs::MarkerArray>("/free_cells_vis_array", 1, keep(&free_markers));
  mapTheWall();
  // projected_map: the wall's columns occupied, the ground before it free.
  ASSERT_TRUE(waitFor(
      mutex_, [&] { return projected && cellAt(*projected, 12.1, 0.1) == 100; }, 10.0));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    EXPECT_EQ(projected->header.frame_id, "map");
    EXPECT_FLOAT_EQ(projected->info.resolution, 0.25f);
    EXPECT_EQ(cellAt(*projected, 6.1, 0.1), 0) << "free space in front of the wall";
    EXPECT_EQ(cellAt(*projected, 12.1, 2.6), 100);
  }
  // octomap_full: the log-odds, binary false, id OcTree.
  ASSERT_TRUE(waitFor(
      mutex_, [&] { return full != nullptr; }, 10.0));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    EXPECT_FALSE(full->binary);
    EXPECT_EQ(full->id, "OcTree");
    const auto tree = treeOf(*full);
    const octomap::OcTreeNode* wall = tree->search(12.1, 0.1, 2.1);
    ASSERT_NE(wall, nullptr);
    EXPECT_GT(wall->getLogOdds(), 0.0f);
  }
  // free_cells_vis_array: free leaves as cubes.
  ASSERT_TRUE(waitFor(
      mutex_, [&] { return free_markers != nullptr; }, 10.0));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    size_t points = 0;
    for (const auto& m : free_markers->markers) {
      if (m.action == visualization_msgs::Marker::DELETEALL) continue;
      EXPECT_EQ(m.ns.rfind("free_cells_z", 0), 0u) << m.ns;
      points += m.points.size();
    }
    EXPECT_GT(points, 100u);
  }
  // The map on request, both kinds.
  bool binary = false;
  const auto on_request = requestMap("/octomap_binary", &binary);
  EXPECT_TRUE(binary);
  ASSERT_NE(on_request->search(12.1, 0.1, 2.1), nullptr);
  EXPECT_TRUE(on_request->isNodeOccupied(on_request->search(12.1, 0.1, 2.1)));
  requestMap("/octomap_full", &binary);
  EXPECT_FALSE(binary);

  // ~clear_bbx: nothing occupied remains in the box; the wall beside it stays.
  BoundingBoxQuery clear;
  clear.request.min.x = 11.0, clear.request.min.y = -1.0, clear.request.min.z = 0.0;
  clear.request.max.x = 14.0, clear.request.max.y = 1.0, clear.request.max.z = 4.0;
  ASSERT_TRUE(ros::service::waitForService("/octomap_accumulator/clear_bbx", ros::Duration(10.0)));
  ASSERT_TRUE(ros::service::call("/octomap_accumulator/clear_bbx", clear));
  const auto cleared = requestMap("/octomap_full");
  size_t occupied_inside = 0;
  for (auto it = cleared->begin_leafs_bbx(octomap::point3d(11.0f, -1.0f, 0.0f), octomap::point3d(14.0f, 1.0f, 4.0f)),
            end = cleared->end_leafs_bbx();
       it != end; ++it)
    occupied_inside += cleared->isNodeOccupied(*it);
  EXPECT_EQ(occupied_inside, 0u);
  ASSERT_NE(cleared->search(12.1, 2.6, 2.1), nullptr);
  EXPECT_TRUE(cleared->isNodeOccupied(cleared->search(12.1, 2.6, 2.1)));
  BoundingBoxQuery inverted = clear;
  inverted.request.min.x = 20.0;  // min > max: refused
  EXPECT_FALSE(ros::service::call("/octomap_accumulator/clear_bbx", inverted));
}

// occupied_cells_vis_array and free_cells_vis_array cost what changed: a
// new subscriber gets the whole map (a DELETEALL, then every block), later
// messages only the blocks that updates changed.
TEST_F(OctomapServerTest, MarkersCarryOnlyTheChangedBlocks) {
  std::map<std::string, std::vector<visualization_msgs::MarkerArrayConstPtr>> received;
  std::vector<ros::Subscriber> subs;
  for (const std::string topic : {"occupied_cells_vis_array", "free_cells_vis_array"})
    subs.push_back(nh_.subscribe<visualization_msgs::MarkerArray>(
        "/" + topic, 10, [&, topic](const visualization_msgs::MarkerArrayConstPtr& msg) {
          std::lock_guard<std::mutex> lock(mutex_);
          received[topic].push_back(msg);
        }));
  auto both = [&] {
    return !received["occupied_cells_vis_array"].empty() && !received["free_cells_vis_array"].empty();
  };
  mapTheWall();
  ASSERT_TRUE(waitFor(mutex_, both, 10.0));
  // The blocks a message carries: a free block has one marker per leaf size
  // ("free_cells_z<bz>_s<side>"), an occupied block one ("occupied_cells_z<bz>").
  using Block = std::pair<std::string, int>;  // "<kind>_cells_z<bz>", id (from bx, by)
  auto blocksOf = [](const visualization_msgs::MarkerArray& msg) {
    std::set<Block> b;
    for (const auto& m : msg.markers)
      if (m.action != visualization_msgs::Marker::DELETEALL) b.emplace(m.ns.substr(0, m.ns.rfind("_s")), m.id);
    return b;
  };
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& [topic, messages] : received)
      ASSERT_EQ(messages.front()->markers.front().action, visualization_msgs::Marker::DELETEALL) << topic;
  }
  // Until the wall's last frames are fused and published (5 Hz): quiet for a second.
  std::map<std::string, std::set<Block>> whole;
  const ros::WallTime quiet_until = ros::WallTime::now() + ros::WallDuration(20.0);
  for (bool quiet = false; !quiet && ros::WallTime::now() < quiet_until;) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      quiet = received["occupied_cells_vis_array"].empty() && received["free_cells_vis_array"].empty();
      for (auto& [topic, messages] : received) {
        for (const auto& msg : messages) {
          const auto b = blocksOf(*msg);
          whole[topic].insert(b.begin(), b.end());
        }
        messages.clear();
      }
    }
    if (!quiet) ros::WallDuration(1.0).sleep();
  }
  ASSERT_GT(whole["occupied_cells_vis_array"].size(), 4u) << "the wall's blocks";
  ASSERT_GT(whole["free_cells_vis_array"].size(), 4u);

  // An update of 4 x 4 x 4 occupied cells from global cell (14, 40, 8), away
  // from the wall and its free space: the blocks (0, 2, 0) and (1, 2, 0) of
  // 16 cells change, and nothing else.
  ros::Publisher update_pub = nh_.advertise<OccupancyUpdate>("/occupancy_update", 1);
  const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(10.0);
  while (update_pub.getNumSubscribers() == 0 && ros::WallTime::now() < until) ros::WallDuration(0.05).sleep();
  ASSERT_GT(update_pub.getNumSubscribers(), 0u) << "the accumulator did not subscribe";
  OccupancyUpdate small;
  small.header.frame_id = "map";
  small.header.stamp = ros::Time::now();
  small.resolution = 0.25;
  const int origin[3] = {14, 40, 8};
  for (int a = 0; a < 3; ++a) {
    small.origin_index[a] = origin[a];
    small.size[a] = 4;
  }
  small.sensor_origin.x = 4.0, small.sensor_origin.y = 10.5, small.sensor_origin.z = 2.5;
  small.run_start = {0};
  small.run_length = {64};
  small.log_odds.assign(64, 1.5f);
  update_pub.publish(small);
  ASSERT_TRUE(waitFor(mutex_, both, 10.0)) << "no markers after the update";
  ros::WallDuration(1.0).sleep();  // any further message would go out within 0.2 s
  std::lock_guard<std::mutex> lock(mutex_);
  // The occupied markers: the update's 64 cells, each block's in its own
  // marker, two blocks of z block 0; no DELETEALL (that is the whole map).
  std::set<std::array<int, 3>> cells;
  std::set<Block> changed;
  size_t whole_map_messages = 0, mixed_markers = 0;
  for (const auto& msg : received["occupied_cells_vis_array"]) {
    whole_map_messages += !msg->markers.empty() && msg->markers.front().action == visualization_msgs::Marker::DELETEALL;
    for (const auto& m : msg->markers) {
      std::set<std::array<int, 3>> blocks_of_points;
      for (const auto& p : m.points) {
        const std::array<int, 3> g = {static_cast<int>(std::floor(p.x / 0.25)),
                                      static_cast<int>(std::floor(p.y / 0.25)),
                                      static_cast<int>(std::floor(p.z / 0.25))};
        cells.insert(g);
        blocks_of_points.insert({g[0] >> 4, g[1] >> 4, g[2] >> 4});
      }
      mixed_markers += blocks_of_points.size() > 1;
    }
    const auto b = blocksOf(*msg);
    changed.insert(b.begin(), b.end());
  }
  const size_t whole_blocks = whole["occupied_cells_vis_array"].size();
  EXPECT_EQ(whole_map_messages, 0u);
  EXPECT_EQ(changed.size(), 2u) << "blocks sent after the update; the map has " << whole_blocks;
  EXPECT_EQ(
      std::count_if(changed.begin(), changed.end(), [](const Block& b) { return b.first != "occupied_cells_z0"; }), 0)
      << "blocks outside z block 0";
  EXPECT_EQ(mixed_markers, 0u) << "markers with the cells of more than one block";
  size_t updated = 0;
  for (const auto& g : cells)
    updated += g[0] >= origin[0] && g[0] < origin[0] + 4 && g[1] >= origin[1] && g[1] < origin[1] + 4 &&
               g[2] >= origin[2] && g[2] < origin[2] + 4;
  EXPECT_EQ(updated, 64u) << "of the update's cells are drawn";
  EXPECT_EQ(cells.size(), 64u) << "cells drawn after the update (the update has 64)";
  // The free markers: the same two blocks (no free leaf in them: DELETEs), nothing else.
  std::set<Block> free_changed;
  size_t free_whole_map_messages = 0, free_cells_drawn = 0;
  for (const auto& msg : received["free_cells_vis_array"]) {
    free_whole_map_messages +=
        !msg->markers.empty() && msg->markers.front().action == visualization_msgs::Marker::DELETEALL;
    for (const auto& m : msg->markers) free_cells_drawn += m.points.size();
    for (const auto& [ns, id] : blocksOf(*msg)) free_changed.emplace("occupied" + ns.substr(4), id);
  }
  EXPECT_EQ(free_whole_map_messages, 0u);
  EXPECT_EQ(free_changed.size(), 2u) << "blocks sent after the update; the map has "
                                     << whole["free_cells_vis_array"].size();
  EXPECT_TRUE(free_changed == changed) << "the free markers' blocks are not the occupied ones'";
  EXPECT_EQ(free_cells_drawn, 0u);
}

// map_file: an accumulator loaded into the running manager with a saved map
// publishes it before any update comes.
TEST_F(OctomapServerTest, AnAccumulatorStartsFromASavedMap) {
  mapTheWall();
  ASSERT_NO_FATAL_FAILURE(saveTheMap());
  nh_.setParam("/restored/full_map_period_s", 0.0);
  nh_.setParam("/restored/map_file", "/tmp/stereo_occupancy_octomap_server/stereo_occupancy_map.ot");
  OctomapConstPtr restored;
  ros::Subscriber sub = nh_.subscribe<Octomap>("/restored/octomap_binary", 1, [&](const OctomapConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    restored = msg;
  });
  nodelet::NodeletLoad load = accumulatorLoad("/restored", /*own_input=*/true);
  ASSERT_TRUE(ros::service::call("/stereo_occupancy_manager/load_nodelet", load));
  ASSERT_TRUE(load.response.success);
  ASSERT_TRUE(waitFor(
      mutex_, [&] { return restored != nullptr; }, 20.0))
      << "the restored map was not published";
  {
    std::lock_guard<std::mutex> lock(mutex_);
    EXPECT_EQ(restored->header.frame_id, "map");
    const auto tree = treeOf(*restored);
    ASSERT_NE(tree->search(12.1, 0.1, 2.1), nullptr);
    EXPECT_TRUE(tree->isNodeOccupied(tree->search(12.1, 0.1, 2.1)));
  }
  nodelet::NodeletUnload unload;
  unload.request.name = "/restored";
  EXPECT_TRUE(ros::service::call("/stereo_occupancy_manager/unload_nodelet", unload));
}

// The mission's database: an accumulator with a save_dir keeps its tiles in
// <save_dir>/<map_name>.db; unloaded and loaded again it continues from it,
// and ~save_map writes the whole mission before any new update comes.
TEST_F(OctomapServerTest, ARestartedAccumulatorContinuesFromItsDatabase) {
  const std::string dir = "/tmp/stereo_occupancy_mission_db";
  ::mkdir(dir.c_str(), 0755);
  for (const char* f : {"/m.db", "/m.db-wal", "/m.db-shm", "/m.bt", "/m.ot"}) std::remove((dir + f).c_str());
  nh_.setParam("/mission/save_dir", dir);
  nh_.setParam("/mission/map_name", "m");
  nh_.setParam("/mission/world_frame", "map");
  nh_.setParam("/mission/full_map_period_s", 0.0);
  OctomapConstPtr mission_map;
  ros::Subscriber sub = nh_.subscribe<Octomap>("/mission/octomap_binary", 1, [&](const OctomapConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    mission_map = msg;
  });
  nodelet::NodeletLoad load = accumulatorLoad("/mission", /*own_input=*/false);  // the updates of the main one
  nodelet::NodeletUnload unload;
  unload.request.name = "/mission";
  ASSERT_TRUE(ros::service::call("/stereo_occupancy_manager/load_nodelet", load));
  ASSERT_TRUE(load.response.success);
  ASSERT_TRUE(ros::service::waitForService("/mission/save_map", ros::Duration(10.0)));
  mapTheWall();  // both accumulators take the updates
  ASSERT_TRUE(waitFor(
      mutex_, [&] { return holdsTheWall(mission_map); }, 20.0))
      << "the wall never reached the mission's map";
  ASSERT_TRUE(ros::service::call("/stereo_occupancy_manager/unload_nodelet", unload));  // closes the database

  {
    TileStore store(dir + "/m.db", 0.0);  // the accumulator let the file go
    EXPECT_GE(store.tiles().size(), 1u);
    const auto whole = MissionMap::assemble(store, Eigen::AlignedBox3d());
    const octomap::OcTreeNode* n = whole->search(12.1, 0.1, 2.1);
    ASSERT_NE(n, nullptr) << "the database does not hold the wall";
    EXPECT_TRUE(whole->isNodeOccupied(n));
  }
  std::remove((dir + "/m.bt").c_str());
  std::remove((dir + "/m.ot").c_str());
  ASSERT_TRUE(ros::service::call("/stereo_occupancy_manager/load_nodelet", load));  // a restart
  ASSERT_TRUE(load.response.success);
  ASSERT_TRUE(ros::service::waitForService("/mission/save_map", ros::Duration(10.0)));
  std_srvs::Trigger save;
  ASSERT_TRUE(ros::service::call("/mission/save_map", save));
  ASSERT_TRUE(save.response.success) << save.response.message;
  octomap::OcTree saved(0.25);
  ASSERT_TRUE(saved.readBinary(dir + "/m.bt"));
  const octomap::OcTreeNode* n = saved.search(12.1, 0.1, 2.1);
  ASSERT_NE(n, nullptr) << "the restarted accumulator's save lacks the wall of its database";
  EXPECT_TRUE(saved.isNodeOccupied(n));
  EXPECT_TRUE(ros::service::call("/stereo_occupancy_manager/unload_nodelet", unload));
}

// A map that no longer changes (started from map_file, hovering): a planner
// that subscribes to projected_map or octomap_binary after rviz's markers
// got the whole map still gets it within full_map_period_s, and in the
// other order too; a latched topic then holds it for the next subscriber.
TEST_F(OctomapServerTest, ALateSubscriberGetsTheWholeMapInEitherOrder) {
  mapTheWall();
  ASSERT_NO_FATAL_FAILURE(saveTheMap());
  for (const bool rviz_first : {true, false}) {
    const std::string name = rviz_first ? "/hover_rviz_first" : "/hover_planner_first";
    nh_.setParam(name + "/full_map_period_s", 0.5);
    nh_.setParam(name + "/map_file", "/tmp/stereo_occupancy_octomap_server/stereo_occupancy_map.ot");
    nh_.setParam(name + "/world_frame", "map");
    nodelet::NodeletLoad load = accumulatorLoad(name, /*own_input=*/true);  // no updates reach it
    ASSERT_TRUE(ros::service::call("/stereo_occupancy_manager/load_nodelet", load));
    ASSERT_TRUE(load.response.success);
    visualization_msgs::MarkerArrayConstPtr markers;
    OctomapConstPtr octomap, latched;
    nav_msgs::OccupancyGridConstPtr projected;
    ros::Subscriber rviz, planner, planner_grid, late;
    auto subscribeRviz = [&] {
      rviz = nh_.subscribe<visualization_msgs::MarkerArray>(name + "/occupied_cells_vis_array", 10,
                                                            [&](const visualization_msgs::MarkerArrayConstPtr& msg) {
                                                              std::lock_guard<std::mutex> lock(mutex_);
                                                              markers = msg;
                                                            });
    };
    auto subscribePlanner = [&] {
      planner = nh_.subscribe<Octomap>(name + "/octomap_binary", 1, [&](const OctomapConstPtr& msg) {
        std::lock_guard<std::mutex> lock(mutex_);
        octomap = msg;
      });
    };
    if (rviz_first) {
      subscribeRviz();
      ASSERT_TRUE(waitFor(
          mutex_, [&] { return markers != nullptr; }, 20.0))
          << name << ": rviz got no markers";
      ros::WallDuration(1.5).sleep();  // the whole map went out, to rviz alone
      subscribePlanner();
    } else {
      subscribePlanner();
      ASSERT_TRUE(waitFor(
          mutex_, [&] { return octomap != nullptr; }, 20.0))
          << name << ": the planner got no map";
      ros::WallDuration(1.5).sleep();
      subscribeRviz();
    }
    planner_grid = nh_.subscribe<nav_msgs::OccupancyGrid>(name + "/projected_map", 1,
                                                          [&](const nav_msgs::OccupancyGridConstPtr& msg) {
                                                            std::lock_guard<std::mutex> lock(mutex_);
                                                            projected = msg;
                                                          });
    EXPECT_TRUE(waitFor(
        mutex_, [&] { return holdsTheWall(octomap); }, 5.0))
        << name << ": octomap_binary";
    EXPECT_TRUE(waitFor(
        mutex_, [&] { return markers != nullptr; }, 5.0))
        << name << ": markers";
    EXPECT_TRUE(waitFor(
        mutex_, [&] { return projected && std::count(projected->data.begin(), projected->data.end(), 100) > 20; }, 5.0))
        << name << ": projected_map without the wall";
    // Latched: the next subscriber gets the last map at once, with no new publication due.
    late = nh_.subscribe<Octomap>(name + "/octomap_binary", 1, [&](const OctomapConstPtr& msg) {
      std::lock_guard<std::mutex> lock(mutex_);
      latched = msg;
    });
    EXPECT_TRUE(waitFor(
        mutex_, [&] { return holdsTheWall(latched); }, 2.0))
        << name << ": nothing latched";
    nodelet::NodeletUnload unload;
    unload.request.name = name;
    EXPECT_TRUE(ros::service::call("/stereo_occupancy_manager/unload_nodelet", unload));
  }
}

// An accumulator whose database another holds maps without it; its save then
// answers false and writes the live map aside, never over the mission's files
// (a locked database once replaced a 66 049-cell mission's .bt with 0 cells).
TEST_F(OctomapServerTest, ASaveWithoutItsDatabaseKeepsTheMissionsFiles) {
  mapTheWall();
  const std::string dir = "/tmp/stereo_occupancy_octomap_server";
  ASSERT_NO_FATAL_FAILURE(saveTheMap());
  const auto bytes = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  };
  const std::string mission_bt = bytes(dir + "/stereo_occupancy_map.bt");
  ASSERT_GT(mission_bt.size(), 100u);
  std::remove((dir + "/stereo_occupancy_map_live_only.bt").c_str());
  nh_.setParam("/second/save_dir", dir);  // the main accumulator holds <dir>/stereo_occupancy_map.db
  nh_.setParam("/second/world_frame", "map");
  nodelet::NodeletLoad load = accumulatorLoad("/second", /*own_input=*/true);
  ASSERT_TRUE(ros::service::call("/stereo_occupancy_manager/load_nodelet", load));
  ASSERT_TRUE(load.response.success);
  ASSERT_TRUE(ros::service::waitForService("/second/save_map", ros::Duration(10.0)));
  std_srvs::Trigger second_save;
  ASSERT_TRUE(ros::service::call("/second/save_map", second_save));
  EXPECT_FALSE(second_save.response.success) << second_save.response.message;
  EXPECT_NE(second_save.response.message.find("locked"), std::string::npos) << second_save.response.message;
  EXPECT_NE(second_save.response.message.find("stereo_occupancy_map_live_only.bt"), std::string::npos)
      << second_save.response.message;
  EXPECT_TRUE(bytes(dir + "/stereo_occupancy_map.bt") == mission_bt) << "the mission's .bt was replaced";
  EXPECT_TRUE(std::ifstream(dir + "/stereo_occupancy_map_live_only.bt").good());
  nodelet::NodeletUnload unload;
  unload.request.name = "/second";
  EXPECT_TRUE(ros::service::call("/stereo_occupancy_manager/unload_nodelet", unload));
}
