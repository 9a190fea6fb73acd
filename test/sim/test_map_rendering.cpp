// Map pictures (map_rendering.h): cells where the map has them, coloured by
// height, with metre axes and a colour bar.

#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <opencv2/imgproc.hpp>

#include "stereo_occupancy/sim/map_rendering.h"

using namespace stereo_occupancy;

TEST(MapRendering, ViewsHaveTheCellsAxesAndAColourBar) {
  octomap::OcTree map(0.25);
  for (float x = 0.125f; x < 10.0f; x += 0.25f) map.updateNode(octomap::point3d(x, 0.125f, 0.125f), true);  // a rail
  map.updateNode(octomap::point3d(5.125f, 0.125f, 4.125f), true);                                           // a post top
  map.updateNode(octomap::point3d(5.125f, 3.125f, 0.125f), false);                                          // free: not drawn
  cv::Mat top, side;
  const double ppm = 16.0;
  renderMapViews(map, ppm, &top, &side);
  ASSERT_EQ(top.type(), CV_8UC3);
  // The plot (10 m x 0.25 m of cells, 10 px margins) sits in a frame: wider and taller than its cells.
  EXPECT_GT(top.cols, static_cast<int>(10.0 * ppm) + 20 + 100);
  EXPECT_GT(side.rows, static_cast<int>(4.25 * ppm) + 20 + 30);
  // Count what is not background: cells, axes, labels, the colour bar.
  auto drawn = [](const cv::Mat& image, const cv::Rect& area) {
    cv::Mat grey;
    cv::cvtColor(image(area), grey, cv::COLOR_BGR2GRAY);
    return cv::countNonZero(cv::abs(grey - 40) > 10);
  };
  const int bottom_axis = drawn(side, cv::Rect(0, side.rows - 40, side.cols, 40));
  const int left_axis = drawn(side, cv::Rect(0, 0, 55, side.rows - 40));
  EXPECT_GT(bottom_axis, 100) << "no tick labels along x";
  EXPECT_GT(left_axis, 50) << "no tick labels along z";
  // The colour bar's top is the highest cell's colour (red), its bottom the lowest's (blue).
  const cv::Vec3b high = heightColour(4.25, 0.0, 4.25), low = heightColour(0.0, 0.0, 4.25);
  bool found_high = false, found_low = false;
  for (int x = side.cols - 90; x < side.cols; ++x) {
    found_high |= side.at<cv::Vec3b>(10, x) == high;  // the bar starts below the 10 px margin
    found_low |= side.at<cv::Vec3b>(side.rows - 41, x) == low;
  }
  EXPECT_TRUE(found_high && found_low) << "no colour bar from blue (low) to red (high)";
  // The post top's colour appears in the side view (it is the highest cell).
  bool post = false;
  for (int y = 0; y < side.rows && !post; ++y)
    for (int x = 0; x < side.cols - 90 && !post; ++x) post = side.at<cv::Vec3b>(y, x) == heightColour(4.125, 0.0, 4.25);
  EXPECT_TRUE(post);
}
