// Two stereo heads into one map: a forward camera sees a wall, a downward
// camera the ground below the vehicle; the one accumulator's map holds both.

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2_ros/transform_broadcaster.h>

#include <memory>
#include <string>

#include "stereo_occupancy/GetOctomap.h"
#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/sim/synthetic_scene.h"

using namespace stereo_occupancy;

namespace {

/// A head: its topic, optical frame and pose.
struct Head {
  std::string topic, frame;
  Eigen::Isometry3d T_W_C;
};

Eigen::Isometry3d pose(const Eigen::Matrix3d& R_W_C, const Eigen::Vector3d& W_t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R_W_C;
  T.translation() = W_t;
  return T;
}

}  // namespace

TEST(TwoHeads, BothCamerasCellsArriveInOneMap) {
  ros::NodeHandle nh;
  tf2_ros::TransformBroadcaster tf;
  // The vehicle 10 m up; forward: optical z along world x; down: optical z along -z.
  Eigen::Matrix3d forward, down;
  forward << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  down << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  const Head heads[2] = {{"/forward/disparity", "camera_forward", pose(forward, {0.0, 0.0, 10.0})},
                         {"/down/disparity", "camera_down", pose(down, {0.0, 0.0, 10.0})}};
  SyntheticScene scene;
  scene.addBox(Eigen::Vector3d(12.0, -3.0, 6.0), Eigen::Vector3d(13.0, 3.0, 14.0));  // ahead, at flight height
  scene.ground_height_m = 0.0;
  const StereoCameraModel camera{StereoCameraConfig()};
  ros::Publisher pubs[2] = {nh.advertise<stereo_msgs::DisparityImage>(heads[0].topic, 5),
                            nh.advertise<stereo_msgs::DisparityImage>(heads[1].topic, 5)};
  const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(20.0);
  while ((pubs[0].getNumSubscribers() == 0 || pubs[1].getNumSubscribers() == 0) && ros::WallTime::now() < until)
    ros::WallDuration(0.05).sleep();
  ASSERT_GT(pubs[0].getNumSubscribers(), 0u) << "the forward mapper did not subscribe";
  ASSERT_GT(pubs[1].getNumSubscribers(), 0u) << "the downward mapper did not subscribe";
  for (int frame = 0; frame < 3; ++frame) {
    const ros::Time stamp = ros::Time::now();
    for (int h = 0; h < 2; ++h) {
      tf.sendTransform(toTransformMsg(heads[h].T_W_C, stamp, "map", heads[h].frame));
      std_msgs::Header header;
      header.stamp = stamp;
      header.frame_id = heads[h].frame;
      auto msg = boost::make_shared<stereo_msgs::DisparityImage>();
      toDisparityImageMsg(renderDisparity(scene, camera, heads[h].T_W_C), header, StereoCameraConfig(), 128.0,
                          1.0 / 16.0, msg.get());
      pubs[h].publish(msg);
    }
    ros::WallDuration(0.2).sleep();
  }
  ASSERT_TRUE(ros::service::waitForService("/octomap_full", ros::Duration(10.0)));
  bool both = false;
  std::unique_ptr<octomap::OcTree> map;
  for (int attempt = 0; attempt < 50 && !both; ++attempt, ros::WallDuration(0.2).sleep()) {
    GetOctomap get;
    ASSERT_TRUE(ros::service::call("/octomap_full", get));
    map = treeFromMsg(get.response.map);
    ASSERT_TRUE(map);
    const octomap::OcTreeNode* wall = map->search(12.1, 0.1, 10.1);
    const octomap::OcTreeNode* ground = map->search(0.1, 0.1, -0.1);  // the cell just below z = 0
    both = wall && map->isNodeOccupied(wall) && ground && map->isNodeOccupied(ground);
  }
  EXPECT_TRUE(both) << "the map lacks the forward camera's wall or the downward camera's ground";
  // Free space seen by each: in front of the wall, and below the vehicle.
  const octomap::OcTreeNode* ahead = map->search(6.1, 0.1, 10.1);
  const octomap::OcTreeNode* below = map->search(0.1, 0.1, 5.1);
  ASSERT_NE(ahead, nullptr);
  ASSERT_NE(below, nullptr);
  EXPECT_FALSE(map->isNodeOccupied(ahead));
  EXPECT_FALSE(map->isNodeOccupied(below));
}
