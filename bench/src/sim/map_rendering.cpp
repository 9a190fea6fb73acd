#include "stereo_occupancy/sim/map_rendering.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

namespace stereo_occupancy {

cv::Vec3b heightColour(double z, double z_min, double z_max) {
  const double t = z_max > z_min ? std::clamp((z - z_min) / (z_max - z_min), 0.0, 1.0) : 0.5;
  const double h = (1.0 - t) * 4.0;  // hue sectors from red (0) to blue (4)
  const int sector = std::min(static_cast<int>(h), 3);
  const double f = h - sector;
  double r = 0, g = 0, b = 0;
  switch (sector) {
    case 0:
      r = 1;
      g = f;
      break;
    case 1:
      r = 1 - f;
      g = 1;
      break;
    case 2:
      g = 1;
      b = f;
      break;
    default:
      g = 1 - f;
      b = 1;
      break;
  }
  return cv::Vec3b(static_cast<uchar>(255 * b), static_cast<uchar>(255 * g), static_cast<uchar>(255 * r));
}

namespace {

const cv::Scalar kBackground(40, 40, 40);
const cv::Scalar kInk(230, 230, 230);
constexpr int kPlotMargin = 10;  ///< empty pixels around the cells
constexpr int kAxisLeft = 60;    ///< room for the vertical axis' labels [px]
constexpr int kAxisBottom = 40;  ///< room for the horizontal axis' labels [px]
constexpr int kBarWidth = 16;    ///< the colour bar [px]
constexpr int kBarRoom = 90;     ///< the colour bar and its labels [px]
constexpr double kMinTickPx = 60.0;
constexpr double kFontScale = 0.4;

/// The occupied leaves' bounding box.
struct Extent {
  double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
};

Extent occupiedExtent(const octomap::OcTree& map) {
  Extent e;
  bool any = false;
  for (auto it = map.begin_leafs(), end = map.end_leafs(); it != end; ++it) {
    if (!map.isNodeOccupied(*it)) continue;
    const double half = 0.5 * it.getSize();
    const double c[3] = {it.getX(), it.getY(), it.getZ()};
    for (int a = 0; a < 3; ++a) {
      e.lo[a] = any ? std::min(e.lo[a], c[a] - half) : c[a] - half;
      e.hi[a] = any ? std::max(e.hi[a], c[a] + half) : c[a] + half;
    }
    any = true;
  }
  return e;
}

/// Ticks 1, 2 or 5 times a power of ten metres apart, at least kMinTickPx.
double tickStep(double pixels_per_m) {
  const double min_m = kMinTickPx / pixels_per_m;
  const double decade = std::pow(10.0, std::floor(std::log10(min_m)));
  for (double f : {1.0, 2.0, 5.0, 10.0})
    if (f * decade >= min_m) return f * decade;
  return 10.0 * decade;
}

std::string metres(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", std::abs(v) < 1e-9 ? 0.0 : v);
  return text;
}

/// @p plot (its cell area starting at kPlotMargin, metres u0 and v0 at its
/// lower left) in a frame with metre axes named @p u_name and @p v_name, and
/// a colour bar of the heights [z0, z1].
cv::Mat framed(const cv::Mat& plot, double u0_m, double v0_m, double pixels_per_m, const char* u_name,
               const char* v_name, double z0, double z1) {
  cv::Mat out(plot.rows + kAxisBottom + kPlotMargin, plot.cols + kAxisLeft + kBarRoom, CV_8UC3, kBackground);
  plot.copyTo(out(cv::Rect(kAxisLeft, kPlotMargin, plot.cols, plot.rows)));
  const int left = kAxisLeft, bottom = kPlotMargin + plot.rows;
  cv::rectangle(out, cv::Rect(left, kPlotMargin, plot.cols, plot.rows), kInk, 1);
  const double step = tickStep(pixels_per_m);
  auto uPx = [&](double u_m) {
    return left + kPlotMargin + static_cast<int>(std::lround((u_m - u0_m) * pixels_per_m));
  };
  auto vPx = [&](double v_m) {
    return bottom - 1 - kPlotMargin - static_cast<int>(std::lround((v_m - v0_m) * pixels_per_m));
  };
  const double u_end = u0_m + (plot.cols - 2 * kPlotMargin) / pixels_per_m;
  const double v_end = v0_m + (plot.rows - 2 * kPlotMargin) / pixels_per_m;
  for (double u = std::ceil(u0_m / step) * step; u <= u_end + 1e-9; u += step) {
    cv::line(out, {uPx(u), bottom}, {uPx(u), bottom + 5}, kInk);
    cv::putText(out, metres(u), {uPx(u) - 8, bottom + 18}, cv::FONT_HERSHEY_SIMPLEX, kFontScale, kInk);
  }
  for (double v = std::ceil(v0_m / step) * step; v <= v_end + 1e-9; v += step) {
    cv::line(out, {left - 5, vPx(v)}, {left, vPx(v)}, kInk);
    cv::putText(out, metres(v), {4, vPx(v) + 4}, cv::FONT_HERSHEY_SIMPLEX, kFontScale, kInk);
  }
  cv::putText(out, std::string(u_name) + " [m]", {left + plot.cols / 2 - 20, bottom + 34}, cv::FONT_HERSHEY_SIMPLEX,
              kFontScale, kInk);
  cv::putText(out, std::string(v_name) + " [m]", {4, kPlotMargin - 1 > 8 ? kPlotMargin - 1 : 9},
              cv::FONT_HERSHEY_SIMPLEX, kFontScale, kInk);
  // The colour bar: height from z0 (bottom) to z1 (top).
  const int bar_x = left + plot.cols + 12;
  for (int v = 0; v < plot.rows; ++v) {
    const double z = z1 - (z1 - z0) * v / std::max(1, plot.rows - 1);
    const cv::Vec3b c = heightColour(z, z0, z1);
    cv::line(out, {bar_x, kPlotMargin + v}, {bar_x + kBarWidth - 1, kPlotMargin + v}, cv::Scalar(c[0], c[1], c[2]));
  }
  cv::putText(out, metres(std::round(z1 * 10.0) / 10.0) + " m", {bar_x + kBarWidth + 4, kPlotMargin + 10},
              cv::FONT_HERSHEY_SIMPLEX, kFontScale, kInk);
  cv::putText(out, metres(std::round(z0 * 10.0) / 10.0) + " m", {bar_x + kBarWidth + 4, bottom - 2},
              cv::FONT_HERSHEY_SIMPLEX, kFontScale, kInk);
  cv::putText(out, "height", {bar_x - 4, bottom + 18}, cv::FONT_HERSHEY_SIMPLEX, kFontScale, kInk);
  return out;
}

}  // namespace

void renderMapViews(const octomap::OcTree& map, double pixels_per_m, cv::Mat* top, cv::Mat* side) {
  const Extent e = occupiedExtent(map);
  const double x0 = e.lo[0], y0 = e.lo[1], z0 = e.lo[2];
  const int margin = kPlotMargin;
  const int w = static_cast<int>(std::ceil((e.hi[0] - x0) * pixels_per_m)) + 2 * margin;
  const int h_top = static_cast<int>(std::ceil((e.hi[1] - y0) * pixels_per_m)) + 2 * margin;
  const int h_side = static_cast<int>(std::ceil((e.hi[2] - z0) * pixels_per_m)) + 2 * margin;
  cv::Mat top_plot(h_top, w, CV_8UC3, kBackground), side_plot(h_side, w, CV_8UC3, kBackground);
  cv::Mat top_height(h_top, w, CV_64FC1, cv::Scalar(-std::numeric_limits<double>::infinity()));
  cv::Mat side_depth(h_side, w, CV_64FC1, cv::Scalar(std::numeric_limits<double>::infinity()));
  for (auto it = map.begin_leafs(), end = map.end_leafs(); it != end; ++it) {
    if (!map.isNodeOccupied(*it)) continue;
    const double half = 0.5 * it.getSize();
    const int u0 = margin + static_cast<int>((it.getX() - half - x0) * pixels_per_m);
    const int u1 = std::max(u0 + 1, margin + static_cast<int>((it.getX() + half - x0) * pixels_per_m));
    // Rows counted up from the plot's bottom: a cell from y to y + s fills
    // rows [h - margin - (y + s), h - margin - y), level with the axis' ticks.
    const int vt0 = h_top - (margin + static_cast<int>((it.getY() + half - y0) * pixels_per_m));
    const int vt1 = std::max(vt0 + 1, h_top - (margin + static_cast<int>((it.getY() - half - y0) * pixels_per_m)));
    const int vs0 = h_side - (margin + static_cast<int>((it.getZ() + half - z0) * pixels_per_m));
    const int vs1 = std::max(vs0 + 1, h_side - (margin + static_cast<int>((it.getZ() - half - z0) * pixels_per_m)));
    const cv::Vec3b colour = heightColour(it.getZ(), z0, e.hi[2]);
    for (int u = std::max(u0, 0); u < std::min(u1, w); ++u) {
      for (int v = std::max(vt0, 0); v < std::min(vt1, h_top); ++v) {
        if (it.getZ() > top_height.at<double>(v, u)) {
          top_height.at<double>(v, u) = it.getZ();
          top_plot.at<cv::Vec3b>(v, u) = colour;
        }
      }
      for (int v = std::max(vs0, 0); v < std::min(vs1, h_side); ++v) {
        if (it.getY() < side_depth.at<double>(v, u)) {  // the cell nearest a viewer at -y
          side_depth.at<double>(v, u) = it.getY();
          side_plot.at<cv::Vec3b>(v, u) = colour;
        }
      }
    }
  }
  *top = framed(top_plot, x0, y0, pixels_per_m, "x", "y", z0, e.hi[2]);
  *side = framed(side_plot, x0, z0, pixels_per_m, "x", "z", z0, e.hi[2]);
}

}  // namespace stereo_occupancy
