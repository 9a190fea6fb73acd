#pragma once
/// @file
/// The world-aligned local occupancy grid one disparity image is drawn into.

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>
#if defined(__SSE2__)
#include <emmintrin.h>
#elif defined(__aarch64__) && defined(__ARM_NEON) && !defined(__AARCH64EB__)
#define STEREO_OCCUPANCY_NEON_BLOCKS 1
#include <arm_neon.h>
#endif

#include "stereo_occupancy/stereo_camera_model.h"
#include "stereo_occupancy/worker_pool.h"

namespace stereo_occupancy {

/// Cells tested at once by blockHasInformation(); a LocalGrid's row is
/// also split into blocks of this many cells (LocalGrid::numBlocks()).
constexpr int kInformationBlock = 16;

/// Dense 3D array of log-odds over an axis-aligned box of the world frame W.
///
/// Cell (i, j, k) of the global grid of cell size c spans
/// [i·c, (i+1)·c) x [j·c, (j+1)·c) x [k·c, (k+1)·c); its centre is
/// ((i, j, k) + 0.5)·c. This is exactly the cell of an octomap::OcTree key at
/// the same resolution (key = global index + 2^15). The local grid holds the
/// global cells originIndex() .. originIndex() + size() - 1, x fastest.
/// Cells nothing was drawn into hold kUnknown (-inf), so that obstacle priority
/// is a plain max().
class LocalGrid {
 public:
  static constexpr float kUnknown = -std::numeric_limits<float>::infinity();

  /// Re-shapes the grid and marks every cell unknown, in chunks on @p
  /// pool's workers if given (a frustum's grid is megabytes to write). Keeps
  /// its memory, unless it is much more than the new size needs (releaseIfOversized).
  void reset(const Eigen::Vector3i& origin_index, const Eigen::Vector3i& size, double resolution_m,
             WorkerPool* pool = nullptr);

  /// Cells the grid's memory holds (at least numCells()).
  size_t capacityCells() const { return data_.capacity(); }

  /// Marks every cell unknown.
  void clear();

  double resolution() const { return resolution_m_; }
  const Eigen::Vector3i& originIndex() const { return origin_index_; }
  const Eigen::Vector3i& size() const { return size_; }
  size_t numCells() const { return data_.size(); }

  /// Position of the grid's lower corner in W [m].
  Eigen::Vector3d originPosition() const { return origin_index_.cast<double>() * resolution_m_; }

  /// Blocks of kInformationBlock cells along x in a row (the last may be shorter).
  int blocksPerRow() const { return (size_.x() + kInformationBlock - 1) / kInformationBlock; }
  /// Blocks of the grid: blocksPerRow() per row, the rows (y, z) in the cells' order.
  size_t numBlocks() const { return static_cast<size_t>(blocksPerRow()) * size_.y() * size_.z(); }

  size_t linearIndex(int x, int y, int z) const {
    return static_cast<size_t>(x) +
           static_cast<size_t>(size_.x()) * (static_cast<size_t>(y) + static_cast<size_t>(size_.y()) * z);
  }
  bool contains(const Eigen::Vector3i& local) const {
    return (local.array() >= 0).all() && (local.array() < size_.array()).all();
  }
  float& at(int x, int y, int z) { return data_[linearIndex(x, y, z)]; }
  float at(int x, int y, int z) const { return data_[linearIndex(x, y, z)]; }
  float* data() { return data_.data(); }
  const float* data() const { return data_.data(); }

  /// Centre of local cell (x, y, z) in W [m].
  Eigen::Vector3d cellCentre(int x, int y, int z) const {
    return (origin_index_ + Eigen::Vector3i(x, y, z)).cast<double>().array().operator+(0.5).matrix() * resolution_m_;
  }

  /// Global index of the cell containing W_point: floor(p / c).
  static Eigen::Vector3i globalIndex(const Eigen::Vector3d& W_point, double resolution_m) {
    return (W_point / resolution_m).array().floor().cast<int>().matrix();
  }

  /// Number of cells that are not kUnknown.
  size_t countKnown() const;

 private:
  Eigen::Vector3i origin_index_ = Eigen::Vector3i::Zero();
  Eigen::Vector3i size_ = Eigen::Vector3i::Zero();
  double resolution_m_ = 1.0;
  std::vector<float> data_;
};

/// Memory a buffer keeps after a smaller image without condition [elements]
/// (16 MiB of floats).
constexpr size_t kKeptBufferElements = size_t{4} << 20;
/// A buffer asked for less than 1 / kBufferReleaseFactor of what it holds lets it go.
constexpr size_t kBufferReleaseFactor = 4;

/// Frees @p buffer's memory if it holds much more than the @p needed
/// elements of this image (one rare huge image must not keep its memory for good).
template <typename T>
void releaseIfOversized(std::vector<T>* buffer, size_t needed) {
  if (buffer->capacity() > kBufferReleaseFactor * needed && buffer->capacity() > kKeptBufferElements)
    std::vector<T>().swap(*buffer);
}

/// True if one of the kInformationBlock cells from @p cells holds
/// information: known (not LocalGrid::kUnknown) and not 0. Skips the empty
/// stretches of a frustum's box 16 cells at a time (SSE2 or NEON where available).
inline bool blockHasInformation(const float* cells) {
#if defined(__SSE2__)
  const __m128 unknown = _mm_set1_ps(LocalGrid::kUnknown), zero = _mm_setzero_ps();
  __m128 hit = zero;
  for (int j = 0; j < kInformationBlock; j += 4) {
    const __m128 v = _mm_loadu_ps(cells + j);
    hit = _mm_or_ps(hit, _mm_and_ps(_mm_cmpneq_ps(v, unknown), _mm_cmpneq_ps(v, zero)));
  }
  return _mm_movemask_ps(hit) != 0;
#elif defined(STEREO_OCCUPANCY_NEON_BLOCKS)
  const float32x4_t unknown = vdupq_n_f32(LocalGrid::kUnknown), zero = vdupq_n_f32(0.0f);
  uint32x4_t hit = vdupq_n_u32(0);
  for (int j = 0; j < kInformationBlock; j += 4) {  // neither unknown nor 0 (NaN included, as cmpneq)
    const float32x4_t v = vld1q_f32(cells + j);
    hit = vorrq_u32(hit, vmvnq_u32(vorrq_u32(vceqq_f32(v, unknown), vceqq_f32(v, zero))));
  }
  return vmaxvq_u32(hit) != 0;
#else
  bool hit = false;
  for (int j = 0; j < kInformationBlock; ++j) hit |= cells[j] != LocalGrid::kUnknown && cells[j] != 0.0f;
  return hit;
#endif
}

/// Bit j set if cell j of the kInformationBlock cells from @p cells holds
/// information (known and not 0, as blockHasInformation() decides): the
/// encoding finds its runs' ends in the bits (SSE2 or NEON where available).
inline uint32_t informationMask(const float* cells) {
  static_assert(kInformationBlock == 16, "four groups of four lanes");
  uint32_t mask = 0;
#if defined(__SSE2__)
  const __m128 unknown = _mm_set1_ps(LocalGrid::kUnknown), zero = _mm_setzero_ps();
  for (int j = 0; j < kInformationBlock; j += 4) {
    const __m128 v = _mm_loadu_ps(cells + j);
    mask |= static_cast<uint32_t>(_mm_movemask_ps(_mm_and_ps(_mm_cmpneq_ps(v, unknown), _mm_cmpneq_ps(v, zero)))) << j;
  }
#elif defined(STEREO_OCCUPANCY_NEON_BLOCKS)
  const float32x4_t unknown = vdupq_n_f32(LocalGrid::kUnknown), zero = vdupq_n_f32(0.0f);
  const uint32_t lane_bits[4] = {1, 2, 4, 8};
  const uint32x4_t bits = vld1q_u32(lane_bits);
  for (int j = 0; j < kInformationBlock; j += 4) {  // neither unknown nor 0 (NaN included, as cmpneq)
    const float32x4_t v = vld1q_f32(cells + j);
    const uint32x4_t hit = vmvnq_u32(vorrq_u32(vceqq_f32(v, unknown), vceqq_f32(v, zero)));
    mask |= vaddvq_u32(vandq_u32(hit, bits)) << j;
  }
#else
  for (int j = 0; j < kInformationBlock; ++j)
    mask |= static_cast<uint32_t>(cells[j] != LocalGrid::kUnknown && cells[j] != 0.0f) << j;
#endif
  return mask;
}

/// True if one of the kInformationBlock cells from @p cells holds exactly
/// @p a or @p b (SSE2 or NEON where available).
inline bool blockHolds(const float* cells, float a, float b) {
#if defined(__SSE2__)
  const __m128 va = _mm_set1_ps(a), vb = _mm_set1_ps(b);
  __m128 hit = _mm_setzero_ps();
  for (int j = 0; j < kInformationBlock; j += 4) {
    const __m128 v = _mm_loadu_ps(cells + j);
    hit = _mm_or_ps(hit, _mm_or_ps(_mm_cmpeq_ps(v, va), _mm_cmpeq_ps(v, vb)));
  }
  return _mm_movemask_ps(hit) != 0;
#elif defined(STEREO_OCCUPANCY_NEON_BLOCKS)
  const float32x4_t va = vdupq_n_f32(a), vb = vdupq_n_f32(b);
  uint32x4_t hit = vdupq_n_u32(0);
  for (int j = 0; j < kInformationBlock; j += 4) {
    const float32x4_t v = vld1q_f32(cells + j);
    hit = vorrq_u32(hit, vorrq_u32(vceqq_f32(v, va), vceqq_f32(v, vb)));
  }
  return vmaxvq_u32(hit) != 0;
#else
  bool hit = false;
  for (int j = 0; j < kInformationBlock; ++j) hit |= cells[j] == a || cells[j] == b;
  return hit;
#endif
}

/// True if one of the kInformationBlock cells from @p cells is known (not
/// LocalGrid::kUnknown): lets a merge of mostly untouched grids skip them
/// 16 cells at a time (SSE2 or NEON where available).
inline bool blockHasKnown(const float* cells) {
#if defined(__SSE2__)
  const __m128 unknown = _mm_set1_ps(LocalGrid::kUnknown);
  __m128 hit = _mm_setzero_ps();
  for (int j = 0; j < kInformationBlock; j += 4) hit = _mm_or_ps(hit, _mm_cmpneq_ps(_mm_loadu_ps(cells + j), unknown));
  return _mm_movemask_ps(hit) != 0;
#elif defined(STEREO_OCCUPANCY_NEON_BLOCKS)
  const float32x4_t unknown = vdupq_n_f32(LocalGrid::kUnknown);
  uint32x4_t hit = vdupq_n_u32(0);
  for (int j = 0; j < kInformationBlock; j += 4)
    hit = vorrq_u32(hit, vmvnq_u32(vceqq_f32(vld1q_f32(cells + j), unknown)));
  return vmaxvq_u32(hit) != 0;
#else
  bool hit = false;
  for (int j = 0; j < kInformationBlock; ++j) hit |= cells[j] != LocalGrid::kUnknown;
  return hit;
#endif
}

/// True if one of the kInformationBlock cells from @p cells is occupied
/// (log-odds > 0): lets silenceNearOccupied() skip a frame's grid 16 cells
/// at a time (SSE2 or NEON where available).
inline bool blockHasOccupied(const float* cells) {
#if defined(__SSE2__)
  const __m128 zero = _mm_setzero_ps();
  __m128 hit = zero;
  for (int j = 0; j < kInformationBlock; j += 4) hit = _mm_or_ps(hit, _mm_cmpgt_ps(_mm_loadu_ps(cells + j), zero));
  return _mm_movemask_ps(hit) != 0;
#elif defined(STEREO_OCCUPANCY_NEON_BLOCKS)
  const float32x4_t zero = vdupq_n_f32(0.0f);
  uint32x4_t hit = vdupq_n_u32(0);
  for (int j = 0; j < kInformationBlock; j += 4) hit = vorrq_u32(hit, vcgtq_f32(vld1q_f32(cells + j), zero));
  return vmaxvq_u32(hit) != 0;
#else
  bool hit = false;
  for (int j = 0; j < kInformationBlock; ++j) hit |= cells[j] > 0.0f;
  return hit;
#endif
}

/// Axis-aligned bounding box in W of the view frustum cut at the maximum range
/// (the camera centre, the four corner rays and the spherical cap at
/// max_range_m, including where the cap bulges past the corners).
Eigen::AlignedBox3d frustumBoundingBox(const StereoCameraModel& camera, const Eigen::Isometry3d& T_W_C);

/// Shapes @p grid to the cells covering @p box, plus @p padding_cells on
/// every side, all unknown (LocalGrid::reset(), on @p pool's workers if given).
void fitGridToBox(const Eigen::AlignedBox3d& box, double resolution_m, int padding_cells, LocalGrid* grid,
                  WorkerPool* pool = nullptr);

}  // namespace stereo_occupancy
