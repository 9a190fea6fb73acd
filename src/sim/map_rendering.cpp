#include "stereo_occupancy/sim/map_rendering.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stereo_occupancy {

cv::Vec3b heightColour(double z, double z_min, double z_max) {
  const double t = z_max > z_min ? std::clamp((z - z_min) / (z_max - z_min), 0.0, 1.0) : 0.5;
  const double h = (1.0 - t) * 4.0;  // hue sectors from red (0) to blue (4)
  const int sector = std::min(static_cast<int>(h), 3);
  const double f = h - sector;
  double r = 0, g = 0, b = 0;
  switch (sector) {
    case 0: r = 1; g = f; break;
    case 1: r = 1 - f; g = 1; break;
    case 2: g = 1; b = f; break;
    default: g = 1 - f; b = 1; break;
  }
  return cv::Vec3b(static_cast<uchar>(255 * b), static_cast<uchar>(255 * g), static_cast<uchar>(255 * r));
}

void renderMapViews(const octomap::OcTree& map, double pixels_per_m, cv::Mat* top, cv::Mat* side) {
  double x0 = 0, y0 = 0, z0 = 0, x1 = 1, y1 = 1, z1 = 1;
  bool any = false;
  for (auto it = map.begin_leafs(), end = map.end_leafs(); it != end; ++it) {
    if (!map.isNodeOccupied(*it)) continue;
    const double h = 0.5 * it.getSize();
    if (!any) {
      x0 = it.getX() - h, y0 = it.getY() - h, z0 = it.getZ() - h;
      x1 = it.getX() + h, y1 = it.getY() + h, z1 = it.getZ() + h;
      any = true;
    }
    x0 = std::min(x0, it.getX() - h), y0 = std::min(y0, it.getY() - h), z0 = std::min(z0, it.getZ() - h);
    x1 = std::max(x1, it.getX() + h), y1 = std::max(y1, it.getY() + h), z1 = std::max(z1, it.getZ() + h);
  }
  const int margin = 10;
  const int w = static_cast<int>(std::ceil((x1 - x0) * pixels_per_m)) + 2 * margin;
  const int h_top = static_cast<int>(std::ceil((y1 - y0) * pixels_per_m)) + 2 * margin;
  const int h_side = static_cast<int>(std::ceil((z1 - z0) * pixels_per_m)) + 2 * margin;
  const cv::Vec3b background(40, 40, 40);
  top->create(h_top, w, CV_8UC3);
  side->create(h_side, w, CV_8UC3);
  top->setTo(cv::Scalar(background[0], background[1], background[2]));
  side->setTo(cv::Scalar(background[0], background[1], background[2]));
  cv::Mat top_height(h_top, w, CV_64FC1, cv::Scalar(-std::numeric_limits<double>::infinity()));
  cv::Mat side_depth(h_side, w, CV_64FC1, cv::Scalar(std::numeric_limits<double>::infinity()));
  for (auto it = map.begin_leafs(), end = map.end_leafs(); it != end; ++it) {
    if (!map.isNodeOccupied(*it)) continue;
    const double half = 0.5 * it.getSize();
    const int u0 = margin + static_cast<int>((it.getX() - half - x0) * pixels_per_m);
    const int u1 = std::max(u0 + 1, margin + static_cast<int>((it.getX() + half - x0) * pixels_per_m));
    const int vt0 = h_top - 1 - (margin + static_cast<int>((it.getY() + half - y0) * pixels_per_m));
    const int vt1 = std::max(vt0 + 1, h_top - 1 - (margin + static_cast<int>((it.getY() - half - y0) * pixels_per_m)));
    const int vs0 = h_side - 1 - (margin + static_cast<int>((it.getZ() + half - z0) * pixels_per_m));
    const int vs1 = std::max(vs0 + 1, h_side - 1 - (margin + static_cast<int>((it.getZ() - half - z0) * pixels_per_m)));
    const cv::Vec3b colour = heightColour(it.getZ(), z0, z1);
    for (int u = std::max(u0, 0); u < std::min(u1, w); ++u) {
      for (int v = std::max(vt0, 0); v < std::min(vt1, h_top); ++v) {
        if (it.getZ() > top_height.at<double>(v, u)) {
          top_height.at<double>(v, u) = it.getZ();
          top->at<cv::Vec3b>(v, u) = colour;
        }
      }
      for (int v = std::max(vs0, 0); v < std::min(vs1, h_side); ++v) {
        if (it.getY() < side_depth.at<double>(v, u)) {  // the cell nearest a viewer at -y
          side_depth.at<double>(v, u) = it.getY();
          side->at<cv::Vec3b>(v, u) = colour;
        }
      }
    }
  }
}

}  // namespace stereo_occupancy
