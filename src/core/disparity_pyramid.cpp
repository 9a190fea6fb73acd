#include "stereo_occupancy/disparity_pyramid.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stereo_occupancy {

void DisparityPyramid::build(const cv::Mat& disparity, const StereoCameraModel& camera, PyramidType type,
                             int top_level) {
  CV_Assert(disparity.type() == CV_32FC1);
  type_ = type;
  const float invalid = invalidValue();
  top_level = std::max(top_level, 0);
  levels_.resize(top_level + 1);

  // Level 0: sanitise. NaN, negative and out-of-range values carry no
  // information. Branch-free, so that it vectorises.
  cv::Mat& d0 = levels_[0];
  d0.create(disparity.rows, disparity.cols, CV_32FC1);
  const StereoCameraModel::DisparityValidity valid = camera.validity();
  for (int y = 0; y < disparity.rows; ++y) {
    const float* in = disparity.ptr<float>(y);
    float* out = d0.ptr<float>(y);
    for (int x = 0; x < disparity.cols; ++x) out[x] = valid(in[x]) ? in[x] : invalid;
  }

  auto reduce = [&](auto op) {  // 2x2 blocks; an odd last row or column pairs with itself
    for (int i = 1; i <= top_level; ++i) {
      const cv::Mat& src = levels_[i - 1];
      cv::Mat& dst = levels_[i];
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
  };
  if (type == PyramidType::kMinDisparity) {
    reduce([](float a, float b) { return b < a ? b : a; });  // eq. 14
  } else {
    reduce([](float a, float b) { return a < b ? b : a; });  // eq. 16
  }
}

PyramidLevelTable::PyramidLevelTable(const StereoCameraModel& camera, double cell_size_m)
    : c_over_b_(static_cast<float>(cell_size_m / camera.config().baseline_m)),
      far_disparity_(static_cast<float>(camera.farDisparity())),
      cell_f_px_m_(cell_size_m * camera.config().focal_length_px) {
  // At most 16 enlargement levels (2^-16 px, far below any use): eq. 15's
  // shifts and the level sizes stay within an int, also where c·d/b
  // underflows to 0 (ilogb(0) = INT_MIN).
  min_level_ = std::clamp(std::ilogb(far_disparity_ * c_over_b_), -16, 0);
  const int size_limit =
      std::ilogb(static_cast<double>(std::max(camera.config().width_px, camera.config().height_px)));
  // The nearest range, not the message's search range: drawing the same scene
  // from a disparity and from a depth camera starts from the same level.
  const double near = camera.bf() / camera.config().min_range_m;
  const int near_level = std::isfinite(near) ? std::ilogb(near * cell_size_m / camera.config().baseline_m)
                                             : size_limit;
  top_level_ = std::max(0, std::min(near_level, size_limit));
}

DisparityBlockBound::DisparityBlockBound(const StereoCameraModel& camera, const InverseSensorModel& model,
                                         double cell_size_m)
    : far_disparity_(static_cast<float>(camera.farDisparity())), bins_per_px_(8.0f) {
  const double bf = camera.bf();
  // For a line at depth z_far: the largest offset u in front of it where its
  // profile is still occupied (eq. 11 is unimodal: bisection), as a disparity.
  auto maxNear = [&](double d_min) {
    if (!(d_min > 0.0)) return 0.0;  // sky: free all the way
    const double z_far = bf / d_min;
    const double delta_l = camera.depthUncertainty(z_far);
    auto occupied = [&](double u) { return model.logOddsHat(z_far - u, z_far, delta_l, cell_size_m) > 0.0; };
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
}

}  // namespace stereo_occupancy
