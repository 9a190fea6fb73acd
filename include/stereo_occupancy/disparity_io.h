#pragma once
/// @file
/// Reading and writing disparity images: PFM (float) and 16-bit PNG; depth
/// images to disparity (eq. 1).

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

/// Disparity d = bf / z of a depth image: CV_16UC1 in millimetres or CV_32FC1
/// in metres. Depth 0 or not finite means "no measurement" (NaN out).
/// @throws std::invalid_argument for another image type.
void depthToDisparity(const cv::Mat& depth, double bf_px_m, cv::Mat* disparity);

}  // namespace stereo_occupancy
