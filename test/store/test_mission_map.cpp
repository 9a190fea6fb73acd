#include <gtest/gtest.h>

#include <octomap/OcTree.h>
#include <sqlite3.h>

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <memory>
#include <sstream>
#include <string>
#include <thread>

#include "../core/octree_text.h"
#include "../core/single_cell.h"
#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/octomap_io.h"
#include "stereo_occupancy/store/mission_map.h"
#include "stereo_occupancy/store/tile_store.h"

using namespace stereo_occupancy;

namespace {
constexpr double kRes = 0.25;

/// A fresh database path (the file and its WAL removed).
std::string freshDatabase(const std::string& name) {
  const std::string path = ::testing::TempDir() + "/" + name + ".db";
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::remove((path + suffix).c_str());
  return path;
}

/// The whole file at @p path.
std::string fileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// An update that sets every cell of the box at @p origin_index of @p size
/// to @p log_odds, seen from its lower corner.
GridUpdate filledBox(const Eigen::Vector3i& origin_index, const Eigen::Vector3i& size, float log_odds) {
  GridUpdate u;
  u.resolution_m = kRes;
  u.origin_index = origin_index;
  u.size = size;
  u.W_sensor_origin = origin_index.cast<double>() * kRes;
  const uint32_t cells = static_cast<uint32_t>(size.prod());
  u.run_start = {0};
  u.run_length = {cells};
  u.log_odds.assign(cells, log_odds);
  return u;
}

/// Runs @p sql on the database at @p path with a connection of its own; false on an error.
bool runSql(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  bool ok = sqlite3_open(path.c_str(), &db) == SQLITE_OK &&
            sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr) == SQLITE_OK;
  sqlite3_close(db);
  return ok;
}

/// The first column of the first row @p sql gives, as an integer (-1: none or an error).
long long sqlNumber(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  sqlite3_stmt* stmt = nullptr;
  long long value = -1;
  if (sqlite3_open(path.c_str(), &db) == SQLITE_OK &&
      sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt, nullptr) == SQLITE_OK && sqlite3_step(stmt) == SQLITE_ROW)
    value = sqlite3_column_int64(stmt, 0);
  sqlite3_finalize(stmt);
  sqlite3_close(db);
  return value;
}

/// The message TileStore's constructor throws for @p path, or "".
std::string storeRefusal(const std::string& path, double resolution_m,
                         TileStore::Access access = TileStore::Access::kReadWrite) {
  try {
    TileStore store(path, resolution_m, access);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

/// One leaf filling @p tile (its node at kTileDepth) with @p log_odds.
MapAccumulator::Leaf tileLeaf(const MapAccumulator::TileIndex& tile, float log_odds) {
  MapAccumulator::Leaf leaf;
  const auto key = [&](int t) { return static_cast<octomap::key_type>(32768 + t * MapAccumulator::kTileCells); };
  leaf.key = octomap::OcTreeKey(key(tile.x()), key(tile.y()), key(tile.z()));
  leaf.depth = MapAccumulator::kTileDepth;
  leaf.log_odds = log_odds;
  return leaf;
}

/// Cells with positive log-odds in @p tree.
size_t occupiedLeaves(const octomap::OcTree& tree) {
  size_t n = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) n += it->getLogOdds() > 0.0f;
  return n;
}
}  // namespace

// Dropping a node deletes its subtree and the ancestors it leaves empty: the
// rest of the tree is node for node what it would be without it, and the
// tree's node count stays right.
TEST(AccumulatingOcTree, DropNodeLeavesTheRestAsIfItNeverWas) {
  AccumulatingOcTree tree(kRes), without(kRes);
  const int offset = static_cast<int>(tree.coordToKey(0.0));
  for (int i = 0; i < 300; ++i) {
    const octomap::OcTreeKey near(offset + i % 17, offset + i % 5, offset + i % 3);
    const octomap::OcTreeKey far(offset + 3000 + i % 11, offset - 700 + i % 7, offset + i % 2);
    tree.setLeaf(near, 16, 0.1f * (i % 9 - 4));
    tree.setLeaf(far, 16, 0.7f);
    without.setLeaf(near, 16, 0.1f * (i % 9 - 4));
  }
  tree.setLeaf(octomap::OcTreeKey(offset + 3060, offset - 650, offset + 40), 13, -1.0f);  // a coarse leaf too
  tree.updateInnerOccupancy();
  without.updateInnerOccupancy();
  const octomap::OcTreeKey far_tile(offset + 3000, offset - 700, offset);
  ASSERT_TRUE(tree.dropNode(far_tile, MapAccumulator::kTileDepth));
  tree.updateInnerOccupancy();
  EXPECT_TRUE(fullTree(tree) == fullTree(without)) << "the rest of the tree changed";
  EXPECT_EQ(tree.size(), tree.calcNumNodes());
  EXPECT_FALSE(tree.dropNode(far_tile, MapAccumulator::kTileDepth)) << "nothing is left there";
  ASSERT_TRUE(tree.dropNode(octomap::OcTreeKey(offset, offset, offset), MapAccumulator::kTileDepth));
  EXPECT_EQ(tree.size(), 0u);
  EXPECT_EQ(tree.getRoot(), nullptr);
}

// A flight that leaves its start, comes back, and leaves again: with a small
// window and a store, the whole mission's map is the map an unbounded
// accumulator builds from the same updates, node for node, while the live
// map holds only the window.
TEST(MissionMap, TilesGoToTheStoreAndComeBackUnchanged) {
  MapAccumulatorConfig windowed;
  windowed.max_extent_m = 40.0;
  MapAccumulatorConfig unbounded;
  unbounded.max_extent_m = 0.0;
  MissionMap mission(windowed);
  mission.attachStore(std::make_shared<TileStore>(freshDatabase("round_trip"), kRes));
  MapAccumulator reference(unbounded);
  auto fly = [&](int x0, float value) {
    for (int i = 0; i < 2 * static_cast<int>(MapAccumulator::kPruneOrigins); ++i) {
      const GridUpdate u = singleCell(Eigen::Vector3i(x0 + i % 40, i % 7, i % 3), value);
      ASSERT_TRUE(mission.integrate(u));
      ASSERT_TRUE(reference.integrate(u));
    }
  };
  fly(0, 0.85f);
  fly(4000, 0.4f);  // 1 km away
  const MaintainResult away = mission.maintain();
  EXPECT_GE(away.tiles_stored, 1u);
  EXPECT_EQ(mission.live().tree().search(0.1, 0.1, 0.1), nullptr) << "the start left RAM";
  fly(0, -0.4f);  // back: the stored tiles come back and take the new updates
  EXPECT_EQ(mission.maintain().tiles_stored, 1u) << "the far tile goes now";
  ASSERT_NE(mission.live().tree().search(0.1, 0.1, 0.1), nullptr);
  fly(-4000, 0.4f);
  mission.maintain();
  EXPECT_LT(mission.live().tree().getNumLeafNodes(), reference.tree().getNumLeafNodes() / 2);
  mission.checkpoint();
  ASSERT_TRUE(mission.store()->flush());
  const auto whole = MissionMap::assemble(*mission.store(), Eigen::AlignedBox3d());
  EXPECT_TRUE(fullTree(*whole) == fullTree(reference.tree())) << "the mission's map differs from the reference";
  // Written a tile at a time, the same files as the assembled tree gives;
  // with two tiles that are one leaf each (a free and an occupied one).
  for (const float value : {-1.0f, 2.0f}) {
    MapAccumulator::Leaf leaf;
    const int x = value > 0 ? 3 : -7;
    leaf.key = octomap::OcTreeKey(static_cast<octomap::key_type>(32768 + x * MapAccumulator::kTileCells), 32768, 32768);
    leaf.depth = MapAccumulator::kTileDepth;
    leaf.log_odds = value;
    mission.store()->put(MapAccumulator::TileIndex(x, 0, 0), {leaf});
  }
  ASSERT_TRUE(mission.store()->flush());
  const auto with_leaves = MissionMap::assemble(*mission.store(), Eigen::AlignedBox3d());
  for (const char* ext : {".bt", ".ot"}) {
    const std::string streamed = ::testing::TempDir() + "/streamed" + ext,
                      assembled = ::testing::TempDir() + "/assembled" + ext;
    MissionMap::writeStore(*mission.store(), streamed, windowed.occupancy_threshold_prob);
    writeOcTree(*with_leaves, assembled);
    EXPECT_TRUE(fileBytes(streamed) == fileBytes(assembled)) << ext << ": the streamed file differs";
    EXPECT_GT(fileBytes(streamed).size(), 1000u);
  }
  // A region of it: only the start.
  const auto start = MissionMap::assemble(*mission.store(),
                                          Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(11, 3, 2)));
  EXPECT_EQ(start->getNumLeafNodes(), 2 * MapAccumulator::kPruneOrigins);  // the first flight's cells, all distinct
}

// clear_bbx over the whole mission: occupied cells in a tile that went to
// the store are cleared there too, the tile goes back to the store (the live
// map stays the window), and cells outside the box keep their values.
TEST(MissionMap, ClearBoxReachesTheTilesOnDisk) {
  MapAccumulatorConfig windowed;
  windowed.max_extent_m = 40.0;
  MissionMap mission(windowed);
  mission.attachStore(std::make_shared<TileStore>(freshDatabase("clear_box"), kRes));
  auto fly = [&](int x0, float value) {
    for (int i = 0; i < 2 * static_cast<int>(MapAccumulator::kPruneOrigins); ++i)
      ASSERT_TRUE(mission.integrate(singleCell(Eigen::Vector3i(x0 + i % 40, i % 7, i % 3), value)));
  };
  fly(0, 2.0f);     // occupied cells at x in [0, 10) m
  fly(4000, 2.0f);  // 1 km away: the start goes to the store
  ASSERT_GE(mission.maintain().tiles_stored, 1u);
  ASSERT_EQ(mission.live().tree().search(0.1, 0.1, 0.1), nullptr);
  const size_t live_leaves = mission.live().tree().getNumLeafNodes();
  // x in [0, 5) m of the start (cells 0..19), and a stretch of the live map.
  const size_t cleared = mission.clearBox(Eigen::Vector3d(0.0, 0.0, 0.0), Eigen::Vector3d(4.99, 2.0, 1.0));
  const size_t half = MapAccumulator::kPruneOrigins;  // of the 200 distinct cells, x below 5 m
  EXPECT_EQ(cleared, half);
  EXPECT_EQ(mission.live().tree().search(0.1, 0.1, 0.1), nullptr) << "the cleared tile went back to the store";
  EXPECT_EQ(mission.live().tree().getNumLeafNodes(), live_leaves);
  EXPECT_EQ(mission.clearBox(Eigen::Vector3d(1000.0, 0.0, 0.0), Eigen::Vector3d(1004.99, 2.0, 1.0)), half);
  mission.checkpoint();
  ASSERT_TRUE(mission.store()->flush());
  const auto start = MissionMap::assemble(*mission.store(),
                                          Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(11, 3, 2)));
  EXPECT_EQ(start->getNumLeafNodes(), 2 * half);
  EXPECT_EQ(occupiedLeaves(*start), half) << "only x in [5, 10) m is left occupied";
  EXPECT_EQ(occupiedLeaves(mission.live().tree()), half) << "the live stretch: the same";
}

// A mission continued from its database, before the first update: there is
// no window yet, so a clear_bbx brings each tile it touches back only for
// the clear. One that finds nothing occupied leaves nothing in RAM (it left
// every tile there), one that clears puts the cleared tile back.
TEST(MissionMap, ClearBoxBeforeTheFirstUpdateLeavesNothingInRam) {
  MapAccumulatorConfig windowed;
  windowed.max_extent_m = 40.0;
  const std::string path = freshDatabase("clear_before_update");
  {
    MissionMap flown(windowed);
    flown.attachStore(std::make_shared<TileStore>(path, kRes));
    for (int i = 0; i < 2 * static_cast<int>(MapAccumulator::kPruneOrigins); ++i)
      ASSERT_TRUE(flown.integrate(singleCell(Eigen::Vector3i(i % 40, i % 7, i % 2), i % 2 ? 2.0f : -2.0f)));
    flown.checkpoint();
    ASSERT_TRUE(flown.store()->flush());
  }
  MissionMap continued(windowed);
  continued.attachStore(std::make_shared<TileStore>(path, kRes));
  ASSERT_FALSE(continued.store()->tiles().empty());
  // Free cells only (z index 0 holds the even i's, all free): nothing to clear.
  EXPECT_EQ(continued.clearBox(Eigen::Vector3d(-100.0, -100.0, 0.0), Eigen::Vector3d(100.0, 100.0, 0.2)), 0u);
  EXPECT_EQ(continued.live().tree().getNumLeafNodes(), 0u) << "tiles stayed in RAM after a clear that found nothing";
  EXPECT_TRUE(continued.live().tiles().empty());
  const size_t occupied =
      continued.clearBox(Eigen::Vector3d(-100.0, -100.0, -100.0), Eigen::Vector3d(100.0, 100.0, 100.0));
  EXPECT_EQ(occupied, MapAccumulator::kPruneOrigins);  // the odd i's: 100 distinct occupied cells
  EXPECT_EQ(continued.live().tree().getNumLeafNodes(), 0u);
  ASSERT_TRUE(continued.store()->flush());
  const auto stored = MissionMap::assemble(*continued.store(), Eigen::AlignedBox3d());
  EXPECT_EQ(occupiedLeaves(*stored), 0u) << "the cleared tile went back to the store cleared";
  size_t known = 0;  // every cell flown is still known (free now), merged leaves or not
  for (int i = 0; i < 2 * static_cast<int>(MapAccumulator::kPruneOrigins); ++i)
    known += stored->search((i % 40 + 0.5) * kRes, (i % 7 + 0.5) * kRes, (i % 2 + 0.5) * kRes) != nullptr;
  EXPECT_EQ(known, 2 * MapAccumulator::kPruneOrigins);
}

// maintain() merges the equal leaves of the tiles that changed: an 8-cell
// cube of clamped free space becomes one leaf, in RAM and in the store, and
// each cell keeps its value; with or without a store.
TEST(MissionMap, MaintainMergesEqualLeaves) {
  const GridUpdate cube = filledBox(Eigen::Vector3i(8, 8, 0), Eigen::Vector3i(8, 8, 8), -0.4f);
  for (const bool with_store : {false, true}) {
    MapAccumulatorConfig windowed;
    windowed.max_extent_m = 40.0;
    MissionMap mission(windowed);
    if (with_store) mission.attachStore(std::make_shared<TileStore>(freshDatabase("merge"), kRes));
    for (int r = 0; r < 6; ++r) ASSERT_TRUE(mission.integrate(cube));  // clamped at the lower bound
    ASSERT_EQ(mission.live().tree().getNumLeafNodes(), 512u);
    const MaintainResult first = mission.maintain();
    EXPECT_EQ(first.nodes_merged, 64u + 8u + 1u) << "store " << with_store;
    EXPECT_EQ(mission.live().tree().getNumLeafNodes(), 1u);
    const float clamped = mission.live().tree().getClampingThresMinLog();
    for (int i = 0; i < 512; ++i) {
      const Eigen::Vector3d p =
          (cube.origin_index + Eigen::Vector3i(i % 8, (i / 8) % 8, i / 64)).cast<double>() * kRes +
          Eigen::Vector3d::Constant(kRes / 2);
      const octomap::OcTreeNode* n = mission.live().tree().search(p.x(), p.y(), p.z());
      ASSERT_NE(n, nullptr);
      EXPECT_EQ(n->getLogOdds(), clamped);
    }
    EXPECT_EQ(mission.maintain().nodes_merged, 0u) << "nothing changed since";
    MapAccumulatorConfig uncompressed = windowed;
    uncompressed.compress_map = false;
    MissionMap plain(uncompressed);
    for (int r = 0; r < 6; ++r) ASSERT_TRUE(plain.integrate(cube));
    EXPECT_EQ(plain.maintain().nodes_merged, 0u);
    EXPECT_EQ(plain.live().tree().getNumLeafNodes(), 512u) << "compress_map false";
    if (!with_store) continue;
    // Away: the tile goes to the store as the one leaf.
    for (int i = 0; i < 2 * static_cast<int>(MapAccumulator::kPruneOrigins); ++i)
      ASSERT_TRUE(mission.integrate(singleCell(Eigen::Vector3i(4000 + i % 40, i % 7, i % 3), 0.4f)));
    EXPECT_GE(mission.maintain().tiles_stored, 1u);
    ASSERT_TRUE(mission.store()->flush());
    std::vector<MapAccumulator::Leaf> leaves;
    ASSERT_TRUE(mission.store()->get(MapAccumulator::TileIndex(0, 0, 0), &leaves));
    ASSERT_EQ(leaves.size(), 1u);
    EXPECT_EQ(leaves[0].depth, 13u);
    EXPECT_EQ(leaves[0].log_odds, clamped);
    // The whole mission's files read back with the merged leaf in them.
    const std::vector<std::string> paths = mission.saveWhole(::testing::TempDir(), "merged");
    for (const std::string& path : paths) {
      std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(path));
      octomap::OcTree binary(kRes);
      const bool bt = path.size() > 3 && path.compare(path.size() - 3, 3, ".bt") == 0;
      if (bt)
        ASSERT_TRUE(binary.readBinary(path)) << path;
      else
        ASSERT_NE(read, nullptr) << path;
      const octomap::OcTree& tree = bt ? binary : *dynamic_cast<octomap::OcTree*>(read.get());
      const octomap::OcTreeNode* n = tree.search(2.1, 2.1, 0.1);
      ASSERT_NE(n, nullptr) << path;
      EXPECT_FALSE(tree.isNodeOccupied(n)) << path;
      EXPECT_EQ(tree.getNumLeafNodes(), 1u + 2 * MapAccumulator::kPruneOrigins) << path;
    }
  }
}

namespace {
/// The tree's full (.ot) bytes.
std::string fullBytes(const octomap::OcTree& tree) {
  std::ostringstream out;
  tree.write(out);
  return out.str();
}

/// Clamped free space over two tiles, with occupied cells sprinkled in the
/// first, so that some nodes merge and some do not: 64 parts with children;
/// in the second tile, nodes above the parts merge too (32-cell cubes).
void flyOverTwoTiles(MissionMap* mission) {
  static_assert(MapAccumulator::kTileCells == 256, "the box straddles the first tile border");
  const GridUpdate box = filledBox(Eigen::Vector3i(192, 0, 0), Eigen::Vector3i(128, 64, 32), -0.4f);
  for (int r = 0; r < 6; ++r) ASSERT_TRUE(mission->integrate(box));
  for (int i = 0; i < 40; ++i)
    ASSERT_TRUE(mission->integrate(singleCell(Eigen::Vector3i(192 + (i * 37) % 64, (i * 11) % 64, i % 32), 2.0f)));
}
}  // namespace

// maintain(kSpread) merges nothing; mergeStep() then merges a part at a time,
// mergeSteps() calls at most (half the 46 updates before the maintain), and
// ends in the tree one maintain() makes.
TEST(MissionMap, SpreadMergesEndInTheTreeOfOneMerge) {
  MissionMap now{MapAccumulatorConfig()}, spread{MapAccumulatorConfig()};
  flyOverTwoTiles(&now);
  flyOverTwoTiles(&spread);
  const size_t leaves_before = spread.live().tree().getNumLeafNodes();
  const size_t merged_now = now.maintain().nodes_merged;
  ASSERT_GT(merged_now, 1000u);
  EXPECT_EQ(spread.maintain(MergeTiming::kSpread).nodes_merged, 0u);
  EXPECT_EQ(spread.live().tree().getNumLeafNodes(), leaves_before);
  ASSERT_TRUE(spread.mergesQueued());
  static_assert(MissionMap::kMergeShare == 2 && MissionMap::kMergeSteps == 16, "46 updates: 23 steps");
  ASSERT_EQ(spread.mergeSteps(), 23u);
  size_t steps = 0, merged = 0, largest = 0;
  while (spread.mergesQueued()) {
    const size_t step = spread.mergeStep().nodes_merged;
    merged += step;
    largest = std::max(largest, step);
    ASSERT_LE(++steps, spread.mergeSteps());
  }
  EXPECT_GT(steps, MissionMap::kMergeSteps) << "more steps than the fewest";
  EXPECT_LE(largest, merged_now / 8) << "the merges are spread";
  EXPECT_EQ(merged, merged_now);
  EXPECT_EQ(fullBytes(spread.live().tree()), fullBytes(now.live().tree()));
  EXPECT_EQ(spread.mergeStep().nodes_merged, 0u) << "nothing queued";
  // Three updates since that maintain: the fewest steps.
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(spread.integrate(singleCell(Eigen::Vector3i(200, i, 0), 2.0f)));
  spread.maintain(MergeTiming::kSpread);
  EXPECT_EQ(spread.mergeSteps(), MissionMap::kMergeSteps);
  // A reset map counts its updates afresh.
  flyOverTwoTiles(&spread);
  spread.reset();
  EXPECT_EQ(spread.mergeSteps(), 0u);
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(spread.integrate(singleCell(Eigen::Vector3i(200, i, 0), 2.0f)));
  spread.maintain(MergeTiming::kSpread);
  EXPECT_EQ(spread.mergeSteps(), MissionMap::kMergeSteps);
}

// The merges above the parts write back only the fusion's blocks below a
// node about to merge: a change below a node that cannot merge (the first
// tile's occupied cells) stays in the cache; one below a node that can (the
// second tile's free cubes) is written back first and keeps that node from
// merging. The tree then is the one the whole tiles written back first give.
TEST(MissionMap, MergesAboveThePartsWriteBackOnlyBelowNodesAboutToMerge) {
  MissionMap lazy{MapAccumulatorConfig()}, eager{MapAccumulatorConfig()};
  flyOverTwoTiles(&lazy);
  flyOverTwoTiles(&eager);
  const GridUpdate box = filledBox(Eigen::Vector3i(192, 0, 0), Eigen::Vector3i(128, 64, 32), -0.4f);
  const std::vector<MapAccumulator::TileIndex> tiles = lazy.live().tilesOf(box);
  ASSERT_EQ(tiles.size(), 2u);
  for (MissionMap* m : {&lazy, &eager})
    for (const auto& t : tiles)
      for (const auto& part : m->live().partsToMerge(t)) m->live().mergePart(part);
  ASSERT_EQ(lazy.live().unwrittenBlocks(), 0u) << "each part wrote its block back";
  const GridUpdate mixed = singleCell(Eigen::Vector3i(200, 3, 1), 2.0f);      // beside the first tile's occupied cells
  const GridUpdate uniform = singleCell(Eigen::Vector3i(300, 40, 20), 2.0f);  // in the second tile's free cubes
  for (MissionMap* m : {&lazy, &eager}) {
    ASSERT_TRUE(m->integrate(mixed));
    ASSERT_TRUE(m->integrate(uniform));
  }
  ASSERT_EQ(lazy.live().unwrittenBlocks(), 2u);
  eager.live().tree();  // every block written back
  size_t merged_lazy = 0, merged_eager = 0;
  for (const auto& t : tiles) {
    merged_lazy += lazy.live().mergeTileAbove(t);
    merged_eager += eager.live().mergeTileAbove(t);
  }
  EXPECT_EQ(lazy.live().unwrittenBlocks(), 1u) << "only the block below a node that could merge";
  EXPECT_GT(merged_lazy, 0u);
  EXPECT_EQ(merged_lazy, merged_eager);
  EXPECT_EQ(fullBytes(lazy.live().tree()), fullBytes(eager.live().tree()));
  const octomap::OcTreeNode* cell =
      lazy.live().tree().search(lazy.live().tree().coordToKey(300.5 * kRes, 40.5 * kRes, 20.5 * kRes));
  ASSERT_NE(cell, nullptr);
  EXPECT_GT(cell->getLogOdds(), 0.0f) << "the written-back change";
}

// As above, for nodes nearer the tile: two 64-cell cubes of free space
// (depth-10 nodes) whose lowest keys set bits 7 and 6, so that the child
// keys on their paths are not the first ones. The change in the second cube
// lies below nodes about to merge: found, written back, it keeps them from
// merging; the first cube merges into one leaf.
TEST(MissionMap, MergesAboveThePartsFindTheBlocksBelowEachNode) {
  MissionMap lazy{MapAccumulatorConfig()}, eager{MapAccumulatorConfig()};
  const GridUpdate cubes = filledBox(Eigen::Vector3i(128, 192, 192), Eigen::Vector3i(128, 64, 64), -0.4f);
  const std::vector<MapAccumulator::TileIndex> tiles = lazy.live().tilesOf(cubes);
  ASSERT_EQ(tiles.size(), 1u);
  for (MissionMap* m : {&lazy, &eager}) {
    ASSERT_TRUE(m->integrate(cubes));
    for (const auto& part : m->live().partsToMerge(tiles[0])) m->live().mergePart(part);
    ASSERT_TRUE(m->integrate(singleCell(Eigen::Vector3i(230, 250, 197), 2.0f)));
  }
  eager.live().tree();  // every block written back
  const size_t merged = lazy.live().mergeTileAbove(tiles[0]);
  EXPECT_EQ(merged, eager.live().mergeTileAbove(tiles[0]));
  EXPECT_EQ(merged, 9u + 7u) << "the first cube: 8 nodes of depth 11 and the cube; the second: 7 of its 8";
  EXPECT_EQ(fullBytes(lazy.live().tree()), fullBytes(eager.live().tree()));
}

// Updates fused between the steps keep their cells: every cell of a map that
// never merges has the same value in the map whose merges were spread.
TEST(MissionMap, SpreadMergesKeepEveryCellsValue) {
  MapAccumulatorConfig uncompressed;
  uncompressed.compress_map = false;
  MissionMap plain(uncompressed), spread{MapAccumulatorConfig()};
  flyOverTwoTiles(&plain);
  flyOverTwoTiles(&spread);
  EXPECT_EQ(plain.maintain(MergeTiming::kSpread).nodes_merged, 0u);
  EXPECT_FALSE(plain.mergesQueued()) << "compress_map false: nothing to merge";
  spread.maintain(MergeTiming::kSpread);
  // Stripes of occupied and free cells across merged and unmerged parts.
  for (int i = 0; spread.mergesQueued(); ++i) {
    spread.mergeStep();
    const GridUpdate stripe =
        filledBox(Eigen::Vector3i(192 + 8 * i, 2 * i, i % 32), Eigen::Vector3i(8, 30, 2), i % 2 ? 0.85f : -0.4f);
    ASSERT_TRUE(plain.integrate(stripe));
    ASSERT_TRUE(spread.integrate(stripe));
  }
  const octomap::OcTree& merged = spread.live().tree();
  EXPECT_LT(merged.getNumLeafNodes(), plain.live().tree().getNumLeafNodes() / 2);
  size_t cells = 0;
  for (auto it = plain.live().tree().begin_leafs(), end = plain.live().tree().end_leafs(); it != end; ++it) {
    ASSERT_EQ(it.getDepth(), 16u);
    const octomap::OcTreeNode* n = merged.search(it.getKey());
    ASSERT_NE(n, nullptr);
    ASSERT_EQ(n->getLogOdds(), it->getLogOdds());
    ++cells;
  }
  EXPECT_GT(cells, 250000u);
}

// A tile that goes to the store while its merges are queued is merged first,
// as one whose merges were done.
TEST(MissionMap, QueuedTileGoesToTheStoreMerged) {
  const GridUpdate cube = filledBox(Eigen::Vector3i(8, 8, 0), Eigen::Vector3i(8, 8, 8), -0.4f);
  MapAccumulatorConfig windowed;
  windowed.max_extent_m = 40.0;
  MissionMap mission(windowed);
  mission.attachStore(std::make_shared<TileStore>(freshDatabase("queued_merge"), kRes));
  for (int r = 0; r < 6; ++r) ASSERT_TRUE(mission.integrate(cube));
  EXPECT_EQ(mission.maintain(MergeTiming::kSpread).nodes_merged, 0u);
  ASSERT_TRUE(mission.mergesQueued());
  for (int i = 0; i < 2 * static_cast<int>(MapAccumulator::kPruneOrigins); ++i)
    ASSERT_TRUE(mission.integrate(singleCell(Eigen::Vector3i(4000 + i % 40, i % 7, i % 3), 0.4f)));
  const MaintainResult away = mission.maintain(MergeTiming::kSpread);
  EXPECT_GE(away.tiles_stored, 1u);
  EXPECT_EQ(away.nodes_merged, 64u + 8u + 1u);
  ASSERT_TRUE(mission.store()->flush());
  std::vector<MapAccumulator::Leaf> leaves;
  ASSERT_TRUE(mission.store()->get(MapAccumulator::TileIndex(0, 0, 0), &leaves));
  ASSERT_EQ(leaves.size(), 1u);
  EXPECT_EQ(leaves[0].depth, 13u);
}

// Merges that come after a checkpoint reach the store: the tiles stored
// when the vehicle leaves are the tiles of one merge. Each step's merged
// tile goes to the outputs; the last step asks for a heap trim; a reset
// empties the queue.
TEST(MissionMap, SpreadMergesAfterACheckpointReachTheStoreAndTheOutputs) {
  MapAccumulatorConfig windowed;
  windowed.max_extent_m = 40.0;
  MissionMap now{MapAccumulatorConfig()}, mission(windowed);
  mission.attachStore(std::make_shared<TileStore>(freshDatabase("spread_checkpoint"), kRes));
  flyOverTwoTiles(&now);
  flyOverTwoTiles(&mission);
  now.maintain();
  bool whole = false;
  mission.takeChangedTiles(false, &whole);  // the first: the whole map
  mission.maintain(MergeTiming::kSpread);
  mission.takeChangedTiles(false, &whole);  // the tiles the updates changed
  EXPECT_FALSE(mission.takeFreedMemory());
  ASSERT_GT(mission.mergeStep().nodes_merged, 0u);
  const std::vector<TileContent> changed = mission.takeChangedTiles(false, &whole);
  ASSERT_EQ(changed.size(), 1u) << "the tile the first step merged in";
  EXPECT_EQ(changed[0].leaves.size(), mission.live().tileLeaves(changed[0].tile).size());
  EXPECT_EQ(mission.checkpoint(), 2u);
  while (mission.mergesQueued()) {
    EXPECT_FALSE(mission.takeFreedMemory()) << "one trim, after the last step";
    mission.mergeStep();
  }
  EXPECT_TRUE(mission.takeFreedMemory());
  for (int i = 0; i < 2 * static_cast<int>(MapAccumulator::kPruneOrigins); ++i)
    ASSERT_TRUE(mission.integrate(singleCell(Eigen::Vector3i(4000 + i % 40, i % 7, i % 3), 0.4f)));
  EXPECT_EQ(mission.maintain(MergeTiming::kSpread).tiles_stored, 2u);
  ASSERT_TRUE(mission.store()->flush());
  for (int t = 0; t < 2; ++t) {
    std::vector<MapAccumulator::Leaf> stored;
    ASSERT_TRUE(mission.store()->get(MapAccumulator::TileIndex(t, 0, 0), &stored));
    EXPECT_EQ(stored.size(), now.live().tileLeaves(MapAccumulator::TileIndex(t, 0, 0)).size()) << "tile " << t;
  }
  ASSERT_TRUE(mission.mergesQueued()) << "the far cells' tile";
  mission.reset();
  EXPECT_FALSE(mission.mergesQueued());
}

// A tile's leaves after merging are its own: octomap's box iterator also
// hands out the merged leaves of the tile next to it, which a tile row must
// not carry (the whole mission's files were unreadable with them).
TEST(MissionMap, MergedTilesKeepTheirOwnLeaves) {
  // 16 x 8 x 8 cells across the border of tiles 0 and 1 (x = 256 cells, 64 m).
  static_assert(MapAccumulator::kTileCells == 256, "the cube straddles the first tile border");
  const GridUpdate cube = filledBox(Eigen::Vector3i(248, 0, 0), Eigen::Vector3i(16, 8, 8), -0.4f);
  MissionMap mission{MapAccumulatorConfig()};
  for (int r = 0; r < 6; ++r) ASSERT_TRUE(mission.integrate(cube));
  ASSERT_GT(mission.maintain().nodes_merged, 0u);
  ASSERT_EQ(mission.live().tree().getNumLeafNodes(), 2u);  // one 8-cell leaf on each side
  const int offset = static_cast<int>(mission.live().tree().coordToKey(0.0));
  for (int t = 0; t < 2; ++t) {
    const std::vector<MapAccumulator::Leaf> leaves = mission.live().tileLeaves(MapAccumulator::TileIndex(t, 0, 0));
    ASSERT_EQ(leaves.size(), 1u) << "tile " << t;
    const int x = static_cast<int>(leaves[0].key[0]) - offset;
    EXPECT_GE(x, t * MapAccumulator::kTileCells) << "tile " << t;
    EXPECT_LT(x, (t + 1) * MapAccumulator::kTileCells) << "tile " << t;
  }
}

// One process per database; a database of another resolution or not of this
// format is refused with a reason, not overwritten.
TEST(TileStore, RefusesASecondOpenerAndAnotherResolution) {
  const std::string path = freshDatabase("lock");
  {
    TileStore first(path, kRes);
    try {
      TileStore second(path, kRes);
      FAIL() << "a second store opened a locked database";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("locked"), std::string::npos) << e.what();
    }
  }
  try {
    TileStore coarse(path, 0.5);
    FAIL() << "a 0.5 m store opened a 0.25 m database";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("0.25"), std::string::npos) << e.what();
  }
  const std::string text = ::testing::TempDir() + "/not_a_database.db";
  {
    FILE* f = std::fopen(text.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs("this is not a database, it is a text file with enough words to fill a page header", f);
    std::fclose(f);
  }
  EXPECT_THROW(TileStore(text, kRes), std::runtime_error);
  TileStore reopened(path, kRes);  // the first closed: open again
  EXPECT_TRUE(reopened.tiles().empty());
}

// kill -9 in mid-flight, several times at different moments: the database
// opens again (the lock goes with the process), holds every update up to the
// last checkpoint the flight reported, and takes new tiles.
TEST(MissionMap, KillNineLosesOnlyWhatCameAfterTheLastCheckpoint) {
  constexpr int kCheckpointEvery = 500;  // updates
  constexpr int kMaxUpdates = 30000;     // 7.5 km of cells along x: inside the key range
  for (int trial = 0; trial < 3; ++trial) {
    const std::string path = freshDatabase("kill9");
    int report[2];
    ASSERT_EQ(pipe(report), 0);
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      close(report[0]);
      MapAccumulatorConfig config;
      config.max_extent_m = 30.0;  // tiles leave RAM as the flight goes on
      MissionMap mission(config);
      mission.attachStore(std::make_shared<TileStore>(path, kRes));
      for (int i = 0; i < kMaxUpdates; ++i) {
        mission.integrate(singleCell(Eigen::Vector3i(i, (i * 7) % 50, 0), 2.0f));  // a new cell each time
        if (i % 100 == 99) mission.maintain();
        if (i % kCheckpointEvery == kCheckpointEvery - 1) {
          mission.checkpoint();
          if (!mission.store()->flush()) _exit(3);
          if (write(report[1], &i, sizeof i) != sizeof i) _exit(4);
        }
      }
      pause();  // wait for the kill
      _exit(0);
    }
    close(report[1]);
    int last = -1, reported = 0;
    while (reported < 3 + trial && read(report[0], &last, sizeof last) == sizeof last) ++reported;
    ASSERT_EQ(reported, 3 + trial) << "the flight stopped early";
    std::this_thread::sleep_for(std::chrono::microseconds(700 * trial));  // lands at another point each trial
    ASSERT_EQ(kill(child, SIGKILL), 0);
    int status = 0;
    ASSERT_EQ(waitpid(child, &status, 0), child);
    ASSERT_TRUE(WIFSIGNALED(status)) << "the flight ended before the kill";
    int later = 0;
    while (read(report[0], &later, sizeof later) == sizeof later) last = later;  // checkpoints before the kill
    close(report[0]);

    TileStore reopened(path, kRes);
    const auto whole = MissionMap::assemble(reopened, Eigen::AlignedBox3d());
    for (int i = 0; i <= last; ++i) {
      const octomap::OcTreeKey key(static_cast<octomap::key_type>(i + 32768),
                                   static_cast<octomap::key_type>((i * 7) % 50 + 32768), 32768);
      const octomap::OcTreeNode* n = whole->search(key);
      ASSERT_TRUE(n && n->getLogOdds() > 0.0f)
          << "trial " << trial << ": update " << i << " of " << last << " (checkpointed) is missing";
    }
    EXPECT_GE(occupiedLeaves(*whole), static_cast<size_t>(last + 1));
    reopened.put(MapAccumulator::TileIndex(100, 100, 0), {MapAccumulator::Leaf{}});
    EXPECT_TRUE(reopened.flush()) << reopened.status().last_error;
  }
}

// A full disk (here: a file size limit) fails the write with the reason and
// loses nothing: the tile stays queued, get() still returns it, and it is
// written once there is room again.
TEST(TileStore, AFullDiskIsAnErrorAndLosesNothing) {
  const std::string path = freshDatabase("full");
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    signal(SIGXFSZ, SIG_IGN);  // a write past the limit fails with EFBIG instead of killing
    int code = 0;
    {
      TileStore store(path, kRes);
      std::vector<MapAccumulator::Leaf> leaves;
      for (int i = 0; i < 40000; ++i) {
        MapAccumulator::Leaf leaf;
        leaf.key = octomap::OcTreeKey(static_cast<octomap::key_type>(32768 + i % 200),
                                      static_cast<octomap::key_type>(32768 + i / 200), 32768);
        leaf.log_odds = 0.5f;
        leaves.push_back(leaf);
      }
      rlimit limit{};
      getrlimit(RLIMIT_FSIZE, &limit);
      const rlim_t unlimited = limit.rlim_cur;
      limit.rlim_cur = 64 * 1024;  // far less than the tile
      setrlimit(RLIMIT_FSIZE, &limit);
      store.put(MapAccumulator::TileIndex(0, 0, 0), leaves);
      std::vector<MapAccumulator::Leaf> back;
      if (store.flush())
        code = 10;  // the write must fail
      else if (store.status().last_error.empty())
        code = 11;  // with a reason
      else if (!store.get(MapAccumulator::TileIndex(0, 0, 0), &back) || back.size() != leaves.size())
        code = 12;
      limit.rlim_cur = unlimited;
      setrlimit(RLIMIT_FSIZE, &limit);
      if (code == 0 && !store.flush()) code = 13;  // room again: written
      if (code == 0 && store.status().queued != 0) code = 14;
    }
    if (code == 0) {
      TileStore reopened(path, kRes);
      std::vector<MapAccumulator::Leaf> back;
      if (!reopened.get(MapAccumulator::TileIndex(0, 0, 0), &back) || back.size() != 40000u) code = 15;
    }
    _exit(code);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "10: a write past the limit succeeded, 11: no reason, 12: the tile was "
                                       "lost, 13/14: not written once there was room, 15: not there after reopening";
}

// Damaged rows (2 MB and 50 kB of 0xff, on which OctoMap's reader overflowed
// its stack or grew to gigabytes, and a row cut short) are moved to
// damaged_tiles when the store opens: the other tiles stay, their tiles start
// empty, the whole mission saves, and a read-only opener refuses the file.
TEST(TileStore, DamagedRowsAreSetAsideAndTheRestIsKept) {
  const std::string path = freshDatabase("damaged");
  {
    TileStore store(path, kRes);
    for (int x = 0; x < 4; ++x) store.put(MapAccumulator::TileIndex(x, 0, 0), {tileLeaf({x, 0, 0}, 2.0f)});
    ASSERT_TRUE(store.flush());
  }
  ASSERT_TRUE(runSql(path,
                     "UPDATE tiles SET octree = zeroblob(2097152) WHERE x = 1; "
                     "UPDATE tiles SET octree = zeroblob(51200) WHERE x = 3; "
                     "UPDATE tiles SET octree = substr(octree, 1, length(octree) - 5) WHERE x = 2"));
  // zeroblob() gives zeros; 0xff is what the damage was.
  ASSERT_TRUE(
      runSql(path, "UPDATE tiles SET octree = CAST(replace(hex(octree), '00', 'FF') AS BLOB) WHERE x IN (1, 3)"));
  ASSERT_TRUE(runSql(path, "UPDATE tiles SET octree = unhex(octree) WHERE x IN (1, 3)") ||
              runSql(path, "SELECT 1"));  // unhex() is SQLite 3.41+; the hex text is damage too
  EXPECT_NE(storeRefusal(path, 0.0, TileStore::Access::kReadOnly).find("3 damaged tile rows"), std::string::npos)
      << storeRefusal(path, 0.0, TileStore::Access::kReadOnly);
  {
    TileStore store(path, kRes);
    EXPECT_EQ(store.status().damaged_rows, 3u);
    EXPECT_NE(store.status().first_damage.find("tile ("), std::string::npos) << store.status().first_damage;
    const auto tiles = store.tiles();
    ASSERT_EQ(tiles.size(), 1u);
    EXPECT_EQ(tiles[0], MapAccumulator::TileIndex(0, 0, 0));
    std::vector<MapAccumulator::Leaf> leaves;
    ASSERT_TRUE(store.get(tiles[0], &leaves));
    EXPECT_EQ(leaves.size(), 1u);
    const auto paths = MissionMap::saveStore(store, ::testing::TempDir(), "damaged", 0.5);
    const auto saved = readOcTreeFile(paths[1]);
    EXPECT_EQ(saved->getNumLeafNodes(), 1u);
    // A row found damaged later is set aside the same way.
    store.setAside(tiles[0], "damaged later");
    EXPECT_TRUE(store.tiles().empty());
    EXPECT_FALSE(store.get(tiles[0], &leaves));
    EXPECT_EQ(store.status().damaged_rows, 4u);
  }
  EXPECT_EQ(sqlNumber(path, "SELECT count(*) FROM damaged_tiles"), 4);
  EXPECT_EQ(sqlNumber(path, "SELECT length(octree) FROM damaged_tiles WHERE x = 1") > 50000, true);
  EXPECT_EQ(sqlNumber(path, "SELECT count(*) FROM tiles"), 0);
}

// Another program's SQLite file is refused and left byte for byte as it was;
// a meta entry that is NULL or no number is refused by name, and the refused
// file is not left locked. A read-only opener never writes (a 0-byte file stays 0 bytes).
TEST(TileStore, ForeignFilesAndBadMetaAreRefusedUnchanged) {
  const std::string foreign = freshDatabase("foreign");
  ASSERT_TRUE(runSql(foreign, "CREATE TABLE users (name TEXT); INSERT INTO users VALUES ('pilot')"));
  const std::string before = fileBytes(foreign);
  EXPECT_NE(storeRefusal(foreign, kRes).find("not a tile database (its tables: users)"), std::string::npos)
      << storeRefusal(foreign, kRes);
  EXPECT_TRUE(fileBytes(foreign) == before) << "the foreign file was changed";
  EXPECT_THROW(TileStore::removeDatabase(foreign), std::runtime_error);
  EXPECT_TRUE(fileBytes(foreign) == before);

  const std::string bad_meta = freshDatabase("bad_meta");
  const std::string tables = "CREATE TABLE meta (key TEXT, value TEXT); CREATE TABLE tiles (x INTEGER);";
  ASSERT_TRUE(runSql(bad_meta, tables + "INSERT INTO meta VALUES ('format', NULL)"));
  EXPECT_NE(storeRefusal(bad_meta, kRes).find("NULL value"), std::string::npos) << storeRefusal(bad_meta, kRes);
  EXPECT_TRUE(runSql(bad_meta, "BEGIN EXCLUSIVE; COMMIT")) << "the refused database stayed locked";
  for (const std::string resolution : {"'abc'", "'0'", "'-1'", "'inf'", "NULL"}) {
    const std::string path = freshDatabase("bad_resolution");
    ASSERT_TRUE(runSql(path, tables +
                                 "INSERT INTO meta VALUES ('format', 'stereo_occupancy tiles 1'), "
                                 "('resolution_m', " +
                                 resolution + ")"));
    const std::string why = storeRefusal(path, 0.0, TileStore::Access::kReadOnly);
    EXPECT_TRUE(why.find("not a positive number") != std::string::npos || why.find("NULL") != std::string::npos)
        << resolution << ": " << why;
    EXPECT_NE(why.find(path), std::string::npos) << why;
  }
  const std::string empty = freshDatabase("empty");
  std::ofstream(empty).close();
  EXPECT_NE(storeRefusal(empty, 0.0, TileStore::Access::kReadOnly).find("not a tile database"), std::string::npos);
  EXPECT_EQ(fileBytes(empty).size(), 0u);
}

// bag_to_map replaces its output's database only through removeDatabase: a
// database an accumulator holds is refused (and stays), an unheld one goes.
TEST(TileStore, RemoveDatabaseHonoursTheLock) {
  const std::string path = freshDatabase("remove");
  {
    TileStore store(path, kRes);
    store.put(MapAccumulator::TileIndex(0, 0, 0), {tileLeaf({0, 0, 0}, 1.0f)});
    ASSERT_TRUE(store.flush());
    try {
      TileStore::removeDatabase(path);
      ADD_FAILURE() << "a held database was removed";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("locked"), std::string::npos) << e.what();
    }
    EXPECT_TRUE(std::ifstream(path).good());
    std::vector<MapAccumulator::Leaf> leaves;
    EXPECT_TRUE(store.get(MapAccumulator::TileIndex(0, 0, 0), &leaves));
  }
  TileStore::removeDatabase(path);
  for (const char* suffix : {"", "-wal", "-shm"}) EXPECT_FALSE(std::ifstream(path + suffix).good()) << suffix;
  TileStore::removeDatabase(path);  // none: nothing to do
}

namespace {
void copyFile(const std::string& from, const std::string& to) {
  std::ofstream(to, std::ios::binary | std::ios::trunc) << fileBytes(from);
}
}  // namespace

// A -wal file that another mission left beside a database is refused, and
// nothing is changed (SQLite would have replayed it: 32 648 of 66 049
// occupied cells lost); the database's own log, left by a kill -9, is
// replayed as before, and with the foreign log moved away the database opens
// as it was last written whole.
TEST(TileStore, AnotherMissionsWalIsRefusedAndItsOwnIsReplayed) {
  const std::string a = freshDatabase("wal_a"), b = freshDatabase("wal_b"), crashed = freshDatabase("wal_crashed");
  const std::string foreign_log = ::testing::TempDir() + "/wal_a_log";
  {
    TileStore mission_a(a, kRes);
    for (int x = 0; x < 3; ++x) mission_a.put(MapAccumulator::TileIndex(x, 0, 0), {tileLeaf({x, 0, 0}, 2.0f)});
    ASSERT_TRUE(mission_a.flush());
    // As a kill -9 leaves them: the database and its log, mid-mission.
    copyFile(a + "-wal", foreign_log);
    copyFile(a, crashed);
    copyFile(a + "-wal", crashed + "-wal");
  }
  {
    TileStore mission_b(b, kRes);
    mission_b.put(MapAccumulator::TileIndex(7, 0, 0), {tileLeaf({7, 0, 0}, -2.0f)});
    ASSERT_TRUE(mission_b.flush());
  }
  ASSERT_FALSE(std::ifstream(b + "-wal").good()) << "a clean close checkpoints and removes the log";
  const std::string b_before = fileBytes(b);
  copyFile(foreign_log, b + "-wal");
  const std::string why = storeRefusal(b, kRes);
  EXPECT_NE(why.find("its -wal file belongs to another database"), std::string::npos) << why;
  EXPECT_TRUE(fileBytes(b) == b_before) << "the foreign log was written into the database";
  EXPECT_TRUE(fileBytes(b + "-wal") == fileBytes(foreign_log)) << "the foreign log was changed";
  EXPECT_NE(storeRefusal(b, 0.0, TileStore::Access::kReadOnly).find("belongs to another database"), std::string::npos);
  std::remove((b + "-wal").c_str());
  {
    TileStore mission_b(b, kRes);
    const auto tiles = mission_b.tiles();
    ASSERT_EQ(tiles.size(), 1u);
    EXPECT_EQ(tiles[0], MapAccumulator::TileIndex(7, 0, 0));
  }
  TileStore recovered(crashed, kRes);  // its own log: replayed
  EXPECT_EQ(recovered.tiles().size(), 3u);
}
