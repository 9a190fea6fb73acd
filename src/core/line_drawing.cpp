#include "stereo_occupancy/line_drawing.h"

#include <algorithm>
#include <cmath>

#if defined(__SSE2__) && defined(__x86_64__)
#define STEREO_OCCUPANCY_X86_64_SIMD 1
#include <emmintrin.h>
#endif

#include "stereo_occupancy/integer_math.h"

namespace stereo_occupancy {

namespace {

/// Where a line's free run stands: cell k's minor coordinates in 32.32 fixed
/// point and its index along the major axis, and their steps per slab.
struct FreeRun {
  int64_t pa, pb, idx_m;
  int64_t dta, dtb, didx_m;
  int64_t sa, sb;  ///< index strides of the minor axes
};

#if STEREO_OCCUPANCY_X86_64_SIMD
/// The free run's cells two at a time, in the 64-bit lanes of SSE2
/// registers: the same 32.32 fixed-point sums and index products as the
/// scalar loop (inside the grid the positions are >= 0 and the cell
/// coordinates and strides fit 32 bits, as _mm_mul_epu32 needs), then a
/// max-store per cell (there is no scatter). Returns the first k not drawn
/// and leaves @p r at it.
int freeRunSse2(float* data, int k, int k_end, float free_value, FreeRun* r) {
  if (k + 1 >= k_end) return k;
  const __m128i two_dta = _mm_set1_epi64x(2 * r->dta), two_dtb = _mm_set1_epi64x(2 * r->dtb);
  const __m128i two_didx_m = _mm_set1_epi64x(2 * r->didx_m);
  const __m128i vsa = _mm_set1_epi64x(r->sa), vsb = _mm_set1_epi64x(r->sb);
  __m128i va = _mm_set_epi64x(r->pa + r->dta, r->pa);  // lane 0: cell k, lane 1: cell k + 1
  __m128i vb = _mm_set_epi64x(r->pb + r->dtb, r->pb);
  __m128i vm = _mm_set_epi64x(r->idx_m + r->didx_m, r->idx_m);
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
  r->pa = _mm_cvtsi128_si64(va);
  r->pb = _mm_cvtsi128_si64(vb);
  r->idx_m = _mm_cvtsi128_si64(vm);
  return k;
}
#endif

}  // namespace

SimdLevel availableSimdLevel() {
#if STEREO_OCCUPANCY_X86_64_SIMD
  return SimdLevel::kSse2;
#else
  return SimdLevel::kScalar;
#endif
}

const char* toString(SimdLevel level) {
  switch (level) {
    case SimdLevel::kScalar:
      return "scalar";
    case SimdLevel::kSse2:
      return "sse2";
  }
  return "?";
}

LineDrawer::LineDrawer(const StereoCameraModel& camera, const LogOddsTable& table, const PyramidLevelTable& levels,
                       SimdLevel simd)
    : camera_(camera), table_(table), levels_(levels), simd_(std::min(simd, availableSimdLevel())) {}

LineDrawer::RayGrid LineDrawer::rayGrid(const Eigen::Vector3d& W_origin, LocalGrid* grid) const {
  RayGrid g;
  g.c = grid->resolution();
  g.inv_c = 1.0 / g.c;
  g.g0 = (W_origin - grid->originPosition()) * g.inv_c;
  g.max_range_m = camera_.config().max_range_m;
  g.size = grid->size();
  g.stride[0] = 1;
  g.stride[1] = g.size.x();
  g.stride[2] = static_cast<int64_t>(g.size.x()) * g.size.y();
  for (int i = 0; i < 3; ++i) g.upper[i] = static_cast<double>(g.size[i]) - RayGrid::kMargin;
  g.data = grid->data();
  return g;
}

uint64_t LineDrawer::drawRay(const Eigen::Vector3d& W_origin, const Eigen::Vector3d& W_dir,
                             const RangeProfile& profile, LocalGrid* grid, double l_begin, double l_stop) const {
  return drawRay(rayGrid(W_origin, grid), W_dir, profile, l_begin, l_stop);
}

uint64_t LineDrawer::drawRay(const RayGrid& g, const Eigen::Vector3d& W_dir, const RangeProfile& profile,
                             double l_begin, double l_stop) const {
  const double c = g.c;
  const double inv_c = g.inv_c;
  const double l_end = std::min({static_cast<double>(profile.endRange()), g.max_range_m, l_stop});
  if (!(l_end > l_begin)) return 0;

  // Cell units relative to the grid's lower corner. One cell per slab of the
  // major axis (a 3D Bresenham line); in each slab the cell is the one where
  // the ray crosses the slab's centre plane, and l is the ray's range there.
  const Eigen::Vector3d& g0 = g.g0;
  const double t_begin = l_begin * inv_c;
  const double t_end = l_end * inv_c;
  const double abs_dir[3] = {std::abs(W_dir[0]), std::abs(W_dir[1]), std::abs(W_dir[2])};
  int m = abs_dir[1] > abs_dir[0] ? 1 : 0;  // the first of the largest, as Eigen's maxCoeff
  if (abs_dir[2] > abs_dir[m]) m = 2;
  static constexpr int kNext[3] = {1, 2, 0};
  const int a = kNext[m];
  const int b = kNext[a];
  const double g_begin[3] = {g0[0] + W_dir[0] * t_begin, g0[1] + W_dir[1] * t_begin, g0[2] + W_dir[2] * t_begin};
  const double g_end[3] = {g0[0] + W_dir[0] * t_end, g0[1] + W_dir[1] * t_end, g0[2] + W_dir[2] * t_end};
  const int k0 = floorToInt(g_begin[m]);
  const int k1 = floorToInt(g_end[m]);
  const int step = W_dir[m] > 0.0 ? 1 : -1;
  const int n = std::abs(k1 - k0) + 1;
  const double dt = 1.0 / abs_dir[m];
  const double t0 = (k0 + 0.5 - g0[m]) / W_dir[m];  // |t0 - t_begin| <= dt / 2

  const Eigen::Vector3i& size = g.size;
  const int64_t* stride = g.stride;
  float* data = g.data;
  auto put = [&](int64_t idx, float value) {
    float& cell = data[idx];
    cell = std::max(cell, value);  // obstacle priority (section V-A, step 2b)
  };
  // When both ends lie inside the grid (the usual case: the grid covers the
  // frustum), so does the segment and no index needs a check.
  bool inside = true;
  for (int i = 0; i < 3; ++i)
    inside &= (std::min(g_begin[i], g_end[i]) >= RayGrid::kMargin) & (std::max(g_begin[i], g_end[i]) < g.upper[i]);
  // The first and the last slab are only partly on the segment: sample the
  // segment point nearest to the centre plane. Cells outside the grid are
  // skipped (only possible when the grid does not cover the segment).
  uint64_t written = 0;
  auto endCell = [&](int km, double t) {
    t = std::clamp(t, t_begin, t_end);
    const int ka = floorToInt(g0[a] + W_dir[a] * t);
    const int kb = floorToInt(g0[b] + W_dir[b] * t);
    if (!inside && (km < 0 || km >= size[m] || ka < 0 || ka >= size[a] || kb < 0 || kb >= size[b])) return;
    put(km * stride[m] + ka * stride[a] + kb * stride[b], profile.at(static_cast<float>(t * c)));
    ++written;
  };
  endCell(k0, t0);
  if (n == 1) return written;

  // Inner slabs 1 .. n-2: t_begin < t < t_end, so their cells lie on the segment.
  // The minor coordinates step in 32.32 fixed point: exact sums, floor by shift.
  constexpr double kOne = 4294967296.0;  // 2^32
  const float t1 = static_cast<float>(t0 + dt);
  int64_t pa = roundToInt64((g0[a] + W_dir[a] * (t0 + dt)) * kOne);
  int64_t pb = roundToInt64((g0[b] + W_dir[b] * (t0 + dt)) * kOne);
  const int64_t dta = roundToInt64(W_dir[a] * dt * kOne), dtb = roundToInt64(W_dir[b] * dt * kOne);
  const float dtf = static_cast<float>(dt), cf = static_cast<float>(c);
  int64_t idx_m = static_cast<int64_t>(k0 + step) * stride[m];
  const int64_t didx_m = step * stride[m];
  const int64_t sa = stride[a], sb = stride[b];
  const float inv_cf = static_cast<float>(inv_c);
  auto firstWith = [&](float u) {  // first inner k whose t_k reaches (l_p + u) / c (n - 1 if none)
    const float steps = ((profile.l_p_m + u) * inv_cf - t1) / dtf;  // +inf for free space
    if (!(steps > 0.0f)) return 1;
    if (steps > static_cast<float>(n - 1)) return n - 1;
    return std::min(n - 1, 1 + ceilToInt(steps));
  };
  // Free space up to the measurement's front: one value for all those cells
  // (all of them on a line of free space, l_p = inf).
  const bool measures = profile.l_p_m < std::numeric_limits<float>::infinity();
  const int k_free = measures ? firstWith(profile.front_m) : n - 1;
  auto cellA = [&]() { return static_cast<int64_t>(pa >> 32); };
  auto cellB = [&]() { return static_cast<int64_t>(pb >> 32); };
  int k = 1;
  if (inside) {
    // The inner cells in four runs, by the offset u = l - l_p at their
    // centre plane: free (u < front), rising (u < -c/2), peak (|u| <= c/2),
    // falling (u > c/2). Free and peak cells share one value; in the rising
    // and falling runs the table position moves by a constant step.
    auto advance = [&]() {
      pa += dta;
      pb += dtb;
      idx_m += didx_m;
    };
    const float free_value = profile.free_log_odds;  // a local: stores to the grid cannot change it
    // The free run, most of the cells drawn, two cells at a time.
#if STEREO_OCCUPANCY_X86_64_SIMD
    if (simd_ == SimdLevel::kSse2 && sa <= 0xffffffffLL && sb <= 0xffffffffLL) {
      FreeRun run{pa, pb, idx_m, dta, dtb, didx_m, sa, sb};
      k = freeRunSse2(data, k, k_free, free_value, &run);
      pa = run.pa;
      pb = run.pb;
      idx_m = run.idx_m;
    }
#endif
    for (; k < k_free; ++k, advance()) put(idx_m + cellA() * sa + cellB() * sb, free_value);
    if (k < n - 1) {  // the measurement's window reaches the inner slabs
      const float hc = profile.half_cell_m;
      const int k_peak = firstWith(-hc), k_fall = firstWith(hc);
      const float dx = dtf * cf * profile.samples_per_m;
      const float x_max = (LogOddsTable::kFrontSigmas + LogOddsTable::kTailSigmas) * LogOddsTable::kSamplesPerSigma;
      auto sampleAt = [&](int kk, float e_shift) {  // table position of inner cell kk
        return ((t1 + (kk - 1) * dtf) * cf - profile.l_p_m + e_shift - profile.row_origin_m) * profile.samples_per_m;
      };
      float x = sampleAt(k, hc);
      for (; k < k_peak; ++k, x += dx, advance())
        put(idx_m + cellA() * sa + cellB() * sb, profile.sample(std::max(x, 0.0f)));
      const float peak = profile.sample((-profile.row_origin_m) * profile.samples_per_m);
      for (; k < k_fall; ++k, advance()) put(idx_m + cellA() * sa + cellB() * sb, peak);
      x = sampleAt(k, -hc);
      for (; k < n - 1; ++k, x += dx, advance())
        put(idx_m + cellA() * sa + cellB() * sb, profile.sample(std::min(x, x_max)));
    }
    written += static_cast<uint64_t>(n - 2);
  } else {
    float t = t1;
    for (; k < n - 1; ++k, t += dtf, pa += dta, pb += dtb) {
      const int64_t ka = cellA(), kb = cellB();
      const int km = k0 + k * step;
      if (km < 0 || km >= size[m] || ka < 0 || ka >= size[a] || kb < 0 || kb >= size[b]) continue;
      put(km * stride[m] + ka * sa + kb * sb, k < k_free ? profile.free_log_odds : profile.at(t * cf));
      ++written;
    }
  }
  endCell(k0 + (n - 1) * step, t0 + (n - 1) * dt);
  return written;
}

void LineDrawer::drawImage(const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                           DrawStatistics* stats) const {
  CV_Assert(disparity.type() == CV_32FC1);
  const Eigen::Matrix3d R_W_C = T_W_C.linear();
  const RayGrid g = rayGrid(T_W_C.translation(), grid);
  stats->coordinate_transfers += 1;  // the camera centre
  for (int y = 0; y < disparity.rows; ++y) {
    const float* row = disparity.ptr<float>(y);
    for (int x = 0; x < disparity.cols; ++x) {
      const float d = row[x];
      if (!camera_.isValidDisparity(d)) continue;  // no information
      ++stats->used_image_pixels;
      ++stats->coordinate_transfers;
      const Eigen::Vector3d W_dir = R_W_C * camera_.rayThroughPixel(x, y).normalized();
      stats->grid_cells_drawn += drawRay(g, W_dir, pixelProfile(camera_, table_, x, y, d), 0.0,
                                         std::numeric_limits<double>::infinity());
    }
  }
}

LineDrawer::Descent LineDrawer::descent(const DisparityPyramid& min_pyramid, const DisparityPyramid* max_pyramid,
                                        const DisparityBlockBound* bound, const Eigen::Isometry3d& T_W_C,
                                        LocalGrid* grid, DrawStatistics* stats) const {
  return Descent{min_pyramid,
                 max_pyramid,
                 bound,
                 T_W_C,
                 rayGrid(T_W_C.translation(), grid),
                 table_.freeProfile(),
                 grid->resolution() * camera_.config().focal_length_px,
                 stats};
}

RangeProfile LineDrawer::profileOf(const Descent& s, double ray_norm, float d_px) const {
  return measuresRange(camera_, d_px) ? measuredProfile(camera_, table_, ray_norm, d_px) : s.free_profile;
}

uint64_t LineDrawer::drawPixel(const Descent& s, int level, int x, int y, float d_px, double z_begin) const {
  const double X = DisparityPyramid::centreOf(level, x, camera_.config().width_px);
  const double Y = DisparityPyramid::centreOf(level, y, camera_.config().height_px);
  const Eigen::Vector3d C_ray = camera_.rayThroughPixel(X, Y);  // z = 1
  const double norm = C_ray.norm();                             // |p_c| / z_c (eq. 2)
  return drawRay(s.grid, s.T_W_C.linear() * (C_ray / norm), profileOf(s, norm, d_px), z_begin * norm,
                 std::numeric_limits<double>::infinity());
}

void LineDrawer::descend(const Descent& s, int level, int x, int y) const {
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
                             DrawStatistics* stats) const {
  stats->coordinate_transfers += 1;  // the camera centre
  const Descent s = descent(min_pyramid, nullptr, nullptr, T_W_C, grid, stats);
  const int top = min_pyramid.topLevel();
  for (int y = 0; y < min_pyramid.height(top); ++y)
    for (int x = 0; x < min_pyramid.width(top); ++x) descend(s, top, x, y);
}

void LineDrawer::descendBounded(const Descent& s, int level, int x, int y, double z_begin) const {
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
  // The block's rays lie within one cell of each other up to the depth
  // z_i = c·f / 2^i (eq. 12) and are free up to the nearest measurement's
  // front: one ray through the block's centre draws that stretch for all of
  // them, its children's lines start at the depth where it ends.
  const auto& cfg = camera_.config();
  const double X = DisparityPyramid::centreOf(level, x, cfg.width_px);
  const double Y = DisparityPyramid::centreOf(level, y, cfg.height_px);
  const Eigen::Vector3d C_ray = camera_.rayThroughPixel(X, Y);  // z = 1
  const double norm = C_ray.norm();
  const RangeProfile nearest = profileOf(s, norm, d_max);
  const double z_shared = std::min(s.cell_f_m_px * powerOfTwo(-level),
                                   static_cast<double>(nearest.l_p_m + nearest.front_m) / norm);
  if (z_shared > z_begin) {
    ++s.stats->coordinate_transfers;
    s.stats->grid_cells_drawn +=
        drawRay(s.grid, s.T_W_C.linear() * (C_ray / norm), s.free_profile, z_begin * norm, z_shared * norm);
    z_begin = z_shared;
  }
  const int w = s.min_pyramid.width(level - 1);
  const int h = s.min_pyramid.height(level - 1);
  for (int cy = 2 * y; cy <= 2 * y + 1 && cy < h; ++cy)
    for (int cx = 2 * x; cx <= 2 * x + 1 && cx < w; ++cx) descendBounded(s, level - 1, cx, cy, z_begin);
}

void LineDrawer::drawPyramidBounded(const DisparityPyramid& min_pyramid, const DisparityPyramid& max_pyramid,
                                    const DisparityBlockBound& bound, const Eigen::Isometry3d& T_W_C,
                                    LocalGrid* grid, DrawStatistics* stats) const {
  CV_Assert(min_pyramid.type() == PyramidType::kMinDisparity && max_pyramid.type() == PyramidType::kMaxDisparity &&
            min_pyramid.topLevel() == max_pyramid.topLevel());
  stats->coordinate_transfers += 1;  // the camera centre
  const Descent s = descent(min_pyramid, &max_pyramid, &bound, T_W_C, grid, stats);
  const int top = min_pyramid.topLevel();
  for (int y = 0; y < min_pyramid.height(top); ++y)
    for (int x = 0; x < min_pyramid.width(top); ++x) descendBounded(s, top, x, y, 0.0);
}

}  // namespace stereo_occupancy
