#pragma once
/// @file
/// The compact form of one drawn local grid: what the mapper sends to the
/// accumulator (run-length encoded changed cells, log-odds as drawn).

#include <Eigen/Core>

#include <algorithm>
#include <cstdint>
#include <limits>
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

  /// Calls f(global_index, log_odds) for every cell, as forEachCell() does,
  /// but brick by brick: the cells of each 2x2x2 block at even global
  /// indices (the eight leaves of one octree node) one after another, in
  /// octree child order (x, then y, then z); the blocks in x, y, z order.
  /// A map updated in this order creates and visits sibling leaves together.
  /// Requires isConsistent().
  template <typename F>
  void forEachCellBySiblings(F&& f) const;

  /// The walk of forEachCellBySiblings() a block at a time: calls
  /// f(first_global_index, values) for every 2x2x2 block at even global
  /// indices that holds a cell, where values[i] is the value of the cell at
  /// first_global_index + (i & 1, (i >> 1) & 1, i >> 2) (octree child order),
  /// NaN where the update has no cell. Requires isConsistent().
  template <typename F>
  void forEachSiblingBlock(F&& f) const;
};

template <typename F>
void GridUpdate::forEachCellBySiblings(F&& f) const {
  forEachSiblingBlock([&](const Eigen::Vector3i& first, const float(&values)[8]) {
    for (int i = 0; i < 8; ++i)
      if (values[i] == values[i]) f(first + Eigen::Vector3i(i & 1, (i >> 1) & 1, i >> 2), values[i]);
  });
}

template <typename F>
void GridUpdate::forEachSiblingBlock(F&& f) const {
  const int nx = size.x(), ny = size.y(), nz = size.z();
  if (log_odds.empty()) return;
  // Each row's stretch of known cells, [x0, x1) with values from log_odds[v]
  // on; a run may go on into the next row.
  struct Segment {
    int x0, x1;
    size_t v;
  };
  std::vector<Segment> segments;
  std::vector<uint32_t> row_first(static_cast<size_t>(ny) * nz + 1, 0);  // segments of row r: [row_first[r], row_first[r+1])
  size_t v = 0;
  for (size_t k = 0; k < run_start.size(); ++k) {
    uint64_t i = run_start[k], left = run_length[k];
    while (left > 0) {
      const uint64_t r = i / nx;
      const int x0 = static_cast<int>(i % nx);
      const int len = static_cast<int>(std::min<uint64_t>(left, static_cast<uint64_t>(nx - x0)));
      segments.push_back({x0, x0 + len, v});
      ++row_first[r + 1];
      v += len;
      i += len;
      left -= len;
    }
  }
  for (size_t r = 1; r < row_first.size(); ++r) row_first[r] += row_first[r - 1];
  // Local index of the first brick along an axis: global index even.
  auto evenStart = [](int origin) { return (origin & 1) != 0 ? -1 : 0; };
  std::vector<float> rows[4];
  for (int z0 = evenStart(origin_index.z()); z0 < nz; z0 += 2) {
    for (int y0 = evenStart(origin_index.y()); y0 < ny; y0 += 2) {
      // The four rows of this strip of bricks, q = dy + 2 dz.
      uint32_t first[4], last[4];
      int x_min = nx, x_max = 0;
      for (int q = 0; q < 4; ++q) {
        const int y = y0 + (q & 1), z = z0 + (q >> 1);
        first[q] = last[q] = 0;
        if (y < 0 || y >= ny || z < 0 || z >= nz) continue;
        const size_t r = static_cast<size_t>(y) + static_cast<size_t>(ny) * z;
        first[q] = row_first[r];
        last[q] = row_first[r + 1];
        if (first[q] == last[q]) continue;
        x_min = std::min(x_min, segments[first[q]].x0);
        x_max = std::max(x_max, segments[last[q] - 1].x1);
      }
      if (x_min >= x_max) continue;
      const int xs = x_min - ((origin_index.x() + x_min) & 1);  // even global index
      const int width = x_max - xs;
      for (int q = 0; q < 4; ++q) {
        if (first[q] == last[q]) continue;
        // NaN: no cell (values are finite); one more than the width for the last block's second column.
        rows[q].assign(width + 1, std::numeric_limits<float>::quiet_NaN());
        for (uint32_t k = first[q]; k < last[q]; ++k)
          std::copy(log_odds.begin() + segments[k].v, log_odds.begin() + segments[k].v + (segments[k].x1 - segments[k].x0),
                    rows[q].begin() + (segments[k].x0 - xs));
      }
      for (int x0 = xs; x0 < x_max; x0 += 2) {
        float values[8];
        bool any = false;
        for (int q = 0; q < 4; ++q) {
          if (first[q] == last[q]) {
            values[2 * q] = values[2 * q + 1] = std::numeric_limits<float>::quiet_NaN();
            continue;
          }
          values[2 * q] = rows[q][x0 - xs];
          values[2 * q + 1] = rows[q][x0 + 1 - xs];
          any |= (values[2 * q] == values[2 * q]) | (values[2 * q + 1] == values[2 * q + 1]);
        }
        if (any) f(origin_index + Eigen::Vector3i(x0, y0, z0), values);
      }
    }
  }
}

/// Encodes the known (not LocalGrid::kUnknown) cells of @p grid with their
/// values; cells whose value is exactly 0 carry nothing and are left out.
void encodeGridUpdate(const LocalGrid& grid, const Eigen::Vector3d& W_sensor_origin, GridUpdate* update);

}  // namespace stereo_occupancy
