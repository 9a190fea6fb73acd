// The whole-map outputs built tile by tile (MapSnapshot) are the live map's
// own, byte for byte, after every kind of change, and a refresh costs the
// tiles that changed.

#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <algorithm>
#include <array>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "../core/single_cell.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/projected_map.h"
#include "stereo_occupancy/store/map_snapshot.h"
#include "stereo_occupancy/store/mission_map.h"

using namespace stereo_occupancy;

namespace {
constexpr double kRes = 0.25;
constexpr double kMinZ = -1.0, kMaxZ = 2.0;  // a band that cuts the boxes below

MapSnapshotConfig snapshotConfig() {
  MapSnapshotConfig c;
  c.resolution_m = kRes;
  c.projection_min_z_m = kMinZ;
  c.projection_max_z_m = kMaxZ;
  return c;
}

/// A box of cells from global index @p lo, free with an occupied wall at its
/// far x end and an occupied cell every 7th, so that the tree has pruned free
/// leaves and single occupied ones.
GridUpdate box(const Eigen::Vector3i& lo, const Eigen::Vector3i& size, float free = -0.4f) {
  LocalGrid grid;
  grid.reset(lo, size, kRes);
  for (int z = 0; z < size.z(); ++z)
    for (int y = 0; y < size.y(); ++y)
      for (int x = 0; x < size.x(); ++x)
        grid.at(x, y, z) = x == size.x() - 1 || (x * 31 + y * 7 + z) % 7 == 0 ? 0.85f : free;
  GridUpdate u;
  encodeGridUpdate(grid, grid.cellCentre(0, size.y() / 2, size.z() / 2), &u);
  return u;
}

std::vector<std::array<float, 3>> sorted(std::vector<std::array<float, 3>> points) {
  std::sort(points.begin(), points.end());
  return points;
}

/// The snapshot's outputs against the tree's: octree data (binary and full),
/// occupied centres, projection.
void expectTheMapsOutputs(const MapSnapshot& snapshot, const octomap::OcTree& tree, const std::string& when) {
  SCOPED_TRACE(when);
  std::ostringstream from_snapshot, from_tree;
  snapshot.writeData(/*binary=*/true, from_snapshot);
  tree.writeBinaryData(from_tree);
  EXPECT_TRUE(from_snapshot.str() == from_tree.str()) << "binary data differs";
  std::ostringstream full_snapshot, full_tree;
  snapshot.writeData(/*binary=*/false, full_snapshot);
  tree.writeData(full_tree);
  EXPECT_TRUE(full_snapshot.str() == full_tree.str()) << "full data differs";
  // The bound messages reserve by: never short, and not far over.
  EXPECT_GE(snapshot.dataBytesBound(true), from_tree.str().size());
  EXPECT_GE(snapshot.dataBytesBound(false), full_tree.str().size());
  EXPECT_LE(snapshot.dataBytesBound(false), full_tree.str().size() + snapshot.numTiles() * 8 * 5);

  std::vector<std::array<float, 3>> centres, expected;
  snapshot.forEachOccupiedCentre([&](const octomap::point3d& p) { centres.push_back({p.x(), p.y(), p.z()}); });
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it)
    if (tree.isNodeOccupied(*it))
      expected.push_back({it.getCoordinate().x(), it.getCoordinate().y(), it.getCoordinate().z()});
  EXPECT_EQ(snapshot.numOccupied(), expected.size());
  EXPECT_TRUE(sorted(centres) == sorted(expected)) << "occupied centres differ";

  const ProjectedMap a = snapshot.projection(), b = projectOccupancy(tree, kMinZ, kMaxZ);
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_DOUBLE_EQ(a.origin_x_m, b.origin_x_m);
  EXPECT_DOUBLE_EQ(a.origin_y_m, b.origin_y_m);
  EXPECT_TRUE(a.cells == b.cells) << "projection differs";
}

/// Takes the mission's changes into @p snapshot; returns how many tiles came.
size_t refresh(MissionMap& mission, MapSnapshot& snapshot) {
  bool whole = false;
  const auto changes = mission.takeChangedTiles(snapshot.needsWholeMap(), &whole);
  snapshot.apply(changes, whole);
  return changes.size();
}
}  // namespace

TEST(MapSnapshot, IsTheLiveMapAfterUpdatesClearsPrunesAndResets) {
  MapAccumulatorConfig config;
  config.max_extent_m = 60.0;
  MissionMap mission(config);
  MapSnapshot snapshot(snapshotConfig());
  snapshot.setKeepFull(true);
  // Across tiles, negative indices too (a tile is 256 cells).
  ASSERT_TRUE(mission.integrate(box(Eigen::Vector3i(-300, -20, -6), Eigen::Vector3i(420, 24, 14))));
  ASSERT_TRUE(mission.integrate(box(Eigen::Vector3i(-40, 250, 0), Eigen::Vector3i(30, 12, 8), -2.0f)));
  EXPECT_GE(refresh(mission, snapshot), 4u);
  EXPECT_GE(snapshot.numTiles(), 4u);
  expectTheMapsOutputs(snapshot, mission.live().tree(), "after the first updates");

  // An update inside one tile: only that tile is encoded again.
  ASSERT_TRUE(mission.integrate(box(Eigen::Vector3i(10, 3, 1), Eigen::Vector3i(6, 5, 4), 0.6f)));
  EXPECT_EQ(refresh(mission, snapshot), 1u);
  expectTheMapsOutputs(snapshot, mission.live().tree(), "after a small update");
  EXPECT_EQ(refresh(mission, snapshot), 0u) << "nothing changed";

  mission.live().clearBox(Eigen::Vector3d(-80.0, -6.0, -2.0), Eigen::Vector3d(-60.0, 6.0, 4.0));
  refresh(mission, snapshot);
  expectTheMapsOutputs(snapshot, mission.live().tree(), "after clear_bbx");

  // Far away, many times: the start is pruned (no store), its tiles change or go.
  for (int i = 0; i < 2 * static_cast<int>(MapAccumulator::kPruneOrigins); ++i)
    ASSERT_TRUE(mission.integrate(singleCell(Eigen::Vector3i(1200 + i % 9, i % 5, i % 3), 0.85f)));
  ASSERT_GT(mission.maintain().leaves_dropped, 0u);
  refresh(mission, snapshot);
  expectTheMapsOutputs(snapshot, mission.live().tree(), "after a prune");

  mission.reset();
  refresh(mission, snapshot);
  EXPECT_EQ(snapshot.numTiles(), 0u);
  expectTheMapsOutputs(snapshot, mission.live().tree(), "after a reset");
}

TEST(MapSnapshot, TilesThatGoToTheStoreLeaveIt) {
  MapAccumulatorConfig config;
  config.max_extent_m = 40.0;
  MissionMap mission(config);
  const std::string path = ::testing::TempDir() + "/snapshot_store.db";
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
  mission.attachStore(std::make_shared<TileStore>(path, kRes));
  MapSnapshot snapshot(snapshotConfig());
  snapshot.setKeepFull(true);
  ASSERT_TRUE(mission.integrate(box(Eigen::Vector3i(-20, -10, -4), Eigen::Vector3i(60, 20, 10))));
  refresh(mission, snapshot);
  const size_t before = snapshot.numTiles();
  for (int i = 0; i < 2 * static_cast<int>(MapAccumulator::kPruneOrigins); ++i)
    ASSERT_TRUE(mission.integrate(singleCell(Eigen::Vector3i(4000 + i % 9, i % 5, i % 3), 0.85f)));
  ASSERT_GE(mission.maintain().tiles_stored, 1u);
  refresh(mission, snapshot);
  EXPECT_EQ(snapshot.numTiles(), mission.live().tiles().size()) << "the stored tiles stayed in the snapshot";
  EXPECT_LE(snapshot.numTiles(), before);
  expectTheMapsOutputs(snapshot, mission.live().tree(), "after tiles went to the store");
}

TEST(MapSnapshot, FullDataOnlyWhileKept) {
  MissionMap mission((MapAccumulatorConfig()));
  MapSnapshot snapshot(snapshotConfig());
  ASSERT_TRUE(mission.integrate(box(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(20, 8, 6))));
  refresh(mission, snapshot);
  EXPECT_FALSE(snapshot.needsWholeMap());
  std::ostringstream out;
  EXPECT_THROW(snapshot.writeData(/*binary=*/false, out), std::logic_error);
  snapshot.setKeepFull(true);
  EXPECT_TRUE(snapshot.needsWholeMap()) << "the tiles have no full data yet";
  refresh(mission, snapshot);
  expectTheMapsOutputs(snapshot, mission.live().tree(), "with full data");
}
