#include "stereo_occupancy/local_grid.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <limits>

namespace stereo_occupancy {

namespace {
/// Cells per part of reset()'s fill on a pool: a part writes 1 MiB, far
/// more than its hand-out costs.
constexpr size_t kFillChunkCells = size_t{1} << 18;
}  // namespace

void LocalGrid::reset(const Eigen::Vector3i& origin_index, const Eigen::Vector3i& size, double resolution_m,
                      WorkerPool* pool) {
  origin_index_ = origin_index;
  size_ = size.cwiseMax(0);
  resolution_m_ = resolution_m;
  const size_t cells = static_cast<size_t>(size_.x()) * size_.y() * size_.z();
  releaseIfOversized(&data_, cells);
  const size_t kept = std::min(data_.size(), cells);  // the cells that hold the last image's values
  if (!pool || pool->size() < 2 || kept <= kFillChunkCells) {
    data_.assign(cells, kUnknown);
    return;
  }
  data_.resize(cells, kUnknown);  // a grown grid's new cells: unknown already
  pool->runInChunks(kept, kFillChunkCells, [&](size_t begin, size_t end) {
    std::fill(data_.begin() + begin, data_.begin() + end, kUnknown);
  });
}

void LocalGrid::clear() { std::fill(data_.begin(), data_.end(), kUnknown); }

size_t LocalGrid::silenceNearOccupied(float value, int radius, WorkerPool* pool) {
  if (radius <= 0) return 0;
  const unsigned workers = pool ? pool->size() : 1;
  // Two chunks of slabs per worker, each at least 2·radius + 1 thick: the
  // even chunks first, then the odd ones, so that no two chunks running at
  // once reach the same cell (a chunk writes radius slabs beyond its ends).
  // A cell is silenced whoever sees it first: the grid and the count do not
  // depend on the order.
  const int min_slabs = 2 * radius + 1;
  const int chunk_slabs = std::max(min_slabs, (size_.z() + 2 * static_cast<int>(workers) - 1) /
                                                  (2 * static_cast<int>(workers)));
  const int chunks = (size_.z() + chunk_slabs - 1) / chunk_slabs;
  if (workers == 1 || chunks < 2) return silenceSlabs(value, radius, 0, size_.z());
  std::vector<size_t> silenced(static_cast<size_t>(chunks), 0);
  for (int parity = 0; parity < 2; ++parity)
    pool->run(static_cast<size_t>(chunks - parity + 1) / 2, [&](size_t i, unsigned) {
      const int chunk = 2 * static_cast<int>(i) + parity;
      const int z_begin = chunk * chunk_slabs;
      silenced[chunk] = silenceSlabs(value, radius, z_begin, std::min(size_.z(), z_begin + chunk_slabs));
    });
  size_t total = 0;
  for (size_t n : silenced) total += n;
  return total;
}

size_t LocalGrid::freeZerosAwayFromOccupied(float free_value, int radius, WorkerPool* pool) {
  if (radius <= 0) return 0;
  // The zeros are marked, the marks near an occupied cell go back to 0 (the
  // sky guard's pass), and the marks left become free space. The mark is
  // the negative normal float nearest 0, which no profile draws (a
  // denormal would read as 0 where denormals are flushed).
  const float mark = -std::numeric_limits<float>::min();
  const size_t zeros = replaceValue(0.0f, mark, pool);
  const size_t near = silenceNearOccupied(mark, radius, pool);
  replaceValue(mark, free_value, pool);
  return zeros - near;
}

size_t LocalGrid::replaceValue(float from, float to, WorkerPool* pool) {
  auto replaceIn = [&](size_t begin, size_t end) {
    size_t n = 0;
    for (size_t i = begin; i < end; ++i)
      if (data_[i] == from) {
        data_[i] = to;
        ++n;
      }
    return n;
  };
  if (!pool || pool->size() < 2 || data_.size() <= kFillChunkCells) return replaceIn(0, data_.size());
  std::atomic<size_t> total{0};
  pool->runInChunks(data_.size(), kFillChunkCells,
                    [&](size_t begin, size_t end) { total += replaceIn(begin, end); });
  return total;
}

size_t LocalGrid::silenceSlabs(float value, int radius, int z_begin, int z_end) {
  size_t silenced = 0;
  auto silenceAround = [&](int x, int y, int z) {
    for (int k = std::max(0, z - radius); k <= std::min(size_.z() - 1, z + radius); ++k)
      for (int j = std::max(0, y - radius); j <= std::min(size_.y() - 1, y + radius); ++j)
        for (int h = std::max(0, x - radius); h <= std::min(size_.x() - 1, x + radius); ++h) {
          float& cell = data_[linearIndex(h, j, k)];
          if (cell == value) {
            cell = 0.0f;
            ++silenced;
          }
        }
  };
  for (int z = z_begin; z < z_end; ++z)
    for (int y = 0; y < size_.y(); ++y) {
      const float* row = &data_[linearIndex(0, y, z)];
      for (int x = 0; x < size_.x(); ++x) {
        if (x % kInformationBlock == 0 && x + kInformationBlock <= size_.x() && !blockHasOccupied(row + x)) {
          x += kInformationBlock - 1;  // nothing occupied in these 16 cells
          continue;
        }
        if (row[x] > 0.0f) silenceAround(x, y, z);
      }
    }
  return silenced;
}

size_t LocalGrid::countKnown() const {
  // Counted on the bits, in 32-bit lanes that vectorise (a float compare
  // with a 64-bit count does not); chunks keep the lanes from overflowing.
  uint32_t unknown_bits;
  std::memcpy(&unknown_bits, &kUnknown, sizeof unknown_bits);
  size_t known = 0;
  for (size_t begin = 0; begin < data_.size(); begin += (1u << 30)) {
    const size_t end = std::min(data_.size(), begin + (size_t{1} << 30));
    uint32_t count = 0;
    for (size_t i = begin; i < end; ++i) {
      uint32_t bits;
      std::memcpy(&bits, &data_[i], sizeof bits);
      count += bits != unknown_bits;
    }
    known += count;
  }
  return known;
}

Eigen::AlignedBox3d frustumBoundingBox(const StereoCameraModel& camera, const Eigen::Isometry3d& T_W_C) {
  const auto& cfg = camera.config();
  const double range = cfg.max_range_m;
  const Eigen::Matrix3d R_W_C = T_W_C.linear();
  const Eigen::Vector3d W_centre = T_W_C.translation();

  Eigen::AlignedBox3d box(W_centre, W_centre);
  // Corner rays through the outer edges of the corner pixels, in C.
  const double x0 = -0.5, x1 = cfg.width_px - 0.5, y0 = -0.5, y1 = cfg.height_px - 0.5;
  const std::array<Eigen::Vector3d, 4> C_corners = {
      camera.rayThroughPixel(x0, y0).normalized(), camera.rayThroughPixel(x1, y0).normalized(),
      camera.rayThroughPixel(x1, y1).normalized(), camera.rayThroughPixel(x0, y1).normalized()};
  for (const auto& r : C_corners) box.extend(W_centre + range * (R_W_C * r));

  auto insideImage = [&](const Eigen::Vector3d& C_dir) {
    if (C_dir.z() <= 0.0) return false;
    const double u = cfg.focal_length_px * C_dir.x() / C_dir.z() + cfg.cx_px;
    const double v = cfg.focal_length_px * C_dir.y() / C_dir.z() + cfg.cy_px;
    return u >= x0 && u <= x1 && v >= y0 && v <= y1;
  };

  // Extreme points of the cap along each world axis: inside the cap, or on
  // one of the four side faces' arcs.
  for (int axis = 0; axis < 3; ++axis) {
    for (double sign : {-1.0, 1.0}) {
      const Eigen::Vector3d C_axis = R_W_C.transpose() * (sign * Eigen::Vector3d::Unit(axis));
      if (insideImage(C_axis)) box.extend(W_centre + range * sign * Eigen::Vector3d::Unit(axis));
      for (int f = 0; f < 4; ++f) {
        const Eigen::Vector3d& a = C_corners[f];
        const Eigen::Vector3d& b = C_corners[(f + 1) % 4];
        const Eigen::Vector3d n = a.cross(b).normalized();
        Eigen::Vector3d q = C_axis - C_axis.dot(n) * n;
        if (q.norm() < 1e-12) continue;
        q.normalize();
        if (a.cross(q).dot(n) >= 0.0 && q.cross(b).dot(n) >= 0.0) box.extend(W_centre + range * (R_W_C * q));
      }
    }
  }
  return box;
}

void fitGridToBox(const Eigen::AlignedBox3d& box, double resolution_m, int padding_cells, LocalGrid* grid,
                  WorkerPool* pool) {
  const Eigen::Vector3i lo = LocalGrid::globalIndex(box.min(), resolution_m).array() - padding_cells;
  const Eigen::Vector3i hi = LocalGrid::globalIndex(box.max(), resolution_m).array() + padding_cells;
  grid->reset(lo, hi - lo + Eigen::Vector3i::Ones(), resolution_m, pool);
}

}  // namespace stereo_occupancy
