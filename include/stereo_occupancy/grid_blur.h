#pragma once
/// @file
/// Distance-dependent Gaussian blur for pose uncertainty (Andert 2009,
/// section VII, eq. 17).

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

#include "stereo_occupancy/local_grid.h"

namespace stereo_occupancy {

/// Pose uncertainty of the vehicle; blur is off when both sigmas are 0.
struct BlurConfig {
  double sigma_trans_m = 0.0;    ///< σ_trans, translational standard deviation [m]
  double sigma_angle_rad = 0.0;  ///< σ_angle, angular standard deviation [rad]
  /// σ is rounded to a multiple of this [cells]; one kernel per rounded σ.
  double sigma_step_cells = 0.5;
  double truncate_sigmas = 3.0;  ///< kernel radius = ceil(truncate_sigmas · σ) [σ]

  bool enabled() const { return sigma_trans_m > 0.0 || sigma_angle_rad > 0.0; }
  bool isValid(std::string* why = nullptr) const;
  bool operator==(const BlurConfig& o) const {
    return sigma_trans_m == o.sigma_trans_m && sigma_angle_rad == o.sigma_angle_rad &&
           sigma_step_cells == o.sigma_step_cells && truncate_sigmas == o.truncate_sigmas;
  }
};

/// Blurs a LocalGrid with a Gaussian whose σ grows with the distance r of each
/// cell from the camera: σ = sqrt(σ_trans² + (r·σ_angle)²) (eq. 17).
///
/// Unknown cells count as log-odds 0 and stay unknown unless the blur gives
/// them a value. Each output cell is convolved with the kernel of its own
/// rounded σ, separably along x, y and z (exact where σ is locally constant).
class DistanceDependentBlur {
 public:
  explicit DistanceDependentBlur(const BlurConfig& config);

  const BlurConfig& config() const { return config_; }

  /// σ at distance r from the camera [m] (eq. 17).
  double sigmaAt(double r_m) const;

  /// Cells to add around a grid so that blur at range r does not hit its border.
  int paddingCells(double max_range_m, double resolution_m) const;

  /// Blurs @p grid in place; W_camera is the camera centre in W [m].
  void apply(const Eigen::Vector3d& W_camera, LocalGrid* grid);

  /// Normalised 1D kernel of rounded-σ index q (σ = q · sigma_step_cells cells), radius ceil(truncate·σ).
  const std::vector<float>& kernel(int q);

 private:
  void pass(int axis, const LocalGrid& grid, const float* in, float* out);

  BlurConfig config_;
  std::vector<std::vector<float>> kernels_;
  std::vector<uint8_t> kernel_index_;
  std::vector<uint8_t> line_nonzero_;  ///< per line of a pass: holds a non-zero input
  std::vector<float> buffer_a_;
  std::vector<float> buffer_b_;
};

}  // namespace stereo_occupancy
