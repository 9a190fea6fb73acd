#include "stereo_occupancy/grid_update.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <vector>

// The encoding's masks in AVX2's eight lanes where the CPU has them
// (chosen at run time, avx2Enabled()).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
#define STEREO_OCCUPANCY_AVX2_MASKS 1
#include <immintrin.h>
#endif

#include "stereo_occupancy/cpu_features.h"

namespace stereo_occupancy {

bool GridUpdateView::isConsistent(std::string* why) const {
  auto fail = [why](const std::string& text) {
    if (why) *why = text;
    return false;
  };
  if (!(std::isfinite(resolution_m) && resolution_m > 0.0)) return fail("resolution is not finite and > 0");
  if (!W_sensor_origin.allFinite()) return fail("sensor origin is not finite");
  if ((size.array() < 0).any()) return fail("negative grid size");
  const uint64_t cells = static_cast<uint64_t>(size.x()) * size.y() * size.z();
  if (cells > std::numeric_limits<uint32_t>::max()) return fail("grid too large for 32-bit cell indices");
  for (int a = 0; a < 3; ++a)  // every global index origin_index + local fits an int
    if (int64_t{origin_index[a]} + size[a] > std::numeric_limits<int>::max())
      return fail("the grid reaches beyond the 32-bit index range");
  if (run_start.size() != run_length.size()) return fail("run_start and run_length differ in length");
  uint64_t total = 0, end = 0;
  for (size_t k = 0; k < run_start.size(); ++k) {
    if (run_start[k] < end) return fail("runs overlap or are not sorted");
    end = static_cast<uint64_t>(run_start[k]) + run_length[k];
    if (end > cells) return fail("a run ends outside the grid");
    total += run_length[k];
  }
  if (total != log_odds.size())
    return fail("the runs cover " + std::to_string(total) + " cells but " + std::to_string(log_odds.size()) +
                " values came");
  // Finite: the exponent bits not all set. One pass without an early exit (vectorisable).
  uint32_t not_finite = 0;
  for (float v : log_odds) {
    uint32_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    not_finite |= static_cast<uint32_t>((bits & 0x7f800000u) == 0x7f800000u);
  }
  if (not_finite != 0) return fail("a log-odds value is not finite");
  return true;
}

namespace {

/// Cells per part of the encoding on a pool (a multiple of kInformationBlock):
/// a part's scan takes tens of microseconds, far more than its hand-out.
constexpr size_t kEncodeChunkCells = size_t{1} << 16;

/// True if a cell carries information: known and not exactly 0.
inline bool informative(float v) { return v != LocalGrid::kUnknown && v != 0.0f; }

/// Blocks whose masks masksOf() computes in one call (a stack array).
constexpr size_t kMaskBatch = 256;

#if STEREO_OCCUPANCY_AVX2_MASKS
/// masksOf() eight cells a lane group: the same compares (not equal,
/// unordered: NaN holds information, as in _mm_cmpneq_ps).
__attribute__((target("avx2"))) void masksOfAvx2(const float* cells, size_t blocks, uint16_t* masks) {
  static_assert(kInformationBlock == 16, "two groups of eight lanes");
  const __m256 unknown = _mm256_set1_ps(LocalGrid::kUnknown), zero = _mm256_setzero_ps();
  for (size_t b = 0; b < blocks; ++b) {
    const __m256 lo = _mm256_loadu_ps(cells + b * kInformationBlock);
    const __m256 hi = _mm256_loadu_ps(cells + b * kInformationBlock + 8);
    const int lo_bits = _mm256_movemask_ps(
        _mm256_and_ps(_mm256_cmp_ps(lo, unknown, _CMP_NEQ_UQ), _mm256_cmp_ps(lo, zero, _CMP_NEQ_UQ)));
    const int hi_bits = _mm256_movemask_ps(
        _mm256_and_ps(_mm256_cmp_ps(hi, unknown, _CMP_NEQ_UQ), _mm256_cmp_ps(hi, zero, _CMP_NEQ_UQ)));
    masks[b] = static_cast<uint16_t>(lo_bits | (hi_bits << 8));
  }
}
#endif

/// informationMask() of @p blocks whole blocks from @p cells.
void masksOf(const float* cells, size_t blocks, uint16_t* masks) {
#if STEREO_OCCUPANCY_AVX2_MASKS
  if (avx2Enabled()) {
    masksOfAvx2(cells, blocks, masks);
    return;
  }
#endif
  for (size_t b = 0; b < blocks; ++b) masks[b] = static_cast<uint16_t>(informationMask(cells + b * kInformationBlock));
}

/// The runs of informative cells in [begin, end) of @p data (begin a
/// multiple of kInformationBlock), appended to @p start and @p length;
/// returns the cells they cover.
size_t findRuns(const float* data, size_t begin, size_t end, std::vector<uint32_t>* start,
                std::vector<uint32_t>* length) {
  // kInformationBlock cells at a time as a bit mask: a run's ends are the
  // mask's changes (no branch per cell). The masks of a batch of whole
  // blocks come first, in a loop of their own (in vector lanes); then four
  // blocks all empty or all in a run cost one compare.
  constexpr uint32_t kFull = (uint32_t{1} << kInformationBlock) - 1;
  constexpr uint64_t kFourFull = 0xffffffffffffffffULL;  // four kFull masks
  size_t cells = 0, first = 0;
  bool in_run = false;
  // The changes of run state in the block of cells from i (mask: its
  // informative cells, within: the cells it has).
  auto addChanges = [&](size_t i, uint32_t mask, uint32_t within) {
    for (uint32_t j = 0;;) {
      const uint32_t changes = (in_run ? ~mask : mask) & within & (kFull << j);
      if (changes == 0) return;
      j = static_cast<uint32_t>(__builtin_ctz(changes));
      if (in_run) {
        start->push_back(static_cast<uint32_t>(first));
        length->push_back(static_cast<uint32_t>(i + j - first));
        cells += i + j - first;
      } else {
        first = i + j;
      }
      in_run = !in_run;
    }
  };
  uint16_t masks[kMaskBatch];
  const size_t whole_end = begin + (end - begin) / kInformationBlock * kInformationBlock;
  size_t i = begin;
  while (i < whole_end) {
    const size_t blocks = std::min(kMaskBatch, (whole_end - i) / kInformationBlock);
    masksOf(data + i, blocks, masks);
    for (size_t k = 0; k < blocks; ++k) {
      if (k + 4 <= blocks) {
        uint64_t four;
        std::memcpy(&four, masks + k, sizeof four);
        if (four == (in_run ? kFourFull : 0)) {
          k += 3;
          continue;
        }
      }
      if (masks[k] != (in_run ? kFull : 0u)) addChanges(i + k * kInformationBlock, masks[k], kFull);
    }
    i += blocks * kInformationBlock;
  }
  if (i < end) {  // the last, partial block
    uint32_t mask = 0;
    for (size_t j = 0; j < end - i; ++j) mask |= static_cast<uint32_t>(informative(data[i + j])) << j;
    addChanges(i, mask, (uint32_t{1} << (end - i)) - 1);
  }
  if (in_run) {
    start->push_back(static_cast<uint32_t>(first));
    length->push_back(static_cast<uint32_t>(end - first));
    cells += end - first;
  }
  return cells;
}

/// One part's runs on a pool.
struct PartRuns {
  std::vector<uint32_t> start, length;
  size_t cells = 0;
};

/// encodeGridUpdate()'s runs and values on a pool: each part's runs found at
/// once, then joined in order (a run that reaches a part's end goes on in
/// the next part's first run if it starts there), the values copied part by
/// part. The same runs as one scan.
void encodeOnPool(const float* data, size_t n, GridUpdate* update, WorkerPool* pool) {
  const size_t parts = (n + kEncodeChunkCells - 1) / kEncodeChunkCells;
  std::vector<PartRuns> found(parts);
  pool->runInChunks(n, kEncodeChunkCells, [&](size_t begin, size_t end) {
    PartRuns& part = found[begin / kEncodeChunkCells];
    part.cells = findRuns(data, begin, end, &part.start, &part.length);
  });
  size_t cells = 0;
  std::vector<size_t> offset(parts);
  for (size_t p = 0; p < parts; ++p) {
    offset[p] = cells;
    cells += found[p].cells;
    for (size_t k = 0; k < found[p].start.size(); ++k) {
      const uint32_t start = found[p].start[k], length = found[p].length[k];
      if (!update->run_start.empty() && update->run_start.back() + update->run_length.back() == start) {
        update->run_length.back() += length;  // a run across the parts' border
      } else {
        update->run_start.push_back(start);
        update->run_length.push_back(length);
      }
    }
  }
  update->log_odds.resize(cells);
  float* out = update->log_odds.data();
  pool->run(parts, [&](size_t p, unsigned) {
    float* to = out + offset[p];
    for (size_t k = 0; k < found[p].start.size(); ++k) {
      std::memcpy(to, data + found[p].start[k], found[p].length[k] * sizeof(float));
      to += found[p].length[k];
    }
  });
}

}  // namespace

void encodeGridUpdate(const LocalGrid& grid, const Eigen::Vector3d& W_sensor_origin, GridUpdate* update,
                      WorkerPool* pool) {
  update->W_sensor_origin = W_sensor_origin;
  update->resolution_m = grid.resolution();
  update->origin_index = grid.originIndex();
  update->size = grid.size();
  update->run_start.clear();
  update->run_length.clear();
  update->log_odds.clear();
  releaseIfOversized(&update->log_odds, grid.numCells());
  releaseIfOversized(&update->run_start, grid.numCells() / 2);
  releaseIfOversized(&update->run_length, grid.numCells() / 2);
  const float* data = grid.data();
  const size_t n = grid.numCells();
  if (pool && pool->size() > 1 && n > kEncodeChunkCells) {
    encodeOnPool(data, n, update, pool);
    return;
  }
  findRuns(data, 0, n, &update->run_start, &update->run_length);
  for (size_t k = 0; k < update->run_start.size(); ++k) {
    const float* run = data + update->run_start[k];
    update->log_odds.insert(update->log_odds.end(), run, run + update->run_length[k]);
  }
}

namespace {

/// One row's stretch of an update's cells, [x0, x1) in local cells, with
/// values from log_odds[v] on.
struct Segment {
  int64_t y, z, x0, x1;
  size_t v;
};

/// The update's runs cut at the rows' ends (a run may go on into the next
/// row), sorted by row, then x. Memory and work follow the runs, never the
/// box the update claims: a message may claim 65535 x 65535 cells and carry one.
std::vector<Segment> rowSegments(const GridUpdateView& u) {
  const int64_t nx = u.size.x(), ny = u.size.y();
  std::vector<Segment> segments;
  segments.reserve(u.run_start.size());
  size_t v = 0;
  for (size_t k = 0; k < u.run_start.size(); ++k) {
    uint64_t i = u.run_start[k], left = u.run_length[k];
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
  return segments;
}

/// Local index of the 2x2x2 block (even global index) a local index is in.
int64_t blockStart(int64_t local, int64_t origin) { return local - ((origin + local) & 1); }
/// The end of the block a local end index is in.
int64_t blockEnd(int64_t local_end, int64_t origin) { return local_end + ((origin + local_end) & 1); }

/// The blocks of the update's strips: a strip is the four rows
/// (y0 + dy, z0 + dz), q = dy + 2 dz, of one line of blocks.
class StripWalk {
 public:
  StripWalk(const GridUpdateView& u, const std::vector<Segment>& segments, const SiblingBlockVisitor& f)
      : log_odds_(u.log_odds), origin_(u.origin_index.cast<int64_t>()), segments_(segments), f_(f) {}

  /// Visits the strip at (y0, z0) whose segments per row are the ranges
  /// [begin[q], end[q]) of the segments, a cluster at a time.
  void visit(int64_t y0, int64_t z0, const size_t (&begin)[4], const size_t (&end)[4]) {
    size_t next[4] = {begin[0], begin[1], begin[2], begin[3]};
    for (;;) {
      // A cluster: the segments whose blocks overlap, in x order; rows_[q] spans it.
      int64_t xs = std::numeric_limits<int64_t>::max();
      for (int q = 0; q < 4; ++q)
        if (next[q] < end[q]) xs = std::min(xs, blockStart(segments_[next[q]].x0, origin_.x()));
      if (xs == std::numeric_limits<int64_t>::max()) return;
      size_t first[4], last[4];
      for (int q = 0; q < 4; ++q) first[q] = last[q] = next[q];
      int64_t xe = xs;  // the cluster's blocks: [xs, xe), each segment adding at most its length + 2
      for (bool grew = true; grew;) {
        grew = false;
        for (int q = 0; q < 4; ++q)
          for (; last[q] < end[q] && blockStart(segments_[last[q]].x0, origin_.x()) <= xe; ++last[q], grew = true)
            xe = std::max(xe, blockEnd(segments_[last[q]].x1, origin_.x()));
      }
      fillRows(xs, xe, first, last);
      for (int q = 0; q < 4; ++q) next[q] = last[q];
      visitCluster(y0, z0, xs, xe, first, last);
    }
  }

 private:
  /// rows_[q] over the cluster [xs, xe): the values of its segments, NaN where no cell.
  void fillRows(int64_t xs, int64_t xe, const size_t (&first)[4], const size_t (&last)[4]) {
    const size_t width = static_cast<size_t>(xe - xs);
    for (int q = 0; q < 4; ++q) {
      if (first[q] == last[q]) continue;
      rows_[q].assign(width, std::numeric_limits<float>::quiet_NaN());
      for (size_t k = first[q]; k < last[q]; ++k)
        std::copy(log_odds_.begin() + segments_[k].v,
                  log_odds_.begin() + segments_[k].v + (segments_[k].x1 - segments_[k].x0),
                  rows_[q].begin() + (segments_[k].x0 - xs));
    }
  }

  /// f() for each block of the cluster [xs, xe) that holds a cell.
  void visitCluster(int64_t y0, int64_t z0, int64_t xs, int64_t xe, const size_t (&first)[4],
                    const size_t (&last)[4]) const {
    for (int64_t x0 = xs; x0 < xe; x0 += 2) {
      float values[8];
      bool any = false;
      for (int q = 0; q < 4; ++q) {
        if (first[q] == last[q]) {
          values[2 * q] = values[2 * q + 1] = std::numeric_limits<float>::quiet_NaN();
          continue;
        }
        values[2 * q] = rows_[q][x0 - xs];
        values[2 * q + 1] = rows_[q][x0 + 1 - xs];
        any |= (values[2 * q] == values[2 * q]) | (values[2 * q + 1] == values[2 * q + 1]);
      }
      if (any)
        f_(Eigen::Vector3i(static_cast<int>(origin_.x() + x0), static_cast<int>(origin_.y() + y0),
                           static_cast<int>(origin_.z() + z0)),
           values);
    }
  }

  const ConstArray<float>& log_odds_;
  const Eigen::Matrix<int64_t, 3, 1> origin_;
  const std::vector<Segment>& segments_;
  const SiblingBlockVisitor& f_;
  std::vector<float> rows_[4];  ///< one cluster's four rows
};

/// The strips of segments [s, s_end) (whole pairs of z planes) in z, then y
/// order: a pair of planes (z0, z0 + 1) are two consecutive ranges of
/// segments, each sorted by y; merged by block row.
void walkStrips(const GridUpdateView& u, const std::vector<Segment>& segments, size_t s, size_t s_end,
                const SiblingBlockVisitor& f) {
  StripWalk strips(u, segments, f);
  const int64_t oy = u.origin_index.y(), oz = u.origin_index.z();
  while (s < s_end) {
    const int64_t z0 = blockStart(segments[s].z, oz);
    size_t plane_end[2], cursor[2];
    cursor[0] = s;
    size_t e = s;
    while (e < s_end && segments[e].z == z0) ++e;
    plane_end[0] = e;
    cursor[1] = e;
    while (e < s_end && segments[e].z == z0 + 1) ++e;
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
      strips.visit(y0, z0, begin, end);
    }
  }
}

}  // namespace

void GridUpdateView::forEachSiblingBlock(const SiblingBlockVisitor& f) const {
  if (log_odds.empty()) return;
  const std::vector<Segment> segments = rowSegments(*this);
  walkStrips(*this, segments, 0, segments.size(), f);
}

}  // namespace stereo_occupancy
