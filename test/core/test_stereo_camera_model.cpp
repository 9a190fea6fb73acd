#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

#include "stereo_occupancy/stereo_camera_model.h"

using stereo_occupancy::StereoCameraConfig;
using stereo_occupancy::StereoCameraModel;

namespace {
StereoCameraConfig paperCamera() {
  StereoCameraConfig c;  // b = 0.3 m, f = 700 px, Δd = 0.5 px, 640x480
  return c;
}
}  // namespace

TEST(StereoCameraModel, DepthFromDisparityEq1) {
  StereoCameraModel cam(paperCamera());
  EXPECT_DOUBLE_EQ(cam.bf(), 210.0);
  EXPECT_DOUBLE_EQ(cam.depthFromDisparity(21.0), 10.0);
  EXPECT_DOUBLE_EQ(cam.disparityFromDepth(25.0), 8.4);
  EXPECT_TRUE(std::isinf(cam.depthFromDisparity(0.0)));
}

TEST(StereoCameraModel, PointInOpticalFrameEq2) {
  StereoCameraModel cam(paperCamera());
  // 70 px right of and 35 px above the principal point at 10 m depth.
  const Eigen::Vector3d p = cam.pointFromDisparity(319.5 + 70.0, 239.5 - 35.0, 21.0);
  EXPECT_NEAR(p.x(), 1.0, 1e-12);
  EXPECT_NEAR(p.y(), -0.5, 1e-12);  // y down: above the centre is negative
  EXPECT_NEAR(p.z(), 10.0, 1e-12);
  EXPECT_NEAR(StereoCameraModel::range(p), std::sqrt(1.0 + 0.25 + 100.0), 1e-12);  // eq. 6
}

TEST(StereoCameraModel, UncertaintiesEq4Eq5Eq7) {
  StereoCameraModel cam(paperCamera());
  EXPECT_NEAR(cam.depthUncertainty(10.0), 100.0 * 0.5 / 210.0, 1e-12);  // 0.238 m
  EXPECT_NEAR(cam.depthUncertainty(10.0), 0.2381, 1e-4);
  EXPECT_NEAR(cam.lateralUncertainty(10.0), 10.0 / 1400.0, 1e-12);
  // Off the axis the range uncertainty grows with l/z.
  EXPECT_NEAR(cam.rangeUncertainty(10.0, 12.0), cam.depthUncertainty(10.0) * 1.2, 1e-12);
}

TEST(StereoCameraModel, DisparityValidity) {
  StereoCameraConfig cfg = paperCamera();
  cfg.min_range_m = 1.0;  // near disparity 210 px
  StereoCameraModel cam(cfg);
  EXPECT_TRUE(cam.isValidDisparity(0.0f));  // infinitely far
  EXPECT_TRUE(cam.isValidDisparity(21.0f));
  EXPECT_TRUE(cam.isValidDisparity(210.0f));
  EXPECT_FALSE(cam.isValidDisparity(210.5f));  // nearer than the minimum range
  EXPECT_FALSE(cam.isValidDisparity(-1.0f));
  EXPECT_FALSE(cam.isValidDisparity(std::nanf("")));
  EXPECT_FALSE(cam.isValidDisparity(INFINITY));
  cfg.min_disparity_px = 4.0;
  cfg.max_disparity_px = 64.0;
  StereoCameraModel matcher(cfg);
  EXPECT_TRUE(matcher.isValidDisparity(0.0f));
  EXPECT_FALSE(matcher.isValidDisparity(3.9f));
  EXPECT_TRUE(matcher.isValidDisparity(4.0f));
  EXPECT_FALSE(matcher.isValidDisparity(64.5f));
  EXPECT_DOUBLE_EQ(matcher.nearDisparity(), 64.0);
}

TEST(StereoCameraModel, ConfigValidation) {
  StereoCameraConfig cfg = paperCamera();
  EXPECT_TRUE(cfg.isValid());
  std::string why;
  cfg.focal_length_px = 0.0;
  EXPECT_FALSE(cfg.isValid(&why));
  EXPECT_NE(why.find("focal_length_px"), std::string::npos);
  cfg = paperCamera();
  cfg.baseline_m = std::nan("");
  EXPECT_FALSE(cfg.isValid());
  cfg = paperCamera();
  cfg.max_range_m = 0.2;  // below the minimum range
  EXPECT_FALSE(cfg.isValid());
  cfg = paperCamera();
  cfg.delta_d_px = -0.5;
  EXPECT_FALSE(cfg.isValid());
  // A principal point at most the image's size outside the image.
  for (double cx : {-cfg.width_px - 1.0, 2.0 * cfg.width_px + 1.0, 1e12}) {
    cfg = paperCamera();
    cfg.cx_px = cx;
    EXPECT_FALSE(cfg.isValid(&why)) << cx;
    EXPECT_NE(why.find("principal point"), std::string::npos) << why;
  }
  cfg = paperCamera();
  cfg.cy_px = -1e12;
  EXPECT_FALSE(cfg.isValid());
  cfg.cy_px = -10.0;
  cfg.cx_px = cfg.width_px + 10.0;
  EXPECT_TRUE(cfg.isValid(&why)) << why;
}

// Eq. 1 backwards for a depth camera: d = bf / z from millimetres (16UC1) or
// metres (32FC1); no depth (0, NaN, inf, negative) becomes an invalid pixel.
TEST(StereoCameraModel, DepthImageToDisparityEq1) {
  const double bf = 0.3 * 700.0;  // b = 0.3 m, f = 700 px
  cv::Mat mm(1, 3, CV_16UC1);
  mm.at<uint16_t>(0, 0) = 10500;  // 10.5 m
  mm.at<uint16_t>(0, 1) = 0;
  mm.at<uint16_t>(0, 2) = 2000;
  cv::Mat d;
  stereo_occupancy::depthToDisparity(mm, bf, &d);
  ASSERT_EQ(d.type(), CV_32FC1);
  EXPECT_FLOAT_EQ(d.at<float>(0, 0), 20.0f);
  EXPECT_TRUE(std::isnan(d.at<float>(0, 1)));
  EXPECT_FLOAT_EQ(d.at<float>(0, 2), 105.0f);
  cv::Mat m(1, 4, CV_32FC1);
  m.at<float>(0, 0) = 21.0f;
  m.at<float>(0, 1) = std::numeric_limits<float>::quiet_NaN();
  m.at<float>(0, 2) = std::numeric_limits<float>::infinity();
  m.at<float>(0, 3) = -1.0f;
  stereo_occupancy::depthToDisparity(m, bf, &d);
  EXPECT_FLOAT_EQ(d.at<float>(0, 0), 10.0f);
  for (int x = 1; x < 4; ++x) EXPECT_TRUE(std::isnan(d.at<float>(0, x))) << x;
  EXPECT_THROW(stereo_occupancy::depthToDisparity(cv::Mat(1, 1, CV_8UC1), bf, &d), std::invalid_argument);
}

// The census of an image's pixels: what an image that maps nothing holds.
TEST(StereoCameraModel, CensusCountsWhatThePixelsHold) {
  StereoCameraConfig cfg;  // b = 0.3 m, f = 700 px: far disparity 210 / 25 = 8.4 px
  cfg.min_disparity_px = 1.0;
  cfg.max_disparity_px = 64.0;
  const StereoCameraModel camera(cfg);
  cv::Mat d(1, 7, CV_32FC1);
  const float values[7] = {std::numeric_limits<float>::quiet_NaN(), -1.0f, 0.0f, 0.5f, 4.0f, 20.0f, 100.0f};
  for (int x = 0; x < 7; ++x) d.at<float>(0, x) = values[x];
  const stereo_occupancy::DisparityCensus c = camera.census(d);
  EXPECT_EQ(c.no_match, 2u);      // NaN, -1
  EXPECT_EQ(c.sky, 1u);           // 0
  EXPECT_EQ(c.out_of_range, 2u);  // 0.5 below the search range, 100 above it
  EXPECT_EQ(c.beyond_range, 1u);  // 4 px: 52 m
  EXPECT_EQ(c.measured, 1u);      // 20 px: 10.5 m
  EXPECT_EQ(c.total(), 7u);
}
