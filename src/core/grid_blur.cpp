#include "stereo_occupancy/grid_blur.h"

#include <algorithm>
#include <array>
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
  // A line along the axis whose input is all zero stays zero: most of a
  // frustum's box is unknown (zero here), so most lines are skipped.
  auto line = [&](int x, int y, int z) {
    return axis == 0 ? y + size.y() * z : (axis == 1 ? x + size.x() * z : x + size.x() * y);
  };
  line_nonzero_.assign(static_cast<size_t>(axis == 0 ? size.y() * size.z()
                                                     : (axis == 1 ? size.x() * size.z() : size.x() * size.y())),
                       0);
  size_t idx = 0;
  for (int z = 0; z < size.z(); ++z)
    for (int y = 0; y < size.y(); ++y)
      for (int x = 0; x < size.x(); ++x, ++idx)
        if (in[idx] != 0.0f) line_nonzero_[line(x, y, z)] = 1;
  idx = 0;
  for (int z = 0; z < size.z(); ++z) {
    for (int y = 0; y < size.y(); ++y) {
      for (int x = 0; x < size.x(); ++x, ++idx) {
        if (!line_nonzero_[line(x, y, z)]) {
          out[idx] = 0.0f;
          continue;
        }
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

  // Rounded σ per cell (eq. 17: σ² = σ_trans² + (r·σ_angle)², r² summed per
  // axis); unknown cells enter as log-odds 0.
  const Eigen::Vector3i& size = grid->size();
  std::array<std::vector<double>, 3> squares;  // (cell centre - camera)² per axis and index
  for (int a = 0; a < 3; ++a) {
    squares[a].resize(size[a]);
    for (int i = 0; i < size[a]; ++i) {
      const double d = (grid->originIndex()[a] + i + 0.5) * c - W_camera[a];
      squares[a][i] = d * d;
    }
  }
  const double trans2 = config_.sigma_trans_m * config_.sigma_trans_m;
  const double angle2 = config_.sigma_angle_rad * config_.sigma_angle_rad;
  const double to_steps = 1.0 / (c * config_.sigma_step_cells);
  size_t idx = 0;
  for (int z = 0; z < size.z(); ++z) {
    for (int y = 0; y < size.y(); ++y) {
      const double yz2 = squares[1][y] + squares[2][z];
      for (int x = 0; x < size.x(); ++x, ++idx) {
        const double steps = std::sqrt(trans2 + (squares[0][x] + yz2) * angle2) * to_steps;
        const int q = steps >= 255.0 ? 255 : static_cast<int>(steps + 0.5);  // round half up, as lround for >= 0
        kernel_index_[idx] = static_cast<uint8_t>(q);
        buffer_a_[idx] = data[idx] == LocalGrid::kUnknown ? 0.0f : data[idx];
      }
    }
  }
  std::array<bool, 256> used{};
  for (size_t i = 0; i < cells; ++i) used[kernel_index_[i]] = true;
  for (int q = 0; q < 256; ++q)
    if (used[q]) kernel(q);  // built once per rounded σ
  pass(0, *grid, buffer_a_.data(), buffer_b_.data());
  pass(1, *grid, buffer_b_.data(), buffer_a_.data());
  pass(2, *grid, buffer_a_.data(), buffer_b_.data());
  for (size_t i = 0; i < cells; ++i) {
    if (data[i] != LocalGrid::kUnknown || buffer_b_[i] != 0.0f) data[i] = buffer_b_[i];
  }
}

}  // namespace stereo_occupancy
