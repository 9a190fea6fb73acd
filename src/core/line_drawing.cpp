#include "stereo_occupancy/line_drawing.h"

#include <algorithm>
#include <cmath>

#if defined(__SSE2__) && defined(__x86_64__)
#define STEREO_OCCUPANCY_X86_64_SIMD 1
#include <emmintrin.h>
#elif defined(__aarch64__) && defined(__ARM_NEON) && !defined(__AARCH64EB__)  // lanes as little-endian
#define STEREO_OCCUPANCY_AARCH64_SIMD 1
#include <arm_neon.h>
#endif

#include "stereo_occupancy/integer_math.h"

// drawLine()'s steps run once per line, 10^5 lines an image: inlined into it,
// as one function they were (out of line they cost time: docs/performance.md).
#if defined(__GNUC__)
#define STEREO_OCCUPANCY_INLINE inline __attribute__((always_inline))
#else
#define STEREO_OCCUPANCY_INLINE inline
#endif

// The per-pixel loops the compiler vectorises run in twice the lanes with
// AVX2 where the CPU has it: GCC compiles them twice and the loader picks one
// (function multiversioning). Both do the same IEEE operations (no FMA: the
// core builds with -ffp-contract=off), so the keys are the same.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
#define STEREO_OCCUPANCY_AVX2_CLONE __attribute__((target_clones("avx2", "default")))
#else
#define STEREO_OCCUPANCY_AVX2_CLONE
#endif

namespace stereo_occupancy {

namespace {

/// Where a line's walk over the inner slabs stands: the current cell's minor
/// coordinates a and b in 32.32 fixed point (exact sums, floor by shift) and
/// its index part along the major axis, their steps per slab, and the index
/// strides of the minor axes.
struct LineCursor {
  int64_t pos_a, pos_b, index_major;
  int64_t step_a, step_b, step_index_major;
  int64_t stride_a, stride_b;

  int64_t index() const { return index_major + (pos_a >> 32) * stride_a + (pos_b >> 32) * stride_b; }
  void advance() {
    pos_a += step_a;
    pos_b += step_b;
    index_major += step_index_major;
  }
};

/// 2^32: one cell in LineCursor's fixed point.
constexpr double kFixedPointOne = 4294967296.0;

/// Obstacle priority (section V-A, step 2b): a cell keeps the larger value.
inline void drawCell(float* data, int64_t index, float value) {
  float& cell = data[index];
  cell = std::max(cell, value);
}

/// A line's walk through the grid: one cell per slab of the major axis (a 3D
/// Bresenham line); in each slab the cell is the one where the ray crosses
/// the slab's centre plane, and the ray's range there is the cell's. Ranges
/// t are in cells along the ray.
struct LineWalk {
  int major = 0, minor_a = 1, minor_b = 2;  ///< axes
  int first_slab = 0;                       ///< index along the major axis of the first slab
  int slabs = 0;                            ///< slabs crossed, both ends included
  int step = 1;                             ///< +1 or -1 along the major axis
  double t_begin = 0.0, t_end = 0.0;        ///< the segment drawn
  double t_first = 0.0;                     ///< at the first slab's centre plane; |t_first - t_begin| <= dt / 2
  double dt = 0.0;                          ///< from one slab's centre plane to the next
  /// Both ends inside the grid (the usual case: the grid covers the
  /// frustum), so the whole segment is and no index needs a check.
  bool inside = true;
};

#if STEREO_OCCUPANCY_X86_64_SIMD
/// The free run's cells two at a time, in the 64-bit lanes of SSE2
/// registers: the same 32.32 fixed-point sums and index products as the
/// scalar loop (inside the grid the positions are >= 0 and the cell
/// coordinates and strides fit 32 bits, as _mm_mul_epu32 needs), then a
/// max-store per cell (there is no scatter). Returns the first k not drawn
/// and leaves @p r at it.
int freeRunSse2(float* data, int k, int k_end, float free_value, LineCursor* r) {
  if (k + 1 >= k_end) return k;
  const __m128i two_dta = _mm_set1_epi64x(2 * r->step_a), two_dtb = _mm_set1_epi64x(2 * r->step_b);
  const __m128i two_didx_m = _mm_set1_epi64x(2 * r->step_index_major);
  const __m128i vsa = _mm_set1_epi64x(r->stride_a), vsb = _mm_set1_epi64x(r->stride_b);
  __m128i va = _mm_set_epi64x(r->pos_a + r->step_a, r->pos_a);  // lane 0: cell k, lane 1: cell k + 1
  __m128i vb = _mm_set_epi64x(r->pos_b + r->step_b, r->pos_b);
  __m128i vm = _mm_set_epi64x(r->index_major + r->step_index_major, r->index_major);
  for (; k + 1 < k_end; k += 2) {
    // The high halves (the cell coordinates) moved to the low ones, which _mm_mul_epu32 multiplies.
    const __m128i ca = _mm_shuffle_epi32(va, _MM_SHUFFLE(3, 3, 1, 1));
    const __m128i cb = _mm_shuffle_epi32(vb, _MM_SHUFFLE(3, 3, 1, 1));
    const __m128i idx = _mm_add_epi64(vm, _mm_add_epi64(_mm_mul_epu32(ca, vsa), _mm_mul_epu32(cb, vsb)));
    float* c0 = data + _mm_cvtsi128_si64(idx);
    float* c1 = data + _mm_cvtsi128_si64(_mm_unpackhi_epi64(idx, idx));
    *c0 = std::max(*c0, free_value);  // obstacle priority (section V-A, step 2b)
    *c1 = std::max(*c1, free_value);
    va = _mm_add_epi64(va, two_dta);
    vb = _mm_add_epi64(vb, two_dtb);
    vm = _mm_add_epi64(vm, two_didx_m);
  }
  r->pos_a = _mm_cvtsi128_si64(va);
  r->pos_b = _mm_cvtsi128_si64(vb);
  r->index_major = _mm_cvtsi128_si64(vm);
  return k;
}
#endif

#if STEREO_OCCUPANCY_AARCH64_SIMD
/// freeRunSse2() in NEON's 64-bit lanes: the same 32.32 fixed-point sums;
/// one unzip gathers the four cell coordinates (the lanes' high halves),
/// two widening multiply-adds by the strides give both cells' indices, then
/// a max-store per cell. The same preconditions (positions >= 0, strides
/// within 32 bits) and the same cells.
int freeRunNeon(float* data, int k, int k_end, float free_value, LineCursor* r) {
  if (k + 1 >= k_end) return k;
  const int64x2_t two_dta = vdupq_n_s64(2 * r->step_a), two_dtb = vdupq_n_s64(2 * r->step_b);
  const int64x2_t two_didx_m = vdupq_n_s64(2 * r->step_index_major);
  const uint32x2_t vsa = vdup_n_u32(static_cast<uint32_t>(r->stride_a));
  const uint32x4_t vsb = vdupq_n_u32(static_cast<uint32_t>(r->stride_b));
  const int64_t a[2] = {r->pos_a, r->pos_a + r->step_a}, b[2] = {r->pos_b, r->pos_b + r->step_b};
  const int64_t m[2] = {r->index_major, r->index_major + r->step_index_major};
  int64x2_t va = vld1q_s64(a), vb = vld1q_s64(b), vm = vld1q_s64(m);  // lane 0: cell k, lane 1: cell k + 1
  for (; k + 1 < k_end; k += 2) {
    // {a_k, a_k+1, b_k, b_k+1}: the high halves of the positions.
    const uint32x4_t cells = vuzp2q_u32(vreinterpretq_u32_s64(va), vreinterpretq_u32_s64(vb));
    const uint64x2_t idx = vmlal_high_u32(vmlal_u32(vreinterpretq_u64_s64(vm), vget_low_u32(cells), vsa), cells, vsb);
    float* c0 = data + static_cast<int64_t>(vgetq_lane_u64(idx, 0));
    float* c1 = data + static_cast<int64_t>(vgetq_lane_u64(idx, 1));
    *c0 = std::max(*c0, free_value);  // obstacle priority (section V-A, step 2b)
    *c1 = std::max(*c1, free_value);
    va = vaddq_s64(va, two_dta);
    vb = vaddq_s64(vb, two_dtb);
    vm = vaddq_s64(vm, two_didx_m);
  }
  r->pos_a = vgetq_lane_s64(va, 0);
  r->pos_b = vgetq_lane_s64(vb, 0);
  r->index_major = vgetq_lane_s64(vm, 0);
  return k;
}
#endif

}  // namespace

void stableOrderAscending(const float* keys, int count, int* order) {
  if (count > kRankOrderedKeys) {  // insertion sort
    for (int i = 0; i < count; ++i) {
      int j = i;
      for (; j > 0 && keys[order[j - 1]] > keys[i]; --j) order[j] = order[j - 1];
      order[j] = i;
    }
    return;
  }
  // A span has about ten leaves, on which the insertion sort's branches
  // mispredicted: a key's place is the number of keys before it in the
  // order, counted by compares without branches.
  for (int i = 0; i < count; ++i) {
    const float key = keys[i];
    int rank = 0;
    for (int j = 0; j < i; ++j) rank += keys[j] <= key;
    for (int j = i + 1; j < count; ++j) rank += keys[j] < key;
    order[rank] = i;
  }
}

SimdLevel availableSimdLevel() {
#if STEREO_OCCUPANCY_X86_64_SIMD
  return SimdLevel::kSse2;
#elif STEREO_OCCUPANCY_AARCH64_SIMD
  return SimdLevel::kNeon;
#else
  return SimdLevel::kScalar;
#endif
}

bool isAvailable(SimdLevel level) { return level == SimdLevel::kScalar || level == availableSimdLevel(); }

const char* toString(SimdLevel level) {
  switch (level) {
    case SimdLevel::kScalar:
      return "scalar";
    case SimdLevel::kSse2:
      return "sse2";
    case SimdLevel::kNeon:
      return "neon";
  }
  return "?";
}

LineDrawer::LineDrawer(const StereoCameraModel& camera, const LogOddsTable& table, const PyramidLevelTable& levels,
                       SimdLevel simd)
    : camera_(camera), table_(table), levels_(levels), simd_(isAvailable(simd) ? simd : availableSimdLevel()) {}

LineDrawer::RayGrid LineDrawer::rayGrid(const Eigen::Vector3d& W_origin, LocalGrid* grid) const {
  RayGrid g;
  g.c = grid->resolution();
  g.inv_c = 1.0 / g.c;
  g.g0 = (W_origin - grid->originPosition()) * g.inv_c;
  g.W_origin = W_origin;
  g.origin_index = grid->originIndex();
  g.max_range_m = camera_.config().max_range_m;
  g.size = grid->size();
  g.stride[0] = 1;
  g.stride[1] = g.size.x();
  g.stride[2] = static_cast<int64_t>(g.size.x()) * g.size.y();
  for (int i = 0; i < 3; ++i) g.upper[i] = static_cast<double>(g.size[i]) - RayGrid::kMargin;
  g.data = grid->data();
  return g;
}

LineDrawer::RayGrid LineDrawer::imageGrid(const Eigen::Vector3d& W_origin, LocalGrid* grid) {
  RayGrid g = rayGrid(W_origin, grid);
  if (!(table_.hitLogOdds() > 0.0f)) {  // no point hits (the paper's profile): nothing to flag
    hit_blocks_.clear();
    return g;
  }
  releaseIfOversized(&hit_blocks_, grid->numBlocks());
  hit_blocks_.assign(grid->numBlocks(), 0);
  g.hit_blocks = hit_blocks_.data();
  g.blocks_per_row = grid->blocksPerRow();
  return g;
}

namespace {

/// The walk of the segment [t_begin, t_end] of the ray g.g0 + t·W_dir (t in cells).
template <class Grid>
STEREO_OCCUPANCY_INLINE LineWalk walkOf(const Grid& g, const Eigen::Vector3d& W_dir, double t_begin, double t_end) {
  LineWalk w;
  w.t_begin = t_begin;
  w.t_end = t_end;
  const double abs_dir[3] = {std::abs(W_dir[0]), std::abs(W_dir[1]), std::abs(W_dir[2])};
  w.major = abs_dir[1] > abs_dir[0] ? 1 : 0;  // the first of the largest, as Eigen's maxCoeff
  if (abs_dir[2] > abs_dir[w.major]) w.major = 2;
  static constexpr int kNextAxis[3] = {1, 2, 0};
  w.minor_a = kNextAxis[w.major];
  w.minor_b = kNextAxis[w.minor_a];
  double begin[3], end[3];
  for (int i = 0; i < 3; ++i) {
    begin[i] = g.g0[i] + W_dir[i] * t_begin;
    end[i] = g.g0[i] + W_dir[i] * t_end;
    w.inside &= (std::min(begin[i], end[i]) >= Grid::kMargin) & (std::max(begin[i], end[i]) < g.upper[i]);
  }
  w.first_slab = floorToInt(begin[w.major]);
  const int last_slab = floorToInt(end[w.major]);
  w.step = W_dir[w.major] > 0.0 ? 1 : -1;
  w.slabs = std::abs(last_slab - w.first_slab) + 1;
  w.dt = 1.0 / abs_dir[w.major];
  w.t_first = (w.first_slab + 0.5 - g.g0[w.major]) / W_dir[w.major];
  return w;
}

/// The first or the last slab, only partly on the segment: the cell of the
/// segment's point nearest to the slab's centre plane (at t), skipped
/// outside the grid (only when the grid does not cover the segment).
/// Returns the cells written (0 or 1).
template <class Grid>
STEREO_OCCUPANCY_INLINE uint64_t drawEndCell(const Grid& g, const Eigen::Vector3d& W_dir, const LineWalk& w,
                                             const RangeProfile& profile, int slab, double t) {
  t = std::clamp(t, w.t_begin, w.t_end);
  const int cell_a = floorToInt(g.g0[w.minor_a] + W_dir[w.minor_a] * t);
  const int cell_b = floorToInt(g.g0[w.minor_b] + W_dir[w.minor_b] * t);
  if (!w.inside && (slab < 0 || slab >= g.size[w.major] || cell_a < 0 || cell_a >= g.size[w.minor_a] || cell_b < 0 ||
                    cell_b >= g.size[w.minor_b]))
    return 0;
  drawCell(g.data, slab * g.stride[w.major] + cell_a * g.stride[w.minor_a] + cell_b * g.stride[w.minor_b],
           profile.tableAt(static_cast<float>(t * g.c)));
  return 1;
}

/// p_hit in the cell that holds the world point @p W_point: floor(W_p / c)
/// by the reciprocal, as LocalGrid::globalIndex() keys it (exactly where 1/c
/// is exact), skipped outside the grid. Returns the cells written (0 or 1).
template <class Grid>
STEREO_OCCUPANCY_INLINE uint64_t drawHitAt(const Grid& g, const Eigen::Vector3d& W_point, float hit_log_odds) {
  int64_t index = 0;
  int cell[3];
  for (int i = 0; i < 3; ++i) {
    cell[i] = floorToInt(W_point[i] * g.inv_c) - g.origin_index[i];
    if (cell[i] < 0 || cell[i] >= g.size[i]) return 0;
    index += cell[i] * g.stride[i];
  }
  drawCell(g.data, index, hit_log_odds);
  if (g.hit_blocks)  // the cell's block, as LocalGrid::numBlocks() numbers them
    g.hit_blocks[(cell[1] + int64_t{cell[2]} * g.size[1]) * g.blocks_per_row +
                 static_cast<unsigned>(cell[0]) / kInformationBlock] = 1;
  return 1;
}

/// The surface profile's hit (RangeProfile::hasPointHit()): p_hit in the cell
/// that holds the measured point, if l_begin <= l_p <= l_stop. A line's walk
/// takes one cell per slab, at the slab's centre plane, and a slab spans dt
/// >= c of range: a cell-wide window around its centre would miss the point
/// in a fraction 1 - 1/dt of the slabs (29 % along a face diagonal, 42 %
/// along the cube's), and the centre plane's cell is not always the point's.
/// Returns the cells written (0 or 1).
template <class Grid>
STEREO_OCCUPANCY_INLINE uint64_t drawPointHit(const Grid& g, const Eigen::Vector3d& W_dir, const RangeProfile& profile,
                                              double l_begin, double l_stop) {
  const double l_p = profile.l_p_m;
  if (!profile.hasPointHit() || !(l_p >= l_begin && l_p <= l_stop)) return 0;
  return drawHitAt(g, g.W_origin + W_dir * l_p, profile.hit_log_odds);
}

/// Component i of T_W_C·p = R_W_C·p + W_origin, summed in Eigen's order
/// (the same bits as Eigen's product; floating-point contraction is off):
/// drawHitAtDepth() and the pixel hits' keys of one axis share it.
STEREO_OCCUPANCY_INLINE double pointComponent(const Eigen::Matrix3d& R_W_C, const Eigen::Vector3d& C_point,
                                              const Eigen::Vector3d& W_origin, int i) {
  return ((R_W_C(i, 0) * C_point[0] + R_W_C(i, 1) * C_point[1]) + R_W_C(i, 2) * C_point[2]) + W_origin[i];
}

/// drawPointHit() for a ray known by its pixel: the measured point
/// W_p = T_W_C·(z·C_ray) (eqs. 1, 2; C_ray has z = 1), if z_begin <= z and
/// |p_C| <= the maximum range. No square root or division. The lines of
/// pixels and blocks put their hits here, and PixelHitRows keys each
/// pixel's as it does. Returns the cells written (0 or 1).
template <class Grid>
STEREO_OCCUPANCY_INLINE uint64_t drawHitAtDepth(const Grid& g, const Eigen::Matrix3d& R_W_C,
                                                const Eigen::Vector3d& C_ray, double z_m, double z_begin_m,
                                                float hit_log_odds) {
  if (!(z_m >= z_begin_m) || z_m * z_m * C_ray.squaredNorm() > g.max_range_m * g.max_range_m) return 0;
  const Eigen::Vector3d C_point = C_ray * z_m;
  return drawHitAt(
      g,
      Eigen::Vector3d(pointComponent(R_W_C, C_point, g.W_origin, 0), pointComponent(R_W_C, C_point, g.W_origin, 1),
                      pointComponent(R_W_C, C_point, g.W_origin, 2)),
      hit_log_odds);
}

/// Every pixel's point hit of whole image rows, keyed as drawHitAtDepth()
/// keys it, but in float, a chunk of pixels at a time in a loop the
/// compiler vectorises (per pixel through drawHitAtDepth(), the hits alone
/// cost twice the bounded descent). A pixel whose point lies within
/// margin_cells of a cell face across an axis gets that axis's cell again
/// in double as drawHitAt() computes it (pointComponent()), and one within
/// a relative margin of the maximum range gets drawHitAtDepth() itself: the
/// cells are drawHitAtDepth()'s exactly. (A plane on a cell face, as in the
/// synthetic scenes, puts all its pixels on the double path: rekeyChunk()
/// takes such chunks in vector lanes too.)
class PixelHitRows {
 public:
  /// Pixels keyed per chunk.
  static constexpr int kChunk = 64;
  /// The float keys' error stays below 2^-20 of the largest magnitude they
  /// handle [cells]; the margin is 8 times that, at least 2^-8 of a cell.
  static constexpr float kMinMarginCells = 1.0f / 256.0f;
  static constexpr double kRelativeMargin = 1.0 / (1 << 17);
  /// Beyond this margin the float keys are not worth it: all in double.
  static constexpr float kMaxMarginCells = 0.125f;
  /// From this many kRekey pixels in a chunk, rekeyChunk() keys them all at
  /// once; fewer go one by one (a vector pass costs about 8 pixels' worth).
  static constexpr int kVectorRekeys = 8;

  /// What keyChunk() found for one pixel: how to draw its hit.
  enum Draw : int32_t {
    kSkip = 0,     ///< not measured, or beyond the maximum range
    kKeyed = 1,    ///< in the grid's cell index[k], whose block is block[k]
    kRekey = 2,    ///< near a cell face: its unsure axes again in double
    kExact = 3,    ///< too near the maximum range to tell in float: drawHitAtDepth()
    kOutside = 4,  ///< in range, surely outside the grid
  };

  /// The keys of up to kChunk pixels.
  struct Keys {
    int32_t draw[kChunk];     ///< Draw
    int32_t unsure[kChunk];   ///< bit i: near a cell face across axis i (cell[i] is only a guess)
    int32_t cell[3][kChunk];  ///< the cell along each axis from the grid's first (floor(q) where sure)
    uint32_t index[kChunk];   ///< kKeyed: the cell's index in the grid
    uint32_t block[kChunk];   ///< kKeyed: its block, as LocalGrid::numBlocks() numbers them
  };

  template <class Grid>
  PixelHitRows(const Grid& g, const StereoCameraModel& camera, const Eigen::Matrix3d& R_W_C) {
    const StereoCameraConfig& cfg = camera.config();
    const double inv_f = 1.0 / cfg.focal_length_px;
    const Eigen::Vector3d per_x = R_W_C.col(0) * (inv_f * g.inv_c);
    const Eigen::Vector3d per_y = R_W_C.col(1) * (inv_f * g.inv_c);
    const Eigen::Vector3d at_00 = R_W_C * Eigen::Vector3d(-cfg.cx_px * inv_f, -cfg.cy_px * inv_f, 1.0) * g.inv_c;
    // Depths beyond twice the range are beyond it: capped, for bounded keys.
    const double z_cap = 2.0 * g.max_range_m;
    // 1 + |cx|/f + w/f + |cy|/f + h/f bounds every ray's terms.
    const double span = 1.0 + (std::abs(cfg.cx_px) + cfg.width_px + std::abs(cfg.cy_px) + cfg.height_px) * inv_f;
    double largest = 0.0;
    for (int i = 0; i < 3; ++i) {
      per_x_[i] = static_cast<float>(per_x[i]);
      per_y_[i] = static_cast<float>(per_y[i]);
      at_00_[i] = static_cast<float>(at_00[i]);
      origin_[i] = static_cast<float>(g.g0[i]);  // relative to the grid: small numbers
      largest = std::max(largest, std::abs(g.g0[i]) + z_cap * g.inv_c * span);
    }
    margin_cells_ = std::max(kMinMarginCells, static_cast<float>(largest * kRelativeMargin));
    // Indices in 32 bits (unsigned: a pixel outside the grid wraps, harmlessly).
    const double cells = static_cast<double>(g.size[0]) * g.size[1] * g.size[2];
    in_float_ = margin_cells_ <= kMaxMarginCells && largest < double{1 << 30} && cells < double{1u << 31};
    for (int i = 0; i < 3; ++i) size_[i] = static_cast<uint32_t>(g.size[i]);
    blocks_per_row_ = static_cast<uint32_t>(g.blocks_per_row);
    z_cap_ = static_cast<float>(z_cap);
    cx_ = static_cast<float>(cfg.cx_px);
    cy_ = static_cast<float>(cfg.cy_px);
    inv_f_ = static_cast<float>(inv_f);
    bf_ = static_cast<float>(camera.bf());
    const double max_r2 = g.max_range_m * g.max_range_m;
    r2_in_ = static_cast<float>(max_r2 * (1.0 - kRelativeMargin));
    r2_out_ = static_cast<float>(max_r2 * (1.0 + kRelativeMargin));
    // isValidDisparity() and measuresRange() (d > 1e-3·far in double: the
    // smallest float above that bound) as one interval.
    const StereoCameraModel::DisparityValidity valid = camera.validity();
    const double measured_above = 1e-3 * camera.farDisparity();
    float min_measured = static_cast<float>(measured_above);
    if (!(static_cast<double>(min_measured) > measured_above))
      min_measured = std::nextafter(min_measured, std::numeric_limits<float>::infinity());
    min_d_ = std::max(valid.min_px, min_measured);
    max_d_ = valid.max_px;
    // What rekeyChunk() needs, in double as drawHitAtDepth() computes it.
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) R_W_C_[i][j] = R_W_C(i, j);
      W_origin_[i] = g.W_origin[i];
      origin_index_[i] = g.origin_index[i];
    }
    inv_c_d_ = g.inv_c;
    cx_d_ = cfg.cx_px;
    cy_d_ = cfg.cy_px;
    inv_f_d_ = inv_f;  // as StereoCameraModel's: 1 / f
    bf_d_ = camera.bf();
  }

  /// False: each pixel keyed in double (a huge grid or range, or 2^31 cells).
  bool keysInFloat() const { return in_float_; }

  /// True if d is a valid disparity that measures a range (isValidDisparity(), measuresRange()).
  bool measured(float d) const { return (d >= min_d_) & (d <= max_d_); }

  /// True if one of pixels [x, x + n) of the row is measured().
  STEREO_OCCUPANCY_AVX2_CLONE bool anyMeasured(const float* row, int x, int n) const {
    const float min_d = min_d_, max_d = max_d_;
    int any = 0;
    for (int k = 0; k < n; ++k) any |= (row[x + k] >= min_d) & (row[x + k] <= max_d);
    return any != 0;
  }

  /// Keys pixels [x, x + n) of row y (n <= kChunk); returns how many are kRekey.
  STEREO_OCCUPANCY_AVX2_CLONE int keyChunk(const float* row, int x, int n, int y, Keys* keys) const {
    // Locals, not members, in the loop: it stores through pointers.
    const float inv_f = inv_f_, cx = cx_, bf = bf_, z_cap = z_cap_, r2_in = r2_in_, r2_out = r2_out_;
    const float min_d = min_d_, max_d = max_d_, m = margin_cells_, one_minus_m = 1.0f - margin_cells_;
    const float ray_y = (static_cast<float>(y) - cy_) * inv_f;
    const float ray_y2_plus_1 = ray_y * ray_y + 1.0f;
    const float yf = static_cast<float>(y);
    const float a0 = at_00_[0] + yf * per_y_[0], a1 = at_00_[1] + yf * per_y_[1], a2 = at_00_[2] + yf * per_y_[2];
    const float s0 = per_x_[0], s1 = per_x_[1], s2 = per_x_[2];
    const float o0 = origin_[0], o1 = origin_[1], o2 = origin_[2];
    const uint32_t size0 = size_[0], size1 = size_[1], size2 = size_[2], blocks_per_row = blocks_per_row_;
    int rekeys = 0;
    for (int k = 0; k < n; ++k) {
      const float d = row[x + k];
      const int measured = (d >= min_d) & (d <= max_d);  // 0 for NaN
      const float z = std::min(bf / (measured ? d : bf), z_cap);
      const float fx = static_cast<float>(x + k);
      const float ray_x = (fx - cx) * inv_f;
      const float r2 = z * z * (ray_x * ray_x + ray_y2_plus_1);
      const int in_range = measured & (r2 <= r2_out), near_max = r2 > r2_in;
      // The point in cells from the grid's first: g0 + z·(R_W_C·C_ray) / c.
      const float q0 = o0 + z * (a0 + fx * s0), q1 = o1 + z * (a1 + fx * s1), q2 = o2 + z * (a2 + fx * s2);
      // Truncation is floor for q >= 0; below 0, q - c < 0: unsure (outside the grid, or in double).
      const int32_t c0 = static_cast<int32_t>(q0), c1 = static_cast<int32_t>(q1), c2 = static_cast<int32_t>(q2);
      const float fc0 = static_cast<float>(c0), fc1 = static_cast<float>(c1), fc2 = static_cast<float>(c2);
      const float f0 = q0 - fc0, f1 = q1 - fc1, f2 = q2 - fc2;
      const int32_t unsure = ((f0 < m) | (f0 > one_minus_m)) | (((f1 < m) | (f1 > one_minus_m)) << 1) |
                             (((f2 < m) | (f2 > one_minus_m)) << 2);
      keys->unsure[k] = unsure;
      keys->cell[0][k] = c0;
      keys->cell[1][k] = c1;
      keys->cell[2][k] = c2;
      const uint32_t u0 = static_cast<uint32_t>(c0), u1 = static_cast<uint32_t>(c1), u2 = static_cast<uint32_t>(c2);
      const int inside = (u0 < size0) & (u1 < size1) & (u2 < size2);  // a negative cell: huge
      const uint32_t grid_row = u1 + u2 * size1;
      keys->index[k] = u0 + grid_row * size0;
      keys->block[k] = grid_row * blocks_per_row + u0 / kInformationBlock;
      // !in_range ? kSkip : near_max ? kExact : unsure ? kRekey : inside ? kKeyed : kOutside, without branches
      const int32_t is_unsure = -static_cast<int32_t>(unsure != 0), is_near = -near_max;  // all ones or 0
      int32_t draw = kOutside + (kKeyed - kOutside) * inside;
      draw = (draw & ~is_unsure) | (kRekey & is_unsure);
      draw = (draw & ~is_near) | (kExact & is_near);
      draw &= -in_range;
      keys->draw[k] = draw;
      rekeys += draw == kRekey;
    }
    return rekeys;
  }

  /// The chunk's kRekey pixels keyed again as drawHitAtDepth() keys them:
  /// their unsure axes in double (the same operations: rayThroughPixel() ·
  /// depthFromDisparity(), pointComponent(), floorToInt()), each pixel then
  /// kKeyed or kOutside. A loop without branches the compiler vectorises,
  /// for chunks with many such pixels (planes on cell faces: whole rows),
  /// where a branch per axis and pixel mispredicts. The other pixels keep
  /// their keys.
  STEREO_OCCUPANCY_AVX2_CLONE void rekeyChunk(const float* row, int x, int n, int y, Keys* keys) const {
    const double cx = cx_d_, inv_f = inv_f_d_, bf = bf_d_, inv_c = inv_c_d_, z_cap = z_cap_;
    const double C_ray_y = (static_cast<double>(y) - cy_d_) * inv_f;
    const float min_d = min_d_, max_d = max_d_;
    const uint32_t size0 = size_[0], size1 = size_[1], size2 = size_[2], blocks_per_row = blocks_per_row_;
    for (int k = 0; k < n; ++k) {
      const int32_t draw = keys->draw[k];
      const int32_t rekey = -static_cast<int32_t>(draw == kRekey);  // all ones or 0
      // A kRekey pixel is measured and in range: its d and z as they are;
      // the others' are clamped so that their unused keys stay finite.
      const float d = std::min(std::max(min_d, row[x + k]), max_d);  // NaN: min_d
      const double z = std::min(bf / static_cast<double>(d), z_cap);
      const double C_point[3] = {((static_cast<double>(x + k) - cx) * inv_f) * z, C_ray_y * z, 1.0 * z};
      const int32_t unsure = keys->unsure[k];
      uint32_t u[3];
      for (int i = 0; i < 3; ++i) {
        const double q =
            (((R_W_C_[i][0] * C_point[0] + R_W_C_[i][1] * C_point[1]) + R_W_C_[i][2] * C_point[2]) + W_origin_[i]) *
            inv_c;
        const int32_t t = static_cast<int32_t>(q);
        const int32_t cell = t - (q < static_cast<double>(t)) - origin_index_[i];  // floorToInt() - origin
        const int32_t again = -((unsure >> i) & 1);
        u[i] = static_cast<uint32_t>((cell & again) | (keys->cell[i][k] & ~again));  // a negative cell: huge
      }
      const int32_t inside = (u[0] < size0) & (u[1] < size1) & (u[2] < size2);
      const uint32_t grid_row = u[1] + u[2] * size1;
      const uint32_t rekeyed = static_cast<uint32_t>(rekey);
      keys->index[k] = ((u[0] + grid_row * size0) & rekeyed) | (keys->index[k] & ~rekeyed);
      keys->block[k] = ((grid_row * blocks_per_row + u[0] / kInformationBlock) & rekeyed) | (keys->block[k] & ~rekeyed);
      keys->draw[k] = ((kOutside + (kKeyed - kOutside) * inside) & rekey) | (draw & ~rekey);
    }
  }

 private:
  float per_x_[3], per_y_[3], at_00_[3], origin_[3];
  float margin_cells_;
  bool in_float_;
  float z_cap_, cx_, cy_, inv_f_, bf_;
  float r2_in_, r2_out_;
  float min_d_, max_d_;  ///< the disparities measured()
  uint32_t size_[3], blocks_per_row_;
  double R_W_C_[3][3], W_origin_[3], inv_c_d_, cx_d_, cy_d_, inv_f_d_, bf_d_;  ///< rekeyChunk()'s, in double
  int32_t origin_index_[3];
};

/// The cursor at the second slab, the first inner one.
template <class Grid>
STEREO_OCCUPANCY_INLINE LineCursor innerCursor(const Grid& g, const Eigen::Vector3d& W_dir, const LineWalk& w) {
  const double t = w.t_first + w.dt;
  LineCursor cursor;
  cursor.pos_a = roundToInt64((g.g0[w.minor_a] + W_dir[w.minor_a] * t) * kFixedPointOne);
  cursor.pos_b = roundToInt64((g.g0[w.minor_b] + W_dir[w.minor_b] * t) * kFixedPointOne);
  cursor.index_major = static_cast<int64_t>(w.first_slab + w.step) * g.stride[w.major];
  cursor.step_a = roundToInt64(W_dir[w.minor_a] * w.dt * kFixedPointOne);
  cursor.step_b = roundToInt64(W_dir[w.minor_b] * w.dt * kFixedPointOne);
  cursor.step_index_major = w.step * g.stride[w.major];
  cursor.stride_a = g.stride[w.minor_a];
  cursor.stride_b = g.stride[w.minor_b];
  return cursor;
}

/// The inner slabs k = 1 .. slabs - 2 in float: their ranges and the first
/// k whose range reaches the measurement's offset u (l = l_p + u).
struct InnerSlabs {
  float t1;     ///< range at slab 1 [cells]
  float dt;     ///< per slab [cells]
  float c;      ///< cell size [m]
  float inv_c;  ///< [1/m]
  int last;     ///< slabs - 1: the end slab, not inner

  /// The first inner k with t_k >= (l_p + u) / c, or last if none (l_p = inf: free space).
  int firstReaching(const RangeProfile& profile, float u) const {
    const float steps = ((profile.l_p_m + u) * inv_c - t1) / dt;
    if (!(steps > 0.0f)) return 1;
    if (steps > static_cast<float>(last)) return last;
    return std::min(last, 1 + ceilToInt(steps));
  }
  /// Range of inner slab k [m].
  float rangeAt(int k) const { return (t1 + (k - 1) * dt) * c; }
};

/// The inner slabs of a line inside the grid; returns the cells written.
STEREO_OCCUPANCY_INLINE uint64_t drawInnerCells(float* data, const InnerSlabs& inner, const RangeProfile& profile,
                                                SimdLevel simd, LineCursor* cursor) {
  // Four runs, by the offset u = l - l_p at the cells' centre planes: free
  // (u < front), rising (u < -c/2), peak (|u| <= c/2), falling (u > c/2).
  // Free and peak cells share one value; in the rising and falling runs the
  // table position moves by a constant step.
  const bool measures = profile.l_p_m < std::numeric_limits<float>::infinity();
  const int k_free = measures ? inner.firstReaching(profile, profile.front_m) : inner.last;
  const float free_value = profile.free_log_odds;  // a local: stores to the grid cannot change it
  int k = 1;
  // The free run, most of the cells drawn, two cells at a time where it can.
  const bool strides_fit = cursor->stride_a <= 0xffffffffLL && cursor->stride_b <= 0xffffffffLL;  // 32-bit lanes
#if STEREO_OCCUPANCY_X86_64_SIMD
  if (simd == SimdLevel::kSse2 && strides_fit) k = freeRunSse2(data, k, k_free, free_value, cursor);
#elif STEREO_OCCUPANCY_AARCH64_SIMD
  if (simd == SimdLevel::kNeon && strides_fit) k = freeRunNeon(data, k, k_free, free_value, cursor);
#else
  static_cast<void>(simd);  // the scalar loop alone
  static_cast<void>(strides_fit);
#endif
  for (; k < k_free; ++k, cursor->advance()) drawCell(data, cursor->index(), free_value);
  if (k < inner.last) {  // the measurement's window reaches the inner slabs
    const float half_cell = profile.half_cell_m;
    const int k_peak = inner.firstReaching(profile, -half_cell), k_fall = inner.firstReaching(profile, half_cell);
    const float sample_step = inner.dt * inner.c * profile.samples_per_m;
    constexpr float kLastSample =
        (LogOddsTable::kFrontSigmas + LogOddsTable::kTailSigmas) * LogOddsTable::kSamplesPerSigma;
    auto sampleAt = [&](int slab, float shift_m) {  // table position of inner slab's cell
      return (inner.rangeAt(slab) - profile.l_p_m + shift_m - profile.row_origin_m) * profile.samples_per_m;
    };
    float x = sampleAt(k, half_cell);
    if (profile.step_sample >= 0) {  // the surface profile: most of its window is free space
      for (; k < k_peak; ++k, x += sample_step, cursor->advance())
        drawCell(data, cursor->index(), profile.stepSample(std::max(x, 0.0f)));
    } else {
      for (; k < k_peak; ++k, x += sample_step, cursor->advance())
        drawCell(data, cursor->index(), profile.sample(std::max(x, 0.0f)));
    }
    const float peak = profile.sample((-profile.row_origin_m) * profile.samples_per_m);
    for (; k < k_fall; ++k, cursor->advance()) drawCell(data, cursor->index(), peak);
    x = sampleAt(k, -half_cell);
    for (; k < inner.last; ++k, x += sample_step, cursor->advance())
      drawCell(data, cursor->index(), profile.sample(std::min(x, kLastSample)));
  }
  return static_cast<uint64_t>(inner.last - 1);
}

/// The same for a line that leaves the grid: cells outside are skipped.
template <class Grid>
STEREO_OCCUPANCY_INLINE uint64_t drawInnerCellsClipped(const Grid& g, const LineWalk& w, const InnerSlabs& inner,
                                                       const RangeProfile& profile, LineCursor* cursor) {
  const bool measures = profile.l_p_m < std::numeric_limits<float>::infinity();
  const int k_free = measures ? inner.firstReaching(profile, profile.front_m) : inner.last;
  uint64_t written = 0;
  float t = inner.t1;
  for (int k = 1; k < inner.last;
       ++k, t += inner.dt, cursor->pos_a += cursor->step_a, cursor->pos_b += cursor->step_b) {
    const int64_t cell_a = cursor->pos_a >> 32, cell_b = cursor->pos_b >> 32;
    const int slab = w.first_slab + k * w.step;
    if (slab < 0 || slab >= g.size[w.major] || cell_a < 0 || cell_a >= g.size[w.minor_a] || cell_b < 0 ||
        cell_b >= g.size[w.minor_b])
      continue;
    drawCell(g.data, slab * g.stride[w.major] + cell_a * cursor->stride_a + cell_b * cursor->stride_b,
             k < k_free ? profile.free_log_odds : profile.tableAt(t * inner.c));
    ++written;
  }
  return written;
}

}  // namespace

uint64_t LineDrawer::drawLine(const RayGrid& g, const Eigen::Vector3d& W_dir, const RangeProfile& profile,
                              double l_begin, double l_stop) const {
  const double l_end = std::min({static_cast<double>(profile.endRange()), g.max_range_m, l_stop});
  uint64_t written = 0;
  if (!(l_end > l_begin)) return written;
  const LineWalk w = walkOf(g, W_dir, l_begin * g.inv_c, l_end * g.inv_c);
  written += drawEndCell(g, W_dir, w, profile, w.first_slab, w.t_first);
  if (w.slabs == 1) return written;
  // Inner slabs: t_begin < t < t_end, so their cells lie on the segment.
  const InnerSlabs inner{static_cast<float>(w.t_first + w.dt), static_cast<float>(w.dt), static_cast<float>(g.c),
                         static_cast<float>(g.inv_c), w.slabs - 1};
  LineCursor cursor = innerCursor(g, W_dir, w);
  written += w.inside ? drawInnerCells(g.data, inner, profile, simd_, &cursor)
                      : drawInnerCellsClipped(g, w, inner, profile, &cursor);
  written += drawEndCell(g, W_dir, w, profile, w.first_slab + (w.slabs - 1) * w.step, w.t_first + (w.slabs - 1) * w.dt);
  return written;
}

uint64_t LineDrawer::drawPixelHits(const RayGrid& grid, const cv::Mat& disparity, int y_begin, int y_end,
                                   const Eigen::Matrix3d& R_W_C, DrawStatistics* stats) const {
  const RayGrid g = grid;  // a local: the flags' byte stores would make the members reload
  const PixelHitRows keying(g, camera_, R_W_C);
  const float hit = table_.hitLogOdds();
  PixelHitRows::Keys keys;
  uint64_t written = 0, pixels = 0;
  auto drawExact = [&](int x, int y, float d) {
    written += drawHitAtDepth(g, R_W_C, camera_.rayThroughPixel(x, y), camera_.depthFromDisparity(d), 0.0, hit);
  };
  const uint32_t size[3] = {static_cast<uint32_t>(g.size[0]), static_cast<uint32_t>(g.size[1]),
                            static_cast<uint32_t>(g.size[2])};
  uint8_t no_blocks = 0;  // where the hits' blocks go when nobody asks for them
  uint8_t* const hit_blocks = g.hit_blocks ? g.hit_blocks : &no_blocks;
  const uint32_t block_mask = g.hit_blocks ? ~0u : 0u;
  // Pixel k's cell with its unsure axes again in double, as drawHitAt() keys them.
  auto drawRekeyed = [&](int x, int y, float d, int k) {
    uint32_t cell[3] = {static_cast<uint32_t>(keys.cell[0][k]), static_cast<uint32_t>(keys.cell[1][k]),
                        static_cast<uint32_t>(keys.cell[2][k])};  // a negative cell: huge
    const int32_t unsure = keys.unsure[k];
    const Eigen::Vector3d C_point = camera_.rayThroughPixel(x, y) * camera_.depthFromDisparity(d);
    for (int i = 0; i < 3; ++i)
      if ((unsure >> i) & 1)
        cell[i] = floorToInt(pointComponent(R_W_C, C_point, g.W_origin, i) * g.inv_c) - g.origin_index[i];
    if (cell[0] >= size[0] || cell[1] >= size[1] || cell[2] >= size[2]) return;  // outside the grid
    ++written;
    const int64_t grid_row = cell[1] + int64_t{cell[2]} * g.size[1];
    drawCell(g.data, cell[0] + grid_row * g.size[0], hit);
    if (g.hit_blocks) g.hit_blocks[grid_row * g.blocks_per_row + cell[0] / kInformationBlock] = 1;  // as drawHitAt()
  };
  for (int y = y_begin; y < y_end; ++y) {
    const float* row = disparity.ptr<float>(y);
    for (int x = 0; x < disparity.cols; x += PixelHitRows::kChunk) {
      const int n = std::min(PixelHitRows::kChunk, disparity.cols - x);
      // Sky or no match; the chunk's first pixel answers for most chunks.
      if (!keying.measured(row[x]) && !keying.anyMeasured(row, x, n)) continue;
      if (!keying.keysInFloat()) {
        for (int k = 0; k < n; ++k)
          if (keying.measured(row[x + k])) ++pixels, drawExact(x + k, y, row[x + k]);
        continue;
      }
      if (keying.keyChunk(row, x, n, y, &keys) >= PixelHitRows::kVectorRekeys) keying.rekeyChunk(row, x, n, y, &keys);
      for (int k = 0; k < n; ++k) {
        const int32_t draw = keys.draw[k];
        if (draw == PixelHitRows::kSkip) continue;
        ++pixels;
        if (draw == PixelHitRows::kKeyed) {  // most pixels
          ++written;
          drawCell(g.data, keys.index[k], hit);  // a neighbour's cell again: cheaper than a branch
          hit_blocks[keys.block[k] & block_mask] = 1;
        } else if (draw == PixelHitRows::kRekey) {
          drawRekeyed(x + k, y, row[x + k], k);
        } else if (draw == PixelHitRows::kExact) {
          drawExact(x + k, y, row[x + k]);
        }
      }
    }
  }
  if (stats) stats->coordinate_transfers += pixels;
  return written;
}

uint64_t LineDrawer::drawRay(const Eigen::Vector3d& W_origin, const Eigen::Vector3d& W_dir, const RangeProfile& profile,
                             LocalGrid* grid, double l_begin, double l_stop) const {
  const RayGrid g = rayGrid(W_origin, grid);
  return drawPointHit(g, W_dir, profile, l_begin, std::min(g.max_range_m, l_stop)) +
         drawLine(g, W_dir, profile, l_begin, l_stop);
}

namespace {
/// Cells per part of the merge of the workers' grids.
constexpr size_t kMergeChunkCells = size_t{1} << 16;

void addTo(const DrawStatistics& from, DrawStatistics* to) {
  to->coordinate_transfers += from.coordinate_transfers;
  to->used_image_pixels += from.used_image_pixels;
  to->grid_cells_drawn += from.grid_cells_drawn;
  to->different_grid_cells += from.different_grid_cells;
}
}  // namespace

template <typename DrawPart>
void LineDrawer::drawParts(size_t parts, const RayGrid& g, LocalGrid* grid, DrawStatistics* stats,
                           const DrawPart& draw_part) {
  const unsigned workers = workersFor(*grid);
  if (workers == 1) {
    for (size_t part = 0; part < parts; ++part) draw_part(part, g, stats);
    return;
  }
  if (worker_grids_.size() < workers - 1) worker_grids_.resize(workers - 1);
  if (worker_hit_blocks_.size() < workers - 1) worker_hit_blocks_.resize(workers - 1);
  for (unsigned w = 1; w < workers; ++w) {
    releaseIfOversized(&worker_grids_[w - 1], grid->numCells());  // after one rare huge grid
    worker_grids_[w - 1].resize(grid->numCells(), LocalGrid::kUnknown);
    if (!g.hit_blocks) continue;
    releaseIfOversized(&worker_hit_blocks_[w - 1], grid->numBlocks());
    worker_hit_blocks_[w - 1].assign(grid->numBlocks(), 0);
  }
  std::vector<PerWorker<DrawStatistics>> worker_stats(workers);
  std::vector<PerWorker<char>> used(workers);
  try {
    pool_->run(parts, [&](size_t part, unsigned w) {
      RayGrid mine = g;
      if (w > 0) {
        mine.data = worker_grids_[w - 1].data();
        if (g.hit_blocks) mine.hit_blocks = worker_hit_blocks_[w - 1].data();
      }
      used[w].value = 1;
      draw_part(part, mine, &worker_stats[w].value);
    });
  } catch (...) {
    mergeWorkerGrids(used, grid);  // the worker grids are unknown again for the next image
    throw;
  }
  for (const PerWorker<DrawStatistics>& s : worker_stats) addTo(s.value, stats);
  mergeWorkerGrids(used, grid);
  if (!g.hit_blocks) return;
  for (unsigned w = 1; w < workers; ++w)
    if (used[w].value)
      for (size_t b = 0; b < worker_hit_blocks_[w - 1].size(); ++b) g.hit_blocks[b] |= worker_hit_blocks_[w - 1][b];
}

unsigned LineDrawer::workersFor(const LocalGrid& grid) const {
  return pool_ && grid.numCells() <= kMaxSharedGridCells ? pool_->size() : 1;
}

int LineDrawer::splitLevel(const DisparityPyramid& pyramid, unsigned workers) const {
  const int64_t wanted = int64_t{kPartsPerWorker} * workers;
  int level = pyramid.topLevel();
  while (level > levels_.minLevel() && int64_t{pyramid.width(level)} * pyramid.height(level) < wanted) --level;
  return level;
}

template <typename DescendFrom>
void LineDrawer::drawPyramidParts(const Descent& s, LocalGrid* grid, DrawStatistics* stats,
                                  const DescendFrom& descend_from) {
  const int top = s.min_pyramid.topLevel();
  const unsigned workers = workersFor(*grid);
  // The levels above the split on this thread: they draw few lines and
  // leave the blocks of the split level to the workers. Cells keep the
  // largest value, so the grid does not depend on who drew what.
  std::vector<PartStart> starts;
  Descent above = s;
  above.parts = &starts;
  above.split_level = workers > 1 ? splitLevel(s.min_pyramid, workers) : top;  // top: each block one part
  for (int y = 0; y < s.min_pyramid.height(top); ++y)
    for (int x = 0; x < s.min_pyramid.width(top); ++x) descend_from(above, top, x, y, 0.0);
  const int level = above.split_level;
  // With pixel hits, bands of the image's rows follow the blocks as parts.
  const cv::Mat& pixels = s.min_pyramid.level(0);  // the input, invalid pixels +inf
  const int bands = s.pixel_hits ? std::min<int>(pixels.rows, static_cast<int>(workers * kHitBandsPerWorker)) : 0;
  const Eigen::Matrix3d R_W_C = s.T_W_C.linear();
  drawParts(starts.size() + bands, s.grid, grid, stats, [&](size_t part, const RayGrid& g, DrawStatistics* part_stats) {
    if (part >= starts.size()) {
      const int band = static_cast<int>(part - starts.size());
      part_stats->grid_cells_drawn +=
          drawPixelHits(g, pixels, band * pixels.rows / bands, (band + 1) * pixels.rows / bands, R_W_C, part_stats);
      return;
    }
    Descent mine = s;
    mine.grid = g;
    mine.stats = part_stats;
    descend_from(mine, level, starts[part].x, starts[part].y, starts[part].z_begin);
  });
}

void LineDrawer::mergeWorkerGrids(const std::vector<PerWorker<char>>& used, LocalGrid* grid) {
  constexpr size_t kBlock = kInformationBlock;
  float* cells = grid->data();
  const size_t n = grid->numCells();
  pool_->runInChunks(n, kMergeChunkCells, [&](size_t begin, size_t end) {
    for (size_t w = 1; w < used.size(); ++w) {
      if (!used[w].value) continue;
      float* other = worker_grids_[w - 1].data();
      for (size_t i = begin; i < end; i += kBlock) {
        const size_t block_end = std::min(end, i + kBlock);
        // Most of a frustum's box is outside the worker's lines: read, not written.
        if (block_end - i == kBlock && !blockHasKnown(other + i)) continue;
        for (size_t j = i; j < block_end; ++j) {
          cells[j] = std::max(cells[j], other[j]);  // obstacle priority, as drawCell
          other[j] = LocalGrid::kUnknown;           // ready for the next image
        }
      }
    }
  });
}

void LineDrawer::drawImage(const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                           DrawStatistics* stats) {
  CV_Assert(disparity.type() == CV_32FC1);
  const Eigen::Matrix3d R_W_C = T_W_C.linear();
  stats->coordinate_transfers += 1;  // the camera centre
  // One part per image row.
  drawParts(disparity.rows, imageGrid(T_W_C.translation(), grid), grid, stats,
            [&](size_t y, const RayGrid& g, DrawStatistics* part_stats) {
              const float* row = disparity.ptr<float>(static_cast<int>(y));
              for (int x = 0; x < disparity.cols; ++x) {
                const float d = row[x];
                if (!camera_.isValidDisparity(d)) continue;  // no information
                ++part_stats->used_image_pixels;
                ++part_stats->coordinate_transfers;
                const Eigen::Vector3d C_ray = camera_.rayThroughPixel(x, static_cast<double>(y));
                const RangeProfile profile = pixelProfile(camera_, table_, x, static_cast<double>(y), d);
                part_stats->grid_cells_drawn +=
                    drawLine(g, R_W_C * C_ray.normalized(), profile, 0.0, std::numeric_limits<double>::infinity());
              }
              if (g.hit_blocks)  // the surface profile: each measured pixel's hit
                part_stats->grid_cells_drawn +=
                    drawPixelHits(g, disparity, static_cast<int>(y), static_cast<int>(y) + 1, R_W_C, nullptr);
            });
}

LineDrawer::Descent LineDrawer::descent(const DisparityPyramid& min_pyramid, const DisparityPyramid* max_pyramid,
                                        const DisparityBlockBound* bound, const Eigen::Isometry3d& T_W_C,
                                        LocalGrid* grid, DrawStatistics* stats) {
  return Descent{min_pyramid,
                 max_pyramid,
                 bound,
                 T_W_C,
                 imageGrid(T_W_C.translation(), grid),
                 table_.freeProfile(),
                 grid->resolution() * camera_.config().focal_length_px,
                 stats};
}

RangeProfile LineDrawer::profileOf(const Descent& s, double ray_norm, float d_px) const {
  return measuresRange(camera_, d_px) ? measuredProfile(camera_, table_, ray_norm, d_px) : s.free_profile;
}

Eigen::Vector3d LineDrawer::blockRay(int level, int x, int y) const {
  const auto& cfg = camera_.config();
  return camera_.rayThroughPixel(DisparityPyramid::centreOf(level, x, cfg.width_px),
                                 DisparityPyramid::centreOf(level, y, cfg.height_px));
}

uint64_t LineDrawer::drawPixel(const Descent& s, int level, int x, int y, float d_px, double z_begin) const {
  const Eigen::Vector3d C_ray = blockRay(level, x, y);  // z = 1
  const double norm = C_ray.norm();                     // |p_c| / z_c (eq. 2)
  const RangeProfile profile = profileOf(s, norm, d_px);
  const uint64_t written = drawLine(s.grid, s.T_W_C.linear() * (C_ray / norm), profile, z_begin * norm,
                                    std::numeric_limits<double>::infinity());
  if (!profile.hasPointHit() || s.pixel_hits) return written;
  return written + drawHitAtDepth(s.grid, s.T_W_C.linear(), C_ray, camera_.depthFromDisparity(d_px), z_begin,
                                  profile.hit_log_odds);
}

void LineDrawer::descend(const Descent& s, int level, int x, int y) const {
  if (s.parts && level == s.split_level) {
    s.parts->push_back({x, y, 0.0});
    return;
  }
  const float d = s.min_pyramid.at(level, x, y);
  ++s.stats->used_image_pixels;
  if (d == DisparityPyramid::kInvalidMin) return;  // the whole block is invalid
  if (level <= levels_.minLevel() || levels_.levelForDisparity(d) >= level) {
    ++s.stats->coordinate_transfers;
    s.stats->grid_cells_drawn += drawPixel(s, level, x, y, d);
    return;
  }
  const int w = s.min_pyramid.width(level - 1);
  const int h = s.min_pyramid.height(level - 1);
  for (int cy = 2 * y; cy <= 2 * y + 1 && cy < h; ++cy)
    for (int cx = 2 * x; cx <= 2 * x + 1 && cx < w; ++cx) descend(s, level - 1, cx, cy);
}

void LineDrawer::drawPyramid(const DisparityPyramid& min_pyramid, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                             DrawStatistics* stats) {
  stats->coordinate_transfers += 1;  // the camera centre
  const Descent s = descent(min_pyramid, nullptr, nullptr, T_W_C, grid, stats);
  drawPyramidParts(s, grid, stats,
                   [this](const Descent& d, int level, int x, int y, double) { descend(d, level, x, y); });
}

void LineDrawer::descendBounded(const Descent& s, int level, int x, int y, double z_begin) const {
  if (s.parts && level == s.split_level) {
    s.parts->push_back({x, y, z_begin});
    return;
  }
  const float d = s.min_pyramid.at(level, x, y);
  ++s.stats->used_image_pixels;
  if (d == DisparityPyramid::kInvalidMin) return;  // the whole block is invalid
  const bool at_bottom = level <= levels_.minLevel();
  const bool fine_enough = levels_.levelForDisparity(d) >= level;
  float d_max = d;
  if (level > 0) {
    ++s.stats->used_image_pixels;
    d_max = s.max_pyramid->at(level, x, y);
  }
  if (at_bottom || (fine_enough && (level <= 0 || s.bound->isFaithful(d, d_max)))) {
    ++s.stats->coordinate_transfers;
    s.stats->grid_cells_drawn += drawPixel(s, level, x, y, d, z_begin);
    return;
  }
  // Fine enough but not faithful: an oblique surface (the ground) whose
  // depths leave no hole is drawn as one free line and its sub-blocks' hits.
  SpanLeaves leaves;
  if (fine_enough && surface_spans_ && table_.hitLogOdds() > 0.0f && isSpan(s, level, x, y, &leaves)) {
    drawSpan(s, level, x, y, d_max, z_begin);
    return;
  }
  // The block's rays lie within one cell of each other up to the depth
  // z_i = c·f / 2^i (eq. 12) and are free up to the nearest measurement's
  // front: one ray through the block's centre draws that stretch for all of
  // them, its children's lines start at the depth where it ends.
  const Eigen::Vector3d C_ray = blockRay(level, x, y);  // z = 1
  const double norm = C_ray.norm();
  const float nearest_front_m = measuresRange(camera_, d_max) ? measuredFrontRange(camera_, table_, norm, d_max)
                                                              : s.free_profile.l_p_m + s.free_profile.front_m;
  const double z_shared = std::min(s.cell_f_m_px * powerOfTwo(-level), static_cast<double>(nearest_front_m) / norm);
  if (z_shared > z_begin) {
    ++s.stats->coordinate_transfers;
    s.stats->grid_cells_drawn +=
        drawLine(s.grid, s.T_W_C.linear() * (C_ray / norm), s.free_profile, z_begin * norm, z_shared * norm);
    z_begin = z_shared;
  }
  const int w = s.min_pyramid.width(level - 1);
  const int h = s.min_pyramid.height(level - 1);
  for (int cy = 2 * y; cy <= 2 * y + 1 && cy < h; ++cy)
    for (int cx = 2 * x; cx <= 2 * x + 1 && cx < w; ++cx) descendBounded(s, level - 1, cx, cy, z_begin);
}

void LineDrawer::SpanLeaves::chain(const DisparityBlockBound& bound, float lo, float hi) {
  if (count == 0) {
    hull_lo = lo;
    hull_hi = hi;
    return;
  }
  const bool below = hi < hull_lo;
  const bool above = lo > hull_hi;
  if ((below && !bound.isFaithful(hi, hull_lo)) || (above && !bound.isFaithful(hull_hi, lo))) chained = false;
  hull_lo = std::min(hull_lo, lo);
  hull_hi = std::max(hull_hi, hi);
}

bool LineDrawer::gatherLeaves(const Descent& s, int level, int x, int y, SpanLeaves* out) const {
  const float lo = s.min_pyramid.at(level, x, y);
  if (lo == DisparityPyramid::kInvalidMin) return true;  // no pixel, no line
  const float hi = level > 0 ? s.max_pyramid->at(level, x, y) : lo;
  if (level <= levels_.minLevel() || s.bound->isFaithful(lo, hi)) {  // where descendBounded() draws a line
    if (!measuresRange(camera_, lo) || out->count == SpanLeaves::kMaxLeaves) return false;
    out->chain(*s.bound, lo, hi);
    const int i = out->count++;
    out->lo[i] = lo;
    out->hi[i] = hi;
    return true;
  }
  const int w = s.min_pyramid.width(level - 1);
  const int h = s.min_pyramid.height(level - 1);
  for (int cy = 2 * y; cy <= 2 * y + 1 && cy < h; ++cy)
    for (int cx = 2 * x; cx <= 2 * x + 1 && cx < w; ++cx)
      if (!gatherLeaves(s, level - 1, cx, cy, out)) return false;
  return true;
}

bool LineDrawer::isSpan(const Descent& s, int level, int x, int y, SpanLeaves* leaves) const {
  if (!gatherLeaves(s, level, x, y, leaves) || leaves->count == 0) return false;
  // Chained leaves leave no gap but faithful ones and those inside them
  // (faithful too where the bound is monotone): the walk below would find no
  // hole. Most spans are chained; only the others need the sort.
  if (leaves->chained && leaves->hull_lo >= s.bound->monotoneFrom()) return true;
  // Nearest first, each next leaf must come within one measurement's gap
  // of the depths before it. The order is sorted farthest first and walked
  // backwards. (The order among equal depths does not change the answer.)
  int order[SpanLeaves::kMaxLeaves];
  stableOrderAscending(leaves->hi, leaves->count, order);
  float reached = leaves->lo[order[leaves->count - 1]];
  for (int i = leaves->count - 2; i >= 0; --i) {
    const int k = order[i];
    if (leaves->hi[k] < reached && !s.bound->isFaithful(leaves->hi[k], reached)) return false;  // a hole
    reached = std::min(reached, leaves->lo[k]);
  }
  return true;
}

void LineDrawer::drawSpan(const Descent& s, int level, int x, int y, float d_max, double z_begin) const {
  constexpr double kToTheEnd = std::numeric_limits<double>::infinity();
  // Free space along the block's centre ray up to the nearest measurement's
  // gap (its pixels' hits come from drawPixelHits()). Up to the front of its
  // profile with the sky value, as a descending block's shared stretch: the
  // sky guard silences it beside a hit.
  const Eigen::Vector3d C_ray = blockRay(level, x, y);
  const double norm = C_ray.norm();
  RangeProfile nearest = profileOf(s, norm, d_max);
  nearest.hit_log_odds = 0.0f;
  nearest.free_log_odds = s.free_profile.free_log_odds;
  ++s.stats->coordinate_transfers;
  s.stats->grid_cells_drawn += drawLine(s.grid, s.T_W_C.linear() * (C_ray / norm), nearest, z_begin * norm, kToTheEnd);
}

void LineDrawer::drawPyramidBounded(const DisparityPyramid& min_pyramid, const DisparityPyramid& max_pyramid,
                                    const DisparityBlockBound& bound, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                                    DrawStatistics* stats) {
  CV_Assert(min_pyramid.type() == PyramidType::kMinDisparity && max_pyramid.type() == PyramidType::kMaxDisparity &&
            min_pyramid.topLevel() == max_pyramid.topLevel());
  stats->coordinate_transfers += 1;  // the camera centre
  Descent s = descent(min_pyramid, &max_pyramid, &bound, T_W_C, grid, stats);
  s.pixel_hits = s.grid.hit_blocks != nullptr;  // the surface profile
  drawPyramidParts(s, grid, stats, [this](const Descent& d, int level, int x, int y, double z_begin) {
    descendBounded(d, level, x, y, z_begin);
  });
}

}  // namespace stereo_occupancy
