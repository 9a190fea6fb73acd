#include "stereo_occupancy/sim/stereo_matching.h"

#include <opencv2/calib3d.hpp>

#include <limits>
#include <sstream>
#include <stdexcept>

namespace stereo_occupancy {

SgbmParameters SgbmParameters::fineBlock() {
  constexpr int kBlockPx = 5, kP1PerPixel = 8, kP2PerPixel = 32;
  SgbmParameters p;
  p.block_size_px = kBlockPx;
  p.p1 = kP1PerPixel * kBlockPx * kBlockPx;
  p.p2 = kP2PerPixel * kBlockPx * kBlockPx;
  p.disp12_max_diff_px = 1;
  return p;
}

std::string SgbmParameters::describe() const {
  std::ostringstream out;
  out << "StereoSGBM: " << num_disparities << " disparities from " << min_disparity_px << ", " << block_size_px
      << " px block, P1 " << p1 << ", P2 " << p2 << ", disp12MaxDiff " << disp12_max_diff_px << ", preFilterCap "
      << prefilter_cap << ", uniqueness " << uniqueness_ratio_percent << " %, speckles " << speckle_size_px << " px / "
      << speckle_range_px << " px" << (full_dp ? ", full DP" : "");
  return out.str();
}

bool SgbmParameters::isValid(std::string* why) const {
  auto fail = [&](const std::string& reason) {
    if (why) *why = reason;
    return false;
  };
  if (num_disparities <= 0 || num_disparities % 16 != 0)
    return fail("num_disparities must be a positive multiple of 16");
  if (block_size_px < 1 || block_size_px % 2 == 0) return fail("block_size_px must be odd and >= 1");
  if (p1 < 0 || p2 <= p1) return fail("P2 must exceed P1 >= 0");
  if (prefilter_cap < 1 || uniqueness_ratio_percent < 0 || speckle_size_px < 0 || speckle_range_px < 0 ||
      disp12_max_diff_px < 0)
    return fail("preFilterCap must be >= 1 and the other counts >= 0");
  return true;
}

cv::Mat matchSgbm(const cv::Mat& left, const cv::Mat& right, const SgbmParameters& params) {
  std::string why;
  if (!params.isValid(&why)) throw std::invalid_argument("SGBM parameters: " + why);
  if (left.type() != CV_8UC1 || right.type() != CV_8UC1 || left.size() != right.size())
    throw std::invalid_argument("SGBM wants two 8-bit grey images of one size");
  // stereo_image_proc's StereoProcessor passes the parameters as they are;
  // OpenCV scales the speckle range by its 16 sub-pixel steps itself.
  auto sgbm = cv::StereoSGBM::create(params.min_disparity_px, params.num_disparities, params.block_size_px, params.p1,
                                     params.p2, params.disp12_max_diff_px, params.prefilter_cap,
                                     params.uniqueness_ratio_percent, params.speckle_size_px, params.speckle_range_px,
                                     params.full_dp ? cv::StereoSGBM::MODE_HH : cv::StereoSGBM::MODE_SGBM);
  cv::Mat fixed_point;  // 1/16 px steps; no match: (min_disparity - 1) * 16
  sgbm->compute(left, right, fixed_point);
  cv::Mat disparity(fixed_point.size(), CV_32FC1);
  const int unmatched = (params.min_disparity_px - 1) * cv::StereoMatcher::DISP_SCALE;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int y = 0; y < fixed_point.rows; ++y) {
    const int16_t* in = fixed_point.ptr<int16_t>(y);
    float* out = disparity.ptr<float>(y);
    for (int x = 0; x < fixed_point.cols; ++x)
      out[x] = in[x] <= unmatched ? nan : static_cast<float>(in[x]) / cv::StereoMatcher::DISP_SCALE;
  }
  return disparity;
}

}  // namespace stereo_occupancy
