#pragma once
/// @file
/// The counters of the paper's Table I.

#include <cstdint>

namespace stereo_occupancy {

/// Work done to draw one disparity image, with the meaning of Table I.
struct DrawStatistics {
  /// Pixel -> grid or grid -> pixel coordinate calculations: one per line
  /// (plus the camera centre) for line drawing; one per grid cell of the
  /// frustum's box (plus the camera centre and the four image corners) for
  /// ray tracing.
  uint64_t coordinate_transfers = 0;
  /// Reads of depth image or pyramid pixels.
  uint64_t used_image_pixels = 0;
  /// Occupancy values computed and written to a cell (a cell may be written many times).
  uint64_t grid_cells_drawn = 0;
  /// Cells holding a value at the end (before blurring); counted only when
  /// DrawingConfig::count_different_cells is set, 0 otherwise.
  uint64_t different_grid_cells = 0;
};

}  // namespace stereo_occupancy
