#pragma once
/// @file
/// wavemap (ethz-asl/wavemap 2.x, found by CMake, never built here) as the
/// issue's peer: its projective integrator into its hashed chunked wavelet
/// octree, behind a plain interface so that no wavemap header or compile
/// option (it exports -march=native) reaches another translation unit.

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <cstddef>
#include <memory>

#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

/// One wavemap map fed by one pinhole camera's depth images.
class WavemapIntegrator {
 public:
  /// A map of @p cell_m cells fed by @p camera's images up to
  /// camera.max_range_m, on @p threads threads (wavemap's thread pool).
  WavemapIntegrator(const StereoCameraConfig& camera, double cell_m, int threads);
  ~WavemapIntegrator();
  WavemapIntegrator(const WavemapIntegrator&) = delete;
  WavemapIntegrator& operator=(const WavemapIntegrator&) = delete;

  /// Integrates @p depth_m (CV_32FC1 of the camera's size [m]; 0: no
  /// measurement, infinity: nothing within the range) seen from @p T_W_C.
  void integrate(const cv::Mat& depth_m, const Eigen::Isometry3d& T_W_C);
  /// The map's memory [bytes].
  size_t memoryBytes() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace stereo_occupancy
