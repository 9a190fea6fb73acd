// Left and right camera images through Debian's stereo_image_proc into the
// mapping nodelets, as on a vehicle: the Middlebury "Aloe" pair (rectified,
// with its true disparities) that opencv-doc ships, a quarter of its size,
// given the dataset's focal length and baseline. The map must hold the
// surfaces the true disparities give, and keep the space before them free.

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2_ros/transform_broadcaster.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cstring>
#include <memory>
#include <mutex>
#include <string>

#include "mono_image.h"
#include "stereo_occupancy/GetOctomap.h"
#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/ros/map_conversions.h"

using namespace stereo_occupancy;

namespace {

const std::string kData = "/usr/share/doc/opencv-doc/examples/data/";  // Debian's opencv-doc
constexpr int kShrink = 4;               // 1282 x 1110 -> 320 x 277: disparities within 64 px
constexpr double kFocalFullPx = 3740.0;  // Middlebury 2006 at full size
constexpr double kBaselineM = 0.16;
constexpr double kFocalPx = kFocalFullPx / kShrink;

/// A rectified camera: no distortion, identity rectification; the right one
/// shifted by the baseline (P[3] = -f b).
sensor_msgs::CameraInfoPtr infoMsg(const cv::Size& size, bool right, const std_msgs::Header& header) {
  auto info = boost::make_shared<sensor_msgs::CameraInfo>();
  info->header = header;
  info->width = size.width;
  info->height = size.height;
  info->distortion_model = "plumb_bob";
  info->D.assign(5, 0.0);
  const double cx = 0.5 * (size.width - 1), cy = 0.5 * (size.height - 1);
  info->K = {kFocalPx, 0, cx, 0, kFocalPx, cy, 0, 0, 1};
  info->R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  info->P = {kFocalPx, 0, cx, right ? -kFocalPx * kBaselineM : 0.0, 0, kFocalPx, cy, 0, 0, 0, 1, 0};
  return info;
}

}  // namespace

TEST(StereoPipeline, StereoImageProcDisparitiesMapTheScene) {
  cv::Mat left = cv::imread(kData + "aloeL.jpg", cv::IMREAD_GRAYSCALE);
  cv::Mat right = cv::imread(kData + "aloeR.jpg", cv::IMREAD_GRAYSCALE);
  cv::Mat truth = cv::imread(kData + "aloeGT.png", cv::IMREAD_GRAYSCALE);  // disparity at full size [px]
  ASSERT_FALSE(left.empty() || right.empty() || truth.empty()) << "opencv-doc's Aloe images are missing in " << kData;
  const cv::Size size(left.cols / kShrink, left.rows / kShrink);
  cv::resize(left, left, size, 0, 0, cv::INTER_AREA);
  cv::resize(right, right, size, 0, 0, cv::INTER_AREA);
  cv::resize(truth, truth, size, 0, 0, cv::INTER_NEAREST);

  ros::NodeHandle nh;
  tf2_ros::TransformBroadcaster tf;
  ros::Publisher left_pub = nh.advertise<sensor_msgs::Image>("/stereo/left/image_raw", 2);
  ros::Publisher right_pub = nh.advertise<sensor_msgs::Image>("/stereo/right/image_raw", 2);
  ros::Publisher left_info_pub = nh.advertise<sensor_msgs::CameraInfo>("/stereo/left/camera_info", 2);
  ros::Publisher right_info_pub = nh.advertise<sensor_msgs::CameraInfo>("/stereo/right/camera_info", 2);
  std::mutex mutex;
  size_t disparities = 0;
  ros::Subscriber disparity_sub = nh.subscribe<stereo_msgs::DisparityImage>(
      "/stereo/disparity", 2, [&](const stereo_msgs::DisparityImageConstPtr&) {
        std::lock_guard<std::mutex> lock(mutex);
        ++disparities;
      });
  const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(30.0);
  while ((left_pub.getNumSubscribers() == 0 || right_pub.getNumSubscribers() == 0) && ros::WallTime::now() < until)
    ros::WallDuration(0.05).sleep();
  ASSERT_GT(left_pub.getNumSubscribers(), 0u) << "stereo_image_proc did not subscribe";

  // The camera 2 m up, looking along the world's +x (REP-103 optical frame).
  Eigen::Isometry3d T_W_C = Eigen::Isometry3d::Identity();
  T_W_C.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  T_W_C.translation() = Eigen::Vector3d(0.0, 0.0, 2.0);
  for (int frame = 0; frame < 6; ++frame) {
    std_msgs::Header header;
    header.stamp = ros::Time::now();
    header.frame_id = "camera_optical";
    tf.sendTransform(toTransformMsg(T_W_C, header.stamp, "map", "camera_optical"));
    left_info_pub.publish(infoMsg(size, false, header));
    right_info_pub.publish(infoMsg(size, true, header));
    left_pub.publish(monoMsg(left, header));
    right_pub.publish(monoMsg(right, header));
    ros::WallDuration(0.5).sleep();
  }
  {
    std::lock_guard<std::mutex> lock(mutex);
    ASSERT_GT(disparities, 0u) << "stereo_image_proc published no disparity image";
  }

  // The map, once it holds the mapped frames.
  ASSERT_TRUE(ros::service::waitForService("/octomap_full", ros::Duration(10.0)));
  const StereoCameraModel camera = [&] {
    StereoCameraConfig c;
    c.width_px = size.width;
    c.height_px = size.height;
    c.focal_length_px = kFocalPx;
    c.baseline_m = kBaselineM;
    c.cx_px = 0.5 * (size.width - 1);
    c.cy_px = 0.5 * (size.height - 1);
    return StereoCameraModel(c);
  }();
  size_t surface = 0, surface_found = 0, before = 0, before_occupied = 0;
  for (int attempt = 0; attempt < 30; ++attempt, ros::WallDuration(0.3).sleep()) {
    GetOctomap get;
    ASSERT_TRUE(ros::service::call("/octomap_full", get));
    const std::unique_ptr<octomap::OcTree> got = treeFromMsg(get.response.map);
    ASSERT_TRUE(got);
    const octomap::OcTree& map = *got;
    // The true surfaces, every 4th pixel: occupied within one cell; the
    // points halfway to them: not occupied.
    surface = surface_found = before = before_occupied = 0;
    for (int y = 0; y < size.height; y += 4)
      for (int x = 0; x < size.width; x += 4) {
        const double d = static_cast<double>(truth.at<uchar>(y, x)) / kShrink;
        if (d <= 0.0) continue;
        const Eigen::Vector3d W_p = T_W_C * camera.pointFromDisparity(x, y, d);
        ++surface;
        bool found = false;
        for (int dz = -1; dz <= 1 && !found; ++dz)
          for (int dy = -1; dy <= 1 && !found; ++dy)
            for (int dx = -1; dx <= 1 && !found; ++dx) {
              const octomap::OcTreeNode* n = map.search(W_p.x() + 0.1 * dx, W_p.y() + 0.1 * dy, W_p.z() + 0.1 * dz);
              found = n && map.isNodeOccupied(n);
            }
        surface_found += found;
        const Eigen::Vector3d W_half = 0.5 * (T_W_C.translation() + W_p);
        const octomap::OcTreeNode* n = map.search(W_half.x(), W_half.y(), W_half.z());
        before += n != nullptr;
        before_occupied += n && map.isNodeOccupied(n);
      }
    if (surface > 0 && surface_found > 0.6 * surface) break;
  }
  ASSERT_GT(surface, 1000u);
  std::printf(
      "[          ] true surface points found occupied: %zu of %zu; halfway points occupied: %zu of %zu "
      "observed\n",
      surface_found, surface, before_occupied, before);
  EXPECT_GT(static_cast<double>(surface_found), 0.6 * static_cast<double>(surface));
  EXPECT_GT(static_cast<double>(before), 0.5 * static_cast<double>(surface));  // the space before was observed
  EXPECT_LT(static_cast<double>(before_occupied), 0.05 * static_cast<double>(before));
}
