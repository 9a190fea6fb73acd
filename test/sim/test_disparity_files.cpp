#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>

#include "stereo_occupancy/sim/disparity_files.h"

using namespace stereo_occupancy;

namespace {
std::string tempPath(const std::string& name) { return ::testing::TempDir() + "stereo_occupancy_" + name; }
}  // namespace

TEST(DisparityIo, PfmRoundTripKeepsNanAndOrientation) {
  cv::Mat img(3, 4, CV_32FC1);
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x) img.at<float>(y, x) = static_cast<float>(10 * y + x) + 0.25f;
  img.at<float>(0, 1) = std::nanf("");
  img.at<float>(2, 3) = 0.0f;
  const std::string path = tempPath("roundtrip.pfm");
  writePfm(path, img);
  const cv::Mat back = readDisparity(path, 0.0);
  ASSERT_EQ(back.size(), img.size());
  EXPECT_TRUE(std::isnan(back.at<float>(0, 1)));
  EXPECT_EQ(back.at<float>(0, 0), 0.25f);  // top-left stays top-left
  EXPECT_EQ(back.at<float>(2, 0), 20.25f);
  EXPECT_EQ(back.at<float>(2, 3), 0.0f);
  std::remove(path.c_str());
}

TEST(DisparityIo, Png16WithScale) {
  cv::Mat raw(2, 3, CV_16UC1);
  raw.at<uint16_t>(0, 0) = 0;
  raw.at<uint16_t>(0, 1) = 336;  // 21 px at 1/16 px
  raw.at<uint16_t>(1, 2) = 65535;
  const std::string path = tempPath("disp16.png");
  ASSERT_TRUE(cv::imwrite(path, raw));
  const cv::Mat d = readDisparity(path, 16.0);
  EXPECT_EQ(d.type(), CV_32FC1);
  EXPECT_EQ(d.at<float>(0, 0), 0.0f);
  EXPECT_FLOAT_EQ(d.at<float>(0, 1), 21.0f);
  EXPECT_FLOAT_EQ(d.at<float>(1, 2), 65535.0f / 16.0f);
  EXPECT_THROW(readDisparity(path, 0.0), std::runtime_error);  // a PNG needs a scale
  std::remove(path.c_str());
}

TEST(DisparityIo, BadFilesThrow) {
  EXPECT_THROW(readPfm(tempPath("does_not_exist.pfm")), std::runtime_error);
  const std::string path = tempPath("bad.pfm");
  {
    std::ofstream out(path);
    out << "PF\n2 2\n-1\n";  // colour PFM: not supported
  }
  EXPECT_THROW(readPfm(path), std::runtime_error);
  {
    std::ofstream out(path);
    out << "Pf\n100 100\n-1\nshort";
  }
  EXPECT_THROW(readPfm(path), std::runtime_error);
  std::remove(path.c_str());
  EXPECT_THROW(readDisparity("image.jpg", 1.0), std::runtime_error);
}
