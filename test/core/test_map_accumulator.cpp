#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <thread>

#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "stereo_occupancy/sim/synthetic_scene.h"

using namespace stereo_occupancy;

namespace {
/// An update of one cell, seen from the cell's centre.
GridUpdate singleCell(const Eigen::Vector3i& g, float value, double res = 0.25) {
  LocalGrid grid;
  grid.reset(g, Eigen::Vector3i(1, 1, 1), res);
  grid.at(0, 0, 0) = value;
  GridUpdate u;
  encodeGridUpdate(grid, grid.cellCentre(0, 0, 0), &u);
  return u;
}
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
}  // namespace

TEST(GridUpdate, EncodesKnownCellsAsRuns) {
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(10, 20, 30), Eigen::Vector3i(4, 3, 2), 0.5);
  for (int x = 1; x < 4; ++x) grid.at(x, 1, 0) = 0.5f;  // one run of 3
  grid.at(0, 0, 1) = -0.2f;                              // a run of 1
  GridUpdate u;
  encodeGridUpdate(grid, Eigen::Vector3d(1, 2, 3), &u);
  EXPECT_EQ(u.run_start, (std::vector<uint32_t>{5, 12}));
  EXPECT_EQ(u.run_length, (std::vector<uint32_t>{3, 1}));
  EXPECT_EQ(u.numCells(), 4u);
  std::string why;
  EXPECT_TRUE(u.isConsistent(&why)) << why;
  int seen = 0;
  u.forEachCell([&](const Eigen::Vector3i& g, float v) {
    if (seen < 3) {
      EXPECT_EQ(g, Eigen::Vector3i(11 + seen, 21, 30));
      EXPECT_FLOAT_EQ(v, 0.5f);
    } else {
      EXPECT_EQ(g, Eigen::Vector3i(10, 20, 31));
    }
    ++seen;
  });
  EXPECT_EQ(seen, 4);
  GridUpdate bad = u;
  bad.run_start = {5, 6};  // overlapping runs
  EXPECT_FALSE(bad.isConsistent(&why));
  bad = u;
  bad.size = Eigen::Vector3i(2, 2, 2);  // runs past the grid's end
  EXPECT_FALSE(bad.isConsistent(&why));
}

// Every value is checked, wherever it stands; finite extremes pass.
TEST(GridUpdate, RefusesNonFiniteValues) {
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(37, 1, 1), 0.25);
  for (int x = 0; x < 37; ++x) grid.at(x, 0, 0) = 0.1f * (x + 1);
  GridUpdate u;
  encodeGridUpdate(grid, Eigen::Vector3d::Zero(), &u);
  ASSERT_EQ(u.numCells(), 37u);
  std::string why;
  const float finite[] = {std::numeric_limits<float>::max(), -std::numeric_limits<float>::max(),
                          std::numeric_limits<float>::denorm_min(), -0.0f};
  for (float v : finite) {
    GridUpdate ok = u;
    ok.log_odds[36] = v;
    EXPECT_TRUE(ok.isConsistent(&why)) << v << ": " << why;
  }
  const float not_finite[] = {std::numeric_limits<float>::quiet_NaN(), -std::numeric_limits<float>::quiet_NaN(),
                              std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()};
  for (float v : not_finite)
    for (size_t at : {size_t{0}, size_t{17}, size_t{36}}) {
      GridUpdate bad = u;
      bad.log_odds[at] = v;
      why.clear();
      EXPECT_FALSE(bad.isConsistent(&why)) << v << " at " << at;
      EXPECT_NE(why.find("not finite"), std::string::npos) << why;
    }
}

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
  EXPECT_EQ(map.prune(), 0u);  // both near a recent origin
  // The vehicle stays near the origin for kPruneOrigins updates: the cell
  // at 50 m goes, the ones near it stay.
  GridUpdate near = singleCell(Eigen::Vector3i(4, 0, 0), 1.0f);
  near.W_sensor_origin = Eigen::Vector3d(1.0, 0.0, 0.0);
  for (size_t i = 0; i < MapAccumulator::kPruneOrigins; ++i) ASSERT_TRUE(map.integrate(near));
  EXPECT_EQ(map.prune(), 1u);
  EXPECT_EQ(map.tree().search(50.1, 0.1, 0.1), nullptr);
  EXPECT_NE(map.tree().search(0.1, 0.1, 0.1), nullptr);
  EXPECT_EQ(map.tree().getNumLeafNodes(), 2u);
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

namespace {
/// The whole tree, every node's value included (.ot format).
std::string fullTree(const octomap::OcTree& tree) {
  std::ostringstream out;
  tree.write(out);
  return out.str();
}
}  // namespace

// The accumulator's fast path against octomap's own updateNode(key, value,
// lazy_eval = true): the same trees, node for node, from a tree holding
// pruned leaves (clamped and not) and with keys in storage order, repeated
// (so that leaves clamp) and in random order.
TEST(AccumulatingOcTree, LeafUpdaterEqualsUpdateNode) {
  const double res = 0.25;
  AccumulatingOcTree fast(res);
  octomap::OcTree plain(res);
  auto both = [&](const octomap::OcTreeKey& key, float value) {
    AccumulatingOcTree::LeafUpdater(&fast).add(key, value);
    plain.updateNode(key, value, true);
  };
  const uint16_t o = 32768;
  // Two pruned 2x2x2 blocks (one clamped occupied, one at 0.4) and a
  // pruned 4x4x4 block of clamped free space, next to single leaves.
  for (int i = 0; i < 8; ++i) {
    const octomap::OcTreeKey a(o + (i & 1), o + ((i >> 1) & 1), o + (i >> 2));
    for (int r = 0; r < 5; ++r) both(a, 0.85f);
    both(octomap::OcTreeKey(o + 4 + (i & 1), o + ((i >> 1) & 1), o + (i >> 2)), 0.4f);
  }
  for (int i = 0; i < 64; ++i)
    for (int r = 0; r < 6; ++r) both(octomap::OcTreeKey(o + 8 + (i & 3), o + ((i >> 2) & 3), o + (i >> 4)), -0.4f);
  both(octomap::OcTreeKey(o + 2, o + 2, o + 2), 0.3f);
  fast.updateInnerOccupancy();
  plain.updateInnerOccupancy();
  fast.prune();
  plain.prune();
  ASSERT_EQ(fullTree(fast), fullTree(plain));
  ASSERT_LT(plain.size(), 8u * 16u) << "the blocks were not pruned";
  // Updates that push the clamped blocks further change nothing (updateNode
  // returns early at the pruned node), others expand them.
  const size_t pruned_size = plain.size();
  both(octomap::OcTreeKey(o + 1, o, o + 1), 0.85f);
  both(octomap::OcTreeKey(o + 9, o + 3, o + 2), -0.4f);
  both(octomap::OcTreeKey(o + 9, o + 3, o + 2), 0.0f);
  EXPECT_EQ(plain.size(), pruned_size);
  ASSERT_EQ(fullTree(fast), fullTree(plain));
  both(octomap::OcTreeKey(o + 5, o + 1, o), 0.3f);
  EXPECT_GT(plain.size(), pruned_size);
  ASSERT_EQ(fullTree(fast), fullTree(plain));

  // A 16x6x5 grid over all of it, in storage order, three times.
  std::mt19937 rng(7);
  const float values[] = {-0.4f, 0.0f, 0.17f, 0.85f, 2.5f, -2.5f};
  std::vector<std::pair<octomap::OcTreeKey, float>> cells;
  for (int z = -1; z < 4; ++z)
    for (int y = -1; y < 5; ++y)
      for (int x = -1; x < 15; ++x) cells.push_back({octomap::OcTreeKey(o + x, o + y, o + z), values[rng() % 6]});
  for (int pass = 0; pass < 3; ++pass) {
    AccumulatingOcTree::LeafUpdater updater(&fast);
    for (const auto& [key, value] : cells) {
      updater.add(key, value);
      plain.updateNode(key, value, true);
    }
    ASSERT_EQ(fullTree(fast), fullTree(plain)) << "pass " << pass;
  }
  // The same grid's 2x2x2 blocks with addSiblings(), some cells missing
  // (NaN), three times: it clamps leaves, and walks from pruned clamped
  // nodes (where the first sibling stops) to siblings of either sign.
  for (int pass = 0; pass < 3; ++pass) {
    AccumulatingOcTree::LeafUpdater updater(&fast);
    for (int z = -2; z < 4; z += 2)
      for (int y = -2; y < 6; y += 2)
        for (int x = -2; x < 16; x += 2) {
          float block[8];
          for (int i = 0; i < 8; ++i) {
            block[i] = rng() % 4 == 0 ? std::numeric_limits<float>::quiet_NaN() : values[rng() % 6];
            if (block[i] == block[i])
              plain.updateNode(octomap::OcTreeKey(o + x + (i & 1), o + y + ((i >> 1) & 1), o + z + (i >> 2)),
                               block[i], true);
          }
          updater.addSiblings(octomap::OcTreeKey(o + x, o + y, o + z), block);
        }
    ASSERT_EQ(fullTree(fast), fullTree(plain)) << "block pass " << pass;
    fast.updateInnerOccupancy();
    plain.updateInnerOccupancy();
    fast.prune();
    plain.prune();
    ASSERT_EQ(fullTree(fast), fullTree(plain)) << "block pass " << pass << ", pruned";
  }
  // Random keys, far apart and close, with repeats.
  AccumulatingOcTree::LeafUpdater updater(&fast);
  for (int i = 0; i < 20000; ++i) {
    const int spread = i % 2 ? 40 : 40000;
    const octomap::OcTreeKey key(o - spread / 2 + rng() % spread, o - spread / 2 + rng() % spread,
                                 o - 5 + rng() % 10);
    const float value = values[rng() % 6];
    updater.add(key, value);
    plain.updateNode(key, value, true);
  }
  EXPECT_EQ(fast.size(), plain.size());
  EXPECT_EQ(fullTree(fast), fullTree(plain));
}

// addSiblings() in a pruned 4x4x4 block of clamped free space: the first
// sibling stops at the pruned node (depth 14, above the leaves' parent), the
// next one, occupied, must walk on from there and expand it.
TEST(AccumulatingOcTree, SiblingsWalkOnFromAPrunedNode) {
  const double res = 0.25;
  AccumulatingOcTree fast(res);
  octomap::OcTree plain(res);
  const uint16_t o = 32768;
  for (int i = 0; i < 64; ++i)
    for (int r = 0; r < 6; ++r) {
      const octomap::OcTreeKey key(o + (i & 3), o + ((i >> 2) & 3), o + (i >> 4));
      AccumulatingOcTree::LeafUpdater(&fast).add(key, -0.4f);
      plain.updateNode(key, -0.4f, true);
    }
  for (octomap::OcTree* tree : {static_cast<octomap::OcTree*>(&fast), &plain}) {
    tree->updateInnerOccupancy();
    tree->prune();
  }
  ASSERT_EQ(fullTree(fast), fullTree(plain));
  ASSERT_EQ(plain.getNumLeafNodes(), 1u) << "the block was not pruned";
  AccumulatingOcTree::LeafUpdater updater(&fast);
  const octomap::OcTreeKey elsewhere(o + 40, o, o);  // a walk to another leaf first
  updater.add(elsewhere, 0.3f);
  plain.updateNode(elsewhere, 0.3f, true);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float block[8] = {-0.4f, 0.85f, nan, -0.4f, 0.3f, nan, nan, -0.4f};
  const octomap::OcTreeKey first(o + 2, o + 2, o);
  updater.addSiblings(first, block);
  for (int i = 0; i < 8; ++i)
    if (block[i] == block[i])
      plain.updateNode(octomap::OcTreeKey(first[0] + (i & 1), first[1] + ((i >> 1) & 1), first[2] + (i >> 2)),
                       block[i], true);
  EXPECT_GT(plain.getNumLeafNodes(), 2u) << "the pruned block was not expanded";
  EXPECT_EQ(fullTree(fast), fullTree(plain));
}

// The order the accumulator walks an update in: every cell once, with its
// value, and the eight cells of each even-aligned 2x2x2 block one after
// another, whatever the parity of the grid's origin and sizes, also for
// runs that go on into the next row.
TEST(GridUpdate, SiblingOrderVisitsEveryCellOnceBlockByBlock) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 40; ++trial) {
    LocalGrid grid;
    const Eigen::Vector3i origin(static_cast<int>(rng() % 21) - 10, static_cast<int>(rng() % 21) - 10,
                                 static_cast<int>(rng() % 21) - 10);
    const Eigen::Vector3i size(1 + rng() % 9, 1 + rng() % 7, 1 + rng() % 6);
    grid.reset(origin, size, 0.25);
    const double density = (rng() % 100) / 100.0;
    for (int z = 0; z < size.z(); ++z)
      for (int y = 0; y < size.y(); ++y)
        for (int x = 0; x < size.x(); ++x)
          if ((rng() % 1000) / 1000.0 < density) grid.at(x, y, z) = 0.01f * static_cast<float>(1 + rng() % 300);
    GridUpdate u;
    encodeGridUpdate(grid, Eigen::Vector3d::Zero(), &u);
    std::map<std::array<int, 3>, float> expected, seen;
    u.forEachCell([&](const Eigen::Vector3i& g, float v) { expected[{g.x(), g.y(), g.z()}] = v; });
    std::set<std::array<int, 3>> finished_blocks;
    std::array<int, 3> block{};
    bool first = true;
    u.forEachCellBySiblings([&](const Eigen::Vector3i& g, float v) {
      const std::array<int, 3> cell{g.x(), g.y(), g.z()};
      EXPECT_EQ(seen.count(cell), 0u) << "a cell twice";
      seen[cell] = v;
      const std::array<int, 3> b{g.x() >> 1, g.y() >> 1, g.z() >> 1};  // floor(g / 2): even-aligned blocks
      if (!first && b != block) {
        EXPECT_EQ(finished_blocks.count(b), 0u) << "a block visited again, trial " << trial;
        finished_blocks.insert(block);
      }
      block = b;
      first = false;
    });
    ASSERT_EQ(seen, expected) << "trial " << trial;
    // The same cells a block at a time: blocks at even global indices, each once and holding a cell.
    std::map<std::array<int, 3>, float> from_blocks;
    std::set<std::array<int, 3>> blocks;
    u.forEachSiblingBlock([&](const Eigen::Vector3i& g, const float(&values)[8]) {
      EXPECT_TRUE(((g.x() | g.y() | g.z()) & 1) == 0) << g.transpose();
      EXPECT_TRUE(blocks.insert({g.x(), g.y(), g.z()}).second) << "a block twice";
      int held = 0;
      for (int i = 0; i < 8; ++i)
        if (values[i] == values[i]) {
          ++held;
          from_blocks[{g.x() + (i & 1), g.y() + ((i >> 1) & 1), g.z() + (i >> 2)}] = values[i];
        }
      EXPECT_GT(held, 0);
    });
    ASSERT_EQ(from_blocks, expected) << "trial " << trial;
  }
}

// The accumulator over several frames of a flight (overlapping views, grids
// of every origin parity) against octomap's updateNode cell by cell in
// storage order: the same tree, node for node.
TEST(MapAccumulator, IntegrateEqualsUpdateNodeOverAFlight) {
  const FlightScenario scenario = makeScenario("posts");
  DrawingConfig drawing;
  drawing.algorithm = DrawingAlgorithm::kLinePyramid;
  drawing.resolution_m = 0.5;
  DisparityDrawer drawer(scenario.camera, drawing);
  MapAccumulatorConfig cfg;
  cfg.resolution_m = 0.5;
  MapAccumulator map(cfg);
  octomap::OcTree plain(0.5);
  plain.setClampingThresMin(cfg.clamping_min_prob);
  plain.setClampingThresMax(cfg.clamping_max_prob);
  plain.setOccupancyThres(cfg.occupancy_threshold_prob);
  const int offset = static_cast<int>(plain.coordToKey(0.0));
  for (size_t frame : {0u, 30u, 31u, 90u, 150u}) {
    const Eigen::Isometry3d T = scenario.cameraPose(frame);
    LocalGrid grid;
    drawer.draw(renderStereoFrame(scenario, frame, 1), T, &grid);
    GridUpdate update;
    encodeGridUpdate(grid, T.translation(), &update);
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
