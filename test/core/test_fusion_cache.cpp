#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <tuple>
#include <vector>

#include "octree_text.h"
#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/fusion_cache.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/worker_pool.h"

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

/// 32 x 16 x 16 blocks (twice FusionCache::kMaxBlocks, 512 rows of 32) with
/// @p cells cells in a row at each block's first, their values alternating
/// between @p a and @p b.
GridUpdate sparseUpdate(int cells, float a, float b) {
  constexpr int kBlocksX = 32, kBlocksY = 16, kBlocksZ = 16;
  static_assert(kBlocksX * kBlocksY * kBlocksZ == 2 * FusionCache::kMaxBlocks, "twice the bound");
  GridUpdate update;
  update.resolution_m = 0.25;
  update.origin_index = Eigen::Vector3i::Zero();
  update.size = Eigen::Vector3i(kBlocksX, kBlocksY, kBlocksZ) * FusionCache::kEdge;
  update.W_sensor_origin = Eigen::Vector3d::Constant(1.0);
  const Eigen::Vector3i& size = update.size;
  for (int z = 0; z < size.z(); z += FusionCache::kEdge)
    for (int y = 0; y < size.y(); y += FusionCache::kEdge)
      for (int x = 0; x < size.x(); x += FusionCache::kEdge) {
        update.run_start.push_back(static_cast<uint32_t>((int64_t{z} * size.y() + y) * size.x() + x));
        update.run_length.push_back(static_cast<uint32_t>(cells));
        for (int c = 0; c < cells; ++c) update.log_odds.push_back(update.log_odds.size() % 2 ? a : b);
      }
  return update;
}

// An update whose cells lie in more blocks than kMaxBlocks (one cell in each
// of 8192): the cache writes its blocks back and lets them go before a row of
// blocks might pass the bound, so it never holds more; the tree gets every cell.
TEST(FusionCache, KeepsItsBoundWithinOneUpdate) {
  AccumulatingOcTree tree(0.25);
  const int offset = static_cast<int>(tree.coordToKey(0.0));
  const GridUpdate update = sparseUpdate(1, 0.5f, 0.5f);
  const Eigen::Vector3i& size = update.size;
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

// An update fused in several batches (written back and let go between them),
// twice, on a pool of three workers and on one thread: the same tree, the
// same blocks touched and the same class changes in the same order; and the
// tree node for node octomap's updateNode's over the same adds.
TEST(FusionCache, BatchesOnAPoolAreUpdateNodesTree) {
  const GridUpdate update = sparseUpdate(3, 0.85f, -0.4f);
  ASSERT_TRUE(update.isConsistent());
  octomap::OcTree plain(0.25);
  const int offset = static_cast<int>(plain.coordToKey(0.0));
  for (int pass = 0; pass < 2; ++pass)
    update.forEachCell([&](const Eigen::Vector3i& g, float v) {
      plain.updateNode(octomap::OcTreeKey(g.x() + offset, g.y() + offset, g.z() + offset), v, true);
    });
  plain.updateInnerOccupancy();
  std::string trees[2];
  std::vector<Eigen::Vector3i> touched[2];
  std::vector<CellClassChange> changes[2];
  for (int run = 0; run < 2; ++run) {
    WorkerPool pool(3);
    WorkerPool* workers = run == 0 ? nullptr : &pool;
    AccumulatingOcTree::WorkerCounters counters;
    AccumulatingOcTree tree(0.25);
    FusionCache cache;
    ClassChangeLog log;
    log.max_changes = 1 << 20;
    std::vector<Eigen::Vector3i> blocks;
    for (int pass = 0; pass < 2; ++pass) {
      EXPECT_GT(cache.add(update, &tree, offset, &log, &blocks, workers, &counters), 0u);  // batches written back
      EXPECT_LE(cache.blocks(), FusionCache::kMaxBlocks);
      touched[run].insert(touched[run].end(), blocks.begin(), blocks.end());
    }
    cache.writeBack(&tree, workers, &counters);
    tree.updateInnerOccupancy();
    trees[run] = fullTree(tree);
    changes[run] = log.changes;
    EXPECT_FALSE(log.overflowed);
  }
  EXPECT_TRUE(trees[0] == fullTree(plain)) << "one thread: not updateNode's tree";
  EXPECT_TRUE(trees[1] == trees[0]) << "three workers: another tree";
  EXPECT_EQ(touched[1], touched[0]);
  EXPECT_EQ(touched[0].size(), 2u * 8192u);
  ASSERT_EQ(changes[1].size(), changes[0].size());
  EXPECT_EQ(changes[0].size(), 3u * 8192u);  // each cell once from unknown; the second pass changes no class
  for (size_t i = 0; i < changes[0].size(); ++i) {
    ASSERT_EQ(changes[1][i].cell, changes[0][i].cell) << "change " << i;
    ASSERT_EQ(changes[1][i].now, changes[0][i].now) << "change " << i;
  }
}

// Dense updates whose rows cross blocks at odd places (stretches of 1 to 16
// cells) and whose runs go on from one row to the next, with values that flip cells
// between free and occupied, exact zeros, and values that reach the
// clamping bounds: after each, the tree is updateNode's over the same adds,
// and the class changes are each cell's, from its value before and after
// (one pass without a log, one whose log overflows).
TEST(FusionCache, StretchesTakeEachCellsUpdateAndClassChange) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> moderate(-1.5f, 1.5f);
  octomap::OcTree plain(0.25);
  const int offset = static_cast<int>(plain.coordToKey(0.0));
  AccumulatingOcTree tree(0.25);
  FusionCache cache;
  ClassChangeLog log;
  const float occupied = plain.getOccupancyThresLog();
  using Change = std::tuple<int, int, int, int>;  // cell, class
  size_t flips = 0, clamped = 0;
  for (int pass = 0; pass < 6; ++pass) {
    LocalGrid grid;
    grid.reset(Eigen::Vector3i(5 + pass, -3, 2), Eigen::Vector3i(43, 9, 5), 0.25);
    for (int z = 0; z < 5; ++z)
      for (int y = 0; y < 9; ++y)
        for (int x = 0; x < 43; ++x) {
          const unsigned kind = rng() % 16;
          grid.at(x, y, z) = kind == 0 ? LocalGrid::kUnknown : kind == 1 ? 4.0f : kind == 2 ? -4.0f : moderate(rng);
        }
    GridUpdate update;
    encodeGridUpdate(grid, Eigen::Vector3d::Zero(), &update);
    std::vector<Change> expected;
    update.forEachCell([&](const Eigen::Vector3i& g, float v) {
      const octomap::OcTreeKey key(g.x() + offset, g.y() + offset, g.z() + offset);
      const octomap::OcTreeNode* before = plain.search(key);
      const CellClass was = before ? classOfLogOdds(before->getLogOdds(), occupied) : CellClass::kUnknown;
      const float old = before ? before->getLogOdds() : 0.0f;
      const float now = plain.updateNode(key, v, true)->getLogOdds();
      clamped += before && now == old;
      const CellClass is = classOfLogOdds(now, occupied);
      if (is == was) return;
      flips += was != CellClass::kUnknown;
      expected.emplace_back(g.x(), g.y(), g.z(), static_cast<int>(is));
    });
    std::vector<Eigen::Vector3i> touched;
    if (pass == 3) {  // no log: the same values
      cache.add(update, &tree, offset, nullptr, &touched);
      continue;
    }
    log.changes.clear();
    log.max_changes = pass == 5 ? 10 : 1 << 20;  // the last pass's log overflows
    cache.add(update, &tree, offset, &log, &touched);
    std::vector<Change> changes;
    for (const CellClassChange& c : log.changes)
      changes.emplace_back(c.cell.x(), c.cell.y(), c.cell.z(), static_cast<int>(c.now));
    std::sort(expected.begin(), expected.end());
    std::sort(changes.begin(), changes.end());
    if (pass == 5) {  // the overflow said, and no more than ten changes kept, each a real one
      EXPECT_TRUE(log.overflowed);
      EXPECT_LE(changes.size(), 10u);
      EXPECT_TRUE(std::includes(expected.begin(), expected.end(), changes.begin(), changes.end()));
      continue;
    }
    EXPECT_FALSE(log.overflowed);
    ASSERT_EQ(changes, expected) << "pass " << pass;
  }
  EXPECT_GT(flips, 100u);    // cells that went from free to occupied or back
  EXPECT_GT(clamped, 100u);  // updates a clamped leaf did not take
  cache.writeBack(&tree, nullptr, nullptr);
  tree.updateInnerOccupancy();
  plain.updateInnerOccupancy();
  EXPECT_TRUE(fullTree(tree) == fullTree(plain));
}
