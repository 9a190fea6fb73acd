#pragma once
// Timing of one drawing algorithm on one image, shared by the benchmarks
// (table1, scaling, performance).

#include <algorithm>
#include <chrono>
#include <vector>

#include "stereo_occupancy/disparity_drawer.h"

namespace stereo_occupancy {
namespace tools {

/// The default drawing configuration with @p algorithm at @p resolution_m,
/// on @p threads threads (benchmarks: one unless told).
inline DrawingConfig drawingConfig(DrawingAlgorithm algorithm, double resolution_m, int threads = 1) {
  DrawingConfig config;
  config.algorithm = algorithm;
  config.resolution_m = resolution_m;
  config.threads = threads;
  return config;
}

/// Draws @p image @p repeats times into @p grid and returns the times [ms],
/// sorted; @p stats holds the last run's counters. With
/// @p time_grid_preparation the shaping and clearing of the grid is timed too.
inline std::vector<double> timeDrawing(DisparityDrawer* drawer, const cv::Mat& image, const Eigen::Isometry3d& T_W_C,
                                       int repeats, bool time_grid_preparation, LocalGrid* grid,
                                       DrawStatistics* stats) {
  std::vector<double> ms;
  for (int r = 0; r < repeats; ++r) {
    auto t0 = std::chrono::steady_clock::now();
    drawer->prepareGrid(T_W_C, grid);
    if (!time_grid_preparation) t0 = std::chrono::steady_clock::now();
    *stats = drawer->drawInto(image, T_W_C, grid);
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ms.begin(), ms.end());
  return ms;
}

}  // namespace tools
}  // namespace stereo_occupancy
