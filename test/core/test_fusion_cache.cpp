#include <gtest/gtest.h>

#include <vector>

#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/fusion_cache.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/local_grid.h"

using namespace stereo_occupancy;

namespace {
/// An update of the 20-cell cube at global cell 0 (2 x 2 x 2 blocks), every cell @p log_odds.
GridUpdate cubeUpdate(float log_odds) {
  LocalGrid grid;
  grid.reset(Eigen::Vector3i::Zero(), Eigen::Vector3i::Constant(20), 0.25);
  for (int z = 0; z < 20; ++z)
    for (int y = 0; y < 20; ++y)
      for (int x = 0; x < 20; ++x) grid.at(x, y, z) = log_odds;
  GridUpdate update;
  encodeGridUpdate(grid, Eigen::Vector3d::Constant(2.5), &update);
  return update;
}
}  // namespace

// The tree takes a block's changes kMinUnwrittenUpdates to kMaxUnwrittenUpdates
// updates after the first change, not before, and the blocks one update
// brought not all at once; a block no update touched for kIdleUpdates is let
// go; the values written are the clamped adds'.
TEST(FusionCache, WritesBlocksBackWhenDueAndLetsIdleOnesGo) {
  AccumulatingOcTree tree(0.25);
  tree.setClampingThresMin(0.12);
  tree.setClampingThresMax(0.97);
  const int offset = static_cast<int>(tree.coordToKey(0.0));
  FusionCache cache;
  const GridUpdate update = cubeUpdate(-0.4f);
  const GridUpdate nothing;  // no cells
  std::vector<Eigen::Vector3i> touched;
  size_t updates_that_wrote = 0, cells_written = 0;
  for (size_t k = 1; k <= FusionCache::kMaxUnwrittenUpdates + 1; ++k) {
    cache.add(update, &tree, offset, nullptr, &touched);
    EXPECT_EQ(touched.size(), 8u);
    EXPECT_EQ(cache.blocks(), 8u);
    const size_t written = cache.maintain(&tree, nullptr, nullptr);
    if (k <= FusionCache::kMinUnwrittenUpdates) {
      ASSERT_EQ(written, 0u) << "update " << k;
      ASSERT_EQ(tree.size(), 0u) << "update " << k;
      ASSERT_EQ(cache.unwrittenBlocks(), 8u);
    }
    updates_that_wrote += written > 0;
    cells_written += written;
  }
  // Each block once (its 1000 cells), after 17 to 24 adds; the eight not in one update.
  EXPECT_EQ(cells_written, 8000u);
  EXPECT_GT(updates_that_wrote, 1u);
  EXPECT_EQ(cache.unwrittenBlocks(), 0u);
  EXPECT_EQ(tree.getNumLeafNodes(), 8000u);
  // Adds of -0.4 from unknown: the lower bound.
  const octomap::OcTreeNode* cell = tree.search(octomap::OcTreeKey(offset + 19, offset + 7, offset));
  ASSERT_NE(cell, nullptr);
  EXPECT_EQ(cell->getLogOdds(), tree.getClampingThresMinLog());
  // Clamped free cells take no more free: nothing to write, and the blocks go when idle.
  cache.add(update, &tree, offset, nullptr, &touched);
  EXPECT_EQ(cache.unwrittenBlocks(), 0u);
  for (size_t k = 1; k <= FusionCache::kIdleUpdates; ++k) {
    ASSERT_EQ(cache.blocks(), 8u) << "idle update " << k;
    cache.add(nothing, &tree, offset, nullptr, &touched);
    EXPECT_TRUE(touched.empty());
    cache.maintain(&tree, nullptr, nullptr);
  }
  EXPECT_EQ(cache.blocks(), 0u);
  // Read back from the tree, a block holds the written values: an occupied add changes one cell.
  const GridUpdate hit = cubeUpdate(3.0f);
  cache.add(hit, &tree, offset, nullptr, &touched);
  EXPECT_EQ(cache.unwrittenBlocks(), 8u);
  EXPECT_EQ(cache.writeBack(&tree, nullptr, nullptr), 8000u);
  cell = tree.search(octomap::OcTreeKey(offset + 19, offset + 7, offset));
  ASSERT_NE(cell, nullptr);
  EXPECT_FLOAT_EQ(cell->getLogOdds(), tree.getClampingThresMinLog() + 3.0f);
}

// An update whose cells lie in more blocks than kMaxBlocks (one cell in each
// of 8192): the cache writes its blocks back and lets them go before a row of
// blocks might pass the bound, so it never holds more; the tree gets every cell.
TEST(FusionCache, KeepsItsBoundWithinOneUpdate) {
  AccumulatingOcTree tree(0.25);
  const int offset = static_cast<int>(tree.coordToKey(0.0));
  constexpr int kBlocksX = 32, kBlocksY = 16, kBlocksZ = 16;  // 8192 blocks, 512 rows of 32
  static_assert(kBlocksX * kBlocksY * kBlocksZ == 2 * FusionCache::kMaxBlocks, "twice the bound");
  const Eigen::Vector3i size(kBlocksX * FusionCache::kEdge, kBlocksY * FusionCache::kEdge,
                             kBlocksZ * FusionCache::kEdge);
  GridUpdate update;
  update.resolution_m = 0.25;
  update.origin_index = Eigen::Vector3i::Zero();
  update.size = size;
  update.W_sensor_origin = Eigen::Vector3d::Constant(1.0);
  for (int z = 0; z < size.z(); z += FusionCache::kEdge)
    for (int y = 0; y < size.y(); y += FusionCache::kEdge)
      for (int x = 0; x < size.x(); x += FusionCache::kEdge) {
        update.run_start.push_back(static_cast<uint32_t>((int64_t{z} * size.y() + y) * size.x() + x));
        update.run_length.push_back(1);
        update.log_odds.push_back(0.5f);
      }
  ASSERT_TRUE(update.isConsistent());
  FusionCache cache;
  std::vector<Eigen::Vector3i> touched;
  const size_t written = cache.add(update, &tree, offset, nullptr, &touched);
  EXPECT_EQ(touched.size(), 8192u);
  EXPECT_LE(cache.blocks(), FusionCache::kMaxBlocks);
  EXPECT_GE(written, 4096u);  // at least the first half's blocks, one cell each
  EXPECT_EQ(written + cache.writeBack(&tree, nullptr, nullptr), 8192u);
  EXPECT_EQ(tree.getNumLeafNodes(), 8192u);
  const octomap::OcTreeNode* last =
      tree.search(octomap::OcTreeKey(offset + size.x() - FusionCache::kEdge, offset + size.y() - FusionCache::kEdge,
                                     offset + size.z() - FusionCache::kEdge));
  ASSERT_NE(last, nullptr);
  EXPECT_EQ(last->getLogOdds(), 0.5f);
}
