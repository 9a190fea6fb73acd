// The two nodelets in a real manager, driven as a vehicle drives them:
// rendered disparity images of a known scene with their poses on /tf.

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2_ros/transform_broadcaster.h>

#include <sys/stat.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <mutex>
#include <vector>

#include "stereo_occupancy/Octomap.h"
#include "stereo_occupancy/OccupancyUpdate.h"
#include "stereo_occupancy/ros/conversions.h"
#include "stereo_occupancy/synthetic_scene.h"

using namespace stereo_occupancy;

namespace {

/// A 6 m wide, 4 m high wall 12 m in front of a camera 2 m above the ground, looking along +x.
SyntheticScene wallScene() {
  SyntheticScene scene;
  scene.boxes.emplace_back(Eigen::Vector3d(12.0, -3.0, 0.0), Eigen::Vector3d(13.0, 3.0, 4.0));
  return scene;
}

class MappingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    update_sub_ = nh_.subscribe("/occupancy_update", 20, &MappingTest::onUpdate, this);
    map_sub_ = nh_.subscribe("/octomap_binary", 2, &MappingTest::onMap, this);
    disparity_pub_ = nh_.advertise<stereo_msgs::DisparityImage>("/stereo/disparity", 5);
    T_W_C_ = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0));
    const StereoCameraModel camera{StereoCameraConfig()};
    image_ = renderDisparity(wallScene(), camera, T_W_C_);
    // Wait for the mapper's subscription and the accumulator's publisher.
    const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(20.0);
    while ((disparity_pub_.getNumSubscribers() == 0 || update_sub_.getNumPublishers() == 0) &&
           ros::WallTime::now() < until)
      ros::WallDuration(0.05).sleep();
    ASSERT_GT(disparity_pub_.getNumSubscribers(), 0u) << "DisparityMapper did not subscribe";
  }

  void onUpdate(const OccupancyUpdateConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    updates_.push_back(msg);
  }
  void onMap(const OctomapConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    map_ = msg;
  }

  /// Sends the camera pose on /tf (unless frame is unknown) and one disparity image at @p stamp.
  void sendFrame(const ros::Time& stamp, const std::string& frame = "camera_optical", bool with_tf = true) {
    if (with_tf) {
      geometry_msgs::TransformStamped t;
      t.header.stamp = stamp;
      t.header.frame_id = "map";
      t.child_frame_id = frame;
      const Eigen::Quaterniond q(T_W_C_.linear());
      t.transform.translation.x = T_W_C_.translation().x();
      t.transform.translation.y = T_W_C_.translation().y();
      t.transform.translation.z = T_W_C_.translation().z();
      t.transform.rotation.x = q.x();
      t.transform.rotation.y = q.y();
      t.transform.rotation.z = q.z();
      t.transform.rotation.w = q.w();
      tf_.sendTransform(t);
    }
    auto msg = boost::make_shared<stereo_msgs::DisparityImage>();
    msg->header.stamp = stamp;
    msg->header.frame_id = frame;
    msg->image.header = msg->header;
    msg->image.width = image_.cols;
    msg->image.height = image_.rows;
    msg->image.encoding = "32FC1";
    msg->image.step = image_.cols * 4;
    msg->image.data.resize(image_.total() * 4);
    std::memcpy(msg->image.data.data(), image_.data, msg->image.data.size());
    msg->f = 700.0f;
    msg->T = 0.3f;
    msg->min_disparity = 0.0f;
    msg->max_disparity = 128.0f;
    msg->delta_d = 1.0f / 16.0f;
    disparity_pub_.publish(msg);
  }

  bool waitFor(const std::function<bool()>& condition, double seconds) {
    const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(seconds);
    while (ros::WallTime::now() < until) {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (condition()) return true;
      }
      ros::WallDuration(0.02).sleep();
    }
    return false;
  }

  ros::NodeHandle nh_;
  ros::Subscriber update_sub_, map_sub_;
  ros::Publisher disparity_pub_;
  tf2_ros::TransformBroadcaster tf_;
  Eigen::Isometry3d T_W_C_;
  cv::Mat image_;
  std::mutex mutex_;
  std::vector<OccupancyUpdateConstPtr> updates_;
  OctomapConstPtr map_;
};

TEST_F(MappingTest, UpdatesMapSaveAndDroppedImages) {
  // 1. One frame: its update has the wall occupied and free space in front.
  ros::Time t0 = ros::Time::now();
  sendFrame(t0);
  ASSERT_TRUE(waitFor([&] { return !updates_.empty(); }, 20.0)) << "no occupancy_update";
  OccupancyUpdateConstPtr first;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    first = updates_.front();
  }
  EXPECT_EQ(first->header.frame_id, "map");
  EXPECT_EQ(first->header.stamp, t0);
  EXPECT_DOUBLE_EQ(first->resolution, 0.25);
  EXPECT_NEAR(first->sensor_origin.z, 2.0, 1e-6);
  GridUpdate update;
  std::string why;
  ASSERT_TRUE(fromMsg(*first, &update, &why)) << why;
  size_t wall = 0, wall_occupied = 0, front = 0, front_free = 0, behind = 0, other_occupied = 0;
  const double c = update.resolution_m;
  update.forEachCell([&](const Eigen::Vector3i& g, float v) {
    const Eigen::Vector3d p = (g.cast<double>().array() + 0.5).matrix() * c;
    const bool in_wall_span = std::abs(p.y()) < 2.5 && p.z() > 0.5 && p.z() < 3.5;
    if (in_wall_span && p.x() > 12.0 && p.x() < 12.25) {
      ++wall;
      wall_occupied += v > 0.0f;
    } else if (in_wall_span && p.x() > 1.0 && p.x() < 10.5) {
      ++front;
      front_free += v < 0.0f;
    } else if (in_wall_span && p.x() > 14.5) {
      ++behind;  // the wall hides everything beyond its measurement's tail
    } else if (v > 0.0f && !(p.x() > 11.5 && p.x() < 14.5)) {
      ++other_occupied;
    }
  });
  EXPECT_GT(wall, 100u);
  EXPECT_GT(static_cast<double>(wall_occupied) / wall, 0.8) << wall_occupied << " of " << wall;
  EXPECT_GT(front, 1000u);
  EXPECT_EQ(front_free, front);
  EXPECT_EQ(behind, 0u);
  EXPECT_EQ(other_occupied, 0u);

  // 2. An image whose frame has no transform is dropped; the next ones still work.
  sendFrame(t0 + ros::Duration(0.1), "frame_without_tf", /*with_tf=*/false);
  for (int i = 2; i <= 6; ++i) {
    ros::WallDuration(0.15).sleep();
    sendFrame(t0 + ros::Duration(0.1 * i));
  }
  ASSERT_TRUE(waitFor([&] { return updates_.size() >= 6; }, 20.0)) << updates_.size() << " updates";
  ros::WallDuration(0.5).sleep();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    EXPECT_EQ(updates_.size(), 6u);
    for (const auto& u : updates_) EXPECT_NE(u->header.stamp, t0 + ros::Duration(0.1)) << "the image without tf";
    EXPECT_EQ(updates_.back()->header.stamp, t0 + ros::Duration(0.6));
  }

  // 3. The accumulated map holds the wall as occupied and the space in front as free.
  ASSERT_TRUE(waitFor([&] { return map_ && map_->header.stamp == t0 + ros::Duration(0.6); }, 20.0));
  OctomapConstPtr map;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    map = map_;
  }
  EXPECT_TRUE(map->binary);
  EXPECT_EQ(map->id, "OcTree");
  std::stringstream data(std::string(map->data.begin(), map->data.end()));
  octomap::OcTree tree(map->resolution);
  tree.readBinaryData(data);
  const octomap::OcTreeNode* at_wall = tree.search(12.1, 0.1, 2.1);
  const octomap::OcTreeNode* in_front = tree.search(6.1, 0.1, 2.1);
  ASSERT_NE(at_wall, nullptr);
  ASSERT_NE(in_front, nullptr);
  EXPECT_TRUE(tree.isNodeOccupied(at_wall));
  EXPECT_FALSE(tree.isNodeOccupied(in_front));
  EXPECT_EQ(tree.search(16.1, 0.1, 2.1), nullptr);  // behind the wall: unknown

  // 4. ~save_map writes a .bt that octomap::OcTree reads back.
  ::mkdir("/tmp/stereo_occupancy_rostest", 0755);
  std::remove("/tmp/stereo_occupancy_rostest/stereo_occupancy_map.bt");
  std_srvs::Trigger save;
  ASSERT_TRUE(ros::service::waitForService("/octomap_accumulator/save_map", ros::Duration(10.0)));
  ASSERT_TRUE(ros::service::call("/octomap_accumulator/save_map", save));
  EXPECT_TRUE(save.response.success) << save.response.message;
  EXPECT_NE(save.response.message.find("/tmp/stereo_occupancy_rostest/stereo_occupancy_map.bt"), std::string::npos);
  octomap::OcTree saved("/tmp/stereo_occupancy_rostest/stereo_occupancy_map.bt");
  ASSERT_NE(saved.search(12.1, 0.1, 2.1), nullptr);
  EXPECT_TRUE(saved.isNodeOccupied(saved.search(12.1, 0.1, 2.1)));
  EXPECT_EQ(saved.getNumLeafNodes(), tree.getNumLeafNodes());
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_mapping");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int result = RUN_ALL_TESTS();
  ros::shutdown();
  return result;
}
