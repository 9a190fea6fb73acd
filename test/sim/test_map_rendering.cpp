// Map pictures (map_rendering.h): cells where the map has them, coloured by
// height, with metre axes and a colour bar.

#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <opencv2/imgproc.hpp>

#include <vector>

#include "stereo_occupancy/sim/map_rendering.h"

using namespace stereo_occupancy;

namespace {

// The frame around a plot: the plot's box starts 60 px from the left and
// 10 px from the top, its cells 10 px inside the box; 40 px below the box
// for the x axis, 90 px right of it for the colour bar.
constexpr int kLeft = 60, kTop = 10, kMargin = 10, kBelow = 40, kRight = 90;
const cv::Vec3b kBackground(40, 40, 40), kInk(230, 230, 230);

/// A rectangle of cells in plot pixels (x from the left, y from the top of the cells' area).
struct Cells {
  cv::Rect area;
  cv::Vec3b colour;
};

/// Pixels inside the plot's box (its border left out) that differ from
/// @p cells, drawn over the background.
int wrongPixels(const cv::Mat& view, int plot_cols, int plot_rows, const std::vector<Cells>& cells) {
  int wrong = 0;
  for (int y = kTop + 1; y < kTop + plot_rows - 1; ++y)
    for (int x = kLeft + 1; x < kLeft + plot_cols - 1; ++x) {
      cv::Vec3b expected = kBackground;
      for (const Cells& c : cells)
        if (c.area.contains(cv::Point(x - kLeft - kMargin, y - kTop - kMargin))) expected = c.colour;
      wrong += view.at<cv::Vec3b>(y, x) != expected;
    }
  return wrong;
}

/// Ink (axis colour) anywhere in @p area of @p view.
bool hasInk(const cv::Mat& view, const cv::Rect& area) {
  for (int y = area.y; y < area.y + area.height; ++y)
    for (int x = area.x; x < area.x + area.width; ++x)
      if (view.at<cv::Vec3b>(y, x) == kInk) return true;
  return false;
}

/// The metre axes of a view whose plot is @p plot_rows high: at 16 px/m the
/// ticks are 5 m apart; x ticks at 0, 5 and 10 m below the cells' first
/// column and every 80 px on, labelled; one y (or z) tick at 0 m, the cells'
/// lowest row, labelled.
void expectAxes(const cv::Mat& view, int plot_rows, const char* name) {
  SCOPED_TRACE(name);
  const int bottom = kTop + plot_rows;  // the first row below the plot's box
  for (int metres : {0, 5, 10}) {
    const int x = kLeft + kMargin + 16 * metres;
    for (int y = bottom; y < bottom + 6; ++y)
      EXPECT_EQ(view.at<cv::Vec3b>(y, x), kInk) << metres << " m tick, row " << y;
    for (int dx : {-3, 3}) EXPECT_EQ(view.at<cv::Vec3b>(bottom + 2, x + dx), kBackground) << metres << " m tick";
    EXPECT_TRUE(hasInk(view, cv::Rect(x - 8, bottom + 8, 20, 11))) << "no label under the " << metres << " m tick";
  }
  const int y0 = bottom - 1 - kMargin;  // the lowest row of cells
  for (int x = kLeft - 5; x < kLeft; ++x) EXPECT_EQ(view.at<cv::Vec3b>(y0, x), kInk) << "0 m tick, column " << x;
  for (int dy : {-3, 3}) EXPECT_EQ(view.at<cv::Vec3b>(y0 + dy, kLeft - 3), kBackground) << "0 m tick";
  EXPECT_TRUE(hasInk(view, cv::Rect(4, y0 - 6, 20, 12))) << "no label at the 0 m tick";
}

}  // namespace

TEST(MapRendering, ViewsHaveTheCellsAxesAndAColourBar) {
  octomap::OcTree map(0.25);
  for (float x = 0.125f; x < 10.0f; x += 0.25f) map.updateNode(octomap::point3d(x, 0.125f, 0.125f), true);  // a rail
  map.updateNode(octomap::point3d(5.125f, 0.125f, 4.125f), true);   // a post top
  map.updateNode(octomap::point3d(5.125f, 3.125f, 0.125f), false);  // free: not drawn
  cv::Mat top, side;
  const double ppm = 16.0;
  renderMapViews(map, ppm, &top, &side);
  ASSERT_EQ(top.type(), CV_8UC3);
  ASSERT_EQ(side.type(), CV_8UC3);
  // The cells span x 0..10 m, y 0..0.25 m, z 0..4.25 m: plots of 160 x 4 and
  // 160 x 68 px of cells with 10 px margins, each in its frame.
  const int plot_cols = 160 + 2 * kMargin, top_rows = 4 + 2 * kMargin, side_rows = 68 + 2 * kMargin;
  ASSERT_EQ(top.size(), cv::Size(kLeft + plot_cols + kRight, kTop + top_rows + kBelow));
  ASSERT_EQ(side.size(), cv::Size(kLeft + plot_cols + kRight, kTop + side_rows + kBelow));
  const cv::Vec3b rail = heightColour(0.125, 0.0, 4.25), post = heightColour(4.125, 0.0, 4.25);
  // Top view: the rail's row, 16 px per metre, in the rail's colour but at
  // x 5..5.25 m, where the post's top is the highest cell; nothing else (the
  // free cell is not drawn).
  EXPECT_EQ(wrongPixels(top, plot_cols, top_rows, {{cv::Rect(0, 0, 160, 4), rail}, {cv::Rect(80, 0, 4, 4), post}}), 0);
  // Side view (z up): the rail along the bottom, the post's top 4 m above it.
  EXPECT_EQ(wrongPixels(side, plot_cols, side_rows, {{cv::Rect(0, 64, 160, 4), rail}, {cv::Rect(80, 0, 4, 4), post}}),
            0);
  expectAxes(top, top_rows, "top view");
  expectAxes(side, side_rows, "side view");
  // The colour bar's top is the highest cell's colour (red), its bottom the lowest's (blue).
  const cv::Vec3b high = heightColour(4.25, 0.0, 4.25), low = heightColour(0.0, 0.0, 4.25);
  bool found_high = false, found_low = false;
  for (int x = side.cols - kRight; x < side.cols; ++x) {
    found_high |= side.at<cv::Vec3b>(kTop, x) == high;  // the bar starts below the 10 px margin
    found_low |= side.at<cv::Vec3b>(kTop + side_rows - 1, x) == low;
  }
  EXPECT_TRUE(found_high && found_low) << "no colour bar from blue (low) to red (high)";
}
