#pragma once
/// @file
/// Ray tracing (Andert 2009, section V-B) and pyramidal ray tracing (section
/// VI-C): every cell of the frustum's bounding box is projected into the
/// image, the nearest measurement over its footprint gives l_p, and the cell
/// gets L̂(s(l)) (eq. 11) at its own distance l.

#include <Eigen/Geometry>

#include "stereo_occupancy/disparity_pyramid.h"
#include "stereo_occupancy/draw_statistics.h"
#include "stereo_occupancy/inverse_sensor_model.h"
#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

/// Draws disparity images into a LocalGrid by ray tracing; not thread-safe.
///
/// A cell is in view when its centre projects into the image, lies in front
/// of the camera and no farther than the maximum range. Cells whose footprint
/// holds no valid pixel, and cells behind the measurement's tail, are left
/// unknown.
class RayTracer {
 public:
  RayTracer(const StereoCameraModel& camera, const LogOddsTable& table, const PyramidLevelTable& levels);

  /// Section V-B: d̂ is the maximum over the bounding rectangle of the
  /// projections of the cell's 8 corners (step 2c), read from level 0 of a
  /// max-disparity pyramid (invalid pixels = -1).
  void drawImage(const DisparityPyramid& max_pyramid, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                 DrawStatistics* stats) const;

  /// Section VI-C: d̂ is the maximum of the 2x2 pixels around the projected
  /// centre at the level that fits the cell's depth (eq. 13 with d = bf/z),
  /// from a max-disparity pyramid (eq. 16).
  void drawPyramid(const DisparityPyramid& max_pyramid, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                   DrawStatistics* stats) const;

  /// Bounded pyramidal ray tracing (beyond the paper): d̂ is the maximum
  /// over the cell's footprint (the square of side c·f/z around the
  /// projected centre), read from the coarsest blocks that cover it and that
  /// @p bound calls faithful; a block mixing depths (an object's silhouette
  /// against its background or the sky) is replaced by its children inside
  /// the footprint. Objects are thus not enlarged to the paper's 2x2 window
  /// of level i pixels, which reaches up to twice the cell's footprint.
  void drawPyramidBounded(const DisparityPyramid& min_pyramid, const DisparityPyramid& max_pyramid,
                          const DisparityBlockBound& bound, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                          DrawStatistics* stats) const;

 private:
  template <typename Lookup>
  void traverse(const Eigen::Isometry3d& T_W_C, LocalGrid* grid, DrawStatistics* stats, Lookup&& lookup) const;

  const StereoCameraModel& camera_;
  const LogOddsTable& table_;
  const PyramidLevelTable& levels_;
};

}  // namespace stereo_occupancy
