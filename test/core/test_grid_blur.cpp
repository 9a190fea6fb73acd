#include <gtest/gtest.h>

#include <cmath>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/grid_blur.h"
#include "stereo_occupancy/sim/synthetic_scene.h"

using namespace stereo_occupancy;

namespace {
LocalGrid impulseGrid(int n, double res, const std::vector<Eigen::Vector3i>& cells, float value) {
  LocalGrid g;
  g.reset(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(n, n, n), res);
  for (const auto& c : cells) g.at(c.x(), c.y(), c.z()) = value;
  return g;
}
double sum(const LocalGrid& g, int x0, int x1, int y0, int y1, int z0, int z1) {
  double s = 0.0;
  for (int z = z0; z <= z1; ++z)
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const float v = g.at(x, y, z);
        if (v != LocalGrid::kUnknown) s += v;
      }
  return s;
}
}  // namespace

TEST(DistanceDependentBlur, SigmaEq17) {
  BlurConfig c;
  c.sigma_trans_m = 0.1;
  c.sigma_angle_rad = 0.02;
  DistanceDependentBlur blur(c);
  EXPECT_NEAR(blur.sigmaAt(0.0), 0.1, 1e-12);
  EXPECT_NEAR(blur.sigmaAt(10.0), std::sqrt(0.01 + 0.04), 1e-12);
  EXPECT_NEAR(blur.sigmaAt(25.0), std::sqrt(0.01 + 0.25), 1e-12);
}

TEST(DistanceDependentBlur, OffWhenBothSigmasAreZero) {
  DistanceDependentBlur blur{BlurConfig()};
  LocalGrid g = impulseGrid(10, 0.25, {{5, 5, 5}}, 2.0f);
  const LocalGrid before = g;
  blur.apply(Eigen::Vector3d::Zero(), &g);
  for (size_t i = 0; i < g.numCells(); ++i) ASSERT_EQ(g.data()[i], before.data()[i]);
  EXPECT_EQ(blur.paddingCells(25.0, 0.25), 0);
}

TEST(DistanceDependentBlur, ConstantSigmaIsAGaussian) {
  BlurConfig c;
  c.sigma_trans_m = 0.25;  // one cell at 0.25 m
  DistanceDependentBlur blur(c);
  LocalGrid g = impulseGrid(15, 0.25, {{7, 7, 7}}, 2.0f);
  blur.apply(Eigen::Vector3d(0, 0, 0), &g);
  const std::vector<float> k = blur.kernel(2);  // σ = 2 · 0.5 cells
  ASSERT_EQ(k.size(), 7u);                      // radius ceil(3σ) = 3
  EXPECT_NEAR(k[3], 1.0 / (std::sqrt(2 * M_PI) * (1 - 2 * 0.00135)), 3e-3);
  EXPECT_NEAR(g.at(7, 7, 7), 2.0 * k[3] * k[3] * k[3], 1e-5);
  EXPECT_NEAR(g.at(8, 7, 7), 2.0 * k[4] * k[3] * k[3], 1e-5);
  EXPECT_NEAR(g.at(8, 9, 6), 2.0 * k[4] * k[5] * k[2], 1e-5);
  EXPECT_NEAR(sum(g, 0, 14, 0, 14, 0, 14), 2.0, 1e-4);  // mass is kept away from the border
  EXPECT_EQ(g.at(0, 0, 0), LocalGrid::kUnknown);        // out of the kernel's reach: still unknown
}

TEST(DistanceDependentBlur, FartherCellsAreBlurredMore) {
  BlurConfig c;
  c.sigma_angle_rad = 0.02;  // σ = 0.1 m at 5 m, 0.4 m at 20 m
  DistanceDependentBlur blur(c);
  const double res = 0.1;
  // Camera at the grid's x = 0 plane; impulses at 5 m and at 20 m.
  LocalGrid g;
  g.reset(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(230, 21, 21), res);
  g.at(50, 10, 10) = 1.0f;
  g.at(200, 10, 10) = 1.0f;
  const Eigen::Vector3d camera(0.05, 1.05, 1.05);
  blur.apply(camera, &g);
  EXPECT_NEAR(blur.sigmaAt(5.0) / res, 1.0, 1e-9);
  EXPECT_NEAR(blur.sigmaAt(20.0) / res, 4.0, 1e-9);
  const float near_peak = g.at(50, 10, 10), far_peak = g.at(200, 10, 10);
  EXPECT_GT(near_peak, 5.0f * far_peak);
  // Kernel of σ = 1 cell at the near impulse; of σ = 4 cells at the far one.
  const double k1 = 1.0 / (std::sqrt(2 * M_PI) * 1.0), k4 = 1.0 / (std::sqrt(2 * M_PI) * 4.0);
  EXPECT_NEAR(near_peak, k1 * k1 * k1, 0.1 * k1 * k1 * k1);
  EXPECT_NEAR(far_peak, k4 * k4 * k4, 0.1 * k4 * k4 * k4);
  // The far one spreads 8 cells along y, the near one does not.
  EXPECT_GT(g.at(200, 18, 10), 0.0f);
  EXPECT_EQ(g.at(50, 18, 10), LocalGrid::kUnknown);
}

TEST(BlurConfig, Validation) {
  BlurConfig c;
  EXPECT_TRUE(c.isValid());
  c.sigma_trans_m = -0.1;
  EXPECT_FALSE(c.isValid());
  c = BlurConfig();
  c.sigma_angle_rad = std::nan("");
  EXPECT_FALSE(c.isValid());
}

namespace {
/// Eq. 17's blur the plain way: every cell of the grid, three dense
/// separable passes, each output cell convolved with the kernel of its own
/// rounded σ (DistanceDependentBlur's documented behaviour).
void referenceBlur(DistanceDependentBlur* blur, const Eigen::Vector3d& W_camera, LocalGrid* grid) {
  const BlurConfig& cfg = blur->config();
  const Eigen::Vector3i n = grid->size();
  const size_t cells = grid->numCells();
  std::vector<int> q(cells);
  std::vector<float> a(cells), b(cells);
  const double c = grid->resolution();
  for (int z = 0; z < n.z(); ++z)
    for (int y = 0; y < n.y(); ++y)
      for (int x = 0; x < n.x(); ++x) {
        const size_t i = grid->linearIndex(x, y, z);
        const Eigen::Vector3d d = grid->cellCentre(x, y, z) - W_camera;
        const double sx = d.x() * d.x(), syz = d.y() * d.y() + d.z() * d.z();
        const double steps =
            std::sqrt(cfg.sigma_trans_m * cfg.sigma_trans_m + (sx + syz) * cfg.sigma_angle_rad * cfg.sigma_angle_rad) /
            (c * cfg.sigma_step_cells);
        const int max_steps = static_cast<int>(BlurConfig::kMaxSigmaCells / cfg.sigma_step_cells);
        q[i] = steps >= max_steps ? max_steps : static_cast<int>(steps + 0.5);
        const float v = grid->data()[i];
        a[i] = v == LocalGrid::kUnknown ? 0.0f : v;
      }
  const int64_t stride[3] = {1, n.x(), static_cast<int64_t>(n.x()) * n.y()};
  auto pass = [&](int axis, const std::vector<float>& in, std::vector<float>* out) {
    for (int z = 0; z < n.z(); ++z)
      for (int y = 0; y < n.y(); ++y)
        for (int x = 0; x < n.x(); ++x) {
          const int64_t i = static_cast<int64_t>(grid->linearIndex(x, y, z));
          const std::vector<float>& k = blur->kernel(q[i]);
          const int r = static_cast<int>(k.size() / 2);
          const int coord = axis == 0 ? x : (axis == 1 ? y : z);
          float sum = 0.0f;
          for (int t = std::max(-r, -coord); t <= std::min(r, n[axis] - 1 - coord); ++t)
            sum += k[t + r] * in[i + t * stride[axis]];
          (*out)[i] = sum;
        }
  };
  pass(0, a, &b);
  pass(1, b, &a);
  pass(2, a, &b);
  for (size_t i = 0; i < cells; ++i)
    if (grid->data()[i] != LocalGrid::kUnknown || b[i] != 0.0f) grid->data()[i] = b[i];
}
}  // namespace

// The fast blur (sparse rows, runs of one kernel) against the plain one on a
// drawn frame whose σ spans several kernels: the same cells, bit for bit
// (each cell's taps are added in the same order).
TEST(DistanceDependentBlur, EqualsThePlainBlurOnADrawnFrame) {
  // Looking along +x, and along +y from (3, -4, 1.5): then the rows along x
  // pass the camera, and σ falls towards it and grows after it in one row.
  const std::pair<double, double> cases[] = {{0.25, 0.0}, {0.5, 0.0}, {0.25, M_PI / 2}};
  for (const auto& [res, yaw] : cases) {
    StereoCameraConfig camera;
    DrawingConfig config;
    config.algorithm = DrawingAlgorithm::kLinePyramid;
    config.resolution_m = res;
    config.blur.sigma_trans_m = 0.1;
    config.blur.sigma_angle_rad = 0.02;  // σ from 0.1 m to 0.51 m: kernels of radius 0 to 7 at 0.25 m
    DisparityDrawer drawer(camera, config);
    Eigen::Isometry3d T_W_C;
    const cv::Mat image = table1Image(StereoCameraModel(camera), &T_W_C);
    if (yaw != 0.0) T_W_C = lookingAlongX(Eigen::Vector3d(3.0, -4.0, 1.5), yaw);
    LocalGrid drawn;
    drawer.prepareGrid(T_W_C, &drawn);
    drawer.drawInto(image, T_W_C, &drawn);
    LocalGrid fast = drawn, plain = drawn;
    drawer.blur(T_W_C, &fast);
    DistanceDependentBlur reference(config.blur);
    referenceBlur(&reference, T_W_C.translation(), &plain);
    size_t known = 0, changed = 0;
    for (size_t i = 0; i < plain.numCells(); ++i) {
      const float p = plain.data()[i], f = fast.data()[i];
      known += p != LocalGrid::kUnknown;
      changed += p != drawn.data()[i];
      if (p == LocalGrid::kUnknown) {
        ASSERT_EQ(f, LocalGrid::kUnknown) << "cell " << i << " at " << res << " m";
      } else {
        ASSERT_EQ(f, p) << "cell " << i << " at " << res << " m";
      }
    }
    EXPECT_GT(changed, drawn.countKnown() / 2) << "the blur did little at " << res << " m";
    EXPECT_GT(known, drawn.countKnown()) << "the blur spread nothing at " << res << " m";
  }
}

// A row through the camera: σ falls towards it and grows again after it, so
// each kernel index comes back on the far side. The runs of one kernel must
// still be found on each side (a bisection over the whole row would skip the
// middle). Checked against the plain blur, bit for bit.
TEST(DistanceDependentBlur, RowThroughTheCameraEqualsThePlainBlur) {
  BlurConfig cfg;
  cfg.sigma_trans_m = 0.05;
  cfg.sigma_angle_rad = 0.05;  // σ from 0.05 m at the camera to 1.25 m at 25 m: 10 kernels
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(-100, -1, -1), Eigen::Vector3i(201, 3, 3), 0.25);
  for (size_t i = 0; i < grid.numCells(); ++i) grid.data()[i] = (i % 7 == 3) ? 0.85f : -0.4f;
  grid.at(0, 0, 0) = LocalGrid::kUnknown;
  const Eigen::Vector3d W_camera = grid.cellCentre(100, 1, 1);
  LocalGrid fast = grid, plain = grid;
  DistanceDependentBlur blur(cfg);
  blur.apply(W_camera, &fast);
  DistanceDependentBlur reference(cfg);
  referenceBlur(&reference, W_camera, &plain);
  size_t changed = 0;
  for (size_t i = 0; i < grid.numCells(); ++i) {
    ASSERT_EQ(fast.data()[i], plain.data()[i]) << "cell " << i;
    changed += plain.data()[i] != grid.data()[i];
  }
  EXPECT_GT(changed, grid.numCells() / 2);
}

// σ is capped at kMaxSigmaCells, so every value of the ranges costs a
// bounded grid and kernel: σ_angle 0.5 rad at 25 m (the top of its range)
// took 43 s and 1 GB an image uncapped. An absurd σ (found by the fuzzer:
// σ_trans of 1e25 m), refused by the table, still pads by the cap.
TEST(DistanceDependentBlur, SigmaIsCappedSoEveryValueInRangeIsBounded) {
  BlurConfig cfg;
  cfg.sigma_trans_m = 1e25;
  std::string why;
  EXPECT_FALSE(cfg.isValid(&why));
  EXPECT_EQ(why.rfind("sigma_trans_m must be in [0, 10]", 0), 0u) << why;
  const int padding = static_cast<int>(std::ceil(cfg.truncate_sigmas * BlurConfig::kMaxSigmaCells)) + 1;  // 25
  EXPECT_EQ(DistanceDependentBlur(cfg).paddingCells(25.0, 0.25), padding);
  cfg.sigma_trans_m = 10.0;  // the ranges' ends
  cfg.sigma_angle_rad = 0.5;
  ASSERT_TRUE(cfg.isValid(&why)) << why;
  DistanceDependentBlur blur(cfg);
  for (double res : {0.02, 0.25, 2.0}) EXPECT_EQ(blur.paddingCells(25.0, res), padding) << res;
  const int widest = static_cast<int>(BlurConfig::kMaxSigmaCells / cfg.sigma_step_cells);
  EXPECT_EQ(blur.kernel(widest).size(), 2u * 24u + 1u);
  // The drawer's grid: the unblurred frustum box and the capped padding, no more.
  DrawingConfig drawing;
  DisparityDrawer unblurred(StereoCameraConfig{}, drawing);
  drawing.blur = cfg;
  DisparityDrawer blurred(StereoCameraConfig{}, drawing);
  LocalGrid plain_grid, blurred_grid;
  unblurred.prepareGrid(Eigen::Isometry3d::Identity(), &plain_grid);
  blurred.prepareGrid(Eigen::Isometry3d::Identity(), &blurred_grid);
  EXPECT_EQ(blurred_grid.size(), plain_grid.size() + Eigen::Vector3i::Constant(2 * padding));
  // Every cell at the cap blurs with the widest kernel, and the whole grid's blur completes.
  for (size_t i = 0; i < blurred_grid.numCells(); i += 97) blurred_grid.data()[i] = 0.85f;
  blur.apply(Eigen::Vector3d::Zero(), &blurred_grid);
  EXPECT_GT(blurred_grid.countKnown(), blurred_grid.numCells() / 2);
}
