#pragma once
/// @file
/// Pictures of a map: top and side views of the occupied cells, coloured by height.

#include <octomap/OcTree.h>
#include <opencv2/core.hpp>

namespace stereo_occupancy {

/// Colour (BGR) of height z on a blue (z_min) to red (z_max) scale.
cv::Vec3b heightColour(double z, double z_min, double z_max);

/// Top view (x right, y up) and side view (x right, z up) of the occupied
/// leaves, @p pixels_per_m, each pixel coloured by the highest occupied cell
/// above it (top) or by the height of the nearest cell (side, seen from -y);
/// framed with metre axes and a colour bar of the heights.
void renderMapViews(const octomap::OcTree& map, double pixels_per_m, cv::Mat* top, cv::Mat* side);

}  // namespace stereo_occupancy
