#pragma once
/// @file
/// Line drawing (Andert 2009, section V-A) and pyramidal line drawing
/// (section VI-B): each valid pixel's ray is traversed through the grid and
/// every cell on it gets L̂(s(l)) (eq. 11), keeping the larger value where lines
/// overlap (obstacle priority).

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "stereo_occupancy/disparity_pyramid.h"
#include "stereo_occupancy/draw_statistics.h"
#include "stereo_occupancy/inverse_sensor_model.h"
#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

/// Draws disparity images into a LocalGrid by line drawing. Holds references
/// to the camera, the lookup tables and the grid; not thread-safe.
class LineDrawer {
 public:
  LineDrawer(const StereoCameraModel& camera, const LogOddsTable& table, const PyramidLevelTable& levels);

  /// Section V-A: one line per valid pixel of a CV_32FC1 disparity image.
  void drawImage(const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                 DrawStatistics* stats) const;

  /// Section VI-B: recursive descent through a min-disparity pyramid (eq. 14)
  /// from its top level; a pixel is drawn at level i when its disparity's
  /// level (eq. 13) is >= i, or when i is the lowest level (eq. 15 below 0).
  void drawPyramid(const DisparityPyramid& min_pyramid, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                   DrawStatistics* stats) const;

  /// Draws the ray from the camera centre along the unit direction W_dir with
  /// the profile of one measurement, up to min(profile end, max range).
  /// Returns the number of cells written; parts of the ray outside the grid
  /// are skipped.
  uint64_t drawRay(const Eigen::Vector3d& W_origin, const Eigen::Vector3d& W_dir, const RangeProfile& profile,
                   LocalGrid* grid) const;

 private:
  /// Draws the line of pixel (x, y) at pyramid level i with disparity d.
  uint64_t drawPixel(int level, int x, int y, float d_px, const Eigen::Isometry3d& T_W_C, LocalGrid* grid) const;
  void descend(const DisparityPyramid& pyramid, int level, int x, int y, const Eigen::Isometry3d& T_W_C,
               LocalGrid* grid, DrawStatistics* stats) const;

  const StereoCameraModel& camera_;
  const LogOddsTable& table_;
  const PyramidLevelTable& levels_;
};

}  // namespace stereo_occupancy
