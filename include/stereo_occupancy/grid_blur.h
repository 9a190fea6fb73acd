#pragma once
/// @file
/// Distance-dependent Gaussian blur for pose uncertainty (Andert 2009,
/// section VII, eq. 17).

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/parameter_table.h"
#include "stereo_occupancy/worker_pool.h"

namespace stereo_occupancy {

/// Pose uncertainty of the vehicle; blur is off when both sigmas are 0.
struct BlurConfig {
  double sigma_trans_m = 0.0;    ///< σ_trans, translational standard deviation [m]
  double sigma_angle_rad = 0.0;  ///< σ_angle, angular standard deviation [rad]
  /// σ is rounded to a multiple of this [cells]; one kernel per rounded σ.
  double sigma_step_cells = 0.5;
  double truncate_sigmas = 3.0;  ///< kernel radius = ceil(truncate_sigmas · σ) [σ]
  /// σ is capped at this many cells: a wider blur washes the obstacles out
  /// of the map, and its cost grows with σ⁴ (padding³ · taps): σ_angle 0.5
  /// rad at 25 m took 43 s and 1 GB an image uncapped.
  static constexpr double kMaxSigmaCells = 8.0;

  bool enabled() const { return sigma_trans_m > 0.0 || sigma_angle_rad > 0.0; }

  /// The parameters (parameter_table.h): f(spec, member) for each.
  template <typename Self, typename F>
  static void forEachParameter(Self& c, F&& f) {
    f(numberParameter("sigma_trans_m", "m", 0.0, 10.0, "translational pose uncertainty (eq. 17); 0 and 0: no blur"),
      c.sigma_trans_m);
    f(numberParameter("sigma_angle_rad", "rad", 0.0, 0.5, "angular pose uncertainty (eq. 17); sigma capped at 8 cells"),
      c.sigma_angle_rad);
    f(numberParameter("sigma_step_cells", "cells", 0.1, 10.0, "sigma is rounded to multiples of this"),
      c.sigma_step_cells);
  }

  /// The ranges of forEachParameter(), and truncate_sigmas in [1, 6].
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

  /// σ at distance r from the camera [m] (eq. 17), before the cap of kMaxSigmaCells.
  double sigmaAt(double r_m) const;

  /// Cells to add around a grid so that blur at range r does not hit its border.
  int paddingCells(double max_range_m, double resolution_m) const;
  static constexpr int kMaxPaddingCells = 1 << 20;  ///< paddingCells() at most

  /// Blurs @p grid in place; W_camera is the camera centre in W [m].
  void apply(const Eigen::Vector3d& W_camera, LocalGrid* grid);
  /// Blurs with @p pool's workers (null: on the calling thread), the same
  /// bit for bit for any number: each row's sums are its own.
  void setWorkers(WorkerPool* pool) { pool_ = pool; }

  /// Normalised 1D kernel of rounded-σ index q (σ = q · sigma_step_cells cells), radius ceil(truncate·σ).
  const std::vector<float>& kernel(int q);

 private:
  /// Cells [lo, hi) of one row (fixed y, z); empty if lo >= hi.
  struct Extent {
    int lo = 0, hi = 0;
    bool empty() const { return lo >= hi; }
  };
  /// Cells [begin, end) of one row that share the rounded σ q.
  struct KernelRun {
    int begin, end, q;
  };
  /// One separable pass along y (axis 1) or z (axis 2): out = in * kernel
  /// over the rows of @p out_extent, reading only the rows' @p in_extent.
  void crossPass(int axis, const LocalGrid& grid, const std::vector<Extent>& in_extent, const float* in,
                 const std::vector<Extent>& out_extent, float* out);
  const float* weights(int q) const { return &weights_[static_cast<size_t>(q) * (2 * radius_ + 1)]; }

  /// The rounded σ of a cell at squared distance r2 from the camera, in
  /// steps of sigma_step_cells (eq. 17), at most max_steps (BlurConfig::kMaxSigmaCells).
  struct SigmaIndex {
    double trans2;    ///< σ_trans² [m²]
    double angle2;    ///< σ_angle² [rad²]
    double to_steps;  ///< 1 / (c · sigma_step_cells) [1/m]
    int max_steps;    ///< kMaxSigmaCells in steps
    int operator()(double r2) const;
  };
  /// Squared distances of the cell centres from the camera, per axis and index [m²].
  struct CameraDistances {
    std::array<std::vector<double>, 3> squares;
    double r2_max = 0.0;  ///< at the box corner farthest from the camera
  };

  // apply()'s steps, in order.
  /// extent_[0]: each row's cells with a non-zero value; false if there are none.
  bool findInputExtents(const LocalGrid& grid);
  static CameraDistances cameraDistances(const LocalGrid& grid, const Eigen::Vector3d& W_camera);
  /// weights_ and radius_ for the rounded σ 0 .. q_max.
  void prepareWeights(int q_max);
  /// extent_[1..3]: where each pass's output can be non-zero.
  void growExtents(const LocalGrid& grid);
  /// runs_ and row_runs_: the cells of each row that share a kernel.
  void findKernelRuns(const LocalGrid& grid, const Eigen::Vector3d& W_camera, const CameraDistances& distances,
                      const SigmaIndex& sigma_index, int q_max);
  /// The pass along x, from the grid into buffer_b_.
  void passAlongX(const LocalGrid& grid);
  /// The result, buffer_b_, into the grid.
  void writeBack(LocalGrid* grid);
  /// Calls f(r_begin, r_end, worker) for parts of the rows [0, rows) on the workers.
  template <typename F>
  void forRows(int rows, const F& f);

  BlurConfig config_;
  WorkerPool* pool_ = nullptr;
  std::vector<std::vector<float>> kernels_;
  int radius_ = 0;              ///< largest kernel radius in the grid [cells]
  std::vector<float> weights_;  ///< per q: its kernel padded with zeros to radius_
  /// Rows' extents of non-zero values: the input, after x, after y, after z.
  std::vector<Extent> extent_[4];
  std::vector<KernelRun> runs_;              ///< per row, over its final extent
  std::vector<uint32_t> row_runs_;           ///< row r's runs are runs_[row_runs_[r] .. row_runs_[r + 1])
  std::vector<double> thresholds_;           ///< per q: the smallest r² whose rounded σ is q [m²]
  std::vector<std::vector<float>> scratch_;  ///< a row's input, per worker
  std::vector<float> buffer_a_;
  std::vector<float> buffer_b_;
};

}  // namespace stereo_occupancy
