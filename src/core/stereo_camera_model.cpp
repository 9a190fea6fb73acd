#include "stereo_occupancy/stereo_camera_model.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace stereo_occupancy {

namespace {
bool fail(std::string* why, const std::string& text) {
  if (why) *why = text;
  return false;
}
}  // namespace

bool StereoCameraConfig::isValid(std::string* why) const {
  if (width_px <= 0 || height_px <= 0) return fail(why, "image size must be positive");
  if (!(std::isfinite(focal_length_px) && focal_length_px > 0.0))
    return fail(why, "focal_length_px must be finite and > 0");
  if (!std::isfinite(cx_px) || !std::isfinite(cy_px)) return fail(why, "cx_px/cy_px must be finite");
  // A rectified principal point may leave the image a little, never by more
  // than its size: farther means a broken camera_info, not a lens.
  if (cx_px < -width_px || cx_px > 2.0 * width_px || cy_px < -height_px || cy_px > 2.0 * height_px)
    return fail(why, "the principal point (" + std::to_string(cx_px) + ", " + std::to_string(cy_px) +
                         ") px lies more than the image's size outside the image");
  if (!(std::isfinite(baseline_m) && baseline_m > 0.0)) return fail(why, "baseline_m must be finite and > 0");
  if (!(std::isfinite(delta_d_px) && delta_d_px > 0.0)) return fail(why, "delta_d_px must be finite and > 0");
  if (!(std::isfinite(min_range_m) && min_range_m > 0.0)) return fail(why, "min_range_m must be finite and > 0");
  if (!(std::isfinite(max_range_m) && max_range_m > min_range_m))
    return fail(why, "max_range_m must be finite and > min_range_m");
  if (!(std::isfinite(min_disparity_px) && min_disparity_px >= 0.0))
    return fail(why, "min_disparity_px must be finite and >= 0");
  if (!(max_disparity_px > min_disparity_px)) return fail(why, "max_disparity_px must be > min_disparity_px");
  return true;
}

bool StereoCameraConfig::operator==(const StereoCameraConfig& o) const {
  return width_px == o.width_px && height_px == o.height_px && focal_length_px == o.focal_length_px &&
         cx_px == o.cx_px && cy_px == o.cy_px && baseline_m == o.baseline_m && delta_d_px == o.delta_d_px &&
         min_range_m == o.min_range_m && max_range_m == o.max_range_m && min_disparity_px == o.min_disparity_px &&
         max_disparity_px == o.max_disparity_px;
}

StereoCameraModel::StereoCameraModel(const StereoCameraConfig& config)
    : config_(config),
      bf_(config.baseline_m * config.focal_length_px),
      inv_f_(1.0 / config.focal_length_px),
      delta_d_over_bf_(config.delta_d_px / bf_),
      far_disparity_px_(bf_ / config.max_range_m) {
  min_valid_ = std::max(static_cast<float>(config.min_disparity_px), std::numeric_limits<float>::min());
  max_valid_ = static_cast<float>(nearDisparity());
}

double StereoCameraModel::nearDisparity() const {
  return std::min(config_.max_disparity_px, bf_ / config_.min_range_m);
}

DisparityCensus StereoCameraModel::census(const cv::Mat& disparity) const {
  CV_Assert(disparity.type() == CV_32FC1);
  DisparityCensus c;
  const float far = static_cast<float>(far_disparity_px_);
  for (int y = 0; y < disparity.rows; ++y) {
    const float* row = disparity.ptr<float>(y);
    for (int x = 0; x < disparity.cols; ++x) {
      const float d = row[x];
      if (!std::isfinite(d) || d < 0.0f)
        ++c.no_match;
      else if (d == 0.0f)
        ++c.sky;
      else if (!isValidDisparity(d))
        ++c.out_of_range;
      else if (d < far)
        ++c.beyond_range;
      else
        ++c.measured;
    }
  }
  return c;
}

void depthToDisparity(const cv::Mat& depth, double bf_px_m, cv::Mat* disparity) {
  if (depth.type() != CV_16UC1 && depth.type() != CV_32FC1)
    throw std::invalid_argument("depth image must be 16UC1 (mm) or 32FC1 (m)");
  disparity->create(depth.rows, depth.cols, CV_32FC1);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const bool mm = depth.type() == CV_16UC1;
  const float bf = static_cast<float>(mm ? bf_px_m * 1000.0 : bf_px_m);  // d = bf / z (eq. 1)
  for (int y = 0; y < depth.rows; ++y) {
    float* out = disparity->ptr<float>(y);
    if (mm) {
      const uint16_t* in = depth.ptr<uint16_t>(y);
      for (int x = 0; x < depth.cols; ++x) out[x] = in[x] == 0 ? nan : bf / static_cast<float>(in[x]);
    } else {
      const float* in = depth.ptr<float>(y);
      for (int x = 0; x < depth.cols; ++x) out[x] = (in[x] > 0.0f && std::isfinite(in[x])) ? bf / in[x] : nan;
    }
  }
}

}  // namespace stereo_occupancy
