#include "stereo_occupancy/ray_tracing.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "stereo_occupancy/integer_math.h"

namespace stereo_occupancy {

RayTracer::RayTracer(const StereoCameraModel& camera, const LogOddsTable& table, const PyramidLevelTable& levels)
    : camera_(camera), table_(table), levels_(levels) {}

template <typename Lookup>
void RayTracer::traverse(const Eigen::Isometry3d& T_W_C, LocalGrid* grid, DrawStatistics* stats,
                         Lookup&& lookup) const {
  const auto& cfg = camera_.config();
  const double c = grid->resolution();
  const double f = cfg.focal_length_px;
  const double max_range2 = cfg.max_range_m * cfg.max_range_m;
  const double u_lo = -0.5, u_hi = cfg.width_px - 0.5, v_lo = -0.5, v_hi = cfg.height_px - 0.5;
  const Eigen::Isometry3d T_C_W = T_W_C.inverse();
  const Eigen::Matrix3d R_C_W = T_C_W.linear();
  const Eigen::Vector3i& size = grid->size();
  // Camera centre and four image corners (section V-B, step 1).
  stats->coordinate_transfers += 5 + static_cast<uint64_t>(grid->numCells());

  // C_cell(x, y, z) = C_first + x·C_step_x + y·C_step_y + z·C_step_z
  const Eigen::Vector3d C_first = T_C_W * grid->cellCentre(0, 0, 0);
  const Eigen::Vector3d C_step_x = R_C_W.col(0) * c;
  const Eigen::Vector3d C_step_y = R_C_W.col(1) * c;
  const Eigen::Vector3d C_step_z = R_C_W.col(2) * c;
  float* data = grid->data();
  const RangeProfile free_profile = table_.freeProfile();  // of every cell that sees no range

  // Along a row of cells (fixed y, z) the cell centre moves linearly:
  // C_p(x) = A + x·S. In front of the camera, inside the image and within
  // the range are linear and quadratic conditions on x, so each row's
  // candidate cells form one interval, found in closed form; the exact tests
  // below still decide each cell.
  const Eigen::Vector3d& S = C_step_x;
  const double a_lo = (u_lo - cfg.cx_px) / f, a_hi = (u_hi - cfg.cx_px) / f;
  const double b_lo = (v_lo - cfg.cy_px) / f, b_hi = (v_hi - cfg.cy_px) / f;
  auto rowInterval = [&](const Eigen::Vector3d& A, double* x_lo, double* x_hi) {
    double lo = 0.0, hi = size.x() - 1.0;
    auto atLeastZero = [&](double p, double q) {  // p + q·x >= 0
      if (q > 0.0)
        lo = std::max(lo, -p / q);
      else if (q < 0.0)
        hi = std::min(hi, -p / q);
      else if (p < 0.0)
        hi = -1.0;
    };
    atLeastZero(A.z(), S.z());
    atLeastZero(A.x() - a_lo * A.z(), S.x() - a_lo * S.z());
    atLeastZero(a_hi * A.z() - A.x(), a_hi * S.z() - S.x());
    atLeastZero(A.y() - b_lo * A.z(), S.y() - b_lo * S.z());
    atLeastZero(b_hi * A.z() - A.y(), b_hi * S.z() - S.y());
    // |A + x·S|² <= R²
    const double qa = S.squaredNorm(), qb = A.dot(S), qc = A.squaredNorm() - max_range2;
    const double disc = qb * qb - qa * qc;
    if (disc < 0.0) {
      hi = -1.0;
    } else {
      const double root = std::sqrt(disc);
      lo = std::max(lo, (-qb - root) / qa);
      hi = std::min(hi, (-qb + root) / qa);
    }
    *x_lo = lo;
    *x_hi = hi;
  };

  for (int z = 0; z < size.z(); ++z) {
    for (int y = 0; y < size.y(); ++y) {
      const Eigen::Vector3d A = C_first + y * C_step_y + z * C_step_z;
      double x_lo, x_hi;
      rowInterval(A, &x_lo, &x_hi);
      if (x_hi < x_lo - 1.0) continue;
      // One cell of slack on each side for rounding; the tests below are exact.
      const int x_first = std::max(0, floorToInt(x_lo) - 1);
      const int x_last = std::min(size.x() - 1, ceilToInt(x_hi) + 1);
      Eigen::Vector3d C_p = A + x_first * S;
      float* row = data + grid->linearIndex(0, y, z);
      for (int x = x_first; x <= x_last; ++x, C_p += S) {
        if (C_p.z() <= 0.0) continue;
        const double inv_z = 1.0 / C_p.z();
        const double u = f * C_p.x() * inv_z + cfg.cx_px;  // step 2b
        const double v = f * C_p.y() * inv_z + cfg.cy_px;
        if (!(u >= u_lo && u < u_hi && v >= v_lo && v < v_hi)) continue;
        const double l2 = C_p.squaredNorm();  // step 2a
        if (l2 > max_range2) continue;
        const double l = std::sqrt(l2);
        const float d_hat = lookup(C_p, u, v, stats);  // step 2c
        if (d_hat < 0.0f) continue;                    // footprint without information
        // Step 2d. The ray through (u, v) is the cell centre's: |p_c| / z_c = l / z.
        // A cell behind the measurement is unknown: tested before the profile is built.
        const float l_f = static_cast<float>(l);
        RangeProfile profile = free_profile;
        if (measuresRange(camera_, d_hat)) {
          const MeasuredRange m = measuredRange(camera_, l * inv_z, d_hat);
          if (l_f - m.l_p_m > table_.tailOf(m.delta_l_m)) continue;
          profile = table_.profile(m.l_p_m, m.delta_l_m);
        }
        row[x] = profile.at(l_f);  // step 2e
        ++stats->grid_cells_drawn;
      }
    }
  }
}

void RayTracer::drawImage(const DisparityPyramid& max_pyramid, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                          DrawStatistics* stats) const {
  const cv::Mat& image = max_pyramid.level(0);
  const auto& cfg = camera_.config();
  const double f = cfg.focal_length_px;
  const double h = 0.5 * grid->resolution();
  const Eigen::Matrix3d R_C_W = T_W_C.linear().transpose();
  std::array<Eigen::Vector3d, 8> C_corner_offsets;
  for (int k = 0; k < 8; ++k)
    C_corner_offsets[k] = R_C_W * Eigen::Vector3d(k & 1 ? h : -h, k & 2 ? h : -h, k & 4 ? h : -h);
  const double min_z = 1e-3 * grid->resolution();

  traverse(T_W_C, grid, stats, [&](const Eigen::Vector3d& C_p, double, double, DrawStatistics* st) {
    // Footprint: bounding rectangle of the 8 projected cube corners (step 2c).
    double u0 = 1e300, u1 = -1e300, v0 = 1e300, v1 = -1e300;
    bool behind = false;
    for (const auto& off : C_corner_offsets) {
      const Eigen::Vector3d q = C_p + off;
      if (q.z() <= min_z) {
        behind = true;  // the cell reaches behind the camera: its footprint is unbounded
        break;
      }
      const double pu = f * q.x() / q.z() + cfg.cx_px;
      const double pv = f * q.y() / q.z() + cfg.cy_px;
      u0 = std::min(u0, pu);
      u1 = std::max(u1, pu);
      v0 = std::min(v0, pv);
      v1 = std::max(v1, pv);
    }
    int x0 = 0, x1 = image.cols - 1, y0 = 0, y1 = image.rows - 1;
    if (!behind) {
      x0 = std::max(x0, floorToInt(u0 + 0.5));
      x1 = std::min(x1, floorToInt(u1 + 0.5));
      y0 = std::max(y0, floorToInt(v0 + 0.5));
      y1 = std::min(y1, floorToInt(v1 + 0.5));
    }
    float m = DisparityPyramid::kInvalidMax;
    for (int yy = y0; yy <= y1; ++yy) {
      const float* row = image.ptr<float>(yy);
      for (int xx = x0; xx <= x1; ++xx) m = row[xx] > m ? row[xx] : m;
    }
    st->used_image_pixels += static_cast<uint64_t>(x1 - x0 + 1) * static_cast<uint64_t>(y1 - y0 + 1);
    return m;
  });
}

void RayTracer::drawPyramid(const DisparityPyramid& max_pyramid, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                            DrawStatistics* stats) const {
  const int top = max_pyramid.topLevel();
  traverse(T_W_C, grid, stats, [&](const Eigen::Vector3d& C_p, double u, double v, DrawStatistics* st) {
    // The level whose pixels are about one cell apart at the cell's depth (eq. 13).
    const int i = std::clamp(levels_.levelForDepth(C_p.z()), 0, top);
    const cv::Mat& level = max_pyramid.level(i);
    // The 2x2 level-i pixels whose centres surround (u, v) (section VI-C).
    const double s = powerOfTwo(-i);
    const int x0 = floorToInt((u + 0.5) * s - 0.5);
    const int y0 = floorToInt((v + 0.5) * s - 0.5);
    if (x0 >= 0 && y0 >= 0 && x0 + 1 < level.cols && y0 + 1 < level.rows) {  // inside: no clipping
      const float* r0 = level.ptr<float>(y0);
      const float* r1 = level.ptr<float>(y0 + 1);
      st->used_image_pixels += 4;
      return std::max(std::max(r0[x0], r0[x0 + 1]), std::max(r1[x0], r1[x0 + 1]));
    }
    float m = DisparityPyramid::kInvalidMax;
    for (int yy = std::max(y0, 0); yy <= y0 + 1 && yy < level.rows; ++yy) {
      const float* row = level.ptr<float>(yy);
      for (int xx = std::max(x0, 0); xx <= x0 + 1 && xx < level.cols; ++xx) {
        m = std::max(m, row[xx]);
        ++st->used_image_pixels;
      }
    }
    return m;
  });
}

namespace {

/// The bounded pyramidal look-up of one cell (beyond the paper): the largest
/// disparity d̂ over the cell's footprint in the image, from the
/// max-disparity pyramid at the footprint's level (eq. 13), refined where a
/// block mixes depths the bound cannot draw with one value.
class FootprintSearch {
 public:
  /// A footprint of half width @p radius_px around the projection (u, v),
  /// clipped to the image (so that a cell at the camera cannot overflow an
  /// int), searched from level @p level.
  FootprintSearch(const DisparityPyramid& min_pyramid, const DisparityPyramid& max_pyramid,
                  const DisparityBlockBound& bound, int level, double u, double v, double radius_px,
                  DrawStatistics* stats)
      : min_pyramid_(min_pyramid),
        max_pyramid_(max_pyramid),
        bound_(bound),
        level_(level),
        // Refined at most two levels: a block of level i-2 reaches at most a
        // quarter of the footprint's side (eq. 13) beyond it.
        finest_level_(std::max(0, level - kRefinedLevels)),
        // Pixel-edge coordinates: level-0 pixel k covers [k, k+1).
        x_lo_(std::max(u + 0.5 - radius_px, 0.0)),
        x_hi_(std::min(u + 0.5 + radius_px, static_cast<double>(max_pyramid.width(0)))),
        y_lo_(std::max(v + 0.5 - radius_px, 0.0)),
        y_hi_(std::min(v + 0.5 + radius_px, static_cast<double>(max_pyramid.height(0)))),
        stats_(stats) {}

  /// d̂ of the footprint; DisparityPyramid::kInvalidMax if it holds no valid pixel.
  float maximum() {
    const double scale = 1.0 / static_cast<double>(1 << level_);
    const int bx0 = std::max(0, static_cast<int>(x_lo_ * scale));  // truncation: floor, or <= 0
    const int by0 = std::max(0, static_cast<int>(y_lo_ * scale));
    const int bx1 = std::min(max_pyramid_.width(level_) - 1, ceilToInt(x_hi_ * scale) - 1);
    const int by1 = std::min(max_pyramid_.height(level_) - 1, ceilToInt(y_hi_ * scale) - 1);
    if ((bx1 - bx0 + 1) * (by1 - by0 + 1) > static_cast<int>(blocks_.size())) {
      // Only near cells whose level was clamped to the top: every block, in order.
      for (int by = by0; by <= by1; ++by)
        for (int bx = bx0; bx <= bx1; ++bx) refine(level_, bx, by);
      return found_;
    }
    // Nearest blocks first: once one is resolved, farther ones are skipped.
    int n = 0;
    const cv::Mat& blocks_of_level = max_pyramid_.level(level_);
    for (int by = by0; by <= by1; ++by) {
      const float* row = blocks_of_level.ptr<float>(by);
      for (int bx = bx0; bx <= bx1; ++bx) blocks_[n++] = {row[bx], bx, by};
    }
    stats_->used_image_pixels += static_cast<uint64_t>(n);
    if (n == 0) return found_;
    int best = 0;
    for (int k = 1; k < n; ++k) best = blocks_[k].max > blocks_[best].max ? k : best;
    const Block& nearest = blocks_[best];
    if (nearest.max < 0.0f) return found_;  // no valid pixel
    // The usual case: the nearest block is uniform enough or wholly inside.
    if (level_ == finest_level_ || inside(nearest.bx, nearest.by, level_) ||
        bound_.isFaithful(min_pyramid_.level(level_).ptr<float>(nearest.by)[nearest.bx], nearest.max)) {
      ++stats_->used_image_pixels;
      return nearest.max;
    }
    sortByDescendingMaximum(n);
    for (int k = 0; k < n && blocks_[k].max > found_; ++k) refine(level_, blocks_[k].bx, blocks_[k].by);
    return found_;
  }

 private:
  static constexpr int kRefinedLevels = 2;
  /// Blocks of the footprint's level that the search orders (3 x 3 at most
  /// where eq. 13's level is not clamped).
  static constexpr size_t kMaxBlocks = 16;
  struct Block {
    float max;
    int bx, by;
  };

  /// Does block b of level j, [b·2^j, (b+1)·2^j), overlap [lo, hi)?
  static bool overlaps(int b, int j, double lo, double hi) {
    return static_cast<double>(b << j)<hi&& static_cast<double>((b + 1) << j)> lo;
  }
  /// Does block (bx, by) of level j lie wholly inside the footprint?
  bool inside(int bx, int by, int j) const {
    return static_cast<double>(bx << j) >= x_lo_ && static_cast<double>((bx + 1) << j) <= x_hi_ &&
           static_cast<double>(by << j) >= y_lo_ && static_cast<double>((by + 1) << j) <= y_hi_;
  }
  /// Depth-first. A block whose maximum cannot raise found_, or that lies
  /// wholly inside the footprint, is not refined; nor is one of the finest level.
  void refine(int j, int bx, int by) {
    const float max = max_pyramid_.level(j).ptr<float>(by)[bx];
    ++stats_->used_image_pixels;
    if (max <= found_) return;  // also an all-invalid block (-1)
    if (j > finest_level_ && !inside(bx, by, j)) {
      ++stats_->used_image_pixels;
      if (!bound_.isFaithful(min_pyramid_.level(j).ptr<float>(by)[bx], max)) {
        const int w = max_pyramid_.width(j - 1), h = max_pyramid_.height(j - 1);
        for (int cy = 2 * by; cy <= 2 * by + 1 && cy < h; ++cy) {
          if (!overlaps(cy, j - 1, y_lo_, y_hi_)) continue;
          for (int cx = 2 * bx; cx <= 2 * bx + 1 && cx < w; ++cx)
            if (overlaps(cx, j - 1, x_lo_, x_hi_)) refine(j - 1, cx, cy);
        }
        return;
      }
    }
    found_ = max;
  }
  /// Insertion sort of the first @p n blocks.
  void sortByDescendingMaximum(int n) {
    for (int k = 1; k < n; ++k) {
      const Block block = blocks_[k];
      int q = k;
      for (; q > 0 && blocks_[q - 1].max < block.max; --q) blocks_[q] = blocks_[q - 1];
      blocks_[q] = block;
    }
  }

  const DisparityPyramid& min_pyramid_;
  const DisparityPyramid& max_pyramid_;
  const DisparityBlockBound& bound_;
  const int level_, finest_level_;
  const double x_lo_, x_hi_, y_lo_, y_hi_;  ///< the footprint [px edges]
  DrawStatistics* stats_;
  float found_ = DisparityPyramid::kInvalidMax;  ///< d̂ so far
  std::array<Block, kMaxBlocks> blocks_;
};

}  // namespace

void RayTracer::drawPyramidBounded(const DisparityPyramid& min_pyramid, const DisparityPyramid& max_pyramid,
                                   const DisparityBlockBound& bound, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                                   DrawStatistics* stats) const {
  CV_Assert(min_pyramid.type() == PyramidType::kMinDisparity && max_pyramid.type() == PyramidType::kMaxDisparity &&
            min_pyramid.topLevel() == max_pyramid.topLevel());
  const int top = max_pyramid.topLevel();
  const double half_cell_f = 0.5 * grid->resolution() * camera_.config().focal_length_px;
  traverse(T_W_C, grid, stats, [&](const Eigen::Vector3d& C_p, double u, double v, DrawStatistics* st) {
    // Eq. 13's level: 2^i <= c·f/z, the footprint spans 2-3 blocks per axis.
    const int level = std::clamp(levels_.levelForDepth(C_p.z()), 0, top);
    return FootprintSearch(min_pyramid, max_pyramid, bound, level, u, v, half_cell_f / C_p.z(), st).maximum();
  });
}

}  // namespace stereo_occupancy
