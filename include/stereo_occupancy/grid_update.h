#pragma once
/// @file
/// The compact form of one drawn local grid: what the mapper sends to the
/// accumulator (run-length encoded changed cells, log-odds as drawn).

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

#include "stereo_occupancy/local_grid.h"

namespace stereo_occupancy {

/// The known cells of a LocalGrid, run-length encoded over the grid's linear
/// index i = x + nx·(y + ny·z): run k covers i = run_start[k] ..
/// run_start[k] + run_length[k] - 1 and takes the next run_length[k] values
/// of log_odds. Mirrors msg/OccupancyUpdate.msg.
struct GridUpdate {
  Eigen::Vector3d W_sensor_origin = Eigen::Vector3d::Zero();  ///< camera centre in W [m]
  double resolution_m = 0.0;                                  ///< cell edge [m]
  Eigen::Vector3i origin_index = Eigen::Vector3i::Zero();     ///< global index of local cell (0, 0, 0)
  Eigen::Vector3i size = Eigen::Vector3i::Zero();             ///< cells along x, y, z
  std::vector<uint32_t> run_start;
  std::vector<uint32_t> run_length;
  std::vector<float> log_odds;

  /// Number of cells carried (the sum of the run lengths).
  size_t numCells() const { return log_odds.size(); }

  /// True if sizes, runs and values fit together and every value is finite;
  /// otherwise @p why says what does not.
  bool isConsistent(std::string* why = nullptr) const;

  /// Calls f(global_index, log_odds) for every cell; requires isConsistent().
  template <typename F>
  void forEachCell(F&& f) const {
    const int64_t nx = size.x(), nxy = static_cast<int64_t>(size.x()) * size.y();
    size_t v = 0;
    for (size_t k = 0; k < run_start.size(); ++k) {
      // Divide once per run, then step through the storage order.
      const int64_t z = run_start[k] / nxy, rest = run_start[k] % nxy;
      Eigen::Vector3i local(static_cast<int>(rest % nx), static_cast<int>(rest / nx), static_cast<int>(z));
      for (uint32_t i = 0; i < run_length[k]; ++i, ++v) {
        f(origin_index + local, log_odds[v]);
        if (++local.x() == size.x()) {
          local.x() = 0;
          if (++local.y() == size.y()) {
            local.y() = 0;
            ++local.z();
          }
        }
      }
    }
  }
};

/// Encodes the known (not LocalGrid::kUnknown) cells of @p grid with their
/// values; cells whose value is exactly 0 carry nothing and are left out.
void encodeGridUpdate(const LocalGrid& grid, const Eigen::Vector3d& W_sensor_origin, GridUpdate* update);

}  // namespace stereo_occupancy
