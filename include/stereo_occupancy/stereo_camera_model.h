#pragma once
/// @file
/// Rectified stereo camera: disparity -> depth, 3D point and range resolution
/// (Andert 2009, section III, eqs. 1-7).
///
/// Frames: the camera's optical frame C (REP-103 optical: x right, y down,
/// z forward). Image coordinates are in pixels with the centre of the top-left
/// pixel at (0, 0).

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <cstdint>
#include <limits>
#include <string>

namespace stereo_occupancy {

/// Intrinsics and range limits of a rectified stereo pair.
struct StereoCameraConfig {
  int width_px = 640;              ///< image width [px]
  int height_px = 480;             ///< image height [px]
  double focal_length_px = 700.0;  ///< f, rectified focal length [px]
  double cx_px = 319.5;            ///< principal point x [px]
  double cy_px = 239.5;            ///< principal point y [px]
  double baseline_m = 0.3;         ///< b, horizontal distance of the cameras [m]
  double delta_d_px = 0.5;         ///< Δd, disparity uncertainty [px] (eq. 4)
  double min_range_m = 0.5;        ///< z_c min: nearer measurements are invalid [m]
  double max_range_m = 25.0;       ///< sensor range limit along the ray [m]
  /// Valid disparity interval of the matcher [px]. Zero disparity is always
  /// "infinitely far"; a positive disparity outside [min, max] is invalid.
  double min_disparity_px = 0.0;
  double max_disparity_px = std::numeric_limits<double>::infinity();

  /// True if every field is finite (the max disparity may be +inf) and in range.
  bool isValid(std::string* why = nullptr) const;
  bool operator==(const StereoCameraConfig& o) const;
  bool operator!=(const StereoCameraConfig& o) const { return !(*this == o); }
};

/// What the pixels of one disparity image hold: why an image may map nothing.
struct DisparityCensus {
  uint64_t no_match = 0;  ///< NaN, infinite or negative: the matcher found nothing
  uint64_t out_of_range =
      0;  ///< outside [min_disparity_px, nearDisparity()]: the search range, or nearer than min_range_m
  uint64_t beyond_range = 0;  ///< 0 < d < farDisparity(): beyond max_range_m (free space up to it)
  uint64_t sky = 0;           ///< 0: infinitely far (free space up to max_range_m)
  uint64_t measured = 0;      ///< a range within [min_range_m, max_range_m]

  uint64_t total() const { return no_match + out_of_range + beyond_range + sky + measured; }
};

/// Pinhole stereo model of section III.
class StereoCameraModel {
 public:
  explicit StereoCameraModel(const StereoCameraConfig& config);

  const StereoCameraConfig& config() const { return config_; }

  /// b·f [m·px]; depth z = bf / d (eq. 1).
  double bf() const { return bf_; }

  /// Depth z_c [m] of disparity d [px] (eq. 1); +inf for d == 0.
  double depthFromDisparity(double d_px) const { return bf_ / d_px; }

  /// Disparity [px] of depth z [m] (inverse of eq. 1).
  double disparityFromDepth(double z_m) const { return bf_ / z_m; }

  /// Direction through image point (x, y), scaled so that its z component is
  /// 1: (x_c/z_c, y_c/z_c, 1) of eq. 2.
  Eigen::Vector3d rayThroughPixel(double x_px, double y_px) const {
    return Eigen::Vector3d((x_px - config_.cx_px) * inv_f_, (y_px - config_.cy_px) * inv_f_, 1.0);
  }

  /// 3D point p_c in the optical frame for pixel (x, y) with disparity d > 0 (eqs. 1, 2).
  Eigen::Vector3d pointFromDisparity(double x_px, double y_px, double d_px) const {
    return rayThroughPixel(x_px, y_px) * depthFromDisparity(d_px);
  }

  /// Range resolution Δz_c = z² Δd / (b f) [m] (eq. 4).
  double depthUncertainty(double z_m) const { return z_m * z_m * config_.delta_d_px / bf_; }

  /// Lateral uncertainty Δx_c = Δy_c = z / (2f) [m] (eq. 5).
  double lateralUncertainty(double z_m) const { return 0.5 * z_m * inv_f_; }

  /// Range along the ray l_p = |p_c| [m] (eq. 6).
  static double range(const Eigen::Vector3d& C_point) { return C_point.norm(); }

  /// Range uncertainty Δl_p = Δz_c · l_p / z_c [m] (eq. 7), with eq. 4's Δz_c
  /// folded in: z_c · l_p · Δd / (b f), without a division.
  double rangeUncertainty(double z_m, double l_m) const { return z_m * l_m * delta_d_over_bf_; }

  /// Smallest disparity whose depth is still inside max_range_m [px].
  double farDisparity() const { return far_disparity_px_; }

  /// Largest valid disparity: the matcher's maximum and the minimum range [px].
  double nearDisparity() const;

  /// True if the pixel's value carries information: 0 (infinitely far) or a
  /// finite disparity in [min_disparity_px, nearDisparity()].
  bool isValidDisparity(float d_px) const { return DisparityValidity{min_valid_, max_valid_}(d_px); }

  /// isValidDisparity() as a value, for loops that should keep its bounds in
  /// registers (a member's bounds are reloaded after every store through a float*).
  struct DisparityValidity {
    float min_px, max_px;
    bool operator()(float d_px) const {
      return (d_px == 0.0f) | ((d_px >= min_px) & (d_px <= max_px));  // branch-free; false for NaN
    }
  };
  DisparityValidity validity() const { return DisparityValidity{min_valid_, max_valid_}; }

  /// Counts @p disparity's pixels (CV_32FC1) by what they hold: one pass,
  /// for the diagnosis of an image that mapped nothing.
  DisparityCensus census(const cv::Mat& disparity) const;

 private:
  StereoCameraConfig config_;
  double bf_;
  double inv_f_;
  double delta_d_over_bf_;   ///< Δd / (b f) [1/m]
  double far_disparity_px_;  ///< b f / max_range_m, asked once per line drawn
  float min_valid_;
  float max_valid_;
};

/// Disparity d = bf / z (eq. 1) of a depth image: CV_16UC1 in millimetres or
/// CV_32FC1 in metres; a depth camera's input for the mapper. Depth 0 or not
/// finite means "no measurement" (NaN out).
/// @throws std::invalid_argument for another image type.
void depthToDisparity(const cv::Mat& depth, double bf_px_m, cv::Mat* disparity);

}  // namespace stereo_occupancy
