#include "stereo_occupancy/grid_blur.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>

namespace stereo_occupancy {

bool BlurConfig::isValid(std::string* why) const {
  if (!parametersInRange(*this, why)) return false;
  if (!(truncate_sigmas >= 1.0 && truncate_sigmas <= 6.0)) {
    if (why) *why = "truncate_sigmas must be in [1, 6]";
    return false;
  }
  return true;
}

DistanceDependentBlur::DistanceDependentBlur(const BlurConfig& config) : config_(config) {}

double DistanceDependentBlur::sigmaAt(double r_m) const {
  const double a = r_m * config_.sigma_angle_rad;
  return std::sqrt(config_.sigma_trans_m * config_.sigma_trans_m + a * a);  // eq. 17
}

int DistanceDependentBlur::paddingCells(double max_range_m, double resolution_m) const {
  if (!config_.enabled()) return 0;
  const double sigma_cells = std::min(sigmaAt(max_range_m) / resolution_m, BlurConfig::kMaxSigmaCells);
  const double cells = std::ceil(config_.truncate_sigmas * sigma_cells) + 1.0;
  return std::min(static_cast<int>(cells), kMaxPaddingCells);
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

namespace {
/// Rows per part of a pass shared by the workers.
constexpr int kRowsPerPart = 32;
}  // namespace

template <typename F>
void DistanceDependentBlur::forRows(int rows, const F& f) {
  const size_t parts = (static_cast<size_t>(rows) + kRowsPerPart - 1) / kRowsPerPart;
  auto part = [&](size_t i, unsigned worker) {
    const int begin = static_cast<int>(i) * kRowsPerPart;
    f(begin, std::min(rows, begin + kRowsPerPart), worker);
  };
  if (pool_)
    pool_->run(parts, part);
  else
    for (size_t i = 0; i < parts; ++i) part(i, 0);
}

void DistanceDependentBlur::crossPass(int axis, const LocalGrid& grid, const std::vector<Extent>& in_extent,
                                      const float* in, const std::vector<Extent>& out_extent, float* out) {
  const int nx = grid.size().x(), ny = grid.size().y(), nz = grid.size().z();
  const int n = axis == 1 ? ny : nz;
  const int row_step = axis == 1 ? 1 : ny;  // row index step of one cell along the axis
  forRows(ny * nz, [&](int r_begin, int r_end, unsigned) {
    for (int r = r_begin; r < r_end; ++r) {  // r = y + ny * z
      const Extent& e = out_extent[r];
      if (e.empty()) continue;
      float* o = out + static_cast<int64_t>(nx) * r;
      std::fill(o + e.lo, o + e.hi, 0.0f);
      const int coord = axis == 1 ? r % ny : r / ny;
      for (uint32_t k = row_runs_[r]; k < row_runs_[r + 1]; ++k) {
        const KernelRun& run = runs_[k];
        const float* w = weights(run.q);
        // Taps in ascending order, as a cell's own sum would add them.
        for (int i = std::max(-radius_, -coord); i <= std::min(radius_, n - 1 - coord); ++i) {
          const float wi = w[i + radius_];
          const Extent& src_extent = in_extent[r + i * row_step];
          const int lo = std::max({run.begin, e.lo, src_extent.lo}), hi = std::min({run.end, e.hi, src_extent.hi});
          if (wi == 0.0f || lo >= hi) continue;  // adds nothing: zero weight or zero input
          const float* src = in + static_cast<int64_t>(nx) * (r + i * row_step);
          for (int x = lo; x < hi; ++x) o[x] += wi * src[x];
        }
      }
    }
  });
}

namespace {

/// Unknown cells enter the blur as log-odds 0.
float knownValue(float v) { return v == LocalGrid::kUnknown ? 0.0f : v; }

}  // namespace

int DistanceDependentBlur::SigmaIndex::operator()(double r2) const {
  const double steps = std::sqrt(trans2 + r2 * angle2) * to_steps;        // eq. 17, in sigma_step_cells steps
  return steps >= max_steps ? max_steps : static_cast<int>(steps + 0.5);  // round half up, as lround
}

void DistanceDependentBlur::apply(const Eigen::Vector3d& W_camera, LocalGrid* grid) {
  if (!config_.enabled()) return;
  // Most of a frustum's box is unknown: the passes visit only each row's
  // extent of non-zero values (grown by the kernel radius per pass), and
  // within a row, runs of cells that share one kernel. Each cell's sum adds
  // its taps in the order of a plain per-cell convolution.
  if (!findInputExtents(*grid)) return;  // all zero or unknown: the blur changes nothing
  const CameraDistances distances = cameraDistances(*grid, W_camera);
  const double c = grid->resolution();
  const SigmaIndex sigma_index{config_.sigma_trans_m * config_.sigma_trans_m,
                               config_.sigma_angle_rad * config_.sigma_angle_rad, 1.0 / (c * config_.sigma_step_cells),
                               static_cast<int>(BlurConfig::kMaxSigmaCells / config_.sigma_step_cells)};
  const int q_max = sigma_index(distances.r2_max);
  prepareWeights(q_max);
  growExtents(*grid);
  findKernelRuns(*grid, W_camera, distances, sigma_index, q_max);
  passAlongX(*grid);
  crossPass(1, *grid, extent_[1], buffer_b_.data(), extent_[2], buffer_a_.data());
  crossPass(2, *grid, extent_[2], buffer_a_.data(), extent_[3], buffer_b_.data());
  writeBack(grid);
}

bool DistanceDependentBlur::findInputExtents(const LocalGrid& grid) {
  const int nx = grid.size().x(), rows = grid.size().y() * grid.size().z();
  std::vector<Extent>& e0 = extent_[0];
  e0.assign(rows, Extent{});
  std::atomic<bool> any{false};
  forRows(rows, [&](int r_begin, int r_end, unsigned) {
    bool mine = false;
    for (int r = r_begin; r < r_end; ++r) {
      const float* row = grid.data() + static_cast<int64_t>(nx) * r;
      int lo = 0;
      while (lo + kInformationBlock <= nx && !blockHasInformation(row + lo)) lo += kInformationBlock;
      while (lo < nx && knownValue(row[lo]) == 0.0f) ++lo;
      if (lo == nx) continue;
      int hi = nx;
      while (hi - kInformationBlock >= lo && !blockHasInformation(row + hi - kInformationBlock))
        hi -= kInformationBlock;
      while (hi > lo && knownValue(row[hi - 1]) == 0.0f) --hi;
      e0[r] = Extent{lo, hi};
      mine = true;
    }
    if (mine) any = true;
  });
  return any;
}

DistanceDependentBlur::CameraDistances DistanceDependentBlur::cameraDistances(const LocalGrid& grid,
                                                                              const Eigen::Vector3d& W_camera) {
  // r² = the sum of the per-axis squares; largest at the box corner farthest from the camera.
  CameraDistances d;
  for (int a = 0; a < 3; ++a) {
    d.squares[a].resize(grid.size()[a]);
    for (int i = 0; i < grid.size()[a]; ++i) {
      const double offset = (grid.originIndex()[a] + i + 0.5) * grid.resolution() - W_camera[a];
      d.squares[a][i] = offset * offset;
    }
    d.r2_max += std::max(d.squares[a].front(), d.squares[a].back());
  }
  return d;
}

void DistanceDependentBlur::prepareWeights(int q_max) {
  radius_ = static_cast<int>(kernel(q_max).size() / 2);  // radii grow with σ
  const int taps = 2 * radius_ + 1;
  weights_.assign(static_cast<size_t>(q_max + 1) * taps, 0.0f);
  for (int q = 0; q <= q_max; ++q) {
    const std::vector<float>& k = kernel(q);
    const int r = static_cast<int>(k.size() / 2);
    std::copy(k.begin(), k.end(), weights_.begin() + static_cast<int64_t>(q) * taps + radius_ - r);
  }
}

void DistanceDependentBlur::growExtents(const LocalGrid& grid) {
  const int nx = grid.size().x(), ny = grid.size().y(), nz = grid.size().z(), rows = ny * nz;
  const std::vector<Extent>& e0 = extent_[0];
  std::vector<Extent>& e1 = extent_[1];
  e1.assign(rows, Extent{});
  for (int r = 0; r < rows; ++r)
    if (!e0[r].empty()) e1[r] = Extent{std::max(0, e0[r].lo - radius_), std::min(nx, e0[r].hi + radius_)};
  // Along y and z: the hull of the rows within the radius.
  auto grow = [&](const std::vector<Extent>& in, int axis, std::vector<Extent>* out) {
    out->assign(rows, Extent{});
    const int n = axis == 1 ? ny : nz;
    const int row_step = axis == 1 ? 1 : ny;
    for (int z = 0; z < nz; ++z)
      for (int y = 0; y < ny; ++y) {
        const int r = y + ny * z, coord = axis == 1 ? y : z;
        Extent hull{nx, 0};
        for (int i = std::max(-radius_, -coord); i <= std::min(radius_, n - 1 - coord); ++i) {
          const Extent& e = in[r + i * row_step];
          if (e.empty()) continue;
          hull.lo = std::min(hull.lo, e.lo);
          hull.hi = std::max(hull.hi, e.hi);
        }
        (*out)[r] = hull;
      }
  };
  grow(extent_[1], 1, &extent_[2]);
  grow(extent_[2], 2, &extent_[3]);
}

void DistanceDependentBlur::findKernelRuns(const LocalGrid& grid, const Eigen::Vector3d& W_camera,
                                           const CameraDistances& distances, const SigmaIndex& sigma_index, int q_max) {
  // Runs of one kernel over each row's final extent (which holds the others).
  // q grows with r², and along a row r² falls up to the camera's x and grows
  // after it: the runs' ends are found by bisection against the smallest r²
  // of each q (itself bisected over the doubles, so q is exactly
  // sigma_index(r²)), without a square root per cell.
  thresholds_.assign(q_max + 1, 0.0);
  for (int q = 1; q <= q_max; ++q) {
    double lo = 0.0, hi = distances.r2_max;  // sigma_index(hi) >= q
    if (sigma_index(lo) >= q) {
      hi = lo;
    } else {
      for (;;) {
        const double mid = lo + 0.5 * (hi - lo);
        if (!(mid > lo && mid < hi)) break;  // adjacent doubles
        (sigma_index(mid) >= q ? hi : lo) = mid;
      }
    }
    thresholds_[q] = hi;
  }
  auto qAt = [&](int x, double yz2) {
    const double r2 = distances.squares[0][x] + yz2;
    int q = 0;
    while (q < q_max && r2 >= thresholds_[q + 1]) ++q;
    return q;
  };
  const int nx = grid.size().x(), ny = grid.size().y(), nz = grid.size().z(), rows = ny * nz;
  // First x whose cell centre is not behind the camera's x: r² falls before it.
  int x_turn = 0;
  while (x_turn < nx && (grid.originIndex().x() + x_turn + 0.5) * grid.resolution() - W_camera.x() < 0.0) ++x_turn;
  runs_.clear();
  row_runs_.assign(rows + 1, 0);
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y) {
      const int r = y + ny * z;
      row_runs_[r] = static_cast<uint32_t>(runs_.size());
      const double yz2 = distances.squares[1][y] + distances.squares[2][z];
      const int lo = extent_[3][r].lo, hi = extent_[3][r].hi;
      const int turn = std::clamp(x_turn, lo, hi);
      for (const auto& [begin, end] : {std::make_pair(lo, turn), std::make_pair(turn, hi)}) {
        for (int x = begin; x < end;) {  // q is monotonic on [begin, end)
          const int q = qAt(x, yz2);
          int first = x + 1, last = end;  // bisect for the first x with another q
          while (first < last) {
            const int mid = first + (last - first) / 2;
            if (qAt(mid, yz2) == q) {
              first = mid + 1;
            } else {
              last = mid;
            }
          }
          runs_.push_back(KernelRun{x, first, q});
          x = first;
        }
      }
    }
  row_runs_[rows] = static_cast<uint32_t>(runs_.size());
}

void DistanceDependentBlur::passAlongX(const LocalGrid& grid) {
  const int nx = grid.size().x(), rows = grid.size().y() * grid.size().z();
  const size_t cells = grid.numCells();
  releaseIfOversized(&buffer_a_, cells);
  releaseIfOversized(&buffer_b_, cells);
  buffer_a_.resize(cells);  // holds values only within the extents
  buffer_b_.resize(cells);
  scratch_.resize(pool_ ? pool_->size() : 1);
  for (std::vector<float>& line : scratch_) line.resize(nx);
  forRows(rows, [&](int r_begin, int r_end, unsigned worker) {
    float* line = scratch_[worker].data();
    for (int r = r_begin; r < r_end; ++r) {
      const Extent& e = extent_[1][r];
      if (e.empty()) continue;
      // The row, unknown as 0, into a scratch line first.
      const float* row = grid.data() + static_cast<int64_t>(nx) * r;
      const int read_lo = std::max(0, e.lo - radius_), read_hi = std::min(nx, e.hi + radius_);
      for (int x = read_lo; x < read_hi; ++x) line[x] = knownValue(row[x]);
      float* o = buffer_b_.data() + static_cast<int64_t>(nx) * r;
      std::fill(o + e.lo, o + e.hi, 0.0f);
      for (uint32_t k = row_runs_[r]; k < row_runs_[r + 1]; ++k) {
        const KernelRun& run = runs_[k];
        const float* w = weights(run.q);
        for (int i = -radius_; i <= radius_; ++i) {
          const float wi = w[i + radius_];
          const int lo = std::max({run.begin, e.lo, -i}), hi = std::min({run.end, e.hi, nx - i});
          if (wi == 0.0f || lo >= hi) continue;
          const float* src = line + i;
          for (int x = lo; x < hi; ++x) o[x] += wi * src[x];
        }
      }
    }
  });
}

void DistanceDependentBlur::writeBack(LocalGrid* grid) {
  // Unknown cells stay unknown unless the blur gave them a value.
  const int nx = grid->size().x(), rows = grid->size().y() * grid->size().z();
  forRows(rows, [&](int r_begin, int r_end, unsigned) {
    for (int r = r_begin; r < r_end; ++r) {
      float* row = grid->data() + static_cast<int64_t>(nx) * r;
      const float* b = buffer_b_.data() + static_cast<int64_t>(nx) * r;
      for (int x = extent_[3][r].lo; x < extent_[3][r].hi; ++x)
        if (row[x] != LocalGrid::kUnknown || b[x] != 0.0f) row[x] = b[x];
    }
  });
}

}  // namespace stereo_occupancy
