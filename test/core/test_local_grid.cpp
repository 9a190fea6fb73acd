#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <algorithm>
#include <limits>
#include <random>

#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/sim/synthetic_scene.h"

using namespace stereo_occupancy;

TEST(LocalGrid, GlobalIndexIsFloor) {
  EXPECT_EQ(LocalGrid::globalIndex(Eigen::Vector3d(0.1, -0.1, 0.26), 0.25), Eigen::Vector3i(0, -1, 1));
  EXPECT_EQ(LocalGrid::globalIndex(Eigen::Vector3d(-0.25, 0.25, -0.26), 0.25), Eigen::Vector3i(-1, 1, -2));
}

TEST(LocalGrid, CellsAreOctomapKeys) {
  for (double res : {0.1, 0.25, 1.0}) {
    octomap::OcTree tree(res);
    LocalGrid grid;
    grid.reset(Eigen::Vector3i(-40, 17, -3), Eigen::Vector3i(8, 8, 8), res);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-50.0, 50.0);
    for (int i = 0; i < 1000; ++i) {
      const Eigen::Vector3d p(u(rng), u(rng), u(rng));
      const Eigen::Vector3i g = LocalGrid::globalIndex(p, res);
      const octomap::OcTreeKey key = tree.coordToKey(p.x(), p.y(), p.z());
      ASSERT_EQ(g.x() + 32768, key[0]);
      ASSERT_EQ(g.y() + 32768, key[1]);
      ASSERT_EQ(g.z() + 32768, key[2]);
    }
    const Eigen::Vector3d centre = grid.cellCentre(2, 3, 4);
    const octomap::OcTreeKey key(-40 + 2 + 32768, 17 + 3 + 32768, -3 + 4 + 32768);
    const octomap::point3d oc = tree.keyToCoord(key);
    EXPECT_NEAR(centre.x(), oc.x(), 1e-5);
    EXPECT_NEAR(centre.y(), oc.y(), 1e-5);
    EXPECT_NEAR(centre.z(), oc.z(), 1e-5);
  }
}

TEST(LocalGrid, ResetMarksUnknown) {
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(1, 2, 3), Eigen::Vector3i(4, 5, 6), 0.5);
  EXPECT_EQ(grid.numCells(), 120u);
  EXPECT_EQ(grid.countKnown(), 0u);
  grid.at(3, 4, 5) = -0.6f;
  EXPECT_EQ(grid.countKnown(), 1u);
  EXPECT_EQ(grid.linearIndex(3, 4, 5), 119u);
  grid.clear();
  EXPECT_EQ(grid.countKnown(), 0u);
  EXPECT_EQ(grid.originPosition(), Eigen::Vector3d(0.5, 1.0, 1.5));
}

// Memory is kept between images of similar size, but one rare huge grid
// (here 64 MiB) does not keep its memory once the grids are small again.
TEST(LocalGrid, ReleasesTheMemoryOfOneHugeGrid) {
  LocalGrid grid;
  grid.reset(Eigen::Vector3i::Zero(), Eigen::Vector3i(256, 256, 256), 0.25);
  EXPECT_GE(grid.capacityCells(), size_t{256} * 256 * 256);
  grid.reset(Eigen::Vector3i::Zero(), Eigen::Vector3i(256, 256, 200), 0.25);  // similar: kept
  EXPECT_GE(grid.capacityCells(), size_t{256} * 256 * 256);
  grid.reset(Eigen::Vector3i::Zero(), Eigen::Vector3i(100, 100, 60), 0.25);  // much smaller: released
  EXPECT_LT(grid.capacityCells(), size_t{256} * 256 * 256 / 4);
  EXPECT_EQ(grid.numCells(), 600000u);
  EXPECT_EQ(grid.countKnown(), 0u);
  // Small grids keep their memory whatever the ratio (no allocation per image).
  grid.reset(Eigen::Vector3i::Zero(), Eigen::Vector3i(10, 10, 10), 0.25);
  EXPECT_GE(grid.capacityCells(), 600000u);
}

// On a pool's workers reset() marks every cell unknown, growing, shrinking
// and at sizes that end inside a chunk of the fill.
TEST(LocalGrid, ResetOnWorkersMarksEveryCellUnknown) {
  for (unsigned threads : {2u, 3u}) {
    WorkerPool pool(threads);
    LocalGrid grid;
    for (const Eigen::Vector3i& size :
         {Eigen::Vector3i(100, 90, 80), Eigen::Vector3i(101, 97, 83), Eigen::Vector3i(90, 90, 70),
          Eigen::Vector3i(64, 64, 64), Eigen::Vector3i(3, 2, 1), Eigen::Vector3i(101, 97, 83)}) {
      std::fill(grid.data(), grid.data() + grid.numCells(), 0.5f);  // what the last image drew
      grid.reset(Eigen::Vector3i(-7, 3, 11), size, 0.25, &pool);
      ASSERT_EQ(grid.size(), size);
      ASSERT_EQ(grid.numCells(), static_cast<size_t>(size.prod()));
      EXPECT_EQ(grid.countKnown(), 0u) << size.transpose() << ", " << threads << " threads";
      EXPECT_EQ(grid.originIndex(), Eigen::Vector3i(-7, 3, 11));
    }
  }
}

// The block tests (SSE2 on x86-64, NEON on aarch64, a plain loop elsewhere)
// say what their definitions say, for one telling value at each of the 16
// places in a block of unknown or of 0, and for blocks with none.
TEST(LocalGrid, BlockTestsMatchTheirDefinitions) {
  const float values[] = {LocalGrid::kUnknown,
                          0.0f,
                          -0.0f,
                          0.4f,
                          -0.4f,
                          1e-30f,
                          -1e-30f,
                          1e-40f,
                          -1e-40f,
                          std::numeric_limits<float>::infinity(),
                          -std::numeric_limits<float>::infinity(),
                          std::numeric_limits<float>::quiet_NaN()};
  int checked = 0;
  for (float background : {LocalGrid::kUnknown, 0.0f})
    for (float value : values)
      for (int j = 0; j < kInformationBlock; ++j) {
        float cells[kInformationBlock];
        std::fill(cells, cells + kInformationBlock, background);
        cells[j] = value;
        bool known = false, information = false, occupied = false;
        for (float c : cells) {
          known |= c != LocalGrid::kUnknown;
          information |= c != LocalGrid::kUnknown && c != 0.0f;
          occupied |= c > 0.0f;
        }
        EXPECT_EQ(blockHasKnown(cells), known) << background << " with " << value << " at " << j;
        EXPECT_EQ(blockHasInformation(cells), information) << background << " with " << value << " at " << j;
        EXPECT_EQ(blockHasOccupied(cells), occupied) << background << " with " << value << " at " << j;
        checked += known + information + occupied;
      }
  EXPECT_GT(checked, 400);  // the blocks hold each answer, not only "no"
}

TEST(FrustumBoundingBox, ContainsTheFrustumAndIsTight) {
  const StereoCameraModel cam{StereoCameraConfig()};
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> angle(-M_PI, M_PI), px(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = (Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitZ()) *
                  Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
    T.translation() = Eigen::Vector3d(angle(rng), angle(rng), angle(rng)) * 30.0;
    const Eigen::AlignedBox3d box = frustumBoundingBox(cam, T);
    Eigen::AlignedBox3d sampled(T.translation(), T.translation());
    // Samples of the cap at the maximum range (the extreme points lie on it):
    // random inside, dense along the image border.
    auto sample = [&](double x, double y) {
      const Eigen::Vector3d p = T * (cam.rayThroughPixel(x, y).normalized() * 25.0);
      EXPECT_LT(box.exteriorDistance(p), 1e-9) << "trial " << trial;
      sampled.extend(p);
    };
    for (int i = 0; i < 20000; ++i) sample(-0.5 + px(rng) * 640.0, -0.5 + px(rng) * 480.0);
    for (int i = 0; i <= 4000; ++i) {
      const double s = i / 4000.0;
      sample(-0.5 + s * 640.0, -0.5);
      sample(-0.5 + s * 640.0, 479.5);
      sample(-0.5, -0.5 + s * 480.0);
      sample(639.5, -0.5 + s * 480.0);
    }
    // Tight: no side more than 2 cm beyond the sampled extremes.
    EXPECT_LT((box.max() - sampled.max()).maxCoeff(), 0.02) << "trial " << trial;
    EXPECT_LT((sampled.min() - box.min()).maxCoeff(), 0.02) << "trial " << trial;
  }
}

TEST(FrustumBoundingBox, LevelCameraAlongX) {
  const StereoCameraModel cam{StereoCameraConfig()};
  const Eigen::AlignedBox3d box = frustumBoundingBox(cam, lookingAlongX(Eigen::Vector3d(1, 2, 3)));
  EXPECT_NEAR(box.max().x(), 1.0 + 25.0, 1e-9);  // the optical axis reaches the full range
  EXPECT_NEAR(box.min().x(), 1.0, 1e-9);
  const double half_width = 25.0 * std::sin(std::atan(320.0 / 700.0));  // left/right faces' arcs
  EXPECT_NEAR(box.max().y(), 2.0 + half_width, 1e-6);
  EXPECT_NEAR(box.min().y(), 2.0 - half_width, 1e-6);
}

TEST(FitGridToBox, SnapsToWholeCells) {
  LocalGrid grid;
  fitGridToBox(Eigen::AlignedBox3d(Eigen::Vector3d(-0.3, 0.1, 2.0), Eigen::Vector3d(1.1, 0.2, 2.4)), 0.25, 1, &grid);
  EXPECT_EQ(grid.originIndex(), Eigen::Vector3i(-3, -1, 7));
  EXPECT_EQ(grid.size(), Eigen::Vector3i(9, 3, 4));
}
