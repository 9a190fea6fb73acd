#pragma once
/// @file
/// The compact form of one drawn local grid: what the mapper sends to the
/// accumulator (run-length encoded changed cells, log-odds as drawn).

#include <Eigen/Core>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "stereo_occupancy/local_grid.h"

namespace stereo_occupancy {

/// A read-only array in memory that someone else owns: a GridUpdate's
/// vectors, or those of a message (read in place, no copy).
template <typename T>
class ConstArray {
 public:
  ConstArray() = default;
  ConstArray(const T* data, size_t size) : data_(data), size_(size) {}
  /// A view of a contiguous container (std::vector, a message's array).
  template <typename Container>
  ConstArray(const Container& c) : data_(c.data()), size_(c.size()) {}  // NOLINT: implicit on purpose

  size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  const T& operator[](size_t i) const { return data_[i]; }
  const T* begin() const { return data_; }
  const T* end() const { return data_ + size_; }

 private:
  const T* data_ = nullptr;
  size_t size_ = 0;
};

struct GridUpdate;

/// The known cells of a drawn local grid, run-length encoded over the grid's
/// linear index i = x + nx·(y + ny·z): run k covers i = run_start[k] ..
/// run_start[k] + run_length[k] - 1 and takes the next run_length[k] values
/// of log_odds. Mirrors msg/OccupancyUpdate.msg. A view: the arrays belong to
/// a GridUpdate or to a message, which must outlive it.
struct GridUpdateView {
  Eigen::Vector3d W_sensor_origin = Eigen::Vector3d::Zero();  ///< camera centre in W [m]
  double resolution_m = 0.0;                                  ///< cell edge [m]
  Eigen::Vector3i origin_index = Eigen::Vector3i::Zero();     ///< global index of local cell (0, 0, 0)
  Eigen::Vector3i size = Eigen::Vector3i::Zero();             ///< cells along x, y, z
  ConstArray<uint32_t> run_start;
  ConstArray<uint32_t> run_length;
  ConstArray<float> log_odds;

  GridUpdateView() = default;
  GridUpdateView(const GridUpdate& update);  // NOLINT: implicit, a GridUpdate is read through its view

  /// Number of cells carried (the sum of the run lengths).
  size_t numCells() const { return log_odds.size(); }

  /// True if sizes, runs and values fit together and every value is finite;
  /// otherwise @p why says what does not.
  bool isConsistent(std::string* why = nullptr) const;

  /// Calls f(global_index, log_odds) for every cell; requires isConsistent().
  template <typename F>
  void forEachCell(F&& f) const;

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

/// A GridUpdate that owns its arrays: what encodeGridUpdate() writes. Its
/// vectors move into a message without a copy; read it through its view.
struct GridUpdate {
  Eigen::Vector3d W_sensor_origin = Eigen::Vector3d::Zero();  ///< camera centre in W [m]
  double resolution_m = 0.0;                                  ///< cell edge [m]
  Eigen::Vector3i origin_index = Eigen::Vector3i::Zero();     ///< global index of local cell (0, 0, 0)
  Eigen::Vector3i size = Eigen::Vector3i::Zero();             ///< cells along x, y, z
  std::vector<uint32_t> run_start;
  std::vector<uint32_t> run_length;
  std::vector<float> log_odds;

  size_t numCells() const { return log_odds.size(); }
  bool isConsistent(std::string* why = nullptr) const { return GridUpdateView(*this).isConsistent(why); }
  template <typename F>
  void forEachCell(F&& f) const {
    GridUpdateView(*this).forEachCell(std::forward<F>(f));
  }
  template <typename F>
  void forEachCellBySiblings(F&& f) const {
    GridUpdateView(*this).forEachCellBySiblings(std::forward<F>(f));
  }
  template <typename F>
  void forEachSiblingBlock(F&& f) const {
    GridUpdateView(*this).forEachSiblingBlock(std::forward<F>(f));
  }
};

inline GridUpdateView::GridUpdateView(const GridUpdate& update)
    : W_sensor_origin(update.W_sensor_origin),
      resolution_m(update.resolution_m),
      origin_index(update.origin_index),
      size(update.size),
      run_start(update.run_start),
      run_length(update.run_length),
      log_odds(update.log_odds) {}

template <typename F>
void GridUpdateView::forEachCell(F&& f) const {
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

template <typename F>
void GridUpdateView::forEachCellBySiblings(F&& f) const {
  forEachSiblingBlock([&](const Eigen::Vector3i& first, const float(&values)[8]) {
    for (int i = 0; i < 8; ++i)
      if (values[i] == values[i]) f(first + Eigen::Vector3i(i & 1, (i >> 1) & 1, i >> 2), values[i]);
  });
}

template <typename F>
void GridUpdateView::forEachSiblingBlock(F&& f) const {
  if (log_odds.empty()) return;
  // Memory and work follow the runs, never the box the update claims: a
  // message may claim 65535 x 65535 cells and carry one.
  const int64_t nx = size.x(), ny = size.y();
  // Each row's stretch of known cells, [x0, x1) with values from log_odds[v]
  // on; a run may go on into the next row. Sorted by row, then x.
  struct Segment {
    int64_t y, z, x0, x1;
    size_t v;
  };
  std::vector<Segment> segments;
  segments.reserve(run_start.size());
  size_t v = 0;
  for (size_t k = 0; k < run_start.size(); ++k) {
    uint64_t i = run_start[k], left = run_length[k];
    while (left > 0) {
      const int64_t row = static_cast<int64_t>(i / static_cast<uint64_t>(nx));
      const int64_t x0 = static_cast<int64_t>(i % static_cast<uint64_t>(nx));
      const int64_t len = std::min<int64_t>(static_cast<int64_t>(left), nx - x0);
      segments.push_back({row % ny, row / ny, x0, x0 + len, v});
      v += static_cast<size_t>(len);
      i += static_cast<uint64_t>(len);
      left -= static_cast<uint64_t>(len);
    }
  }
  // Local index of the 2x2x2 block (even global index) a local index is in, and the end of its block.
  const int64_t ox = origin_index.x(), oy = origin_index.y(), oz = origin_index.z();
  auto blockStart = [](int64_t local, int64_t origin) { return local - ((origin + local) & 1); };
  auto blockEnd = [](int64_t local_end, int64_t origin) { return local_end + ((origin + local_end) & 1); };
  std::vector<float> rows[4];  // q = dy + 2 dz: one cluster's four rows, NaN where no cell
  // A strip: the four rows (y0 + dy, z0 + dz) of one line of blocks; its
  // segments per row are the ranges [begin[q], end[q]) of `segments`.
  auto visitStrip = [&](int64_t y0, int64_t z0, const size_t(&begin)[4], const size_t(&end)[4]) {
    size_t next[4] = {begin[0], begin[1], begin[2], begin[3]};
    for (;;) {
      // A cluster: the segments whose blocks overlap, in x order; rows[q] spans it.
      int64_t xs = std::numeric_limits<int64_t>::max();
      for (int q = 0; q < 4; ++q)
        if (next[q] < end[q]) xs = std::min(xs, blockStart(segments[next[q]].x0, ox));
      if (xs == std::numeric_limits<int64_t>::max()) return;
      size_t first[4], last[4];
      for (int q = 0; q < 4; ++q) first[q] = last[q] = next[q];
      int64_t xe = xs;  // the cluster's blocks: [xs, xe), each segment adding at most its length + 2
      for (bool grew = true; grew;) {
        grew = false;
        for (int q = 0; q < 4; ++q)
          for (; last[q] < end[q] && blockStart(segments[last[q]].x0, ox) <= xe; ++last[q], grew = true)
            xe = std::max(xe, blockEnd(segments[last[q]].x1, ox));
      }
      const size_t width = static_cast<size_t>(xe - xs);
      for (int q = 0; q < 4; ++q) {
        if (first[q] == last[q]) continue;
        rows[q].assign(width, std::numeric_limits<float>::quiet_NaN());
        for (size_t k = first[q]; k < last[q]; ++k)
          std::copy(log_odds.begin() + segments[k].v,
                    log_odds.begin() + segments[k].v + (segments[k].x1 - segments[k].x0),
                    rows[q].begin() + (segments[k].x0 - xs));
        next[q] = last[q];
      }
      for (int64_t x0 = xs; x0 < xe; x0 += 2) {
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
        if (any)
          f(Eigen::Vector3i(static_cast<int>(ox + x0), static_cast<int>(oy + y0), static_cast<int>(oz + z0)), values);
      }
    }
  };
  // The strips in z, then y order: a pair of planes (z0, z0 + 1) are two
  // consecutive ranges of segments, each sorted by y; merge them by block row.
  size_t s = 0;
  while (s < segments.size()) {
    const int64_t z0 = blockStart(segments[s].z, oz);
    size_t plane_end[2], cursor[2];
    cursor[0] = s;
    size_t e = s;
    while (e < segments.size() && segments[e].z == z0) ++e;
    plane_end[0] = e;
    cursor[1] = e;
    while (e < segments.size() && segments[e].z == z0 + 1) ++e;
    plane_end[1] = e;
    s = e;
    for (;;) {
      int64_t y0 = std::numeric_limits<int64_t>::max();
      for (int p = 0; p < 2; ++p)
        if (cursor[p] < plane_end[p]) y0 = std::min(y0, blockStart(segments[cursor[p]].y, oy));
      if (y0 == std::numeric_limits<int64_t>::max()) break;
      size_t begin[4], end[4];
      for (int q = 0; q < 4; ++q) {
        const int p = q >> 1;
        const int64_t y = y0 + (q & 1);
        begin[q] = cursor[p];
        while (cursor[p] < plane_end[p] && segments[cursor[p]].y == y) ++cursor[p];
        end[q] = cursor[p];
      }
      visitStrip(y0, z0, begin, end);
    }
  }
}

/// Encodes the known (not LocalGrid::kUnknown) cells of @p grid with their
/// values; cells whose value is exactly 0 carry nothing and are left out.
void encodeGridUpdate(const LocalGrid& grid, const Eigen::Vector3d& W_sensor_origin, GridUpdate* update);

}  // namespace stereo_occupancy
