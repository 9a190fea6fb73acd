#pragma once
/// @file
/// Disparity image pyramids (Andert 2009, section VI): min-disparity pyramid
/// for line drawing (eq. 14), max-disparity pyramid for ray tracing (eq. 16),
/// enlarged levels i < 0 (eq. 15), and the level choice of eqs. 12-13.

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "stereo_occupancy/integer_math.h"
#include "stereo_occupancy/inverse_sensor_model.h"
#include "stereo_occupancy/stereo_camera_model.h"
#include "stereo_occupancy/worker_pool.h"

namespace stereo_occupancy {

/// Which reduction builds level i+1 from level i.
enum class PyramidType {
  kMinDisparity,  ///< eq. 14: keeps the farthest point of each block (line drawing)
  kMaxDisparity,  ///< eq. 16: keeps the nearest point of each block (ray tracing)
};

/// A pyramid of sanitised disparity images d_i, i = 0 .. topLevel().
///
/// Level 0 is the input with invalid pixels replaced by a value that the
/// pyramid's reduction ignores: +inf for the min pyramid, -1 for the max
/// pyramid. Zero (infinitely far) and valid disparities are kept as they are.
/// Level i+1 has ceil(w_i / 2) x ceil(h_i / 2) pixels; a block at the right or
/// bottom edge reduces only the pixels that exist. Levels i < 0 are not stored:
/// at() reads them through eq. 15.
class DisparityPyramid {
 public:
  static constexpr float kInvalidMin = std::numeric_limits<float>::infinity();
  static constexpr float kInvalidMax = -1.0f;

  /// Builds levels 0..top_level from a CV_32FC1 disparity image [px]; with
  /// a @p pool, the pass over the image in bands of rows on its workers (the
  /// same pyramid).
  void build(const cv::Mat& disparity, const StereoCameraModel& camera, PyramidType type, int top_level,
             WorkerPool* pool = nullptr);
  /// The min pyramid into @p min_pyramid and the max pyramid into @p
  /// max_pyramid (either may be null) of the same image, as build() builds
  /// them, in one pass over the image's memory: each pair of its rows is
  /// reduced into both while it is in the cache (the bounded algorithms
  /// draw from both).
  static void buildPyramids(const cv::Mat& disparity, const StereoCameraModel& camera, int top_level,
                            DisparityPyramid* min_pyramid, DisparityPyramid* max_pyramid, WorkerPool* pool = nullptr);

  PyramidType type() const { return type_; }
  int topLevel() const { return static_cast<int>(levels_.size()) - 1; }
  /// Value that marks a pixel without information in this pyramid.
  float invalidValue() const { return type_ == PyramidType::kMinDisparity ? kInvalidMin : kInvalidMax; }

  /// Stored level i, 0 <= i <= topLevel().
  const cv::Mat& level(int i) const { return levels_[i]; }

  /// Width and height of level i; for i < 0 the size of level 0 times 2^-i.
  int width(int i) const { return i >= 0 ? levels_[i].cols : levels_[0].cols << -i; }
  int height(int i) const { return i >= 0 ? levels_[i].rows : levels_[0].rows << -i; }

  /// d_i(x, y) for any level; for i < 0, d_i(x, y) = d_0(x >> -i, y >> -i) (eq. 15).
  float at(int i, int x, int y) const {
    if (i >= 0) return levels_[i].ptr<float>(y)[x];
    return levels_[0].ptr<float>(y >> -i)[x >> -i];
  }

  /// Image coordinate (level 0 pixels) of the centre of pixel x at level i,
  /// along an axis with @p size0 level-0 pixels: the centre of the level-0
  /// pixels the block covers (a block at the right or bottom edge may be cut).
  static double centreOf(int i, int x, int size0) {
    if (i <= 0) return (x + 0.5) * powerOfTwo(i) - 0.5;
    const double first = static_cast<double>(x << i);
    const double last = static_cast<double>(std::min((x + 1) << i, size0) - 1);
    return 0.5 * (first + last);
  }

 private:
  PyramidType type_ = PyramidType::kMinDisparity;
  std::vector<cv::Mat> levels_;
};

/// Pyramid level per disparity (eqs. 12-13) for a grid of cell size c.
///
/// Neighbouring pixels of level i lie Δp = z·2^i/f apart (eq. 12); the level
/// drawn is the one with 0.5·c < Δp <= c (eq. 13), i.e.
/// i(d) = floor(log2(c·d / b)). Disparities below the far disparity of the
/// maximum range (including 0, infinitely far) use the level of the maximum
/// range, since their rays are drawn as free space up to it.
class PyramidLevelTable {
 public:
  PyramidLevelTable(const StereoCameraModel& camera, double cell_size_m);

  /// Level for disparity d [px], clamped to [minLevel(), topLevel()].
  int levelForDisparity(float d_px) const {
    const float d = d_px > far_disparity_ ? d_px : far_disparity_;
    const int i = floorLog2(d * c_over_b_);  // floor(log2(c·d/b)): the float's exponent
    return i < min_level_ ? min_level_ : (i > top_level_ ? top_level_ : i);
  }

  /// Level for a depth z [m] (eq. 13 with d = bf/z), clamped likewise.
  int levelForDepth(double z_m) const {
    if (!(z_m > 0.0)) return top_level_;
    const int i = floorLog2(cell_f_px_m_ / z_m);  // floor(log2(c·f/z))
    return i < min_level_ ? min_level_ : (i > top_level_ ? top_level_ : i);
  }

  /// Lowest level used: min(0, level of the maximum range), at least -16; < 0 means eq. 15 enlargements.
  int minLevel() const { return min_level_; }
  /// Lowest minLevel() a DisparityDrawer accepts for pyramidal line drawing
  /// (ray tracing reads level i < 0 per cell at no extra cost): level i < 0 draws 4^-i lines
  /// per pixel, so a grid far finer than the pixels' spacing at the maximum
  /// range would cost without bound. -3 is 8 x 8 lines per pixel.
  static constexpr int kLowestLevel = -3;
  /// Highest level worth building: that of the minimum range's disparity, at
  /// most the level where the image shrinks to one pixel.
  int topLevel() const { return top_level_; }

  /// Unclamped eq. 13 level of disparity d > 0.
  static int rawLevel(double d_px, double cell_size_m, double baseline_m) {
    return std::ilogb(d_px * cell_size_m / baseline_m);
  }

 private:
  float c_over_b_;
  float far_disparity_;
  int min_level_;
  int top_level_;
  double cell_f_px_m_;  ///< c·f
};

/// The depth bound of the bounded pyramids (beyond the paper, see README).
///
/// A block whose valid disparities span [d_min, d_max] is represented
/// faithfully by one line at d_min (or one look-up of d_max) when the nearest
/// measurement lies where the farthest one's profile is still occupied:
/// L̂(z_near; l_p = z_far) > 0 (eq. 11, with Δl of eq. 5 at z_far). That
/// offset is at least half a cell and grows with Δl, so for far blocks it
/// reaches about Δl; a nearer obstacle would be drawn free by the far line
/// and needs its own lines. A block of sky (zero) and measurements in range
/// never is; a block wholly beyond the range always is (drawn free to it).
class DisparityBlockBound {
 public:
  DisparityBlockBound(const StereoCameraModel& camera, const InverseSensorModel& model, double cell_size_m);

  /// True if one line at d_min (one look-up of d_max) stands for every
  /// disparity in [d_min, d_max]; requires 0 <= d_min <= d_max, both valid.
  bool isFaithful(float d_min, float d_max) const {
    if (d_max < far_disparity_) return true;  // all sky or beyond the range: free to the range
    return d_max <= maxNearDisparity(d_min);
  }

  /// Largest d_max for which a block with this d_min is faithful [px] (0 for sky).
  float maxNearDisparity(float d_min) const {
    const float bin = d_min * bins_per_px_;  // compared before the cast: a huge d_min has no size_t
    if (bin < static_cast<float>(max_d_max_.size())) return max_d_max_[static_cast<size_t>(bin)];
    // Beyond the table (disparities above kMaxTabulatedPx): one cell,
    // z_far - z_near <= c, i.e. d_max <= d_min·bf / (bf - c·d_min).
    const float rest = bf_ - c_ * d_min;
    return rest > 0.0f ? d_min * bf_ / rest : std::numeric_limits<float>::infinity();
  }

  /// From this disparity on a faithful pair's inner pairs are faithful:
  /// isFaithful(a, b) implies isFaithful(a', b') for monotoneFrom() <= a <=
  /// a' <= b' <= b (maxNearDisparity() never falls as d_min grows). A gap
  /// inside a faithful gap is then one. (Below it lie the surface profile's
  /// ranges hundreds of metres out, whose gap covers the whole range.) [px]
  float monotoneFrom() const { return monotone_from_; }

  /// Disparities up to this are tabulated (8 bins per pixel).
  static constexpr double kMaxTabulatedPx = 1024.0;

 private:
  float far_disparity_;
  float bins_per_px_;
  std::vector<float> max_d_max_;  ///< per bin [k, k+1) / bins_per_px of d_min, conservative over the bin
  float bf_;                      ///< b·f [px·m]
  float c_;                       ///< cell size [m]
  float monotone_from_;           ///< monotoneFrom()
};

}  // namespace stereo_occupancy
