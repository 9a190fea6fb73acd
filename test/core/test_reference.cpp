// The six algorithms against plain reference implementations, cell
// by cell: written for clarity, not speed (double arithmetic, the exact model
// of eq. 11 instead of the lookup table, pyramids computed block by block
// from the image instead of level by level, no fixed point, no runs). The
// optimised code must give the same cells with the same values, within the
// lookup table's interpolation error (stated below).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <set>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "stereo_occupancy/sim/synthetic_scene.h"

using namespace stereo_occupancy;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// L̂ of one measurement along its ray, from the exact model (eq. 11), with
/// the table's cut-offs: plain free space in front of -c/2 - 4Δl, nothing
/// behind +c/2 + 3Δl (NaN: not drawn).
struct ExactProfile {
  const InverseSensorModel* model;
  double c, l_p = kInf, delta_l = 1.0;
  double value(double l) const {
    if (!std::isfinite(l_p)) return model->freeLogOdds();
    const double u = l - l_p;
    if (u < -0.5 * c - 4.0 * delta_l) return model->freeLogOdds();
    if (u > 0.5 * c + 3.0 * delta_l + 1e-9) return std::numeric_limits<double>::quiet_NaN();  // the end itself is drawn
    return model->logOddsHat(l, l_p, delta_l, c);
  }
  double end() const { return std::isfinite(l_p) ? l_p + 0.5 * c + 3.0 * delta_l : kInf; }
};

class Reference {
 public:
  Reference(const StereoCameraConfig& camera, const DrawingConfig& config)
      : cam_(camera), cfg_(camera), model_(config.sensor_model), c_(config.resolution_m) {}

  /// Eqs. 1, 2, 4, 6, 7 for pixel position (x, y) with disparity d.
  ExactProfile profile(double x, double y, double d) const {
    ExactProfile p{&model_, c_};
    if (!(d > 1e-3 * cam_.farDisparity())) return p;  // infinitely far: free to the range
    const double z = cam_.bf() / d;
    p.l_p = z * cam_.rayThroughPixel(x, y).norm();
    p.delta_l = cam_.depthUncertainty(z) * p.l_p / z;
    return p;
  }

  /// One cell per slab of the major axis, the one where the ray crosses the
  /// slab's centre plane (the first and last slab: the segment point nearest it).
  /// Only the segment of ranges [l_begin, l_stop] of the line, if given.
  void drawLine(const Eigen::Isometry3d& T_W_C, double x, double y, double d, LocalGrid* grid, double l_begin = 0.0,
                double l_stop = kInf) const {
    const ExactProfile p = profile(x, y, d);
    const double l_end = std::min({p.end(), cfg_.max_range_m, l_stop});
    if (!(l_end > l_begin)) return;
    const Eigen::Vector3d dir = T_W_C.linear() * cam_.rayThroughPixel(x, y).normalized();
    const Eigen::Vector3d g0 = (T_W_C.translation() - grid->originPosition()) / c_;
    int m = 0;
    dir.cwiseAbs().maxCoeff(&m);
    const double t_begin = l_begin / c_, t_end = l_end / c_;
    const int k0 = static_cast<int>(std::floor(g0[m] + dir[m] * t_begin));
    const int k1 = static_cast<int>(std::floor(g0[m] + dir[m] * t_end));
    for (int k = std::min(k0, k1); k <= std::max(k0, k1); ++k) {
      const double t = std::clamp((k + 0.5 - g0[m]) / dir[m], t_begin, t_end);
      const Eigen::Vector3d g = g0 + dir * t;
      Eigen::Vector3i cell = g.array().floor().cast<int>();
      cell[m] = k;
      // On a cell border (a tie) either cell is right; the optimised code
      // steps in fixed point and may take the other one.
      for (int axis : {(m + 1) % 3, (m + 2) % 3}) {
        const double fraction = g[axis] - std::floor(g[axis]);
        if (fraction < 1e-6 || fraction > 1.0 - 1e-6) {
          for (int side : {-1, 0, 1}) {
            Eigen::Vector3i other = cell;
            other[axis] += side;
            if (grid->contains(other)) ties.insert(grid->linearIndex(other.x(), other.y(), other.z()));
          }
        }
      }
      const double v = p.value(t * c_);
      if (std::isnan(v) || !grid->contains(cell)) continue;
      float& out = grid->at(cell.x(), cell.y(), cell.z());
      out = std::max(out, static_cast<float>(v));
    }
  }

  /// Section V-A.
  void line(const cv::Mat& d, const Eigen::Isometry3d& T_W_C, LocalGrid* grid) const {
    for (int y = 0; y < d.rows; ++y)
      for (int x = 0; x < d.cols; ++x)
        if (cam_.isValidDisparity(d.at<float>(y, x))) drawLine(T_W_C, x, y, d.at<float>(y, x), grid);
  }

  /// Eq. 14 (or 16) computed directly: the min (max) of the valid pixels of the
  /// 2^i x 2^i block (x, y); +inf (-1) if it has none.
  double block(const cv::Mat& d, int i, int x, int y, bool take_min) const {
    double best = take_min ? kInf : -1.0;
    for (int yy = y << i; yy < std::min((y + 1) << i, d.rows); ++yy)
      for (int xx = x << i; xx < std::min((x + 1) << i, d.cols); ++xx) {
        const float v = d.at<float>(yy, xx);
        if (!cam_.isValidDisparity(v)) continue;
        best = take_min ? std::min(best, static_cast<double>(v)) : std::max(best, static_cast<double>(v));
      }
    return best;
  }

  /// Eq. 13 with eq. 12's spacing, by log2; clamped to the levels drawn.
  int level(double d) const {
    return std::clamp(static_cast<int>(std::floor(std::log2(c_ * std::max(d, cam_.farDisparity()) / cfg_.baseline_m))),
                      minLevel(), topLevel());
  }
  int minLevel() const {
    return std::min(0, static_cast<int>(std::floor(std::log2(c_ * cam_.farDisparity() / cfg_.baseline_m))));
  }
  int topLevel() const {
    const int near = static_cast<int>(std::floor(std::log2(c_ * cam_.bf() / cfg_.min_range_m / cfg_.baseline_m)));
    const int size = static_cast<int>(std::floor(std::log2(std::max(cfg_.width_px, cfg_.height_px))));
    return std::max(0, std::min(near, size));
  }

  /// Section VI-B: from the top level, a block is drawn at its centre when its
  /// minimum's level is at least i, else its four children are visited.
  void linePyramid(const cv::Mat& d, const Eigen::Isometry3d& T_W_C, LocalGrid* grid) const {
    const int top = topLevel();
    for (int y = 0; (y << top) < d.rows; ++y)
      for (int x = 0; (x << top) < d.cols; ++x) descend(d, T_W_C, top, x, y, grid);
  }
  void descend(const cv::Mat& d, const Eigen::Isometry3d& T_W_C, int i, int x, int y, LocalGrid* grid) const {
    const double d_min = block(d, i, x, y, true);
    if (d_min == kInf) return;
    if (i <= minLevel() || level(d_min) >= i) {
      // The centre of the level-0 pixels the block covers.
      const double cx = 0.5 * ((x << i) + std::min((x + 1) << i, d.cols) - 1);
      const double cy = 0.5 * ((y << i) + std::min((y + 1) << i, d.rows) - 1);
      drawLine(T_W_C, cx, cy, d_min, grid);
      return;
    }
    for (int cy = 2 * y; cy <= 2 * y + 1 && (cy << (i - 1)) < d.rows; ++cy)
      for (int cx = 2 * x; cx <= 2 * x + 1 && (cx << (i - 1)) < d.cols; ++cx) descend(d, T_W_C, i - 1, cx, cy, grid);
  }

  /// The bounded line pyramid (README, "bounded pyramids"): a block is drawn
  /// as in linePyramid() only if DisparityBlockBound calls its [min, max]
  /// faithful (the bound itself is tested against the exact model in
  /// test_bounded_pyramids.cpp); otherwise its centre ray draws the stretch
  /// that is free for all its pixels, up to the depth where its children's
  /// rays part by a cell (c·f / 2^i, eq. 12) or the nearest measurement's
  /// front, and the children start there.
  void linePyramidBounded(const cv::Mat& d, const Eigen::Isometry3d& T_W_C, const DisparityBlockBound& bound,
                          LocalGrid* grid) const {
    const int top = topLevel();
    for (int y = 0; (y << top) < d.rows; ++y)
      for (int x = 0; (x << top) < d.cols; ++x) descendBounded(d, T_W_C, bound, top, x, y, 0.0, grid);
  }
  void descendBounded(const cv::Mat& d, const Eigen::Isometry3d& T_W_C, const DisparityBlockBound& bound, int i, int x,
                      int y, double z_begin, LocalGrid* grid) const {
    const double d_min = block(d, i, x, y, true);
    if (d_min == kInf) return;
    const double d_max = block(d, i, x, y, false);
    const double cx = 0.5 * ((x << i) + std::min((x + 1) << i, d.cols) - 1);
    const double cy = 0.5 * ((y << i) + std::min((y + 1) << i, d.rows) - 1);
    const double norm = cam_.rayThroughPixel(cx, cy).norm();  // range per depth
    if (i <= minLevel() ||
        (level(d_min) >= i && (i <= 0 || bound.isFaithful(static_cast<float>(d_min), static_cast<float>(d_max))))) {
      drawLine(T_W_C, cx, cy, d_min, grid, z_begin * norm);
      return;
    }
    const ExactProfile nearest = profile(cx, cy, d_max);
    const double front = nearest.l_p - 0.5 * c_ - 4.0 * nearest.delta_l;  // free in front of it (kInf: sky)
    const double z_shared = std::min(c_ * cfg_.focal_length_px / std::pow(2.0, i), front / norm);
    if (z_shared > z_begin) {
      drawLine(T_W_C, cx, cy, 0.0, grid, z_begin * norm, z_shared * norm);  // d = 0: free
      z_begin = z_shared;
    }
    for (int by = 2 * y; by <= 2 * y + 1 && (by << (i - 1)) < d.rows; ++by)
      for (int bx = 2 * x; bx <= 2 * x + 1 && (bx << (i - 1)) < d.cols; ++bx)
        descendBounded(d, T_W_C, bound, i - 1, bx, by, z_begin, grid);
  }

  /// The bounded ray tracing's d̂ of a cell at depth z seen at (u, v): the
  /// maximum over the blocks of eq. 13's level i that overlap its footprint
  /// (a square of side c·f / z), where a block that sticks out of the
  /// footprint and that DisparityBlockBound does not call faithful is
  /// replaced by its children, down to level i - 2. -1: no valid pixel.
  double boundedFootprintMax(const cv::Mat& d, const DisparityBlockBound& bound, double z, double u, double v) const {
    const int i = std::clamp(static_cast<int>(std::floor(std::log2(c_ * cfg_.focal_length_px / z))), 0, topLevel());
    const double r = 0.5 * c_ * cfg_.focal_length_px / z;
    const double x_lo = std::max(u + 0.5 - r, 0.0), x_hi = std::min(u + 0.5 + r, static_cast<double>(d.cols));
    const double y_lo = std::max(v + 0.5 - r, 0.0), y_hi = std::min(v + 0.5 + r, static_cast<double>(d.rows));
    auto overlaps = [](int b, int j, double lo, double hi) { return (b << j) < hi && ((b + 1) << j) > lo; };
    const int j_min = std::max(0, i - 2);
    std::function<double(int, int, int)> leaves = [&](int j, int bx, int by) {
      const double hi = block(d, j, bx, by, false);
      if (hi < 0.0) return -1.0;
      const bool inside = (bx << j) >= x_lo && ((bx + 1) << j) <= x_hi && (by << j) >= y_lo && ((by + 1) << j) <= y_hi;
      if (j == j_min || inside ||
          bound.isFaithful(static_cast<float>(block(d, j, bx, by, true)), static_cast<float>(hi)))
        return hi;
      double m = -1.0;
      for (int cy = 2 * by; cy <= 2 * by + 1 && (cy << (j - 1)) < d.rows; ++cy)
        for (int cx = 2 * bx; cx <= 2 * bx + 1 && (cx << (j - 1)) < d.cols; ++cx)
          if (overlaps(cx, j - 1, x_lo, x_hi) && overlaps(cy, j - 1, y_lo, y_hi))
            m = std::max(m, leaves(j - 1, cx, cy));
      return m;
    };
    double m = -1.0;
    for (int by = 0; (by << i) < d.rows; ++by)
      for (int bx = 0; (bx << i) < d.cols; ++bx)
        if (overlaps(bx, i, x_lo, x_hi) && overlaps(by, i, y_lo, y_hi)) m = std::max(m, leaves(i, bx, by));
    return m;
  }

  /// Sections V-B and VI-C: every cell of the box whose centre is in view.
  /// @p bound: the bounded variant's footprint (boundedFootprintMax).
  void rayTrace(const cv::Mat& d, const Eigen::Isometry3d& T_W_C, bool pyramid, LocalGrid* grid,
                const DisparityBlockBound* bound = nullptr) const {
    const Eigen::Isometry3d T_C_W = T_W_C.inverse();
    const double f = cfg_.focal_length_px, h = 0.5 * c_;
    for (int z = 0; z < grid->size().z(); ++z)
      for (int y = 0; y < grid->size().y(); ++y)
        for (int x = 0; x < grid->size().x(); ++x) {
          const Eigen::Vector3d C_p = T_C_W * grid->cellCentre(x, y, z);
          if (C_p.z() <= 0.0) continue;
          const double u = f * C_p.x() / C_p.z() + cfg_.cx_px, v = f * C_p.y() / C_p.z() + cfg_.cy_px;
          if (!(u >= -0.5 && u < d.cols - 0.5 && v >= -0.5 && v < d.rows - 0.5)) continue;
          const double l = C_p.norm();
          if (l > cfg_.max_range_m) continue;
          double d_hat = -1.0;
          if (bound) {
            d_hat = boundedFootprintMax(d, *bound, C_p.z(), u, v);
          } else if (pyramid) {  // the 2x2 level-i pixels around (u, v), i of the cell's depth
            const int i = std::clamp(static_cast<int>(std::floor(std::log2(c_ * f / C_p.z()))), 0, topLevel());
            const double s = std::pow(2.0, -i);
            const int x0 = static_cast<int>(std::floor((u + 0.5) * s - 0.5));
            const int y0 = static_cast<int>(std::floor((v + 0.5) * s - 0.5));
            for (int by = std::max(y0, 0); by <= y0 + 1 && (by << i) < d.rows; ++by)
              for (int bx = std::max(x0, 0); bx <= x0 + 1 && (bx << i) < d.cols; ++bx)
                d_hat = std::max(d_hat, block(d, i, bx, by, false));
          } else {  // the bounding rectangle of the 8 projected corners
            double u0 = kInf, u1 = -kInf, v0 = kInf, v1 = -kInf;
            bool behind = false;
            for (int k = 0; k < 8; ++k) {
              const Eigen::Vector3d q =
                  T_C_W * (grid->cellCentre(x, y, z) + Eigen::Vector3d(k & 1 ? h : -h, k & 2 ? h : -h, k & 4 ? h : -h));
              if (q.z() <= 1e-3 * c_) behind = true;
              u0 = std::min(u0, f * q.x() / q.z() + cfg_.cx_px);
              u1 = std::max(u1, f * q.x() / q.z() + cfg_.cx_px);
              v0 = std::min(v0, f * q.y() / q.z() + cfg_.cy_px);
              v1 = std::max(v1, f * q.y() / q.z() + cfg_.cy_px);
            }
            const int xa = behind ? 0 : std::max(0, static_cast<int>(std::floor(u0 + 0.5)));
            const int xb = behind ? d.cols - 1 : std::min(d.cols - 1, static_cast<int>(std::floor(u1 + 0.5)));
            const int ya = behind ? 0 : std::max(0, static_cast<int>(std::floor(v0 + 0.5)));
            const int yb = behind ? d.rows - 1 : std::min(d.rows - 1, static_cast<int>(std::floor(v1 + 0.5)));
            for (int yy = ya; yy <= yb; ++yy)
              for (int xx = xa; xx <= xb; ++xx)
                if (cam_.isValidDisparity(d.at<float>(yy, xx)))
                  d_hat = std::max(d_hat, static_cast<double>(d.at<float>(yy, xx)));
          }
          if (d_hat < 0.0) continue;  // no information in the footprint
          const double value = profile(u, v, d_hat).value(l);
          if (!std::isnan(value)) grid->at(x, y, z) = static_cast<float>(value);
        }
  }

  /// Cells next to a line's tie on a cell border (see drawLine).
  mutable std::set<size_t> ties;

 private:
  StereoCameraModel cam_;
  StereoCameraConfig cfg_;
  InverseSensorModel model_;
  double c_;
};

/// Compares a drawn grid with the reference's, cell by cell.
struct Comparison {
  size_t known = 0;          ///< cells known in the reference
  size_t only_one = 0;       ///< cells known in one grid only
  size_t value_differs = 0;  ///< cells known in both, values apart by more than the tolerance
  double max_difference = 0.0;
};
Comparison compare(const LocalGrid& drawn, const LocalGrid& reference, double tolerance, const std::set<size_t>& ties) {
  Comparison out;
  for (size_t i = 0; i < drawn.numCells(); ++i) {
    if (ties.count(i)) continue;
    const float a = drawn.data()[i], b = reference.data()[i];
    const bool ka = a != LocalGrid::kUnknown, kb = b != LocalGrid::kUnknown;
    out.known += kb;
    if (ka != kb) {
      ++out.only_one;
    } else if (ka) {
      const double diff = std::abs(static_cast<double>(a) - b);
      out.max_difference = std::max(out.max_difference, diff);
      out.value_differs += diff > tolerance;
    }
  }
  return out;
}

}  // namespace

// The table's bilinear interpolation against the exact model: < 0.005 in
// log-odds over the whole model (test_inverse_sensor_model.cpp); on these
// frames the largest difference is 0.0011, float sums included, so 0.002
// (what docs/tests.md promises) holds with room to spare.
constexpr double kValueTolerance = 0.002;
// Cells next to a tie (a line along a cell border, see drawLine) are left
// out; on these frames they are at most 7.3 % of the known cells.
constexpr double kMaxTieShare = 0.08;

TEST(ReferenceImplementation, PaperAlgorithmsMatchCellByCell) {
  const StereoCameraConfig camera;
  Eigen::Isometry3d T_table1;
  const cv::Mat image = table1Image(StereoCameraModel(camera), &T_table1);
  Eigen::Isometry3d T_turned = lookingAlongX(Eigen::Vector3d(0.3, -0.7, 2.4), 0.35, 0.2);
  for (const auto& [T_W_C, resolution] :
       {std::make_pair(T_table1, 0.5), std::make_pair(T_turned, 0.5), std::make_pair(T_turned, 0.25)}) {
    for (DrawingAlgorithm algorithm : {DrawingAlgorithm::kLine, DrawingAlgorithm::kLinePyramid,
                                       DrawingAlgorithm::kRayTrace, DrawingAlgorithm::kRayTracePyramid}) {
      DrawingConfig config;
      config.algorithm = algorithm;
      config.resolution_m = resolution;
      DisparityDrawer drawer(camera, config);
      LocalGrid drawn;
      drawer.draw(image, T_W_C, &drawn);
      LocalGrid reference = drawn;
      reference.clear();
      const Reference ref(camera, config);
      switch (algorithm) {
        case DrawingAlgorithm::kLine:
          ref.line(image, T_W_C, &reference);
          break;
        case DrawingAlgorithm::kLinePyramid:
          ref.linePyramid(image, T_W_C, &reference);
          break;
        case DrawingAlgorithm::kRayTrace:
          ref.rayTrace(image, T_W_C, false, &reference);
          break;
        default:
          ref.rayTrace(image, T_W_C, true, &reference);
          break;
      }
      const Comparison c = compare(drawn, reference, kValueTolerance, ref.ties);
      SCOPED_TRACE(std::string(toString(algorithm)) + " at " + std::to_string(resolution) + " m");
      std::printf(
          "%-16s %.2f m: known %zu (ties left out: %zu), known in one only %zu, values apart %zu, "
          "max difference %.4f\n",
          toString(algorithm), resolution, c.known, ref.ties.size(), c.only_one, c.value_differs, c.max_difference);
      EXPECT_GT(c.known, 2000u);
      EXPECT_LT(static_cast<double>(ref.ties.size()), kMaxTieShare * c.known);
      // Identical cells; values within the table's error.
      EXPECT_EQ(c.only_one, 0u);
      EXPECT_EQ(c.value_differs, 0u) << "max difference " << c.max_difference;
    }
  }
}

// The bounded variants (beyond the paper) against their plain references,
// on the Table I image and on a frame of the posts flight (ground seen
// obliquely from above, where the bounded pyramids descend the most).
TEST(ReferenceImplementation, BoundedAlgorithmsMatchCellByCell) {
  const StereoCameraConfig camera;
  Eigen::Isometry3d T_table1;
  const cv::Mat table1 = table1Image(StereoCameraModel(camera), &T_table1);
  const FlightScenario posts = makeScenario("posts");
  const cv::Mat flight = renderStereoFrame(posts, 100, 1);
  struct Case {
    const cv::Mat* image;
    Eigen::Isometry3d T_W_C;
    double resolution;
  };
  // Turned off the grid's axes: the Table I pose looks along x from a cell
  // border, so the block centres' rays run along cell borders (ties).
  const Eigen::Isometry3d T_turned = lookingAlongX(Eigen::Vector3d(0.3, -0.7, 2.4), 0.35, 0.2);
  for (const Case& k :
       {Case{&table1, T_turned, 0.5}, Case{&table1, T_table1, 0.25}, Case{&flight, posts.cameraPose(100), 0.5}}) {
    for (DrawingAlgorithm algorithm :
         {DrawingAlgorithm::kLinePyramidBounded, DrawingAlgorithm::kRayTracePyramidBounded}) {
      DrawingConfig config;
      config.algorithm = algorithm;
      config.resolution_m = k.resolution;
      DisparityDrawer drawer(camera, config);
      LocalGrid drawn;
      drawer.draw(*k.image, k.T_W_C, &drawn);
      LocalGrid reference = drawn;
      reference.clear();
      const Reference ref(camera, config);
      const DisparityBlockBound bound(StereoCameraModel(camera), InverseSensorModel(config.sensor_model),
                                      config.resolution_m);
      if (algorithm == DrawingAlgorithm::kLinePyramidBounded) {
        ref.linePyramidBounded(*k.image, k.T_W_C, bound, &reference);
      } else {
        ref.rayTrace(*k.image, k.T_W_C, true, &reference, &bound);
      }
      const Comparison c = compare(drawn, reference, kValueTolerance, ref.ties);
      SCOPED_TRACE(std::string(toString(algorithm)) + " at " + std::to_string(k.resolution) + " m");
      std::printf(
          "%-24s %.2f m: known %zu (ties left out: %zu), known in one only %zu, values apart %zu, "
          "max difference %.4f\n",
          toString(algorithm), k.resolution, c.known, ref.ties.size(), c.only_one, c.value_differs, c.max_difference);
      EXPECT_GT(c.known, 2000u);
      EXPECT_LT(static_cast<double>(ref.ties.size()), kMaxTieShare * c.known);
      EXPECT_EQ(c.only_one, 0u);
      EXPECT_EQ(c.value_differs, 0u) << "max difference " << c.max_difference;
    }
  }
}
