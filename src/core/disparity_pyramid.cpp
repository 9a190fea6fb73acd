#include "stereo_occupancy/disparity_pyramid.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "stereo_occupancy/cpu_features.h"
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
// The first pass in AVX2's eight lanes where the CPU has them (chosen at
// run time, avx2Enabled(); the same results lane for lane as SSE2's, with
// the quiet forms of its compares).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
#define STEREO_OCCUPANCY_AVX2_PYRAMID 1
#include <immintrin.h>
#endif

namespace stereo_occupancy {

namespace {

// The reductions of two values. op(a, b) keeps a for equal values (also +0
// against -0); so do the lanes' _mm_min_ps(b, a) and _mm_max_ps(b, a), which
// return their second operand then.
struct MinDisparity {  // eq. 14
  static float op(float a, float b) { return b < a ? b : a; }
#if defined(__SSE2__)
  static __m128 op4(__m128 a, __m128 b) { return _mm_min_ps(b, a); }
#endif
#if STEREO_OCCUPANCY_AVX2_PYRAMID
  __attribute__((target("avx2"))) static __m256 op8(__m256 a, __m256 b) { return _mm256_min_ps(b, a); }
#endif
};
struct MaxDisparity {  // eq. 16
  static float op(float a, float b) { return a < b ? b : a; }
#if defined(__SSE2__)
  static __m128 op4(__m128 a, __m128 b) { return _mm_max_ps(b, a); }
#endif
#if STEREO_OCCUPANCY_AVX2_PYRAMID
  __attribute__((target("avx2"))) static __m256 op8(__m256 a, __m256 b) { return _mm256_max_ps(b, a); }
#endif
};

/// One pyramid's first two levels as they are built: level 0 (the
/// sanitised input), level 1, and the value of a pixel without information.
struct FirstLevels {
  cv::Mat* d0;
  cv::Mat* d1;
  float invalid;
};

/// The rows a pass writes for one pyramid: rows 2y and 2y + 1 of level 0
/// (the same row for an odd last input row) and row y of level 1.
struct RowPair {
  float* s0;
  float* s1;
  float* out;
};
RowPair rowPair(const FirstLevels& levels, int y, bool two_rows) {
  float* s0 = levels.d0->ptr<float>(2 * y);
  return {s0, two_rows ? levels.d0->ptr<float>(2 * y + 1) : s0, levels.d1->ptr<float>(y)};
}

/// sanitiseAndReduceRow() from block @p x on, one value at a time.
template <typename Reduction>
void sanitiseAndReduceFrom(const float* in0, const float* in1, int cols, StereoCameraModel::DisparityValidity valid,
                           float invalid, const RowPair& r, int x) {
  const int w = (cols + 1) / 2;
  const int full = cols / 2;  // blocks with two columns
  auto sanitise = [&](float d) { return valid(d) ? d : invalid; };
  for (; x < full; ++x) {
    const float a = r.s0[2 * x] = sanitise(in0[2 * x]), b = r.s0[2 * x + 1] = sanitise(in0[2 * x + 1]);
    const float c = r.s1[2 * x] = sanitise(in1[2 * x]), d = r.s1[2 * x + 1] = sanitise(in1[2 * x + 1]);
    r.out[x] = Reduction::op(Reduction::op(a, b), Reduction::op(c, d));
  }
  if (full < w) {
    const float a = r.s0[2 * full] = sanitise(in0[2 * full]), c = r.s1[2 * full] = sanitise(in1[2 * full]);
    r.out[full] = Reduction::op(a, c);
  }
}

#if defined(__SSE2__)
/// sanitise()'s test of an input value, four at a time in SSE2 lanes.
struct Lanes4 {
  __m128 zero = _mm_setzero_ps(), lo, hi;
  explicit Lanes4(StereoCameraModel::DisparityValidity valid)
      : lo(_mm_set1_ps(valid.min_px)), hi(_mm_set1_ps(valid.max_px)) {}
  __m128 ok(__m128 d) const {
    return _mm_or_ps(_mm_cmpeq_ps(d, zero), _mm_and_ps(_mm_cmpge_ps(d, lo), _mm_cmple_ps(d, hi)));
  }
};
/// Four blocks of level 1 (eight columns of both rows) for one pyramid:
/// the input values, tested once (@p ok) and masked (@p valid_d), take the
/// pyramid's invalid value where they failed (the min's and the max's
/// differ), go to level 0 and are reduced with Reduction::op4 into level 1.
template <typename Reduction>
#if defined(__GNUC__)
__attribute__((always_inline))  // out of line, the lanes went through memory
#endif
inline void
reduceLanes(const __m128 (&ok)[4], const __m128 (&valid_d)[4], __m128 invalid, const RowPair& r, int x) {
  __m128 v[4];
  for (int k = 0; k < 4; ++k) v[k] = _mm_or_ps(valid_d[k], _mm_andnot_ps(ok[k], invalid));
  _mm_storeu_ps(r.s0 + 2 * x, v[0]);
  _mm_storeu_ps(r.s0 + 2 * x + 4, v[1]);
  _mm_storeu_ps(r.s1 + 2 * x, v[2]);
  _mm_storeu_ps(r.s1 + 2 * x + 4, v[3]);
  const __m128 top = Reduction::op4(_mm_shuffle_ps(v[0], v[1], _MM_SHUFFLE(2, 0, 2, 0)),
                                    _mm_shuffle_ps(v[0], v[1], _MM_SHUFFLE(3, 1, 3, 1)));
  const __m128 bottom = Reduction::op4(_mm_shuffle_ps(v[2], v[3], _MM_SHUFFLE(2, 0, 2, 0)),
                                       _mm_shuffle_ps(v[2], v[3], _MM_SHUFFLE(3, 1, 3, 1)));
  _mm_storeu_ps(r.out + x, Reduction::op4(top, bottom));
}
#endif

#if STEREO_OCCUPANCY_AVX2_PYRAMID
/// reduceLanes() for eight blocks (sixteen columns of both rows) in AVX2
/// lanes. The pairs' shuffle works within each half of the registers, which
/// leaves the blocks in the order 0, 1, 4, 5, 2, 3, 6, 7: one permute of
/// their 64-bit pairs puts them back.
template <typename Reduction>
__attribute__((target("avx2"), always_inline)) inline void reduceLanes8(const __m256 (&ok)[4],
                                                                        const __m256 (&valid_d)[4], __m256 invalid,
                                                                        const RowPair& r, int x) {
  __m256 v[4];
  for (int k = 0; k < 4; ++k) v[k] = _mm256_or_ps(valid_d[k], _mm256_andnot_ps(ok[k], invalid));
  _mm256_storeu_ps(r.s0 + 2 * x, v[0]);
  _mm256_storeu_ps(r.s0 + 2 * x + 8, v[1]);
  _mm256_storeu_ps(r.s1 + 2 * x, v[2]);
  _mm256_storeu_ps(r.s1 + 2 * x + 8, v[3]);
  const __m256 top = Reduction::op8(_mm256_shuffle_ps(v[0], v[1], _MM_SHUFFLE(2, 0, 2, 0)),
                                    _mm256_shuffle_ps(v[0], v[1], _MM_SHUFFLE(3, 1, 3, 1)));
  const __m256 bottom = Reduction::op8(_mm256_shuffle_ps(v[2], v[3], _MM_SHUFFLE(2, 0, 2, 0)),
                                       _mm256_shuffle_ps(v[2], v[3], _MM_SHUFFLE(3, 1, 3, 1)));
  const __m256 blocks = Reduction::op8(top, bottom);
  _mm256_storeu_ps(r.out + x,
                   _mm256_castpd_ps(_mm256_permute4x64_pd(_mm256_castps_pd(blocks), _MM_SHUFFLE(3, 1, 2, 0))));
}

/// sanitiseAndReduceRow()'s blocks from @p x on, eight at a time in AVX2
/// lanes with the same tests and reductions; returns the first block not done.
template <bool kMin, bool kMax>
__attribute__((target("avx2"))) int sanitiseAndReduceBlocks8(const float* in0, const float* in1, int cols,
                                                             StereoCameraModel::DisparityValidity valid,
                                                             float min_invalid_value, float max_invalid_value,
                                                             const RowPair& min_rows, const RowPair& max_rows, int x) {
  const __m256 zero = _mm256_setzero_ps(), lo = _mm256_set1_ps(valid.min_px), hi = _mm256_set1_ps(valid.max_px);
  const __m256 min_invalid = _mm256_set1_ps(min_invalid_value), max_invalid = _mm256_set1_ps(max_invalid_value);
  for (; 2 * x + 16 <= cols; x += 8) {  // eight blocks: sixteen columns of both rows
    const __m256 d[4] = {_mm256_loadu_ps(in0 + 2 * x), _mm256_loadu_ps(in0 + 2 * x + 8), _mm256_loadu_ps(in1 + 2 * x),
                         _mm256_loadu_ps(in1 + 2 * x + 8)};
    __m256 ok[4], valid_d[4];
    for (int k = 0; k < 4; ++k) {  // Lanes4::ok()
      ok[k] = _mm256_or_ps(_mm256_cmp_ps(d[k], zero, _CMP_EQ_OQ),
                           _mm256_and_ps(_mm256_cmp_ps(d[k], lo, _CMP_GE_OQ), _mm256_cmp_ps(d[k], hi, _CMP_LE_OQ)));
      valid_d[k] = _mm256_and_ps(ok[k], d[k]);
    }
    if constexpr (kMin) reduceLanes8<MinDisparity>(ok, valid_d, min_invalid, min_rows, x);
    if constexpr (kMax) reduceLanes8<MaxDisparity>(ok, valid_d, max_invalid, max_rows, x);
  }
  return x;
}
#endif

/// Row y of level 1 and rows 2y, 2y + 1 of level 0 from the input rows
/// @p in0 and @p in1 (the same row for an odd last one), for the min
/// pyramid if @p min_levels is set and the max pyramid if @p max_levels
/// is: each pair of input rows is sanitised into level 0 and reduced into
/// a row of level 1 while it is in registers, with the pyramid's reduction
/// (MinDisparity, MaxDisparity), eight blocks at a time in AVX2 lanes where
/// the CPU has them, then four at a time in SSE2 lanes; with
/// both, each value is loaded and tested once. NaN, negative and
/// out-of-range values carry no information. kMin and kMax say which are
/// set, so that one pyramid's loop has no branches for the other.
template <bool kMin, bool kMax>
void sanitiseAndReduceRow(const float* in0, const float* in1, int cols, StereoCameraModel::DisparityValidity valid,
                          const FirstLevels* min_levels, const FirstLevels* max_levels, int y) {
  const bool two_rows = in1 != in0;
  RowPair min_rows{}, max_rows{};
  if constexpr (kMin) min_rows = rowPair(*min_levels, y, two_rows);
  if constexpr (kMax) max_rows = rowPair(*max_levels, y, two_rows);
  int x = 0;
#if STEREO_OCCUPANCY_AVX2_PYRAMID
  if (avx2Enabled())
    x = sanitiseAndReduceBlocks8<kMin, kMax>(in0, in1, cols, valid, kMin ? min_levels->invalid : 0.0f,
                                             kMax ? max_levels->invalid : 0.0f, min_rows, max_rows, x);
#endif
#if defined(__SSE2__)
  const Lanes4 lanes(valid);
  const __m128 min_invalid = _mm_set1_ps(kMin ? min_levels->invalid : 0.0f);
  const __m128 max_invalid = _mm_set1_ps(kMax ? max_levels->invalid : 0.0f);
  for (; 2 * x + 8 <= cols; x += 4) {  // four blocks: eight columns of both rows
    const __m128 d[4] = {_mm_loadu_ps(in0 + 2 * x), _mm_loadu_ps(in0 + 2 * x + 4), _mm_loadu_ps(in1 + 2 * x),
                         _mm_loadu_ps(in1 + 2 * x + 4)};
    __m128 ok[4], valid_d[4];
    for (int k = 0; k < 4; ++k) {
      ok[k] = lanes.ok(d[k]);
      valid_d[k] = _mm_and_ps(ok[k], d[k]);
    }
    if constexpr (kMin) reduceLanes<MinDisparity>(ok, valid_d, min_invalid, min_rows, x);
    if constexpr (kMax) reduceLanes<MaxDisparity>(ok, valid_d, max_invalid, max_rows, x);
  }
#endif
  if constexpr (kMin) sanitiseAndReduceFrom<MinDisparity>(in0, in1, cols, valid, min_levels->invalid, min_rows, x);
  if constexpr (kMax) sanitiseAndReduceFrom<MaxDisparity>(in0, in1, cols, valid, max_levels->invalid, max_rows, x);
}

/// The rows [y_begin, y_end) of level 1 (and their rows of level 0) of the
/// min pyramid, when @p min_levels is set, and of the max pyramid, when
/// @p max_levels is: both from the same input rows while they are in the cache.
void sanitiseAndReduce(const cv::Mat& disparity, StereoCameraModel::DisparityValidity valid, int y_begin, int y_end,
                       const FirstLevels* min_levels, const FirstLevels* max_levels) {
  for (int y = y_begin; y < y_end; ++y) {  // rows of level 1
    const float* in0 = disparity.ptr<float>(2 * y);
    const float* in1 = 2 * y + 1 < disparity.rows ? disparity.ptr<float>(2 * y + 1) : in0;  // an odd last row
    if (min_levels && max_levels)
      sanitiseAndReduceRow<true, true>(in0, in1, disparity.cols, valid, min_levels, max_levels, y);
    else if (min_levels)
      sanitiseAndReduceRow<true, false>(in0, in1, disparity.cols, valid, min_levels, nullptr, y);
    else
      sanitiseAndReduceRow<false, true>(in0, in1, disparity.cols, valid, nullptr, max_levels, y);
  }
}

/// Levels 2 .. top of @p levels from level 1: 2x2 blocks; an odd last row or column pairs with itself.
template <typename Reduction>
void reduceUpperLevels(std::vector<cv::Mat>* levels) {
  auto op = [](float a, float b) { return Reduction::op(a, b); };
  for (size_t i = 2; i < levels->size(); ++i) {
    const cv::Mat& src = (*levels)[i - 1];
    cv::Mat& dst = (*levels)[i];
    const int w = (src.cols + 1) / 2;
    const int h = (src.rows + 1) / 2;
    const int full = src.cols / 2;  // blocks with two columns
    dst.create(h, w, CV_32FC1);
    for (int y = 0; y < h; ++y) {
      const float* r0 = src.ptr<float>(2 * y);
      const float* r1 = 2 * y + 1 < src.rows ? src.ptr<float>(2 * y + 1) : r0;
      float* out = dst.ptr<float>(y);
      for (int x = 0; x < full; ++x) out[x] = op(op(r0[2 * x], r0[2 * x + 1]), op(r1[2 * x], r1[2 * x + 1]));
      if (full < w) out[full] = op(r0[2 * full], r1[2 * full]);
    }
  }
}

/// Level-1 rows (or level-0 rows) per part of the first pass on a pool: a
/// part reads and writes tens of kB, more than a part's hand-out costs.
constexpr int kRowsPerPart = 16;

/// Calls part(y_begin, y_end) over [0, rows): on the pool's workers in bands
/// of rows where there are several, else at once.
template <typename Part>
void inRowBands(int rows, WorkerPool* pool, const Part& part) {
  const int parts = pool ? std::min(rows / kRowsPerPart, 2 * static_cast<int>(pool->size())) : 1;
  if (parts < 2) {
    part(0, rows);
    return;
  }
  pool->run(static_cast<size_t>(parts), [&](size_t i, unsigned) {
    part(static_cast<int>(rows * static_cast<int64_t>(i) / parts),
         static_cast<int>(rows * static_cast<int64_t>(i + 1) / parts));
  });
}

}  // namespace

void DisparityPyramid::build(const cv::Mat& disparity, const StereoCameraModel& camera, PyramidType type, int top_level,
                             WorkerPool* pool) {
  if (type == PyramidType::kMinDisparity)
    buildPyramids(disparity, camera, top_level, this, nullptr, pool);
  else
    buildPyramids(disparity, camera, top_level, nullptr, this, pool);
}

void DisparityPyramid::buildPyramids(const cv::Mat& disparity, const StereoCameraModel& camera, int top_level,
                                     DisparityPyramid* min_pyramid, DisparityPyramid* max_pyramid, WorkerPool* pool) {
  CV_Assert(disparity.type() == CV_32FC1 && (min_pyramid || max_pyramid) && min_pyramid != max_pyramid);
  top_level = std::max(top_level, 0);
  const StereoCameraModel::DisparityValidity valid = camera.validity();
  FirstLevels first[2] = {};  // d0 null: that pyramid is not built
  DisparityPyramid* pyramids[2] = {min_pyramid, max_pyramid};
  for (int k = 0; k < 2; ++k) {
    DisparityPyramid* p = pyramids[k];
    if (!p) continue;
    p->type_ = k == 0 ? PyramidType::kMinDisparity : PyramidType::kMaxDisparity;
    p->levels_.resize(top_level + 1);
    p->levels_[0].create(disparity.rows, disparity.cols, CV_32FC1);
    if (top_level > 0) p->levels_[1].create((disparity.rows + 1) / 2, (disparity.cols + 1) / 2, CV_32FC1);
    first[k] = {&p->levels_[0], top_level > 0 ? &p->levels_[1] : nullptr, p->invalidValue()};
  }
  if (top_level == 0) {  // level 0 alone: sanitise. Branch-free, so that it vectorises.
    inRowBands(disparity.rows, pool, [&](int y_begin, int y_end) {
      for (int y = y_begin; y < y_end; ++y) {
        const float* in = disparity.ptr<float>(y);
        for (const FirstLevels& f : first) {
          if (!f.d0) continue;
          float* out = f.d0->ptr<float>(y);
          const float invalid = f.invalid;  // a local: stores to out cannot change it
          for (int x = 0; x < disparity.cols; ++x) out[x] = valid(in[x]) ? in[x] : invalid;
        }
      }
    });
    return;
  }
  // The pass over the whole image in bands of rows; the levels above it
  // hold a third of level 1's pixels, too few to share.
  inRowBands((disparity.rows + 1) / 2, pool, [&](int y_begin, int y_end) {
    sanitiseAndReduce(disparity, valid, y_begin, y_end, min_pyramid ? &first[0] : nullptr,
                      max_pyramid ? &first[1] : nullptr);
  });
  if (min_pyramid) reduceUpperLevels<MinDisparity>(&min_pyramid->levels_);
  if (max_pyramid) reduceUpperLevels<MaxDisparity>(&max_pyramid->levels_);
}

PyramidLevelTable::PyramidLevelTable(const StereoCameraModel& camera, double cell_size_m)
    : c_over_b_(static_cast<float>(cell_size_m / camera.config().baseline_m)),
      far_disparity_(static_cast<float>(camera.farDisparity())),
      cell_f_px_m_(cell_size_m * camera.config().focal_length_px) {
  // At most 16 enlargement levels (2^-16 px, far below any use): eq. 15's
  // shifts and the level sizes stay within an int, also where c·d/b
  // underflows to 0 (ilogb(0) = INT_MIN).
  constexpr int kMostEnlargements = 16;
  min_level_ = std::clamp(std::ilogb(far_disparity_ * c_over_b_), -kMostEnlargements, 0);
  const int size_limit = std::ilogb(static_cast<double>(std::max(camera.config().width_px, camera.config().height_px)));
  // The nearest range, not the message's search range: drawing the same scene
  // from a disparity and from a depth camera starts from the same level.
  const double near = camera.bf() / camera.config().min_range_m;
  const int near_level = std::isfinite(near) ? std::ilogb(near * cell_size_m / camera.config().baseline_m) : size_limit;
  top_level_ = std::max(0, std::min(near_level, size_limit));
}

DisparityBlockBound::DisparityBlockBound(const StereoCameraModel& camera, const InverseSensorModel& model,
                                         double cell_size_m)
    : far_disparity_(static_cast<float>(camera.farDisparity())), bins_per_px_(8.0f) {
  const double bf = camera.bf();
  // For a line at depth z_far: the largest offset u in front of it where its
  // profile does not yet call a cell free (eq. 11 is unimodal: bisection), as
  // a disparity. For the Gaussian profile that is where it is occupied; the
  // surface profile's gap (no information) counts too.
  auto maxNear = [&](double d_min) {
    if (!(d_min > 0.0)) return 0.0;  // sky: free all the way
    const double z_far = bf / d_min;
    const double delta_l = camera.depthUncertainty(z_far);
    const bool surface = model.config().profile == SensorProfile::kSurface;
    auto occupied = [&](double u) {
      const double L = model.logOddsHat(z_far - u, z_far, delta_l, cell_size_m);
      return surface ? L >= 0.0 : L > 0.0;
    };
    double lo = 0.0, hi = z_far;
    if (occupied(hi)) return std::numeric_limits<double>::infinity();
    for (int it = 0; it < 40; ++it) {
      const double mid = 0.5 * (lo + hi);
      (occupied(mid) ? lo : hi) = mid;
    }
    return bf / (z_far - lo);
  };
  const double near = std::min(camera.nearDisparity(), kMaxTabulatedPx);
  const int bins = static_cast<int>(std::ceil(near * bins_per_px_)) + 1;
  max_d_max_.resize(bins);
  double previous = maxNear(0.0);
  for (int k = 0; k < bins; ++k) {
    const double next = maxNear((k + 1) / static_cast<double>(bins_per_px_));
    max_d_max_[k] = static_cast<float>(std::min(previous, next));  // d_min anywhere in the bin
    previous = next;
  }
  bf_ = static_cast<float>(bf);
  c_ = static_cast<float>(cell_size_m);
  // Beyond the table the one-cell bound rises with d_min (each float step
  // rounds monotonically); it must not start below the table's last bin.
  const float first_untabulated = static_cast<float>(bins) / bins_per_px_;
  monotone_from_ = std::numeric_limits<float>::infinity();
  if (max_d_max_.back() <= maxNearDisparity(first_untabulated)) {
    size_t first = max_d_max_.size() - 1;  // the first bin of the table's rising tail
    while (first > 0 && max_d_max_[first - 1] <= max_d_max_[first]) --first;
    monotone_from_ = static_cast<float>(first) / bins_per_px_;
  }
}

}  // namespace stereo_occupancy
