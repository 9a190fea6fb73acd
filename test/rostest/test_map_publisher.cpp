// MapPublisher in a real roscore: the map's outputs go out only while
// someone listens and only when the map changed; a new subscriber of the
// markers first gets the whole map, then the changed blocks; the whole-map
// outputs wait for full_map_period_s; the services answer with the map.

#include <gtest/gtest.h>
#include <nav_msgs/OccupancyGrid.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <visualization_msgs/MarkerArray.h>

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cell_update.h"
#include "stereo_occupancy/GetOctomap.h"
#include "stereo_occupancy/Octomap.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/ros/map_publisher.h"
#include "stereo_occupancy/ros/mapping_pipeline.h"
#include "wait_for.h"

using namespace stereo_occupancy;

namespace {

/// A map, its lock and its publisher under the namespace @p ns; the timer
/// slow enough (100 s) that each test publishes by hand.
class MapPublisherTest : public ::testing::Test {
 protected:
  void start(const std::string& ns, MapPublisherConfig config = MapPublisherConfig()) {
    config.publish_rate_hz = 0.01;
    nh_ = ros::NodeHandle(ns);
    fusion_ = std::make_unique<MapFusion>(OctomapAccumulatorParameters());
    publisher_ = std::make_unique<MapPublisher>(config, MapAccumulatorConfig(), fusion_.get(), &fusion_mutex_, ns);
    publisher_->advertise(nh_);
  }

  /// Fuses @p cells (occupied) as the accumulator does: under the lock, the publisher told.
  void fuse(const std::vector<Eigen::Vector3i>& cells, double stamp_s) {
    std::lock_guard<std::mutex> lock(fusion_mutex_);
    std::string why;
    ASSERT_TRUE(fusion_->fuse(cellUpdate(cells, 2.0f, stamp_s), &why)) << why;
    publisher_->mapChanged();
  }

  /// Subscribes to @p topic, keeping every message, and waits for the connection.
  template <class M>
  ros::Subscriber keep(const std::string& topic, std::vector<boost::shared_ptr<const M>>* messages) {
    ros::Subscriber sub = nh_.subscribe<M>(topic, 10, [this, messages](const boost::shared_ptr<const M>& msg) {
      std::lock_guard<std::mutex> lock(test_mutex_);
      messages->push_back(msg);
    });
    EXPECT_TRUE(waitFor(
        test_mutex_, [&] { return sub.getNumPublishers() > 0; }, 10.0))
        << topic;
    ros::WallDuration(0.2).sleep();  // the publisher's side of the connection
    return sub;
  }

  /// How many of @p messages have come (under the test's lock).
  template <class M>
  size_t count(const std::vector<M>& messages) {
    std::lock_guard<std::mutex> lock(test_mutex_);
    return messages.size();
  }

  ros::NodeHandle nh_;
  std::mutex fusion_mutex_, test_mutex_;
  std::unique_ptr<MapFusion> fusion_;
  std::unique_ptr<MapPublisher> publisher_;
};

const Eigen::Vector3i kBlockA(1, 1, 1), kBlockB(40, 1, 1);  // cells in two blocks of 16³

}  // namespace

TEST_F(MapPublisherTest, TheMarkersCarryTheWholeMapToANewSubscriberThenOnlyTheChangedBlocks) {
  start("/markers");
  fuse({kBlockA, kBlockB}, 1.0);
  publisher_->publish();  // nobody listens: nothing built, the changes kept for the next subscriber
  std::vector<visualization_msgs::MarkerArrayConstPtr> markers;
  ros::Subscriber sub = keep("occupied_cells_vis_array", &markers);
  publisher_->publish();
  ASSERT_TRUE(waitFor(
      test_mutex_, [&] { return markers.size() == 1; }, 5.0));
  {
    std::lock_guard<std::mutex> lock(test_mutex_);
    const auto& whole = markers[0]->markers;
    ASSERT_EQ(whole.size(), 3u);  // DELETEALL, then both blocks
    EXPECT_EQ(whole[0].action, visualization_msgs::Marker::DELETEALL);
    EXPECT_EQ(whole[1].action, visualization_msgs::Marker::ADD);
    EXPECT_EQ(whole[1].points.size(), 1u);
    EXPECT_EQ(whole[1].header.frame_id, "map");
  }
  publisher_->publish();  // nothing changed: nothing goes out
  fuse({kBlockB + Eigen::Vector3i(1, 0, 0)}, 2.0);
  publisher_->publish();
  ASSERT_TRUE(waitFor(
      test_mutex_, [&] { return markers.size() == 2; }, 5.0));
  ros::WallDuration(0.3).sleep();
  std::lock_guard<std::mutex> lock(test_mutex_);
  ASSERT_EQ(markers.size(), 2u) << "a publish without a change sent markers";
  ASSERT_EQ(markers[1]->markers.size(), 1u);  // block B only, no DELETEALL
  EXPECT_EQ(markers[1]->markers[0].action, visualization_msgs::Marker::ADD);
  EXPECT_EQ(markers[1]->markers[0].points.size(), 2u);
  EXPECT_EQ(markers[1]->markers[0].header.stamp, ros::Time(2.0));
}

TEST_F(MapPublisherTest, TheWholeMapWaitsForFullMapPeriod) {
  MapPublisherConfig config;
  config.full_map_period_s = 3600.0;
  start("/period", config);
  fuse({kBlockA}, 1.0);
  std::vector<OctomapConstPtr> maps;
  std::vector<visualization_msgs::MarkerArrayConstPtr> markers;
  ros::Subscriber map_sub = keep("octomap_binary", &maps);
  ros::Subscriber marker_sub = keep("occupied_cells_vis_array", &markers);
  publisher_->publish();
  ASSERT_TRUE(waitFor(
      test_mutex_, [&] { return maps.size() == 1 && markers.size() == 1; }, 5.0));
  fuse({kBlockB}, 2.0);
  publisher_->publish();  // the markers carry the change; the whole map waits an hour
  ASSERT_TRUE(waitFor(
      test_mutex_, [&] { return markers.size() == 2; }, 5.0));
  ros::WallDuration(0.3).sleep();
  EXPECT_EQ(count(maps), 1u);
}

TEST_F(MapPublisherTest, TheWholeMapOutputsAreTheTreesAndTheServicesAnswerWithIt) {
  MapPublisherConfig config;
  config.full_map_period_s = 0.0;
  config.projection_min_z_m = 0.0;
  config.projection_max_z_m = 1.0;
  start("/whole", config);
  fuse({kBlockA, kBlockB}, 1.0);
  std::vector<OctomapConstPtr> binary, full;
  std::vector<sensor_msgs::PointCloud2ConstPtr> clouds;
  std::vector<nav_msgs::OccupancyGridConstPtr> grids;
  ros::Subscriber binary_sub = keep("octomap_binary", &binary);
  ros::Subscriber full_sub = keep("octomap_full", &full);
  ros::Subscriber cloud_sub = keep("octomap_point_cloud_centers", &clouds);
  ros::Subscriber grid_sub = keep("projected_map", &grids);
  publisher_->publish();
  ASSERT_TRUE(waitFor(
      test_mutex_, [&] { return !binary.empty() && !full.empty() && !clouds.empty() && !grids.empty(); }, 5.0));
  Octomap tree_binary, tree_full;
  {
    std::lock_guard<std::mutex> lock(fusion_mutex_);
    std_msgs::Header header;
    header.frame_id = "map";
    header.stamp = ros::Time(1.0);
    toMsg(fusion_->map().tree(), true, header, &tree_binary);
    toMsg(fusion_->map().tree(), false, header, &tree_full);
  }
  {
    std::lock_guard<std::mutex> lock(test_mutex_);
    EXPECT_EQ(binary[0]->data, tree_binary.data);  // byte for byte the tree's
    EXPECT_EQ(full[0]->data, tree_full.data);
    EXPECT_EQ(binary[0]->header.stamp, ros::Time(1.0));
    EXPECT_EQ(clouds[0]->width * clouds[0]->height, 2u);  // the two occupied cells' centres
    EXPECT_EQ(grids[0]->header.frame_id, "map");
    EXPECT_EQ(std::count(grids[0]->data.begin(), grids[0]->data.end(), 100), 2);  // both cells in the band
  }
  GetOctomap get;
  ASSERT_TRUE(ros::service::call("/whole/octomap_binary", get));
  EXPECT_TRUE(get.response.map.binary);
  EXPECT_EQ(get.response.map.data, tree_binary.data);
  ASSERT_TRUE(ros::service::call("/whole/octomap_full", get));
  EXPECT_FALSE(get.response.map.binary);
  EXPECT_EQ(get.response.map.data, tree_full.data);
}

TEST(MapPublisherConfig, TheProjectionBandMustHaveAHeight) {
  MapPublisherConfig config;
  std::string why;
  EXPECT_TRUE(config.isValid(&why)) << why;
  config.projection_min_z_m = config.projection_max_z_m = 2.0;
  EXPECT_FALSE(config.isValid(&why));
  EXPECT_NE(why.find("projection_min_z_m"), std::string::npos) << why;
  config = MapPublisherConfig();
  config.publish_rate_hz = 0.0;
  EXPECT_FALSE(config.isValid(&why));
  EXPECT_EQ(why.rfind("publish_rate_hz must be in", 0), 0u) << why;
}
