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
#include <cmath>
#include <cstdio>
#include <memory>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "stereo_occupancy/BoundingBoxQuery.h"
#include "stereo_occupancy/GetOctomap.h"
#include "stereo_occupancy/Octomap.h"
#include "stereo_occupancy/ros/conversions.h"
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
  std::vector<std::string> topics = {"octomap_binary", "octomap_full", "occupied_cells_vis_array",
                                     "free_cells_vis_array", "octomap_point_cloud_centers", "projected_map"};
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
    ASSERT_TRUE(waitFor(mutex_, [&] { return holdsTheWall(latest_map_); }, 20.0)) << "the wall never reached the map";
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
  ros::Subscriber projected_sub =
      nh_.subscribe<nav_msgs::OccupancyGrid>("/projected_map", 1, keep(&projected));
  ros::Subscriber full_sub = nh_.subscribe<Octomap>("/octomap_full", 1, keep(&full));
  ros::Subscriber free_sub =
      nh_.subscribe<visualization_msgs::MarkerArray>("/free_cells_vis_array", 1, keep(&free_markers));
  mapTheWall();
  // projected_map: the wall's columns occupied, the ground before it free.
  ASSERT_TRUE(waitFor(mutex_, [&] { return projected && cellAt(*projected, 12.1, 0.1) == 100; }, 10.0));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    EXPECT_EQ(projected->header.frame_id, "map");
    EXPECT_FLOAT_EQ(projected->info.resolution, 0.25f);
    EXPECT_EQ(cellAt(*projected, 6.1, 0.1), 0) << "free space in front of the wall";
    EXPECT_EQ(cellAt(*projected, 12.1, 2.6), 100);
  }
  // octomap_full: the log-odds, binary false, id OcTree.
  ASSERT_TRUE(waitFor(mutex_, [&] { return full != nullptr; }, 10.0));
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
  ASSERT_TRUE(waitFor(mutex_, [&] { return free_markers != nullptr; }, 10.0));
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
  auto blocks = [](const visualization_msgs::MarkerArray& msg) {
    std::set<std::pair<std::string, int>> b;
    for (const auto& m : msg.markers)
      if (m.action != visualization_msgs::Marker::DELETEALL) b.emplace(m.ns.substr(0, m.ns.rfind("_s")), m.id);
    return b.size();
  };
  std::map<std::string, size_t> whole;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto& [topic, messages] : received) {
      ASSERT_EQ(messages.front()->markers.front().action, visualization_msgs::Marker::DELETEALL) << topic;
      for (const auto& msg : messages) whole[topic] = std::max(whole[topic], blocks(*msg));
      messages.clear();
    }
  }
  // One more frame of the same wall changes some blocks: messages of those only.
  mapTheWall();
  ASSERT_TRUE(waitFor(mutex_, both, 10.0));
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& [topic, messages] : received) {
    const std::string ns = topic == "free_cells_vis_array" ? "free_cells_z" : "occupied_cells_z";
    for (const auto& msg : messages) {
      ASSERT_FALSE(msg->markers.empty()) << topic;
      EXPECT_NE(msg->markers.front().action, visualization_msgs::Marker::DELETEALL) << topic;
      EXPECT_LE(blocks(*msg), whole[topic]) << topic;
      for (const auto& m : msg->markers) EXPECT_EQ(m.ns.rfind(ns, 0), 0u) << m.ns;
    }
  }
}

// map_file: an accumulator loaded into the running manager with a saved map
// publishes it before any update comes.
TEST_F(OctomapServerTest, AnAccumulatorStartsFromASavedMap) {
  mapTheWall();
  ::mkdir("/tmp/stereo_occupancy_octomap_server", 0755);
  std_srvs::Trigger save;
  ASSERT_TRUE(ros::service::call("/octomap_accumulator/save_map", save));
  ASSERT_TRUE(save.response.success) << save.response.message;
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
  ASSERT_TRUE(waitFor(mutex_, [&] { return restored != nullptr; }, 20.0)) << "the restored map was not published";
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
  ASSERT_TRUE(waitFor(mutex_, [&] { return holdsTheWall(mission_map); }, 20.0))
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
