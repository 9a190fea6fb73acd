#include "stereo_occupancy/local_grid.h"

#include <algorithm>
#include <array>
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
  pool->runInChunks(kept, kFillChunkCells,
                    [&](size_t begin, size_t end) { std::fill(data_.begin() + begin, data_.begin() + end, kUnknown); });
}

void LocalGrid::clear() { std::fill(data_.begin(), data_.end(), kUnknown); }

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
