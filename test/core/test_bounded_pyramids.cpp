// The bounded pyramidal variants (beyond the paper) against thin obstacles
// that the paper's pyramids lose or enlarge: a 5 cm post at 8 m in front of a
// wall at 20 m, and a 2 cm wire against the sky at 10 m, with 0.25 m cells.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/sim/synthetic_scene.h"

using namespace stereo_occupancy;

namespace {

constexpr double kCell = 0.25;

/// How an algorithm drew the cells of one obstacle, and the cells beside it.
struct ObstacleCells {
  int cells = 0;            ///< cells the obstacle passes through (in view)
  int occupied = 0;         ///< of those, with log-odds > 0
  int free = 0;             ///< of those, with log-odds < 0
  int beside_occupied = 0;  ///< occupied cells at the obstacle's depth but 1-2 cells beside it
};

/// Draws @p disparity with @p algorithm (no blur) and reads the cells of the
/// cells lo..hi (global indices, one cell thick along @p lateral_axis) and
/// their neighbours one and two cells away along that axis.
ObstacleCells drawAndInspect(DrawingAlgorithm algorithm, const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C,
                             const Eigen::Vector3i& lo, const Eigen::Vector3i& hi, int lateral_axis) {
  DrawingConfig config;
  config.algorithm = algorithm;
  config.resolution_m = kCell;
  DisparityDrawer drawer(StereoCameraConfig(), config);
  LocalGrid grid;
  drawer.draw(disparity, T_W_C, &grid);
  ObstacleCells out;
  auto value = [&](Eigen::Vector3i global) {
    const Eigen::Vector3i local = global - grid.originIndex();
    EXPECT_TRUE(grid.contains(local));
    return grid.contains(local) ? grid.at(local.x(), local.y(), local.z()) : LocalGrid::kUnknown;
  };
  for (int z = lo.z(); z <= hi.z(); ++z)
    for (int y = lo.y(); y <= hi.y(); ++y)
      for (int x = lo.x(); x <= hi.x(); ++x) {
        const float v = value({x, y, z});
        ++out.cells;
        out.occupied += v > 0.0f;
        out.free += v < 0.0f && v != LocalGrid::kUnknown;
        for (int side : {-2, -1, 1, 2}) {
          Eigen::Vector3i beside(x, y, z);
          beside[lateral_axis] += side;
          out.beside_occupied += value(beside) > 0.0f;
        }
      }
  return out;
}

Eigen::Vector3i cellOf(const Eigen::Vector3d& p) { return LocalGrid::globalIndex(p, kCell); }

/// Per-pixel line drawing finds all @p cells of the obstacle; so does the
/// bounded pyramid, and it draws none of them free.
void expectKept(const ObstacleCells& plain, const ObstacleCells& bounded, int cells) {
  EXPECT_EQ(plain.occupied, cells);
  EXPECT_EQ(bounded.cells, cells);
  EXPECT_EQ(bounded.occupied, cells);
  EXPECT_EQ(bounded.free, 0);
}

/// Ray tracing finds all @p cells; the bounded pyramid too, without calling
/// more cells beside the obstacle occupied than plain ray tracing, where the
/// paper's pyramid does.
void expectNotEnlarged(const char* what, const ObstacleCells& plain, const ObstacleCells& paper,
                       const ObstacleCells& bounded, int cells) {
  EXPECT_EQ(plain.occupied, cells);
  EXPECT_EQ(bounded.occupied, cells);
  EXPECT_EQ(bounded.free, 0);
  EXPECT_GT(paper.beside_occupied, 0);  // the 2x2 window of a coarse level reaches the neighbours
  EXPECT_LE(bounded.beside_occupied, plain.beside_occupied);
  std::printf("%s: cells beside it called occupied: raytrace %d, raytrace_pyramid %d, bounded %d\n", what,
              plain.beside_occupied, paper.beside_occupied, bounded.beside_occupied);
}

/// Camera 2 m above ground level looking along +x (no ground in these scenes).
Eigen::Isometry3d camera() { return lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0)); }

class PostBeforeWall : public ::testing::Test {
 protected:
  void SetUp() override {
    scene.addBox({20.0, -15.0, -5.0}, {21.0, 15.0, 10.0});  // the wall at 20 m
    // A 5 cm post at 8.1 m: 4.3 px wide, thinner than one 8 px block of the
    // wall's pyramid level (eq. 13: 2^3 px at 20 m) -- no block holds only post.
    scene.addBox({8.1 - 0.025, 0.37 - 0.025, -1.0}, {8.1 + 0.025, 0.37 + 0.025, 5.0});
    disparity = renderDisparity(scene, StereoCameraModel(StereoCameraConfig()), camera());
  }
  ObstacleCells inspect(DrawingAlgorithm algorithm) const {
    // The post's cells from 1 to 3 m height (well inside the image).
    return drawAndInspect(algorithm, disparity, camera(), cellOf({8.1, 0.37, 1.0}), cellOf({8.1, 0.37, 2.99}), 1);
  }
  SyntheticScene scene;
  cv::Mat disparity;
};

TEST_F(PostBeforeWall, PaperLinePyramidLosesThePost) {
  const ObstacleCells paper = inspect(DrawingAlgorithm::kLinePyramid);
  EXPECT_EQ(paper.cells, 8);
  EXPECT_EQ(paper.occupied, 0);  // every block's line runs to the wall...
  EXPECT_EQ(paper.free, 8);      // ...and draws the post free
}

TEST_F(PostBeforeWall, BoundedLinePyramidKeepsThePost) {
  expectKept(inspect(DrawingAlgorithm::kLine), inspect(DrawingAlgorithm::kLinePyramidBounded), 8);
}

TEST_F(PostBeforeWall, BoundedRayTracingDoesNotEnlargeThePost) {
  expectNotEnlarged("post", inspect(DrawingAlgorithm::kRayTrace), inspect(DrawingAlgorithm::kRayTracePyramid),
                    inspect(DrawingAlgorithm::kRayTracePyramidBounded), 8);
}

class WireAgainstSky : public ::testing::Test {
 protected:
  void SetUp() override {
    // A 2 cm wire 1.1 m above the camera at 10.1 m, 1.4 px thick; all else is
    // sky, matched at zero disparity.
    scene.addBox({10.1 - 0.01, -4.0, 3.1 - 0.01}, {10.1 + 0.01, 4.0, 3.1 + 0.01});
    disparity = renderDisparity(scene, StereoCameraModel(StereoCameraConfig()), camera());
  }
  ObstacleCells inspect(DrawingAlgorithm algorithm) const {
    // The wire's cells from y = -3.5 to 3.5 m (well inside the image).
    return drawAndInspect(algorithm, disparity, camera(), cellOf({10.1, -3.5, 3.1}), cellOf({10.1, 3.49, 3.1}), 2);
  }
  SyntheticScene scene;
  cv::Mat disparity;
};

TEST_F(WireAgainstSky, PaperLinePyramidLosesTheWire) {
  const ObstacleCells paper = inspect(DrawingAlgorithm::kLinePyramid);
  EXPECT_EQ(paper.cells, 28);
  EXPECT_EQ(paper.occupied, 0);  // zero (sky) wins every block's minimum
  EXPECT_EQ(paper.free, 28);
}

TEST_F(WireAgainstSky, BoundedLinePyramidKeepsTheWire) {
  expectKept(inspect(DrawingAlgorithm::kLine), inspect(DrawingAlgorithm::kLinePyramidBounded), 28);
}

TEST_F(WireAgainstSky, BoundedRayTracingDoesNotEnlargeTheWire) {
  expectNotEnlarged("wire", inspect(DrawingAlgorithm::kRayTrace), inspect(DrawingAlgorithm::kRayTracePyramid),
                    inspect(DrawingAlgorithm::kRayTracePyramidBounded), 28);
}

/// The bound itself: a nearer measurement must lie where the far line's
/// profile (eq. 11) is still occupied, and never across the sky.
TEST(DisparityBlockBound, FaithfulWhereTheFarProfileIsOccupied) {
  const StereoCameraModel cam{StereoCameraConfig()};  // bf = 210 px·m, Δd = 0.5 px, 25 m range
  const InverseSensorModel model{InverseSensorModelConfig()};
  const DisparityBlockBound bound(cam, model, kCell);
  const auto d = [&](double z) { return static_cast<float>(cam.disparityFromDepth(z)); };
  // The occupied reach in front of the far measurement, by the exact model.
  auto reach = [&](double z_far) {
    double u = 0.0;
    while (model.logOddsHat(z_far - u - 0.001, z_far, cam.depthUncertainty(z_far), kCell) > 0.0) u += 0.001;
    return u;
  };
  for (double z_far : {3.0, 5.2, 8.0, 12.0, 20.0, 24.0}) {
    const double u = reach(z_far);
    SCOPED_TRACE(z_far);
    EXPECT_GE(u, 0.5 * kCell);  // at least the eq. 11 window
    EXPECT_TRUE(bound.isFaithful(d(z_far), d(z_far)));
    EXPECT_TRUE(bound.isFaithful(d(z_far), d(z_far - 0.97 * u)));
    EXPECT_FALSE(bound.isFaithful(d(z_far), d(z_far - 1.03 * u)));
  }
  EXPECT_NEAR(reach(20.0), 0.79, 0.03);             // Δz(20 m) = 0.95 m: about 0.67 Δz + c/2
  EXPECT_FALSE(bound.isFaithful(d(20.0), d(8.0)));  // the post before the wall
  EXPECT_TRUE(bound.isFaithful(0.0f, 0.0f));        // all sky
  EXPECT_TRUE(bound.isFaithful(0.0f, d(30.0)));     // sky and beyond the range: free to the range
  EXPECT_FALSE(bound.isFaithful(0.0f, d(10.0)));    // the wire against the sky
  EXPECT_FALSE(bound.isFaithful(0.0f, d(24.9)));
  EXPECT_TRUE(bound.isFaithful(d(25.5), d(24.9)));  // the ground across the range limit
}

}  // namespace

namespace {

/// The bound for a camera whose disparities reach far above its table: the
/// table stops at DisparityBlockBound::kMaxTabulatedPx, beyond it one cell.
TEST(DisparityBlockBound, BeyondTheTableOneCell) {
  StereoCameraConfig config;
  config.focal_length_px = 1e5;  // bf = 1e6 px·m: disparities up to 2e6 px at 0.5 m
  config.baseline_m = 10.0;
  const StereoCameraModel cam(config);
  const InverseSensorModel model{InverseSensorModelConfig()};
  const DisparityBlockBound bound(cam, model, kCell);
  const float d_min = 50000.0f;  // z = 20 m, far above the table
  EXPECT_NEAR(bound.maxNearDisparity(d_min), 50000.0 * 1e6 / (1e6 - kCell * 50000.0), 0.1);  // 50632.9
  EXPECT_TRUE(bound.isFaithful(d_min, 50600.0f));
  EXPECT_FALSE(bound.isFaithful(d_min, 50700.0f));
}

/// The span test's shortcut relies on it: a gap inside a faithful gap is
/// faithful, for both profiles and the cell sizes users run, from twice the
/// camera's range on.
TEST(DisparityBlockBound, InnerPairsOfAFaithfulPairAreFaithful) {
  const StereoCameraModel cam{StereoCameraConfig()};
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (const SensorProfile profile : {SensorProfile::kGaussian, SensorProfile::kSurface})
    for (double cell_m : {0.05, 0.1, 0.25, 0.5}) {
      InverseSensorModelConfig model_config;
      model_config.profile = profile;
      const DisparityBlockBound bound(cam, InverseSensorModel(model_config), cell_m);
      SCOPED_TRACE(cell_m);
      ASSERT_LE(bound.monotoneFrom(), 0.5 * cam.farDisparity());
      const float lowest = bound.monotoneFrom(), highest = static_cast<float>(cam.nearDisparity()) + 50.0f;
      int faithful = 0, inner_unfaithful = 0;
      for (int i = 0; i < 20000; ++i) {
        // A faithful pair (a, b), b up to a tenth beyond the bound, and a pair inside it.
        const float a = lowest + (highest - lowest) * unit(rng);
        const float b = a + 1.1f * (std::min(bound.maxNearDisparity(a), 2.0f * highest) - a) * unit(rng);
        const float a_inner = a + (b - a) * unit(rng);
        const float b_inner = a_inner + (b - a_inner) * unit(rng);
        if (!bound.isFaithful(a, b)) continue;
        ++faithful;
        inner_unfaithful += !bound.isFaithful(a_inner, b_inner);
      }
      EXPECT_GT(faithful, 15000);
      EXPECT_EQ(inner_unfaithful, 0);
    }
}

/// Cells so near the camera that their footprint spans more top-level blocks
/// than the bounded ray tracer sorts (40 blocks of 64 px at 0.1 m with 5 cm
/// cells, at most 16 sorted): all blocks still count. Upper half of the image unmatched, lower
/// half a wall at 3 m, so a cell whose footprint reaches the lower half is
/// free, whatever the order of its blocks.
TEST(BoundedRayTracing, NearCellsSeeEveryBlockOfTheirFootprint) {
  StereoCameraConfig config;
  config.max_range_m = 5.0;  // a small grid at 5 cm
  const StereoCameraModel cam(config);
  cv::Mat image(480, 640, CV_32FC1, cv::Scalar(static_cast<float>(cam.disparityFromDepth(3.0))));
  image.rowRange(0, 240).setTo(std::numeric_limits<float>::quiet_NaN());
  const Eigen::Isometry3d T_W_C = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0));
  DrawingConfig drawing;
  drawing.algorithm = DrawingAlgorithm::kRayTracePyramidBounded;
  drawing.resolution_m = 0.05;
  DisparityDrawer drawer(config, drawing);
  LocalGrid grid;
  drawer.draw(image, T_W_C, &grid);
  size_t near_cells = 0, free_cells = 0;
  for (int z = 0; z < grid.size().z(); ++z)
    for (int y = 0; y < grid.size().y(); ++y)
      for (int x = 0; x < grid.size().x(); ++x) {
        const Eigen::Vector3d C_p = T_W_C.inverse() * grid.cellCentre(x, y, z);
        if (C_p.z() < 0.05 || C_p.z() > 0.15) continue;
        const double u = config.focal_length_px * C_p.x() / C_p.z() + config.cx_px;
        const double v = config.focal_length_px * C_p.y() / C_p.z() + config.cy_px;
        if (u < 0.0 || u > 639.0 || v < 0.0 || v > 479.0) continue;
        const double r = 0.5 * 0.05 * config.focal_length_px / C_p.z();
        if (v + 0.5 + r < 250.0) continue;  // the footprint stays in the unmatched half
        ++near_cells;
        const float value = grid.at(x, y, z);
        free_cells += value < 0.0f && value != LocalGrid::kUnknown;
      }
  EXPECT_GE(near_cells, 3u);  // the frustum is a few cells wide there
  EXPECT_EQ(free_cells, near_cells);
}

}  // namespace
