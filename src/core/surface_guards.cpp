#include "stereo_occupancy/surface_guards.h"

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <vector>

namespace stereo_occupancy {

namespace {
/// Marks a cell that the guards' second pass sets to 0: the negative normal
/// float nearest 0, which no profile draws (a denormal would read as 0
/// where denormals are flushed).
constexpr float kKeepMark = -std::numeric_limits<float>::min();
/// A value no cell holds: the guard of that value is off.
constexpr float kNoValue = std::numeric_limits<float>::quiet_NaN();

/// Chunks of slabs per worker and parity in the first pass on a pool: a
/// frame's hits crowd into a few slabs (the ground, a house front), so one
/// chunk per worker would leave the others waiting; the pool hands the
/// chunks out one by one.
constexpr int kGuardChunksPerWorker = 4;
/// Cells per part of the second pass on a pool: a part reads 1 MiB, far
/// more than its hand-out costs.
constexpr size_t kSettleChunkCells = size_t{1} << 18;

/// What the guards' first pass looks for around each occupied cell.
struct Guard {
  float sky_value;  ///< cells holding it within sky_radius become 0
  int sky_radius;
  float gap_value;  ///< cells holding it within gap_radius are kept 0
  int gap_radius;
  float edge_value = kNoValue;  ///< cells holding it within edge_radius, beside the cell, become 0
  int edge_radius = 0;
  Eigen::Vector3d grid_camera = Eigen::Vector3d::Zero();  ///< the camera centre in the grid's cells
};

/// The first of @p flags [b, last) that is set, or last. Most flags are 0:
/// eight at a time.
size_t nextSetFlag(const uint8_t* flags, size_t b, size_t last) {
  for (; b < last; ++b) {
    if (b % 8 == 0 && b + 8 <= last) {
      uint64_t eight;
      std::memcpy(&eight, flags + b, sizeof eight);
      if (eight == 0) {
        b += 7;
        continue;
      }
    }
    if (flags[b]) return b;
  }
  return last;
}

/// Bit j set if cells[j] (j < 4) equals @p a, @p b or @p c (SSE2 or NEON
/// where available; a NaN matches nothing).
inline uint32_t equalMask4(const float* cells, float a, float b, float c) {
#if defined(__SSE2__)
  const __m128 v = _mm_loadu_ps(cells);
  const __m128 hit = _mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(v, _mm_set1_ps(a)), _mm_cmpeq_ps(v, _mm_set1_ps(b))),
                               _mm_cmpeq_ps(v, _mm_set1_ps(c)));
  return static_cast<uint32_t>(_mm_movemask_ps(hit));
#elif defined(STEREO_OCCUPANCY_NEON_BLOCKS)
  const float32x4_t v = vld1q_f32(cells);
  const uint32x4_t hit =
      vorrq_u32(vorrq_u32(vceqq_f32(v, vdupq_n_f32(a)), vceqq_f32(v, vdupq_n_f32(b))), vceqq_f32(v, vdupq_n_f32(c)));
  const uint32_t lane_bits[4] = {1, 2, 4, 8};
  return vaddvq_u32(vandq_u32(hit, vld1q_u32(lane_bits)));
#else
  uint32_t mask = 0;
  for (int j = 0; j < 4; ++j) mask |= static_cast<uint32_t>(cells[j] == a || cells[j] == b || cells[j] == c) << j;
  return mask;
#endif
}

/// True if cell @p f lies in front of cell @p hit as seen from @p grid_camera:
/// at least half a cell nearer along the ray through the hit's centre (the
/// free space its own measurement and the views of it clear), not beside it.
bool inFrontOf(const Eigen::Vector3i& f, const Eigen::Vector3i& hit, const Eigen::Vector3d& grid_camera) {
  const Eigen::Vector3d ray = hit.cast<double>().array() + 0.5 - grid_camera.array();
  const double along = (f - hit).cast<double>().dot(ray);  // < -|ray| / 2, without the root
  return along < 0.0 && along * along > 0.25 * ray.squaredNorm();
}

/// The two passes of the guards over one grid.
class GuardPass {
 public:
  explicit GuardPass(LocalGrid* grid)
      : grid_(*grid), data_(grid->data()), cells_(grid->numCells()), size_(grid->size()) {}
  /// The first pass, in slabs of z or y on @p pool's workers; returns the
  /// cells it marked. @p occupied_blocks as for applySurfaceGuards().
  size_t guardNearOccupied(const Guard& guard, WorkerPool* pool, const uint8_t* occupied_blocks);
  /// The second pass: the zeros left become @p free_value, the marks 0;
  /// returns the zeros set free.
  size_t settleMarks(float free_value, WorkerPool* pool);

 private:
  /// guardNearOccupied() for the occupied cells in the slabs [begin, end)
  /// of @p axis (2: z; 1: y, only with @p occupied_blocks).
  size_t guardSlabs(const Guard& guard, int axis, int begin, int end, const uint8_t* occupied_blocks);
  /// The axis whose slabs share the occupied blocks out best among chunks
  /// of the thickness chunkSlabs() gives: 2 (z) unless y's largest chunk
  /// holds fewer (a flat ground's hits lie in a few slabs of z).
  int slabAxis(const uint8_t* occupied_blocks, int min_slabs, int wanted) const;
  /// Slabs per chunk along an axis of @p size cells.
  static int chunkSlabs(int size, int min_slabs, int wanted) {
    return std::max(min_slabs, (size + wanted - 1) / wanted);
  }

  const LocalGrid& grid_;
  float* data_;
  size_t cells_;
  Eigen::Vector3i size_;
};

size_t GuardPass::guardNearOccupied(const Guard& guard, WorkerPool* pool, const uint8_t* occupied_blocks) {
  const int radius = std::max({guard.sky_radius, guard.gap_radius, guard.edge_radius});
  const unsigned workers = pool ? pool->size() : 1;
  // Chunks of slabs, kGuardChunksPerWorker per worker and parity, each at
  // least 2·radius + 1 thick: the even chunks first, then the odd ones, so
  // that no two chunks running at once reach the same cell (a chunk writes
  // radius slabs beyond its ends). A cell is marked whoever sees it first:
  // the grid and the count do not depend on the order.
  const int min_slabs = 2 * radius + 1;
  const int wanted = 2 * kGuardChunksPerWorker * static_cast<int>(workers);
  if (workers == 1) return guardSlabs(guard, 2, 0, size_.z(), occupied_blocks);
  const int axis = slabAxis(occupied_blocks, min_slabs, wanted);
  const int chunk_slabs = chunkSlabs(size_[axis], min_slabs, wanted);
  const int chunks = (size_[axis] + chunk_slabs - 1) / chunk_slabs;
  if (chunks < 2) return guardSlabs(guard, axis, 0, size_[axis], occupied_blocks);
  std::vector<size_t> marked(static_cast<size_t>(chunks), 0);
  for (int parity = 0; parity < 2; ++parity)
    pool->run(static_cast<size_t>(chunks - parity + 1) / 2, [&](size_t i, unsigned) {
      const int chunk = 2 * static_cast<int>(i) + parity;
      const int begin = chunk * chunk_slabs;
      marked[chunk] = guardSlabs(guard, axis, begin, std::min(size_[axis], begin + chunk_slabs), occupied_blocks);
    });
  size_t total = 0;
  for (size_t n : marked) total += n;
  return total;
}

int GuardPass::slabAxis(const uint8_t* occupied_blocks, int min_slabs, int wanted) const {
  if (!occupied_blocks || size_.y() <= 0 || size_.z() <= 0) return 2;  // the scan of every row goes by z
  const size_t blocks_per_row = static_cast<size_t>(grid_.blocksPerRow()), rows_y = static_cast<size_t>(size_.y());
  const int z_slabs = chunkSlabs(size_.z(), min_slabs, wanted), y_slabs = chunkSlabs(size_.y(), min_slabs, wanted);
  std::vector<size_t> per_z((size_.z() + z_slabs - 1) / z_slabs, 0), per_y((size_.y() + y_slabs - 1) / y_slabs, 0);
  const size_t blocks = grid_.numBlocks();
  for (size_t b = nextSetFlag(occupied_blocks, 0, blocks); b < blocks;
       b = nextSetFlag(occupied_blocks, b + 1, blocks)) {
    const size_t row = b / blocks_per_row;
    ++per_z[row / rows_y / z_slabs];
    ++per_y[row % rows_y / y_slabs];
  }
  const size_t largest_z = *std::max_element(per_z.begin(), per_z.end());
  const size_t largest_y = *std::max_element(per_y.begin(), per_y.end());
  return largest_y < largest_z && per_y.size() >= 2 ? 1 : 2;
}

size_t GuardPass::guardSlabs(const Guard& guard, int axis, int begin, int end, const uint8_t* occupied_blocks) {
  const int radius = std::max({guard.sky_radius, guard.gap_radius, guard.edge_radius});
  // The sky and edge guards' cells become 0 at once (nothing else reads
  // them); the gap's zeros near a hit are marked, so that settleMarks() can
  // tell them from the zeros far from every hit.
  const float silenced = guard.gap_radius > 0 ? kKeepMark : 0.0f;
  // A guard that is off holds a value no cell holds: only guards of radii
  // below the box's need the distance.
  const bool sky_only = guard.gap_radius <= 0 && guard.edge_radius <= 0;  // one value to replace, anywhere in reach
  size_t marked = 0;
  // True if cell (h, j, k) is not in front of one of the run's cells within the edge guard's reach.
  auto besideRun = [&](int h, int j, int k, int x0, int x1, int y, int z) {
    for (int x = std::max(x0, h - guard.edge_radius); x <= std::min(x1, h + guard.edge_radius); ++x)
      if (!inFrontOf({h, j, k}, {x, y, z}, guard.grid_camera)) return true;
    return false;
  };
  // The cells within reach of a run [x0, x1] of occupied cells in row (y,
  // z): the union of its cells' neighbourhoods, a row of the box at a time
  // (marking is idempotent, so the union is what cell by cell would mark).
  auto markAroundRun = [&](int x0, int x1, int y, int z) {
    const int h_begin = std::max(0, x0 - radius), h_end = std::min(size_.x() - 1, x1 + radius);
    for (int k = std::max(0, z - radius); k <= std::min(size_.z() - 1, z + radius); ++k)
      for (int j = std::max(0, y - radius); j <= std::min(size_.y() - 1, y + radius); ++j) {
        float* row = &data_[grid_.linearIndex(0, j, k)];
        if (sky_only) {  // branch-free: a few cells a row, whose values a branch would mispredict
          for (int h = h_begin; h <= h_end; ++h) {
            const bool sky = row[h] == guard.sky_value;
            marked += sky;
            row[h] = sky ? silenced : row[h];
          }
          continue;
        }
        const int dist_jk = std::max(std::abs(j - y), std::abs(k - z));
        auto markCell = [&](int h) {
          float& cell = row[h];
          const bool sky = cell == guard.sky_value, gap = cell == guard.gap_value, edge = cell == guard.edge_value;
          if (!sky && !gap && !edge) return;
          const int reach = sky ? guard.sky_radius : gap ? guard.gap_radius : guard.edge_radius;
          if (reach < radius && std::max({x0 - h, h - x1, dist_jk}) > reach) return;  // Chebyshev to the run
          if (edge && !besideRun(h, j, k, x0, x1, y, z)) return;
          cell = gap ? kKeepMark : silenced;
          ++marked;
        };
        // Most cells hold none of the values: four at a time, then the
        // candidates in order (marking a cell changes no other's test).
        int h = h_begin;
        for (; h + 4 <= h_end + 1; h += 4)
          for (uint32_t m = equalMask4(row + h, guard.sky_value, guard.gap_value, guard.edge_value); m != 0; m &= m - 1)
            markCell(h + __builtin_ctz(m));
        for (; h <= h_end; ++h) markCell(h);
      }
  };
  // The runs of occupied cells in the block of row (y, z) from x_begin, cut
  // at its end (the union of the pieces' neighbourhoods is the run's).
  auto markBlock = [&](int x_begin, int y, int z) {
    const float* row = &data_[grid_.linearIndex(0, y, z)];
    const int x_end = std::min(size_.x(), x_begin + kInformationBlock);
    for (int x = x_begin; x < x_end; ++x) {
      if (!(row[x] > 0.0f)) continue;
      const int x0 = x;
      while (x + 1 < x_end && row[x + 1] > 0.0f) ++x;  // marks are never > 0: the run stays
      markAroundRun(x0, x, y, z);
    }
  };
  const int blocks_per_row = grid_.blocksPerRow();
  // The flagged blocks of the rows [first, last) (a row: y + size.y · z).
  auto markFlagged = [&](size_t first_row, size_t last_row) {
    const size_t first = first_row * blocks_per_row, last = last_row * blocks_per_row;
    for (size_t b = nextSetFlag(occupied_blocks, first, last); b < last;
         b = nextSetFlag(occupied_blocks, b + 1, last)) {
      const size_t row = b / blocks_per_row;
      markBlock(static_cast<int>(b % blocks_per_row) * kInformationBlock, static_cast<int>(row % size_.y()),
                static_cast<int>(row / size_.y()));
    }
  };
  if (occupied_blocks) {  // the drawer's flags: a few thousand of the grid's blocks
    const size_t rows_y = static_cast<size_t>(size_.y());
    if (axis == 2) {
      markFlagged(static_cast<size_t>(begin) * rows_y, static_cast<size_t>(end) * rows_y);
    } else {  // slabs of y: their rows in each slab of z
      for (int z = 0; z < size_.z(); ++z)
        markFlagged(static_cast<size_t>(z) * rows_y + begin, static_cast<size_t>(z) * rows_y + end);
    }
    return marked;
  }
  const int z_begin = begin, z_end = end;  // axis 2: the scan goes by z
  for (int z = z_begin; z < z_end; ++z)
    for (int y = 0; y < size_.y(); ++y) {
      const float* row = &data_[grid_.linearIndex(0, y, z)];
      for (int x = 0; x < size_.x(); x += kInformationBlock)
        if (x + kInformationBlock > size_.x() || blockHasOccupied(row + x)) markBlock(x, y, z);
    }
  return marked;
}

size_t GuardPass::settleMarks(float free_value, WorkerPool* pool) {
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
      if (blockHolds(data_ + i, 0.0f, kKeepMark)) freed += settleCells(data_ + i, kInformationBlock);
    return freed + settleCells(data_ + i, end - i);
  };
  if (!pool || pool->size() < 2 || cells_ <= kSettleChunkCells) return settle(0, cells_);
  std::atomic<size_t> total{0};
  pool->runInChunks(cells_, kSettleChunkCells, [&](size_t begin, size_t end) { total += settle(begin, end); });
  return total;
}

}  // namespace

size_t silenceNearOccupied(LocalGrid* grid, float value, int radius, WorkerPool* pool, const uint8_t* occupied_blocks) {
  // A zero silenced is the zero it was: counted, it would be counted again by each run that reaches it.
  if (radius <= 0 || value == 0.0f) return 0;
  return GuardPass(grid).guardNearOccupied({value, radius, kNoValue, 0}, pool, occupied_blocks);
}

size_t freeZerosAwayFromOccupied(LocalGrid* grid, float free_value, int radius, WorkerPool* pool) {
  if (radius <= 0) return 0;
  GuardPass(grid).guardNearOccupied({kNoValue, 0, 0.0f, radius}, pool, nullptr);
  return GuardPass(grid).settleMarks(free_value, pool);
}

size_t applySurfaceGuards(LocalGrid* grid, const SurfaceGuards& guards, WorkerPool* pool,
                          const uint8_t* occupied_blocks) {
  if (guards.gap_radius <= 0 && guards.edge_radius <= 0) {
    silenceNearOccupied(grid, guards.sky_value, guards.sky_radius, pool, occupied_blocks);
    return 0;
  }
  Guard guard{guards.sky_radius > 0 ? guards.sky_value : kNoValue, guards.sky_radius,
              guards.gap_radius > 0 ? 0.0f : kNoValue, guards.gap_radius};
  if (guards.edge_radius > 0) {
    guard.edge_value = guards.free_value;
    guard.edge_radius = guards.edge_radius;
    guard.grid_camera = guards.grid_camera;
  }
  GuardPass pass(grid);
  pass.guardNearOccupied(guard, pool, occupied_blocks);
  return guards.gap_radius > 0 ? pass.settleMarks(guards.free_value, pool) : 0;
}

}  // namespace stereo_occupancy
