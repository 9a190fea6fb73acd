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

// The tree takes a block's changes FusionCache::kMaxUnwrittenUpdates updates
// after the first change, not before; a block no update touched for kIdleUpdates is
// let go; the values written are the clamped adds'.
TEST(FusionCache, WritesBlocksBackWhenDueAndLetsIdleOnesGo) {
  AccumulatingOcTree tree(0.25);
  tree.setClampingThresMin(0.12);
  tree.setClampingThresMax(0.97);
  const int offset = static_cast<int>(tree.coordToKey(0.0));
  FusionCache cache;
  const GridUpdate update = cubeUpdate(-0.4f);
  const GridUpdate nothing;  // no cells
  std::vector<Eigen::Vector3i> touched;
  for (size_t k = 1; k <= FusionCache::kMaxUnwrittenUpdates + 1; ++k) {
    cache.add(update, tree, offset, nullptr, &touched);
    EXPECT_EQ(touched.size(), 8u);
    EXPECT_EQ(cache.blocks(), 8u);
    const size_t written = cache.maintain(&tree, nullptr, nullptr);
    if (k <= FusionCache::kMaxUnwrittenUpdates) {
      ASSERT_EQ(written, 0u) << "update " << k;
      ASSERT_EQ(tree.size(), 0u) << "update " << k;
      ASSERT_EQ(cache.unwrittenBlocks(), 8u);
    } else {
      EXPECT_EQ(written, 8000u);
      EXPECT_EQ(cache.unwrittenBlocks(), 0u);
    }
  }
  EXPECT_EQ(tree.getNumLeafNodes(), 8000u);
  // Seventeen adds of -0.4 from unknown: the lower bound.
  const octomap::OcTreeNode* cell = tree.search(octomap::OcTreeKey(offset + 19, offset + 7, offset));
  ASSERT_NE(cell, nullptr);
  EXPECT_EQ(cell->getLogOdds(), tree.getClampingThresMinLog());
  // Clamped free cells take no more free: nothing to write, and the blocks go when idle.
  cache.add(update, tree, offset, nullptr, &touched);
  EXPECT_EQ(cache.unwrittenBlocks(), 0u);
  for (size_t k = 1; k <= FusionCache::kIdleUpdates; ++k) {
    ASSERT_EQ(cache.blocks(), 8u) << "idle update " << k;
    cache.add(nothing, tree, offset, nullptr, &touched);
    EXPECT_TRUE(touched.empty());
    cache.maintain(&tree, nullptr, nullptr);
  }
  EXPECT_EQ(cache.blocks(), 0u);
  // Read back from the tree, a block holds the written values: an occupied add changes one cell.
  const GridUpdate hit = cubeUpdate(3.0f);
  cache.add(hit, tree, offset, nullptr, &touched);
  EXPECT_EQ(cache.unwrittenBlocks(), 8u);
  EXPECT_EQ(cache.writeBack(&tree, nullptr, nullptr), 8000u);
  cell = tree.search(octomap::OcTreeKey(offset + 19, offset + 7, offset));
  ASSERT_NE(cell, nullptr);
  EXPECT_FLOAT_EQ(cell->getLogOdds(), tree.getClampingThresMinLog() + 3.0f);
}
