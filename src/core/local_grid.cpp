#include "stereo_occupancy/local_grid.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <cstdlib>
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

namespace {
/// Marks a cell that the guards' second pass sets to 0: the negative normal
/// float nearest 0, which no profile draws (a denormal would read as 0
/// where denormals are flushed).
constexpr float kKeepMark = -std::numeric_limits<float>::min();
/// A value no cell holds: the guard of that value is off.
constexpr float kNoValue = std::numeric_limits<float>::quiet_NaN();
}  // namespace

size_t LocalGrid::silenceNearOccupied(float value, int radius, WorkerPool* pool, const uint8_t* occupied_blocks) {
  // A zero silenced is the zero it was: counted, it would be counted again by each run that reaches it.
  if (radius <= 0 || value == 0.0f) return 0;
  return guardNearOccupied({value, radius, kNoValue, 0}, pool, occupied_blocks);
}

size_t LocalGrid::freeZerosAwayFromOccupied(float free_value, int radius, WorkerPool* pool) {
  if (radius <= 0) return 0;
  guardNearOccupied({kNoValue, 0, 0.0f, radius}, pool, nullptr);
  return settleMarks(free_value, pool);
}

size_t LocalGrid::applySurfaceGuards(float sky_value, int sky_radius, float free_value, int gap_radius,
                                     WorkerPool* pool, const uint8_t* occupied_blocks) {
  if (gap_radius <= 0) {
    silenceNearOccupied(sky_value, sky_radius, pool, occupied_blocks);
    return 0;
  }
  guardNearOccupied({sky_radius > 0 ? sky_value : kNoValue, sky_radius, 0.0f, gap_radius}, pool, occupied_blocks);
  return settleMarks(free_value, pool);
}

size_t LocalGrid::guardNearOccupied(const Guard& guard, WorkerPool* pool, const uint8_t* occupied_blocks) {
  const int radius = std::max(guard.sky_radius, guard.gap_radius);
  const unsigned workers = pool ? pool->size() : 1;
  // Two chunks of slabs per worker, each at least 2·radius + 1 thick: the
  // even chunks first, then the odd ones, so that no two chunks running at
  // once reach the same cell (a chunk writes radius slabs beyond its ends).
  // A cell is marked whoever sees it first: the grid and the count do not
  // depend on the order.
  const int min_slabs = 2 * radius + 1;
  const int chunk_slabs = std::max(min_slabs, (size_.z() + 2 * static_cast<int>(workers) - 1) /
                                                  (2 * static_cast<int>(workers)));
  const int chunks = (size_.z() + chunk_slabs - 1) / chunk_slabs;
  if (workers == 1 || chunks < 2) return guardSlabs(guard, 0, size_.z(), occupied_blocks);
  std::vector<size_t> marked(static_cast<size_t>(chunks), 0);
  for (int parity = 0; parity < 2; ++parity)
    pool->run(static_cast<size_t>(chunks - parity + 1) / 2, [&](size_t i, unsigned) {
      const int chunk = 2 * static_cast<int>(i) + parity;
      const int z_begin = chunk * chunk_slabs;
      marked[chunk] = guardSlabs(guard, z_begin, std::min(size_.z(), z_begin + chunk_slabs), occupied_blocks);
    });
  size_t total = 0;
  for (size_t n : marked) total += n;
  return total;
}

size_t LocalGrid::guardSlabs(const Guard& guard, int z_begin, int z_end, const uint8_t* occupied_blocks) {
  const int radius = std::max(guard.sky_radius, guard.gap_radius);
  // The sky guard's cells become 0 at once (nothing else reads them); the
  // gap's zeros near a hit are marked, so that settleMarks() can tell them
  // from the zeros far from every hit.
  const float sky_to = guard.gap_radius > 0 ? kKeepMark : 0.0f;
  // A guard that is off holds a value no cell holds: only two guards of
  // different radii need the distance.
  const bool by_distance = guard.sky_radius > 0 && guard.gap_radius > 0 && guard.sky_radius != guard.gap_radius;
  const bool sky_only = guard.gap_radius <= 0;  // the default: one value to replace, at any distance in reach
  size_t marked = 0;
  // The cells within reach of a run [x0, x1] of occupied cells in row (y,
  // z): the union of its cells' neighbourhoods, a row of the box at a time
  // (marking is idempotent, so the union is what cell by cell would mark).
  auto markAroundRun = [&](int x0, int x1, int y, int z) {
    const int h_begin = std::max(0, x0 - radius), h_end = std::min(size_.x() - 1, x1 + radius);
    for (int k = std::max(0, z - radius); k <= std::min(size_.z() - 1, z + radius); ++k)
      for (int j = std::max(0, y - radius); j <= std::min(size_.y() - 1, y + radius); ++j) {
        float* row = &data_[linearIndex(0, j, k)];
        if (sky_only) {  // branch-free: a few cells a row, whose values a branch would mispredict
          for (int h = h_begin; h <= h_end; ++h) {
            const bool sky = row[h] == guard.sky_value;
            marked += sky;
            row[h] = sky ? sky_to : row[h];
          }
          continue;
        }
        const int dist_jk = std::max(std::abs(j - y), std::abs(k - z));
        for (int h = h_begin; h <= h_end; ++h) {
          float& cell = row[h];
          const bool sky = cell == guard.sky_value, gap = cell == guard.gap_value;
          if (!sky && !gap) continue;
          const int reach = sky ? guard.sky_radius : guard.gap_radius;
          if (by_distance && std::max({x0 - h, h - x1, dist_jk}) > reach) continue;  // Chebyshev to the run
          cell = sky ? sky_to : kKeepMark;
          ++marked;
        }
      }
  };
  // The runs of occupied cells in the block of row (y, z) from x_begin, cut
  // at its end (the union of the pieces' neighbourhoods is the run's).
  auto markBlock = [&](int x_begin, int y, int z) {
    const float* row = &data_[linearIndex(0, y, z)];
    const int x_end = std::min(size_.x(), x_begin + kInformationBlock);
    for (int x = x_begin; x < x_end; ++x) {
      if (!(row[x] > 0.0f)) continue;
      const int x0 = x;
      while (x + 1 < x_end && row[x + 1] > 0.0f) ++x;  // marks are never > 0: the run stays
      markAroundRun(x0, x, y, z);
    }
  };
  const int blocks_per_row = blocksPerRow();
  if (occupied_blocks) {  // the drawer's flags: a few thousand of the grid's blocks
    const size_t first = static_cast<size_t>(z_begin) * size_.y() * blocks_per_row;
    const size_t last = static_cast<size_t>(z_end) * size_.y() * blocks_per_row;
    for (size_t b = first; b < last; ++b) {
      if (b % 8 == 0 && b + 8 <= last) {  // most flags are 0: eight at a time
        uint64_t eight;
        std::memcpy(&eight, occupied_blocks + b, sizeof eight);
        if (eight == 0) {
          b += 7;
          continue;
        }
      }
      if (!occupied_blocks[b]) continue;
      const size_t row = b / blocks_per_row;
      markBlock(static_cast<int>(b % blocks_per_row) * kInformationBlock, static_cast<int>(row % size_.y()),
                static_cast<int>(row / size_.y()));
    }
    return marked;
  }
  for (int z = z_begin; z < z_end; ++z)
    for (int y = 0; y < size_.y(); ++y) {
      const float* row = &data_[linearIndex(0, y, z)];
      for (int x = 0; x < size_.x(); x += kInformationBlock)
        if (x + kInformationBlock > size_.x() || blockHasOccupied(row + x)) markBlock(x, y, z);
    }
  return marked;
}

size_t LocalGrid::settleMarks(float free_value, WorkerPool* pool) {
  // The gap's zeros and the marks are few: only the blocks that hold one are written.
  auto settleCells = [free_value](float* cells, size_t n) {
    size_t freed = 0;
    for (size_t i = 0; i < n; ++i) {
      const float v = cells[i];
      freed += v == 0.0f;
      cells[i] = v == 0.0f ? free_value : (v == kKeepMark ? 0.0f : v);
    }
    return freed;
  };
  auto settle = [&](size_t begin, size_t end) {
    size_t freed = 0, i = begin;
    for (; i + kInformationBlock <= end; i += kInformationBlock)
      if (blockHolds(data_.data() + i, 0.0f, kKeepMark)) freed += settleCells(data_.data() + i, kInformationBlock);
    return freed + settleCells(data_.data() + i, end - i);
  };
  if (!pool || pool->size() < 2 || data_.size() <= kFillChunkCells) return settle(0, data_.size());
  std::atomic<size_t> total{0};
  pool->runInChunks(data_.size(), kFillChunkCells, [&](size_t begin, size_t end) { total += settle(begin, end); });
  return total;
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
