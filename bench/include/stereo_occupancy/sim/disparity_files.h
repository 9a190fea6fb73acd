#pragma once
/// @file
/// Disparity image files for the tools and tests: PFM (float) and 16-bit PNG.

#include <opencv2/core.hpp>

#include <string>

namespace stereo_occupancy {

/// Reads a single-channel PFM ("Pf") file into a CV_32FC1 image, top row
/// first. @throws std::runtime_error with a one-line reason on failure.
cv::Mat readPfm(const std::string& path);

/// Writes a CV_32FC1 image as a little-endian single-channel PFM.
/// @throws std::runtime_error on failure.
void writePfm(const std::string& path, const cv::Mat& image);

/// Reads a disparity image: .pfm as is; a 16-bit PNG as value / scale, with
/// the value 0 kept as 0 (infinitely far). @throws std::runtime_error.
cv::Mat readDisparity(const std::string& path, double png_scale);

}  // namespace stereo_occupancy
