// The input messages to the core's types (no roscore needed).

#include <gtest/gtest.h>

#include <cmath>

#include "stereo_occupancy/ros/input_conversions.h"

using namespace stereo_occupancy;

TEST(Conversions, CameraFromDisparityImage) {
  stereo_msgs::DisparityImage msg;
  msg.image.width = 640;
  msg.image.height = 480;
  msg.f = 700.0f;
  msg.T = 0.3f;
  msg.min_disparity = 0.0f;
  msg.max_disparity = 128.0f;
  msg.delta_d = 0.0625f;
  DisparityMapperParameters params;
  StereoCameraConfig cam;
  std::string why;
  ASSERT_TRUE(cameraFromDisparityImage(msg, nullptr, params, &cam, &why)) << why;
  EXPECT_DOUBLE_EQ(cam.focal_length_px, 700.0);
  EXPECT_NEAR(cam.baseline_m, 0.3, 1e-7);
  EXPECT_DOUBLE_EQ(cam.cx_px, 319.5);
  EXPECT_DOUBLE_EQ(cam.max_disparity_px, 128.0);
  EXPECT_DOUBLE_EQ(cam.delta_d_px, 0.5);  // the parameter: at least the message's 1/16 px
  sensor_msgs::CameraInfo info;
  info.width = 640;
  info.height = 480;
  info.P[0] = 700.0;
  info.P[2] = 330.0;
  info.P[6] = 250.0;
  ASSERT_TRUE(cameraFromDisparityImage(msg, &info, params, &cam, &why));
  EXPECT_DOUBLE_EQ(cam.cx_px, 330.0);
  EXPECT_DOUBLE_EQ(cam.cy_px, 250.0);
  for (float bad_f : {0.0f, -700.0f, std::nanf(""), INFINITY}) {
    msg.f = bad_f;
    EXPECT_FALSE(cameraFromDisparityImage(msg, nullptr, params, &cam, &why)) << bad_f;
  }
  msg.f = 700.0f;
  msg.T = -0.3f;
  EXPECT_FALSE(cameraFromDisparityImage(msg, nullptr, params, &cam, &why));
  // A camera_info whose principal point is 10^12 px away: refused with the reason.
  msg.T = 0.3f;
  info.P[2] = 1e12;
  EXPECT_FALSE(cameraFromDisparityImage(msg, &info, params, &cam, &why));
  EXPECT_NE(why.find("principal point"), std::string::npos) << why;
  info.P[2] = -100.0;  // a little outside the image, as rectification may put it: taken
  EXPECT_TRUE(cameraFromDisparityImage(msg, &info, params, &cam, &why)) << why;
}

TEST(Conversions, PoseFromTransform) {
  geometry_msgs::TransformStamped t;
  t.transform.translation.x = 1.0;
  t.transform.rotation.w = 1.0;
  Eigen::Isometry3d T;
  ASSERT_TRUE(poseFromTransform(t, &T));
  EXPECT_EQ(T.translation(), Eigen::Vector3d(1, 0, 0));
  t.transform.rotation.w = 2.0;  // not a unit quaternion
  EXPECT_FALSE(poseFromTransform(t, &T));
  t.transform.rotation.w = 1.0;
  t.transform.translation.y = std::nan("");
  EXPECT_FALSE(poseFromTransform(t, &T));
}
