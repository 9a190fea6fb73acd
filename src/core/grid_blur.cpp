#include "stereo_occupancy/grid_blur.h"

#include <algorithm>
#include <cmath>

namespace stereo_occupancy {

bool BlurConfig::isValid(std::string* why) const {
  auto fail = [why](const char* text) {
    if (why) *why = text;
    return false;
  };
  if (!(std::isfinite(sigma_trans_m) && sigma_trans_m >= 0.0)) return fail("sigma_trans_m must be finite and >= 0");
  if (!(std::isfinite(sigma_angle_rad) && sigma_angle_rad >= 0.0 && sigma_angle_rad < 1.0))
    return fail("sigma_angle_rad must be in [0, 1)");
  if (!(sigma_step_cells >= 0.1 && sigma_step_cells <= 10.0)) return fail("sigma_step_cells must be in [0.1, 10]");
  if (!(truncate_sigmas >= 1.0 && truncate_sigmas <= 6.0)) return fail("truncate_sigmas must be in [1, 6]");
  return true;
}

DistanceDependentBlur::DistanceDependentBlur(const BlurConfig& config) : config_(config) {}

double DistanceDependentBlur::sigmaAt(double r_m) const {
  const double a = r_m * config_.sigma_angle_rad;
  return std::sqrt(config_.sigma_trans_m * config_.sigma_trans_m + a * a);  // eq. 17
}

int DistanceDependentBlur::paddingCells(double max_range_m, double resolution_m) const {
  if (!config_.enabled()) return 0;
  return static_cast<int>(std::ceil(config_.truncate_sigmas * sigmaAt(max_range_m) / resolution_m)) + 1;
}

const std::vector<float>& DistanceDependentBlur::kernel(int q) {
  if (q >= static_cast<int>(kernels_.size())) kernels_.resize(q + 1);
  std::vector<float>& k = kernels_[q];
  if (k.empty()) {
    const double sigma = q * config_.sigma_step_cells;
    if (q == 0) {
      k = {1.0f};
    } else {
      const int radius = static_cast<int>(std::ceil(config_.truncate_sigmas * sigma));
      k.resize(2 * radius + 1);
      double sum = 0.0;
      for (int i = -radius; i <= radius; ++i) sum += std::exp(-0.5 * i * i / (sigma * sigma));
      for (int i = -radius; i <= radius; ++i)
        k[i + radius] = static_cast<float>(std::exp(-0.5 * i * i / (sigma * sigma)) / sum);
    }
  }
  return k;
}

void DistanceDependentBlur::pass(int axis, const LocalGrid& grid, const float* in, float* out) {
  const Eigen::Vector3i& size = grid.size();
  const int64_t stride = axis == 0 ? 1 : (axis == 1 ? size.x() : static_cast<int64_t>(size.x()) * size.y());
  const int n = size[axis];
  size_t idx = 0;
  for (int z = 0; z < size.z(); ++z) {
    for (int y = 0; y < size.y(); ++y) {
      for (int x = 0; x < size.x(); ++x, ++idx) {
        const std::vector<float>& k = kernels_[kernel_index_[idx]];
        const int radius = static_cast<int>(k.size() / 2);
        if (radius == 0) {
          out[idx] = in[idx];
          continue;
        }
        const int coord = axis == 0 ? x : (axis == 1 ? y : z);
        const int lo = std::max(-radius, -coord);
        const int hi = std::min(radius, n - 1 - coord);
        float sum = 0.0f;
        for (int i = lo; i <= hi; ++i) sum += k[i + radius] * in[static_cast<int64_t>(idx) + i * stride];
        out[idx] = sum;
      }
    }
  }
}

void DistanceDependentBlur::apply(const Eigen::Vector3d& W_camera, LocalGrid* grid) {
  if (!config_.enabled()) return;
  const size_t cells = grid->numCells();
  const double c = grid->resolution();
  kernel_index_.resize(cells);
  buffer_a_.resize(cells);
  buffer_b_.resize(cells);
  float* data = grid->data();

  // Rounded σ per cell (eq. 17); unknown cells enter as log-odds 0.
  size_t idx = 0;
  const Eigen::Vector3i& size = grid->size();
  for (int z = 0; z < size.z(); ++z) {
    for (int y = 0; y < size.y(); ++y) {
      for (int x = 0; x < size.x(); ++x, ++idx) {
        const double r = (grid->cellCentre(x, y, z) - W_camera).norm();
        const double sigma_cells = sigmaAt(r) / c;
        const int q = std::min(255, static_cast<int>(std::lround(sigma_cells / config_.sigma_step_cells)));
        kernel_index_[idx] = static_cast<uint8_t>(q);
        kernel(q);
        buffer_a_[idx] = data[idx] == LocalGrid::kUnknown ? 0.0f : data[idx];
      }
    }
  }
  pass(0, *grid, buffer_a_.data(), buffer_b_.data());
  pass(1, *grid, buffer_b_.data(), buffer_a_.data());
  pass(2, *grid, buffer_a_.data(), buffer_b_.data());
  for (size_t i = 0; i < cells; ++i) {
    if (data[i] != LocalGrid::kUnknown || buffer_b_[i] != 0.0f) data[i] = buffer_b_[i];
  }
}

}  // namespace stereo_occupancy
