#pragma once
/// @file
/// OpenCV's StereoSGBM set up as stereo_image_proc sets it up: one place for
/// the tools and the simulated flights that match real (or rendered) images.

#include <opencv2/core.hpp>

#include <string>

namespace stereo_occupancy {

/// The matcher's parameters. The defaults are those of stereo_image_proc's
/// Disparity.cfg (image_pipeline 1.17, Debian 12 and Noetic alike) with
/// stereo_algorithm = StereoSGBM: stereo_image_proc's own default algorithm
/// is StereoBM, and these are the values it hands to StereoSGBM when SGBM is
/// chosen (its fullDP false: MODE_SGBM).
struct SgbmParameters {
  int min_disparity_px = 0;           ///< min_disparity
  int num_disparities = 64;           ///< disparity_range: a multiple of 16
  int block_size_px = 15;             ///< correlation_window_size (odd)
  int p1 = 200;                       ///< P1: penalty of a 1 px disparity change between neighbours
  int p2 = 400;                       ///< P2: penalty of a larger change
  int disp12_max_diff_px = 0;         ///< disp12MaxDiff: left-right check tolerance
  int prefilter_cap = 31;             ///< prefilter_cap
  int uniqueness_ratio_percent = 15;  ///< uniqueness_ratio
  int speckle_size_px = 100;          ///< speckle_size: smaller regions are removed
  int speckle_range_px = 4;           ///< speckle_range: disparity spread within a region
  bool full_dp = false;               ///< fullDP (MODE_HH)

  /// A 5 px block with OpenCV's recommended penalties (P1 = 8 and P2 = 32
  /// times the block's area) and a 1 px left-right check, the rest as above:
  /// sharper at depth edges than stereo_image_proc's 15 px block. Not
  /// stereo_image_proc's defaults, though evaluate_stereo_pair took it for them.
  static SgbmParameters fineBlock();

  /// Largest disparity the search can return [px].
  int maxDisparityPx() const { return min_disparity_px + num_disparities - 1; }
  /// "StereoSGBM: 64 disparities, 15 px block, P1 200, P2 400, ...": for the record.
  std::string describe() const;
  /// True if OpenCV accepts the values (num_disparities a positive multiple
  /// of 16, an odd block of at least 1 px, P2 > P1 >= 0, ...).
  bool isValid(std::string* why = nullptr) const;
};

/// Matches a rectified pair (8-bit grey, the same size) with StereoSGBM and
/// @p params: the left image's disparity in pixels (CV_32FC1, 1/16 px steps);
/// NaN where the matcher found no match (SGBM's min_disparity - 1, as the
/// flights mark unmatched pixels). @throws std::invalid_argument for invalid
/// parameters or images.
cv::Mat matchSgbm(const cv::Mat& left, const cv::Mat& right, const SgbmParameters& params = SgbmParameters());

}  // namespace stereo_occupancy
