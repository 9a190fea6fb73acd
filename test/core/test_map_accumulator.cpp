#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <thread>
#include <vector>

#include "octree_text.h"
#include "single_cell.h"
#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "stereo_occupancy/sim/synthetic_scene.h"

using namespace stereo_occupancy;

namespace {
double logit(double p) { return std::log(p / (1.0 - p)); }

/// Integrates the Table I image, drawn with @p algorithm, into @p map.
void integrateTable1Image(DrawingAlgorithm algorithm, MapAccumulator* map) {
  StereoCameraConfig camera;
  Eigen::Isometry3d T;
  const cv::Mat image = table1Image(StereoCameraModel(camera), &T);
  DrawingConfig drawing;
  drawing.algorithm = algorithm;
  DisparityDrawer drawer(camera, drawing);
  LocalGrid grid;
  drawer.draw(image, T, &grid);
  GridUpdate update;
  encodeGridUpdate(grid, T.translation(), &update);
  ASSERT_TRUE(map->integrate(update));
}

/// The updates of @p frames of @p scenario, drawn with line_pyramid at @p resolution_m.
std::vector<GridUpdate> flightUpdates(const FlightScenario& scenario, const std::vector<size_t>& frames,
                                      double resolution_m = 0.25) {
  DrawingConfig drawing;
  drawing.algorithm = DrawingAlgorithm::kLinePyramid;
  drawing.resolution_m = resolution_m;
  DisparityDrawer drawer(scenario.camera, drawing);
  std::vector<GridUpdate> updates;
  for (size_t frame : frames) {
    const Eigen::Isometry3d T = scenario.cameraPose(frame);
    LocalGrid grid;
    drawer.draw(renderStereoFrame(scenario, frame, 1), T, &grid);
    updates.emplace_back();
    encodeGridUpdate(grid, T.translation(), &updates.back());
  }
  return updates;
}

/// Sets every cell of the key-aligned cube of @p edge cells that holds
/// @p W_near in @p tree to @p log_odds; returns the cube's first global cell.
Eigen::Vector3i setCube(octomap::OcTree* tree, int edge, const Eigen::Vector3d& W_near, float log_odds) {
  const int offset = static_cast<int>(tree->coordToKey(0.0));
  const Eigen::Vector3i first = (W_near / (tree->getResolution() * edge)).array().floor().cast<int>() * edge;
  for (int z = 0; z < edge; ++z)
    for (int y = 0; y < edge; ++y)
      for (int x = 0; x < edge; ++x) {
        const Eigen::Vector3i g = first + Eigen::Vector3i(x, y, z);
        tree->setNodeValue(octomap::OcTreeKey(g.x() + offset, g.y() + offset, g.z() + offset), log_odds);
      }
  return first;
}
}  // namespace

// OcTree keys run from 0 to 65535 (global index -32768 .. 32767 at depth
// 16); an update whose box leaves them is refused whole, the others are kept.
TEST(MapAccumulator, RefusesBoxesBeyondTheKeyRange) {
  MapAccumulator map(MapAccumulatorConfig{});
  const int kFirst = -32768, kLast = 32767;
  const Eigen::Vector3i kept[] = {{kFirst, 0, 0}, {kLast, kLast, kLast}, {0, kFirst, kLast}};
  const Eigen::Vector3i refused[] = {{kFirst - 1, 0, 0}, {0, kLast + 1, 0}, {0, 0, kFirst - 1}, {1 << 30, 0, 0}};
  for (const auto& g : kept) ASSERT_TRUE(map.integrate(singleCell(g, 1.0f)));
  std::string why;
  for (const auto& g : refused) {
    EXPECT_FALSE(map.integrate(singleCell(g, 1.0f), &why)) << g.transpose();
    EXPECT_NE(why.find("key range"), std::string::npos) << why;
  }
  // A box inside the range at its origin but reaching past its end.
  GridUpdate reaching = singleCell(Eigen::Vector3i(kLast, 0, 0), 1.0f);
  reaching.size.x() = 2;
  EXPECT_FALSE(map.integrate(reaching, &why));
  size_t leaves = 0;
  for (auto it = map.tree().begin_leafs(), end = map.tree().end_leafs(); it != end; ++it) {
    ++leaves;
    const octomap::OcTreeKey k = it.getKey();
    const Eigen::Vector3i g(k[0] - 32768, k[1] - 32768, k[2] - 32768);
    EXPECT_TRUE(g == kept[0] || g == kept[1] || g == kept[2]) << g.transpose();
    EXPECT_NEAR(it->getLogOdds(), 1.0f, 1e-6);
  }
  EXPECT_EQ(leaves, 3u);
  EXPECT_EQ(map.updates(), 3u);
}

TEST(MapAccumulator, AddsLogOddsWithClamping) {
  MapAccumulatorConfig cfg;
  MapAccumulator map(cfg);
  const Eigen::Vector3i g(-7, 3, 12);
  for (int i = 0; i < 2; ++i) ASSERT_TRUE(map.integrate(singleCell(g, 0.6f)));
  const octomap::point3d centre((g.x() + 0.5) * 0.25, (g.y() + 0.5) * 0.25, (g.z() + 0.5) * 0.25);
  const octomap::OcTreeNode* node = map.tree().search(centre);
  ASSERT_NE(node, nullptr);
  EXPECT_NEAR(node->getLogOdds(), 1.2f, 1e-5);
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(map.integrate(singleCell(g, 0.6f)));
  EXPECT_NEAR(map.tree().search(centre)->getLogOdds(), logit(0.97), 1e-4);  // clamped at clamping_max_prob
  for (int i = 0; i < 40; ++i) ASSERT_TRUE(map.integrate(singleCell(g, -0.6f)));
  EXPECT_NEAR(map.tree().search(centre)->getLogOdds(), logit(0.12), 1e-4);
  EXPECT_EQ(map.updates(), 62u);
  map.reset();
  EXPECT_EQ(map.tree().size(), 0u);
  EXPECT_EQ(map.updates(), 0u);
}

TEST(MapAccumulator, RefusesOtherResolutionsAndBrokenUpdates) {
  MapAccumulator map(MapAccumulatorConfig{});
  std::string why;
  EXPECT_FALSE(map.integrate(singleCell(Eigen::Vector3i(0, 0, 0), 1.0f, 0.5), &why));
  EXPECT_NE(why.find("resolution"), std::string::npos);
  GridUpdate broken = singleCell(Eigen::Vector3i(0, 0, 0), 1.0f);
  broken.log_odds.push_back(2.0f);
  EXPECT_FALSE(map.integrate(broken, &why));
  EXPECT_EQ(map.tree().size(), 0u);
  EXPECT_EQ(map.updates(), 0u);
}

TEST(MapAccumulator, PruneKeepsTheMapWithinItsExtent) {
  MapAccumulatorConfig cfg;
  cfg.max_extent_m = 10.0;
  MapAccumulator map(cfg);
  ASSERT_TRUE(map.integrate(singleCell(Eigen::Vector3i(0, 0, 0), 1.0f)));
  ASSERT_TRUE(map.integrate(singleCell(Eigen::Vector3i(200, 0, 0), 1.0f)));  // seen from 50 m away
  EXPECT_EQ(map.prune(), 0u);                                                // both near a recent origin
  // The vehicle stays near the origin for kPruneOrigins updates: the cell
  // at 50 m goes, the ones near it stay.
  GridUpdate near = singleCell(Eigen::Vector3i(4, 0, 0), 1.0f);
  near.W_sensor_origin = Eigen::Vector3d(1.0, 0.0, 0.0);
  for (size_t i = 0; i < MapAccumulator::kPruneOrigins; ++i) ASSERT_TRUE(map.integrate(near));
  bool all = false;
  map.takeChangedBlocks(&all);
  EXPECT_EQ(map.prune(), 1u);
  EXPECT_EQ(map.tree().search(50.1, 0.1, 0.1), nullptr);
  EXPECT_NE(map.tree().search(0.1, 0.1, 0.1), nullptr);
  EXPECT_EQ(map.tree().getNumLeafNodes(), 2u);
  // The outputs delete the dropped cell's block and republish nothing else.
  const std::vector<MapAccumulator::BlockIndex> changed = map.takeChangedBlocks(&all);
  EXPECT_FALSE(all);
  ASSERT_EQ(changed.size(), 1u);
  EXPECT_EQ(changed[0], Eigen::Vector3i(12, 0, 0));  // cell 200 / 16
}

namespace {
/// Whether one of @p regions holds the cell @p g.
bool inRegions(const std::vector<CellBox>& regions, const Eigen::Vector3i& g) {
  for (const CellBox& r : regions)
    if (r.contains(g)) return true;
  return false;
}
}  // namespace

// What changes the map besides integrate() reports where (for the distance
// field, which reads only those regions again): a prune the space outside
// the box it kept, a dropped or loaded tile its box, a cleared box itself;
// the class changes of updates before them are kept. A reset, and too many
// regions, say all; the old call says all for any region.
TEST(MapAccumulator, ClassChangeRegionsSayWhereTheMapChangedOtherwise) {
  MapAccumulatorConfig cfg;
  cfg.max_extent_m = 10.0;
  MapAccumulator map(cfg);
  map.recordClassChanges(true);
  bool all = false;
  std::vector<CellBox> regions;
  map.takeClassChanges(&all, &regions);
  EXPECT_TRUE(all);
  ASSERT_TRUE(map.integrate(singleCell(Eigen::Vector3i(200, 0, 0), 1.0f)));  // 50 m away, pruned below
  GridUpdate near = singleCell(Eigen::Vector3i(4, 0, 0), 1.0f);
  near.W_sensor_origin = Eigen::Vector3d(1.0, 0.0, 0.0);
  for (size_t i = 0; i < MapAccumulator::kPruneOrigins; ++i) ASSERT_TRUE(map.integrate(near));
  map.takeClassChanges(&all, &regions);
  ASSERT_TRUE(map.integrate(singleCell(Eigen::Vector3i(0, 0, 0), 1.0f)));  // a change before the prune
  ASSERT_EQ(map.prune(), 1u);
  std::vector<CellClassChange> changes = map.takeClassChanges(&all, &regions);
  EXPECT_FALSE(all);
  ASSERT_EQ(changes.size(), 1u);
  EXPECT_EQ(changes[0].cell, Eigen::Vector3i(0, 0, 0));
  EXPECT_EQ(regions.size(), 6u);  // the slabs around the kept box
  EXPECT_TRUE(inRegions(regions, Eigen::Vector3i(200, 0, 0)));
  EXPECT_TRUE(inRegions(regions, Eigen::Vector3i(0, 0, -200)));
  for (const Eigen::Vector3i& kept : {Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(4, 0, 0), Eigen::Vector3i(30, 30, 30)})
    EXPECT_FALSE(inRegions(regions, kept)) << kept.transpose();
  // A tile dropped and loaded again.
  const MapAccumulator::TileIndex tile(0, 0, 0);
  const std::vector<MapAccumulator::Leaf> leaves = map.tileLeaves(tile);
  ASSERT_EQ(leaves.size(), 2u);
  ASSERT_EQ(map.dropTile(tile), 2u);
  changes = map.takeClassChanges(&all, &regions);
  EXPECT_FALSE(all);
  EXPECT_TRUE(changes.empty());
  ASSERT_EQ(regions.size(), 1u);
  EXPECT_EQ(regions[0].min(), Eigen::Vector3i::Zero());
  EXPECT_EQ(regions[0].max(), Eigen::Vector3i::Constant(MapAccumulator::kTileCells - 1));
  map.insertLeaves(leaves);
  map.takeClassChanges(&all, &regions);
  ASSERT_EQ(regions.size(), 1u);
  EXPECT_EQ(regions[0].min(), Eigen::Vector3i::Zero());  // the leaves' bounding box
  EXPECT_EQ(regions[0].max(), Eigen::Vector3i(4, 0, 0));
  // A cleared box: its cells.
  EXPECT_EQ(map.clearBox(Eigen::Vector3d(0.9, -0.1, -0.1), Eigen::Vector3d(1.1, 0.1, 0.1)), 1u);
  map.takeClassChanges(&all, &regions);
  ASSERT_EQ(regions.size(), 1u);
  EXPECT_TRUE(regions[0].contains(Eigen::Vector3i(4, 0, 0)));
  EXPECT_FALSE(regions[0].contains(Eigen::Vector3i(0, 0, 0)));
  // The old call: all for a region.
  ASSERT_EQ(map.dropTile(tile), 2u);
  EXPECT_TRUE(map.takeClassChanges(&all).empty());
  EXPECT_TRUE(all);
  // Too many regions give way to all.
  for (size_t i = 0; i <= MapAccumulator::kMaxClassRegions / 2; ++i) {
    map.insertLeaves(leaves);
    ASSERT_EQ(map.dropTile(tile), 2u);
  }
  EXPECT_TRUE(map.takeClassChanges(&all, &regions).empty());
  EXPECT_TRUE(all);
  EXPECT_TRUE(regions.empty());
  map.insertLeaves(leaves);
  map.reset();
  map.takeClassChanges(&all, &regions);
  EXPECT_TRUE(all);
  EXPECT_TRUE(regions.empty());
}

// One update far away (an empty one, or one cell 5 km off with its origin
// beside it) cannot make prune() drop the map the vehicle is in.
TEST(MapAccumulator, OneFarUpdateDoesNotPruneTheMap) {
  MapAccumulatorConfig cfg;
  cfg.max_extent_m = 100.0;
  MapAccumulator map(cfg);
  GridUpdate here = singleCell(Eigen::Vector3i(8, 8, 8), 1.0f);
  for (int i = 0; i < 64; ++i) {
    here.origin_index.x() = 8 + i;
    here.W_sensor_origin.x() = (8 + i + 0.5) * 0.25;
    ASSERT_TRUE(map.integrate(here));
  }
  // An empty update whose origin is 10^6 m from its (empty) box: refused.
  GridUpdate empty;
  empty.resolution_m = 0.25;
  empty.W_sensor_origin = Eigen::Vector3d(1e6, 0.0, 0.0);
  std::string why;
  EXPECT_FALSE(map.integrate(empty, &why));
  EXPECT_NE(why.find("sensor origin"), std::string::npos) << why;
  // A well-formed update 5 km away: taken, but the map near the vehicle stays.
  ASSERT_TRUE(map.integrate(singleCell(Eigen::Vector3i(20000, 0, 0), 1.0f)));
  EXPECT_EQ(map.prune(), 0u);
  EXPECT_EQ(map.tree().getNumLeafNodes(), 65u);
}

TEST(MapAccumulator, SavedFilesReadBackAndReplaceAtomically) {
  MapAccumulator map(MapAccumulatorConfig{});
  integrateTable1Image(DrawingAlgorithm::kLinePyramid, &map);
  const std::string dir = ::testing::TempDir();
  {
    std::ofstream old(dir + "/acc_map.bt");
    old << "previous";
  }
  const auto paths = map.save(dir, "acc_map");
  ASSERT_EQ(paths.size(), 2u);
  octomap::OcTree bt(paths[0]);
  EXPECT_EQ(bt.getNumLeafNodes(), map.tree().getNumLeafNodes());
  std::unique_ptr<octomap::AbstractOcTree> ot(octomap::AbstractOcTree::read(paths[1]));
  ASSERT_NE(dynamic_cast<octomap::OcTree*>(ot.get()), nullptr);
  // The post at 6 m (table1Scene) is occupied in the saved map.
  const octomap::OcTreeNode* post = bt.search(5.6, 1.5, 1.0);
  ASSERT_NE(post, nullptr);
  EXPECT_TRUE(bt.isNodeOccupied(post));
  EXPECT_THROW(map.save("/nonexistent_dir_for_test", "m"), std::runtime_error);
  std::remove(paths[0].c_str());
  std::remove(paths[1].c_str());
}

// A kill -9 in the middle of saving leaves the previous file whole: each save
// writes a temporary file and renames it into place.
TEST(MapAccumulator, KillDuringSaveLeavesThePreviousMapIntact) {
  MapAccumulator map(MapAccumulatorConfig{});
  integrateTable1Image(DrawingAlgorithm::kLine, &map);  // a dense map: saves take a while
  const std::string dir = ::testing::TempDir();
  const auto paths = map.save(dir, "kill_map");  // the previous, complete files
  const size_t leaves = map.tree().getNumLeafNodes();
  const size_t leaves_bt = octomap::OcTree(paths[0]).getNumLeafNodes();  // .bt is pruned to occupied/free

  int killed_mid_write = 0;
  for (int trial = 0; trial < 5; ++trial) {
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      for (;;) map.save(dir, "kill_map");  // saves until killed
    }
    // Kill as soon as a temporary file shows that a write is under way (plus
    // a little more each trial, to land at other points of the write).
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    auto writing = [&] {
      for (const auto& p : paths)
        if (access((p + ".tmp" + std::to_string(child)).c_str(), F_OK) == 0) return true;
      return false;
    };
    while (!writing() && std::chrono::steady_clock::now() < give_up)
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    std::this_thread::sleep_for(std::chrono::microseconds(300 * trial));
    ASSERT_EQ(kill(child, SIGKILL), 0);
    int status = 0;
    ASSERT_EQ(waitpid(child, &status, 0), child);
    ASSERT_TRUE(WIFSIGNALED(status));
    octomap::OcTree bt(paths[0]);
    EXPECT_EQ(bt.getNumLeafNodes(), leaves_bt) << "trial " << trial;
    std::unique_ptr<octomap::AbstractOcTree> ot(octomap::AbstractOcTree::read(paths[1]));
    auto* full = dynamic_cast<octomap::OcTree*>(ot.get());
    ASSERT_NE(full, nullptr) << "trial " << trial;
    EXPECT_EQ(full->getNumLeafNodes(), leaves) << "trial " << trial;
    for (const auto& p : paths) {  // the killed save's temporary file, if it was writing
      const std::string tmp = p + ".tmp" + std::to_string(child);
      killed_mid_write += access(tmp.c_str(), F_OK) == 0;
      std::remove(tmp.c_str());
    }
  }
  EXPECT_GT(killed_mid_write, 0) << "no kill landed during a write: the test proved nothing";
  std::remove(paths[0].c_str());
  std::remove(paths[1].c_str());
}

// The accumulator over several frames of a flight (overlapping views, grids
// of every origin parity) against octomap's updateNode cell by cell in
// storage order: the same tree, node for node.
TEST(MapAccumulator, IntegrateEqualsUpdateNodeOverAFlight) {
  const FlightScenario scenario = makeScenario("posts");
  MapAccumulatorConfig cfg;
  cfg.resolution_m = 0.5;
  MapAccumulator map(cfg);
  octomap::OcTree plain(0.5);
  plain.setClampingThresMin(cfg.clamping_min_prob);
  plain.setClampingThresMax(cfg.clamping_max_prob);
  plain.setOccupancyThres(cfg.occupancy_threshold_prob);
  const int offset = static_cast<int>(plain.coordToKey(0.0));
  for (const GridUpdate& update : flightUpdates(scenario, {0u, 30u, 31u, 90u, 150u}, cfg.resolution_m)) {
    ASSERT_GT(update.numCells(), 1000u);
    ASSERT_TRUE(map.integrate(update));
    update.forEachCell([&](const Eigen::Vector3i& g, float v) {
      plain.updateNode(octomap::OcTreeKey(g.x() + offset, g.y() + offset, g.z() + offset), v, true);
    });
  }
  plain.updateInnerOccupancy();
  EXPECT_EQ(map.tree().size(), plain.size());
  EXPECT_EQ(fullTree(map.tree()), fullTree(plain));
}

// The fusion's cache (fusion_cache.h) against updateNode cell by cell, over
// 26 updates of a flight (25 in a row, then a jump that leaves the first
// views' blocks idle) into a map holding pruned, clamped free and occupied
// cubes: the tree read after 6 updates (a write-back for the reader), after
// 18 (the cache's own write-backs of blocks 16 updates old and of idle
// ones in between) and at the end is updateNode's tree node for node; a
// clamped cube that updates only confirmed stays one leaf.
TEST(MapAccumulator, TheCachedFusionIsUpdateNodesTreeWhenRead) {
  const FlightScenario scenario = makeScenario("posts");
  std::vector<size_t> frames;
  for (size_t k = 0; k < 25; ++k) frames.push_back(k);
  frames.push_back(90);
  MapAccumulatorConfig cfg;
  cfg.resolution_m = 0.5;
  const std::vector<GridUpdate> updates = flightUpdates(scenario, frames, cfg.resolution_m);
  // Clamped cubes ahead of the first camera, each one pruned leaf: free ones
  // (the views' free rays end in them), an occupied one on the ground, and a
  // free one high above, which the views' free space only confirms.
  octomap::OcTree cubes(cfg.resolution_m);
  cubes.setClampingThresMin(cfg.clamping_min_prob);
  cubes.setClampingThresMax(cfg.clamping_max_prob);
  const int offset = static_cast<int>(cubes.coordToKey(0.0));
  auto cube = [&](int edge, const Eigen::Vector3d& W_near, float log_odds) { setCube(&cubes, edge, W_near, log_odds); };
  const float free_log_odds = static_cast<float>(logit(cfg.clamping_min_prob));
  const float occupied_log_odds = static_cast<float>(logit(cfg.clamping_max_prob));
  const Eigen::Isometry3d T0 = scenario.cameraPose(0);
  cube(32, T0 * Eigen::Vector3d(0.0, 0.0, 10.0), free_log_odds);  // a leaf above the cache's blocks
  cube(8, T0 * Eigen::Vector3d(0.0, 3.0, 14.0), occupied_log_odds);
  cube(8, T0 * Eigen::Vector3d(0.0, -100.0, 0.0), free_log_odds);  // far above: nobody looks there
  cubes.updateInnerOccupancy();
  cubes.prune();
  ASSERT_LE(cubes.getNumLeafNodes(), 3u);
  const std::string path = ::testing::TempDir() + "cached_fusion_cubes.ot";
  ASSERT_TRUE(cubes.write(path));

  MapAccumulator map(cfg);
  map.load(path);
  std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(path));
  auto* plain = dynamic_cast<octomap::OcTree*>(read.get());
  ASSERT_NE(plain, nullptr);
  plain->setClampingThresMin(cfg.clamping_min_prob);
  plain->setClampingThresMax(cfg.clamping_max_prob);
  plain->setOccupancyThres(cfg.occupancy_threshold_prob);
  for (size_t i = 0; i < updates.size(); ++i) {
    const GridUpdate& update = updates[i];
    ASSERT_GT(update.numCells(), 1000u);
    ASSERT_TRUE(map.integrate(update));
    update.forEachCell([&](const Eigen::Vector3i& g, float v) {
      plain->updateNode(octomap::OcTreeKey(g.x() + offset, g.y() + offset, g.z() + offset), v, true);
    });
    if (i == 5 || i == 17 || i + 1 == updates.size()) {
      plain->updateInnerOccupancy();
      ASSERT_EQ(map.tree().size(), plain->size()) << "after update " << i + 1;
      ASSERT_EQ(fullTree(map.tree()), fullTree(*plain)) << "after update " << i + 1;
    }
  }
  // The views reached into the free cube ahead (expanded), not into the one above.
  auto leavesNear = [&](const Eigen::Vector3d& W_p, double half_m) {
    size_t n = 0;
    const octomap::point3d lo(W_p.x() - half_m, W_p.y() - half_m, W_p.z() - half_m);
    const octomap::point3d hi(W_p.x() + half_m, W_p.y() + half_m, W_p.z() + half_m);
    for (auto it = map.tree().begin_leafs_bbx(lo, hi), end = map.tree().end_leafs_bbx(); it != end; ++it) ++n;
    return n;
  };
  EXPECT_GT(leavesNear(T0 * Eigen::Vector3d(0.0, 0.0, 10.0), 0.5), 1u);
  EXPECT_EQ(leavesNear(T0 * Eigen::Vector3d(0.0, -100.0, 0.0), 0.5), 1u);
  std::remove(path.c_str());
}

namespace {
/// Integrates @p update into @p map and expects each of its cells to hold
/// updateNode's value from the value the map's tree gave it just before (a
/// cache that kept a cell's value from before a clear, a dropped tile or a
/// prune would add to that instead). Returns the cells whose value changed.
size_t expectAddedToTheTreesValues(MapAccumulator* map, const GridUpdate& update) {
  const octomap::OcTree& tree = map->tree();
  const int offset = static_cast<int>(tree.coordToKey(0.0));
  const float lo = tree.getClampingThresMinLog(), hi = tree.getClampingThresMaxLog();
  auto keyOf = [offset](const Eigen::Vector3i& g) {
    return octomap::OcTreeKey(g.x() + offset, g.y() + offset, g.z() + offset);
  };
  std::vector<float> before;
  update.forEachCell([&](const Eigen::Vector3i& g, float) {
    const octomap::OcTreeNode* node = map->tree().search(keyOf(g));
    before.push_back(node ? node->getLogOdds() : std::numeric_limits<float>::quiet_NaN());
  });
  EXPECT_TRUE(map->integrate(update));
  size_t i = 0, wrong = 0, changed = 0;
  update.forEachCell([&](const Eigen::Vector3i& g, float u) {
    const float v = before[i++];
    float expected = v;
    if (std::isnan(v))
      expected = std::clamp(0.0f + u, lo, hi);
    else if (!((u >= 0.0f && v >= hi) || (u <= 0.0f && v <= lo)))
      expected = std::clamp(v + u, lo, hi);
    const octomap::OcTreeNode* node = map->tree().search(keyOf(g));
    wrong += !node || node->getLogOdds() != expected;
    changed += !(expected == v);
  });
  EXPECT_EQ(wrong, 0u) << "of " << i << " cells";
  return changed;
}
}  // namespace

// The fusion's cache holds a block's values from update to update: a clear,
// a dropped tile and a prune change the tree's, and the next update adds to
// the tree's new values, not to the cached old ones.
TEST(MapAccumulator, UpdatesAfterAClearADroppedTileOrAPruneAddToTheTreesValues) {
  const FlightScenario scenario = makeScenario("posts");
  const std::vector<GridUpdate> updates = flightUpdates(scenario, {0u});
  const GridUpdate& u = updates[0];
  MapAccumulatorConfig cfg;
  const Eigen::Vector3d W_lo = u.origin_index.cast<double>() * cfg.resolution_m;
  const Eigen::Vector3d W_hi = W_lo + u.size.cast<double>() * cfg.resolution_m;
  {
    MapAccumulator map(cfg);
    ASSERT_TRUE(map.integrate(u));
    ASSERT_TRUE(map.integrate(u));
    ASSERT_GT(map.clearBox(W_lo, W_hi), 100u);  // every occupied cell of the view
    EXPECT_GT(expectAddedToTheTreesValues(&map, u), 100u);
  }
  {
    MapAccumulator map(cfg);
    ASSERT_TRUE(map.integrate(u));
    const Eigen::Vector3i first_cell = u.origin_index + u.size / 2;
    const MapAccumulator::TileIndex tile =
        (first_cell.cast<double>() / MapAccumulator::kTileCells).array().floor().cast<int>().matrix();
    ASSERT_GT(map.dropTile(tile), 100u);
    EXPECT_GT(expectAddedToTheTreesValues(&map, u), 100u);
  }
  {
    cfg.max_extent_m = 4.0;  // less than the view's range: a prune drops its far cells
    MapAccumulator map(cfg);
    ASSERT_TRUE(map.integrate(u));
    ASSERT_GT(map.prune(), 100u);
    EXPECT_GT(expectAddedToTheTreesValues(&map, u), 100u);
  }
}

// The parts of the spread merges (compress_map) are listed without writing
// the fusion's cache back (all of a mission's dirty tiles at once held one
// update for 1.5-3 ms): the tree's parts and the cached blocks, in the
// order, and no other, that a write-back would leave.
TEST(MapAccumulator, PartsToMergeAreTheWrittenBackTreesWithoutTheWriteBack) {
  const FlightScenario scenario = makeScenario("posts");
  const std::vector<GridUpdate> updates = flightUpdates(scenario, {0u, 60u});
  MapAccumulator map{MapAccumulatorConfig()};
  ASSERT_TRUE(map.integrate(updates[0]));
  std::vector<MapAccumulator::TileIndex> tiles = map.tilesOf(updates[0]);
  for (const auto& t : map.tilesOf(updates[1])) tiles.push_back(t);
  std::sort(tiles.begin(), tiles.end(), [](const auto& a, const auto& b) {
    return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
  });
  tiles.erase(std::unique(tiles.begin(), tiles.end()), tiles.end());
  map.tree();  // the first view written back
  size_t parts_before = 0;
  for (const auto& t : tiles) parts_before += map.partsToMerge(t).size();
  ASSERT_TRUE(map.integrate(updates[1]));  // in the cache
  const size_t leaves = map.leafTree(CellBox()).getNumLeafNodes();
  std::vector<std::vector<octomap::OcTreeKey>> cached;
  for (const auto& t : tiles) cached.push_back(map.partsToMerge(t));
  EXPECT_EQ(map.leafTree(CellBox()).getNumLeafNodes(), leaves) << "partsToMerge() wrote the cache back";
  map.tree();
  size_t parts_after = 0;
  for (size_t i = 0; i < tiles.size(); ++i) {
    const std::vector<octomap::OcTreeKey> written = map.partsToMerge(tiles[i]);
    parts_after += written.size();
    EXPECT_TRUE(cached[i] == written) << "tile " << tiles[i].transpose() << ": " << cached[i].size() << " parts, "
                                      << written.size() << " after the write-back";
  }
  EXPECT_GT(parts_after, parts_before + 10);  // the second view's new parts came from the cache
  EXPECT_GT(map.leafTree(CellBox()).getNumLeafNodes(), leaves);
}

// Fusion on several threads (each row of 16-cell blocks added by one
// worker, each block written back by one) against one thread: over a flight's overlapping views, into a map that
// holds pruned coarse leaves (clamped free and occupied cubes of 64 and 32
// cells, above the workers' subtrees, which stay on the calling thread), the
// same tree node for node, the same node count, the same changed blocks
// and tiles, and the same class changes in the same order.
TEST(MapAccumulator, ThreadCountsFuseTheSameTree) {
  const FlightScenario scenario = makeScenario("posts");
  const std::vector<GridUpdate> updates = flightUpdates(scenario, {0u, 1u, 30u, 31u, 90u});
  // Two key-aligned cubes in front of the first camera, pruned to one leaf each.
  MapAccumulatorConfig cfg;
  octomap::OcTree cubes(cfg.resolution_m);
  const Eigen::Vector3d ahead = scenario.cameraPose(0) * Eigen::Vector3d(0.0, 0.0, 12.0);
  auto cube = [&](int edge, const Eigen::Vector3d& W_near, float log_odds) { setCube(&cubes, edge, W_near, log_odds); };
  cube(64, ahead, static_cast<float>(logit(cfg.clamping_min_prob)));
  cube(32, ahead + Eigen::Vector3d(0.0, 0.0, -8.0), static_cast<float>(logit(cfg.clamping_max_prob)));
  cubes.updateInnerOccupancy();
  cubes.prune();
  ASSERT_LE(cubes.getNumLeafNodes(), 2u);
  const std::string path = ::testing::TempDir() + "fusion_cubes.ot";
  ASSERT_TRUE(cubes.write(path));

  auto fused = [&](int threads, std::vector<std::vector<MapAccumulator::BlockIndex>>* changed) {
    MapAccumulatorConfig c = cfg;
    c.threads = threads;
    auto map = std::make_unique<MapAccumulator>(c);
    map->load(path);
    map->recordClassChanges(true);
    bool all = false;
    map->takeChangedBlocks(&all);
    map->takeDirtyTiles();
    map->takeClassChanges(&all);
    for (const GridUpdate& u : updates) {
      EXPECT_TRUE(map->integrate(u));
      // The class changes, in their order: each as a block index of its own.
      const std::vector<CellClassChange> changes = map->takeClassChanges(&all);
      EXPECT_FALSE(all);
      EXPECT_GT(changes.size(), 1000u);
      changed->emplace_back();
      for (const CellClassChange& change : changes)
        changed->back().push_back(change.cell * 4 + Eigen::Vector3i::Constant(static_cast<int>(change.now)));
      changed->push_back(map->takeChangedBlocks(&all));
      std::sort(changed->back().begin(), changed->back().end(), [](const auto& a, const auto& b) {
        return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
      });
      std::vector<MapAccumulator::TileIndex> tiles = map->takeDirtyTiles();
      std::sort(tiles.begin(), tiles.end(), [](const auto& a, const auto& b) {
        return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
      });
      changed->push_back(tiles);
    }
    return map;
  };
  std::vector<std::vector<MapAccumulator::BlockIndex>> changed_one;
  const auto one = fused(1, &changed_one);
  ASSERT_GT(one->tree().size(), 100000u);
  // The updates reached both cubes: their single leaves were expanded.
  EXPECT_GT(one->tree().getNumLeafNodes(), 2u * cubes.getNumLeafNodes() + 1000u);
  for (int threads : {2, 3, 5}) {
    std::vector<std::vector<MapAccumulator::BlockIndex>> changed;
    const auto many = fused(threads, &changed);
    EXPECT_EQ(many->tree().size(), one->tree().size()) << threads << " threads";
    EXPECT_EQ(fullTree(many->tree()), fullTree(one->tree())) << threads << " threads";
    EXPECT_EQ(changed, changed_one) << threads << " threads";
  }
  std::remove(path.c_str());
}

// A saved map loads back: the same leaves and values from the .ot, the same
// occupancy from the .bt; a file of another resolution or none is refused
// and the map stays as it was.
TEST(MapAccumulator, LoadsWhatItSaved) {
  MapAccumulator map{MapAccumulatorConfig()};
  integrateTable1Image(DrawingAlgorithm::kLinePyramid, &map);
  const std::string dir = ::testing::TempDir();
  const auto paths = map.save(dir, "load_test");
  MapAccumulator from_ot{MapAccumulatorConfig()}, from_bt{MapAccumulatorConfig()};
  from_ot.load(paths[1]);
  EXPECT_EQ(fullTree(from_ot.tree()), fullTree(map.tree()));
  EXPECT_EQ(from_ot.updates(), 0u);
  from_bt.load(paths[0]);
  size_t occupied = 0, agree = 0;
  for (auto it = map.tree().begin_leafs(), end = map.tree().end_leafs(); it != end; ++it) {
    if (!map.tree().isNodeOccupied(*it)) continue;
    ++occupied;
    const octomap::OcTreeNode* n = from_bt.tree().search(it.getKey());
    agree += n && from_bt.tree().isNodeOccupied(n);
  }
  EXPECT_GT(occupied, 1000u);
  EXPECT_EQ(agree, occupied);

  MapAccumulatorConfig coarse;
  coarse.resolution_m = 0.5;
  MapAccumulator other{coarse};
  EXPECT_THROW(other.load(paths[1]), std::runtime_error);
  EXPECT_THROW(from_ot.load(dir + "does_not_exist.ot"), std::runtime_error);
  EXPECT_EQ(fullTree(from_ot.tree()), fullTree(map.tree()));  // unchanged by the failed load
  for (const auto& p : paths) std::remove(p.c_str());
}

// clear_bbx: no occupied cell is left in the box, the cells outside keep
// their values, and a pruned occupied block that the box cuts keeps its
// part outside.
TEST(MapAccumulator, ClearBoxLeavesNothingOccupiedInside) {
  // A 4 m cube of clamped occupied cells, pruned to coarse leaves, loaded from a file.
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(16, 16, 16), 0.25);
  octomap::OcTree cube(0.25);
  for (int z = 0; z < 16; ++z)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) {
        const Eigen::Vector3d p = grid.cellCentre(x, y, z);
        cube.setNodeValue(p.x(), p.y(), p.z(), cube.getClampingThresMaxLog());
      }
  cube.updateInnerOccupancy();
  cube.prune();
  ASSERT_LT(cube.getNumLeafNodes(), 16u * 16u * 16u);
  const std::string path = ::testing::TempDir() + "clear_box_cube.ot";
  ASSERT_TRUE(cube.write(path));
  MapAccumulator map{MapAccumulatorConfig()};
  map.load(path);
  std::remove(path.c_str());
  ASSERT_EQ(map.tree().getNumLeafNodes(), cube.getNumLeafNodes());  // coarse leaves, as saved
  const size_t cleared = map.clearBox(Eigen::Vector3d(0.5, 0.5, 0.5), Eigen::Vector3d(1.49, 1.49, 1.49));
  EXPECT_EQ(cleared, 4u * 4u * 4u);
  size_t occupied_inside = 0, occupied_outside = 0;
  for (int z = 0; z < 16; ++z)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) {
        const Eigen::Vector3d p = grid.cellCentre(x, y, z);
        const octomap::OcTreeNode* n = map.tree().search(p.x(), p.y(), p.z());
        ASSERT_NE(n, nullptr);
        const bool inside = (p.array() > 0.5).all() && (p.array() < 1.5).all();
        (inside ? occupied_inside : occupied_outside) += map.tree().isNodeOccupied(n);
      }
  EXPECT_EQ(occupied_inside, 0u);
  EXPECT_EQ(occupied_outside, 16u * 16u * 16u - 64u);
  EXPECT_EQ(map.clearBox(Eigen::Vector3d(0.5, 0.5, 0.5), Eigen::Vector3d(1.49, 1.49, 1.49)), 0u);  // nothing left
}

// The outputs redo only the blocks a clear_bbx reached, not the whole map.
TEST(MapAccumulator, ClearBoxChangesOnlyItsBlocks) {
  MapAccumulator map{MapAccumulatorConfig()};
  for (int x : {5, 40, 100}) ASSERT_TRUE(map.integrate(singleCell(Eigen::Vector3i(x, 5, 5), 1.0f)));
  bool all = false;
  map.takeChangedBlocks(&all);  // the new map's "everything"
  ASSERT_TRUE(all);
  // Cells 36..47 along x at 0.25 m: the cell at x = 40 (block 2) only.
  EXPECT_EQ(map.clearBox(Eigen::Vector3d(9.0, 1.0, 1.0), Eigen::Vector3d(11.9, 1.49, 1.49)), 1u);
  const std::vector<MapAccumulator::BlockIndex> blocks = map.takeChangedBlocks(&all);
  EXPECT_FALSE(all);
  ASSERT_EQ(blocks.size(), 1u);
  EXPECT_EQ(blocks[0], Eigen::Vector3i(2, 0, 0));  // 40 / 16
  EXPECT_EQ(map.clearBox(Eigen::Vector3d(9.0, 1.0, 1.0), Eigen::Vector3d(11.9, 1.49, 1.49)), 0u);
  EXPECT_TRUE(map.takeChangedBlocks(&all).empty());  // nothing cleared, nothing changed
}

// A map within the slack beyond its extent is left as it is (a prune
// rebuilds the tree); once it reaches past the slack, everything beyond the
// extent goes, the cell within the slack too.
TEST(MapAccumulator, PruneWaitsForTheSlack) {
  MapAccumulatorConfig cfg;
  cfg.max_extent_m = 10.0;
  MapAccumulator map(cfg);
  GridUpdate near = singleCell(Eigen::Vector3i(0, 0, 0), 1.0f);
  for (size_t i = 0; i < MapAccumulator::kPruneOrigins; ++i) ASSERT_TRUE(map.integrate(near));
  // 12 m away: beyond the extent of 10 m, within its slack of 2.5 m. The
  // vehicle then stays near the origin until that update's origin leaves
  // the ring of recent origins.
  ASSERT_TRUE(map.integrate(singleCell(Eigen::Vector3i(48, 0, 0), 1.0f)));
  for (size_t i = 0; i < MapAccumulator::kPruneOrigins; ++i) ASSERT_TRUE(map.integrate(near));
  EXPECT_EQ(map.prune(), 0u);
  EXPECT_NE(map.tree().search(12.1, 0.1, 0.1), nullptr);
  GridUpdate beyond = singleCell(Eigen::Vector3i(60, 0, 0), 1.0f);  // 15 m: past the slack
  ASSERT_TRUE(map.integrate(beyond));
  for (size_t i = 0; i < MapAccumulator::kPruneOrigins; ++i) ASSERT_TRUE(map.integrate(near));
  EXPECT_EQ(map.prune(), 2u);
  EXPECT_EQ(map.tree().search(12.1, 0.1, 0.1), nullptr);
  EXPECT_EQ(map.tree().search(15.1, 0.1, 0.1), nullptr);
  EXPECT_NE(map.tree().search(0.1, 0.1, 0.1), nullptr);
  EXPECT_EQ(map.prune(), 0u);  // the map is within its extent again
}

// The blocks an update changed, for outputs that cost what changed: all of
// the map's blocks first and after a reset; then only those updates touched.
TEST(MapAccumulator, TracksTheBlocksUpdatesChange) {
  MapAccumulator map{MapAccumulatorConfig()};
  bool all = false;
  EXPECT_TRUE(map.takeChangedBlocks(&all).empty());
  EXPECT_TRUE(all);  // a new map: "everything" (nothing) changed
  ASSERT_TRUE(map.integrate(singleCell(Eigen::Vector3i(5, 5, 5), 1.0f)));
  ASSERT_TRUE(map.integrate(singleCell(Eigen::Vector3i(-1, 20, 40), 1.0f)));
  std::vector<MapAccumulator::BlockIndex> blocks = map.takeChangedBlocks(&all);
  EXPECT_FALSE(all);
  ASSERT_EQ(blocks.size(), 2u);
  std::sort(blocks.begin(), blocks.end(), [](const auto& a, const auto& b) { return a.x() < b.x(); });
  EXPECT_EQ(blocks[0], Eigen::Vector3i(-1, 1, 2));  // floor(-1 / 16) = -1
  EXPECT_EQ(blocks[1], Eigen::Vector3i(0, 0, 0));
  EXPECT_TRUE(map.takeChangedBlocks(&all).empty());  // taken
  ASSERT_TRUE(map.integrate(singleCell(Eigen::Vector3i(6, 5, 5), 1.0f)));
  blocks = map.takeChangedBlocks(&all);
  ASSERT_EQ(blocks.size(), 1u);
  EXPECT_EQ(blocks[0], Eigen::Vector3i(0, 0, 0));
  map.markAllChanged();  // a new subscriber: every block that holds a cell
  blocks = map.takeChangedBlocks(&all);
  EXPECT_TRUE(all);
  EXPECT_EQ(blocks.size(), 2u);
}

namespace {
/// The class of the cell @p g in @p tree: its leaf's (a coarse one's too), or unknown.
CellClass classIn(const octomap::OcTree& tree, const Eigen::Vector3i& g) {
  const int offset = static_cast<int>(tree.coordToKey(0.0));
  const octomap::OcTreeNode* node = tree.search(octomap::OcTreeKey(g.x() + offset, g.y() + offset, g.z() + offset));
  return node ? classOfLogOdds(node->getLogOdds(), tree.getOccupancyThresLog()) : CellClass::kUnknown;
}
bool lessCell(const Eigen::Vector3i& a, const Eigen::Vector3i& b) {
  return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
}
}  // namespace

// The class changes the fusion records against each update's cells' classes
// looked up before and after it: over a flight's overlapping views into a map
// loaded with pruned cubes (expanded by the updates; two near the threshold,
// one clamped), on 1, 2 and 3 threads: the same cells, each once, with its
// class after the update; the tree the same as without recording.
TEST(MapAccumulator, RecordsTheCellsWhoseClassAnUpdateChanged) {
  const FlightScenario scenario = makeScenario("posts");
  const std::vector<GridUpdate> updates = flightUpdates(scenario, {0u, 1u, 30u});
  MapAccumulatorConfig cfg;
  octomap::OcTree cubes(cfg.resolution_m);
  const Eigen::Vector3d ahead = scenario.cameraPose(0) * Eigen::Vector3d(0.0, 0.0, 12.0);
  std::vector<std::pair<Eigen::Vector3i, int>> cube_boxes;  // first cell, edge
  auto cube = [&](int edge, const Eigen::Vector3d& W_near, float log_odds) {
    cube_boxes.emplace_back(setCube(&cubes, edge, W_near, log_odds), edge);
  };
  auto inCube = [&](const Eigen::Vector3i& g) {
    for (const auto& c : cube_boxes)
      if ((g.array() >= c.first.array()).all() && (g.array() < c.first.array() + c.second).all()) return true;
    return false;
  };
  // Near the threshold, so that the updates change their cells' classes; and one clamped (no change).
  cube(16, ahead, -0.05f);
  cube(8, ahead + Eigen::Vector3d(0.0, 0.0, -4.0), 0.05f);
  cube(16, ahead + Eigen::Vector3d(0.0, 0.0, 4.0), static_cast<float>(logit(cfg.clamping_max_prob)));
  cubes.updateInnerOccupancy();
  cubes.prune();
  ASSERT_LE(cubes.getNumLeafNodes(), 3u);
  const std::string path = ::testing::TempDir() + "recording_cubes.ot";
  ASSERT_TRUE(cubes.write(path));

  MapAccumulatorConfig plain_cfg = cfg;
  plain_cfg.threads = 1;
  MapAccumulator plain(plain_cfg);  // never records
  plain.load(path);
  for (const GridUpdate& u : updates) ASSERT_TRUE(plain.integrate(u));
  for (int threads : {1, 2, 3}) {
    MapAccumulatorConfig c = cfg;
    c.threads = threads;
    MapAccumulator map(c);
    map.load(path);
    bool all = false;
    EXPECT_TRUE(map.takeClassChanges(&all).empty());
    EXPECT_FALSE(all);  // not recording
    map.recordClassChanges(true);
    EXPECT_TRUE(map.takeClassChanges(&all).empty());
    EXPECT_TRUE(all);  // what the map holds is news to the caller
    size_t expanded_changes = 0;
    for (const GridUpdate& u : updates) {
      std::vector<std::pair<Eigen::Vector3i, CellClass>> before;
      u.forEachCell([&](const Eigen::Vector3i& g, float) { before.emplace_back(g, classIn(map.tree(), g)); });
      ASSERT_TRUE(map.integrate(u));
      std::vector<CellClassChange> expected;
      for (const auto& b : before) {
        const CellClass now = classIn(map.tree(), b.first);
        if (now != b.second) expected.push_back(CellClassChange{b.first, now});
        expanded_changes += inCube(b.first) && now != b.second;
      }
      std::vector<CellClassChange> got = map.takeClassChanges(&all);
      EXPECT_FALSE(all);
      auto sorted = [](std::vector<CellClassChange> v) {
        std::sort(v.begin(), v.end(), [](const auto& a, const auto& b) { return lessCell(a.cell, b.cell); });
        return v;
      };
      got = sorted(got);
      expected = sorted(expected);
      ASSERT_GT(expected.size(), 1000u);
      ASSERT_EQ(got.size(), expected.size()) << threads << " threads";
      for (size_t i = 0; i < got.size(); ++i) {
        ASSERT_EQ(got[i].cell, expected[i].cell) << threads << " threads";
        ASSERT_EQ(got[i].now, expected[i].now) << got[i].cell.transpose();
      }
    }
    EXPECT_GT(expanded_changes, 0u) << "no cell of the pruned cubes changed class: move them";
    EXPECT_EQ(fullTree(map.tree()), fullTree(plain.tree())) << threads << " threads";
    // Anything but an update: all.
    map.clearBox(ahead - Eigen::Vector3d::Constant(20.0), ahead + Eigen::Vector3d::Constant(20.0));
    EXPECT_TRUE(map.takeClassChanges(&all).empty());
    EXPECT_TRUE(all);
    ASSERT_TRUE(map.integrate(updates[0]));
    EXPECT_FALSE(map.takeClassChanges(&all).empty());
    EXPECT_FALSE(all);
    map.reset();
    map.takeClassChanges(&all);
    EXPECT_TRUE(all);
    map.recordClassChanges(false);
    ASSERT_TRUE(map.integrate(updates[0]));
    EXPECT_TRUE(map.takeClassChanges(&all).empty());
    EXPECT_FALSE(all);
  }
  std::remove(path.c_str());
}
