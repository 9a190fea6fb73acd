#pragma once
/// @file
/// The compact form of one drawn local grid: what the mapper sends to the
/// accumulator (run-length encoded changed cells, log-odds as drawn).

#include <Eigen/Core>

#include <algorithm>
#include <cstdint>
#include <functional>
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

/// f(first_global_index, values) of GridUpdateView::forEachSiblingBlock():
/// called once per block, with the octree's work inside it, so the call
/// through a std::function costs nothing that shows.
using SiblingBlockVisitor = std::function<void(const Eigen::Vector3i&, const float (&)[8])>;

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
  void forEachSiblingBlock(const SiblingBlockVisitor& f) const;
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
  void forEachSiblingBlock(const SiblingBlockVisitor& f) const { GridUpdateView(*this).forEachSiblingBlock(f); }
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

/// Encodes the known (not LocalGrid::kUnknown) cells of @p grid with their
/// values; cells whose value is exactly 0 carry nothing and are left out.
/// With a @p pool of two or more workers, parts of the grid are scanned at
/// once; the update is the same bit for bit (tested).
void encodeGridUpdate(const LocalGrid& grid, const Eigen::Vector3d& W_sensor_origin, GridUpdate* update,
                      WorkerPool* pool = nullptr);

}  // namespace stereo_occupancy
