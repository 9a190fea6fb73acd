#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include "distance_field_scene.h"
#include "single_cell.h"
#include "stereo_occupancy/distance_field.h"

using namespace stereo_occupancy;

namespace {

constexpr double kRes = 0.25;

/// A small window (32 x 32 x 16 cells), so that the brute force stays quick.
DistanceFieldConfig smallWindow(bool unknown_is_occupied, double max_distance_m = 1.0) {
  DistanceFieldConfig c;
  c.window_xy_m = 8.0;
  c.window_z_m = 4.0;
  c.max_distance_m = max_distance_m;
  c.unknown_is_occupied = unknown_is_occupied;
  return c;
}

/// Every cell of the field's window against the brute force: its class and
/// its distance, exactly (the same float of the same squared distance).
::testing::AssertionResult matchesBruteForce(const FieldScene& scene) {
  const BruteForceField brute(scene.field, scene.map.tree());
  size_t wrong = 0;
  std::ostringstream first;
  for (int z = 0; z < brute.size.z(); ++z)
    for (int y = 0; y < brute.size.y(); ++y)
      for (int x = 0; x < brute.size.x(); ++x) {
        const Eigen::Vector3i l(x, y, z);
        const DistanceSample s = scene.field.sample(brute.centre(l, kRes));
        const size_t i = brute.index(l);
        const float expected = brute.distance(brute.sq[i], scene.field);
        if (s.in_window && s.cell_class == brute.classes[i] && s.distance_m == expected) continue;
        if (wrong++ < 5)
          first << " cell " << (brute.first + l).transpose() << ": in_window " << s.in_window << " class "
                << int(s.cell_class) << " (" << int(brute.classes[i]) << ") distance " << s.distance_m << " ("
                << expected << ");";
      }
  if (wrong == 0) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << wrong << " of " << brute.sq.size() << " cells differ:" << first.str();
}

/// The box of cells around @p W_vehicle that covers the small window and a margin beyond it.
void windowAndMargin(const Eigen::Vector3d& W_vehicle, Eigen::Vector3i* first, Eigen::Vector3i* size) {
  *size = Eigen::Vector3i(48, 48, 28);
  *first = (W_vehicle / kRes).array().floor().cast<int>().matrix() - *size / 2;
}

}  // namespace

// --- against the brute force --------------------------------------------------

/// (unknown_is_occupied, fusion threads, max_distance_m)
class DistanceFieldRandom : public ::testing::TestWithParam<std::tuple<bool, int, double>> {};

// Random maps fused through the accumulator (its class changes feed the
// field): updates that add and remove obstacles over the window and beyond
// its edges, small updates that change a few cells, and the vehicle moving
// by blocks along each axis, within the hysteresis, by a jump farther than
// the window and back: after each update every cell equals the brute force.
TEST_P(DistanceFieldRandom, EqualsTheBruteForceThroughUpdatesAndMoves) {
  const bool uio = std::get<0>(GetParam());
  FieldScene scene(smallWindow(uio, std::get<2>(GetParam())), std::get<1>(GetParam()));
  std::mt19937 rng(47);
  const std::vector<Eigen::Vector3d> path = {{0.1, 0.1, 0.1},   {1.0, 0.2, 0.1},   {3.1, 0.2, 0.1},   {3.1, -3.2, 1.0},
                                             {5.3, -5.0, -3.1}, {60.0, 40.0, 5.0}, {58.2, 41.0, 5.0}, {0.1, 0.1, 0.1}};
  size_t checks = 0;
  for (const Eigen::Vector3d& W_vehicle : path) {
    // The move alone first (no update): the cells that enter are read from
    // the map, those near the side that left are recomputed.
    scene.refresh(W_vehicle);
    EXPECT_TRUE(matchesBruteForce(scene)) << "moved to " << W_vehicle.transpose();
    Eigen::Vector3i first, size;
    windowAndMargin(W_vehicle, &first, &size);
    // Dense enough for obstacles everywhere, sparse enough for distances up to the saturation.
    ASSERT_TRUE(scene.integrate(randomUpdate(&rng, first, size, 0.3, 0.01), W_vehicle));
    EXPECT_TRUE(matchesBruteForce(scene)) << "at " << W_vehicle.transpose();
    ASSERT_TRUE(scene.integrate(randomUpdate(&rng, first, size, 0.5, 0.02), W_vehicle));
    EXPECT_TRUE(matchesBruteForce(scene)) << "at " << W_vehicle.transpose();
    // A few cells: obstacles come and go inside the window, at its edge and beyond.
    std::uniform_int_distribution<int> corner(0, 40);
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3i at = first + Eigen::Vector3i(corner(rng), corner(rng), corner(rng) / 2);
      ASSERT_TRUE(scene.integrate(randomUpdate(&rng, at, Eigen::Vector3i(4, 4, 4), 0.2, 0.3), W_vehicle));
    }
    EXPECT_TRUE(matchesBruteForce(scene)) << "at " << W_vehicle.transpose();
    checks += 4;
  }
  EXPECT_EQ(checks, 4 * path.size());
}

INSTANTIATE_TEST_SUITE_P(UnknownThreadsReach, DistanceFieldRandom,
                         ::testing::Values(std::make_tuple(false, 1, 1.0), std::make_tuple(true, 1, 1.0),
                                           std::make_tuple(false, 3, 1.0), std::make_tuple(true, 3, 1.0),
                                           std::make_tuple(false, 1, 2.0),   // the default reach: 7 cells
                                           std::make_tuple(true, 2, 2.6)));  // a reach beyond one block: 10 cells

// Moves through a map of few obstacles (most blocks that enter or leave
// hold none, so only the columns near the ones that do are recomputed):
// single blocks along each axis, diagonals across two and three axes, back
// and forth, each alone against the brute force.
TEST(DistanceField, MovesAmongFewObstacles) {
  for (bool uio : {false, true}) {
    DistanceFieldConfig config = smallWindow(uio, 1.0);
    config.window_xy_m = 16.0;  // 8 x 8 x 2 blocks
    FieldScene scene(config);
    std::mt19937 rng(13);
    // Known everywhere the window goes, but for a few unknown cells.
    ASSERT_TRUE(scene.integrate(
        randomUpdate(&rng, Eigen::Vector3i(-60, -60, -30), Eigen::Vector3i(120, 120, 60), 0.0002, 0.0002),
        Eigen::Vector3d(0.1, 0.1, 0.1)));
    EXPECT_TRUE(matchesBruteForce(scene));
    const std::vector<Eigen::Vector3d> path = {{2.3, 0.1, 0.1},    {2.3, 2.4, 0.1},   {4.5, 4.6, 0.1},
                                               {4.5, 4.6, 2.3},    {6.8, 2.2, -0.1},  {2.1, -2.3, -2.4},
                                               {-0.2, -4.5, -2.4}, {-4.6, -0.2, 2.2}, {0.1, 0.1, 0.1}};
    for (const Eigen::Vector3d& W_vehicle : path) {
      const Eigen::Vector3d before = scene.field.window().min();
      scene.refresh(W_vehicle);
      EXPECT_NE(scene.field.window().min(), before) << "no move to " << W_vehicle.transpose();
      EXPECT_TRUE(matchesBruteForce(scene)) << "uio " << uio << " at " << W_vehicle.transpose();
      // One block along x among few obstacles: the slab that entered (8 x 2
      // blocks) and at most one more layer of blocks, not its neighbours'
      // layer and the band that every block that enters and leaves would
      // take (3 layers); unless unknown is occupied (every known block then
      // differs from the outside).
      if (!uio && W_vehicle == path.front()) EXPECT_LE(scene.field.lastUpdatedCells(), 2u * 16u * 512u);
    }
  }
}

// A move along x and y at once: one obstacle in the block that leaves at the
// corner (beyond both new faces), no other near: the corner's cells forget it.
TEST(DistanceField, DiagonalMoveForgetsTheCornerThatLeft) {
  DistanceFieldConfig config = smallWindow(false, 1.0);
  config.window_xy_m = 16.0;  // blocks -4 .. 3 around the origin
  FieldScene scene(config);
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(-40, -40, -10), Eigen::Vector3i(80, 80, 20), kRes);
  std::fill(grid.data(), grid.data() + grid.numCells(), -2.0f);
  grid.at(15, 15, 10) = 2.0f;  // cell (-25, -25, 0): the corner of block (-4, -4, 0) nearest the origin
  GridUpdate update;
  encodeGridUpdate(grid, Eigen::Vector3d(0.1, 0.1, 0.1), &update);
  ASSERT_TRUE(scene.integrate(update, Eigen::Vector3d(0.1, 0.1, 0.1)));
  EXPECT_TRUE(matchesBruteForce(scene));
  EXPECT_FLOAT_EQ(scene.field.sample(Eigen::Vector3d(-22.5, -22.5, 0.5) * kRes).distance_m, std::sqrt(8.0f) * 0.25f);
  scene.refresh(Eigen::Vector3d(2.3, 2.3, 0.1));  // one block along x and y
  EXPECT_NEAR(scene.field.window().min().x(), -24 * kRes, 1e-9);
  EXPECT_TRUE(matchesBruteForce(scene));
  EXPECT_FLOAT_EQ(scene.field.sample(Eigen::Vector3d(-22.5, -22.5, 0.5) * kRes).distance_m, 1.0f);
}

// A reach beyond what pass 1 takes as one 64-bit word (6.5 m: 26 cells, 4
// blocks), in a window smaller than the reach: its scan, against the brute force.
TEST(DistanceField, LongReachEqualsTheBruteForce) {
  DistanceFieldConfig config = smallWindow(false, 6.5);
  config.window_xy_m = 4.0;
  config.window_z_m = 2.0;
  for (bool uio : {false, true}) {
    config.unknown_is_occupied = uio;
    FieldScene scene(config);
    std::mt19937 rng(7);
    const Eigen::Vector3d W_vehicle(0.1, 0.1, 0.1);
    ASSERT_TRUE(scene.integrate(
        randomUpdate(&rng, Eigen::Vector3i(-12, -12, -6), Eigen::Vector3i(24, 24, 12), 0.05, 0.002), W_vehicle));
    EXPECT_TRUE(matchesBruteForce(scene)) << "unknown_is_occupied " << uio;
    ASSERT_TRUE(scene.integrate(randomUpdate(&rng, Eigen::Vector3i(-4, -4, -2), Eigen::Vector3i(8, 8, 4), 0.1, 0.05),
                                W_vehicle));
    EXPECT_TRUE(matchesBruteForce(scene)) << "unknown_is_occupied " << uio;
  }
}

// Squared distances beyond what the passes' 16-bit lanes hold (20 m at
// 0.1 m: 40000 cells^2) go through 32-bit lanes: read whole, then updated
// from class changes, against a brute force over the window's obstacles.
TEST(DistanceField, WideLanesEqualTheBruteForce) {
  constexpr double kFine = 0.1;
  for (bool uio : {false, true}) {
    DistanceFieldConfig config;
    config.window_xy_m = 1.6;
    config.window_z_m = 1.6;
    config.max_distance_m = 20.0;
    config.unknown_is_occupied = uio;
    MapAccumulatorConfig map_config;
    map_config.resolution_m = kFine;
    MapAccumulator map(map_config);
    map.recordClassChanges(true);
    DistanceField field(config, kFine);
    const Eigen::Vector3d W_vehicle(0.01, 0.01, 0.01);
    std::mt19937 rng(uio ? 5 : 6);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int round = 0; round < 2; ++round) {
      LocalGrid grid;
      grid.reset(Eigen::Vector3i(-12, -12, -12), Eigen::Vector3i(24, 24, 24), kFine);
      for (int z = 0; z < 24; ++z)
        for (int y = 0; y < 24; ++y)
          for (int x = 0; x < 24; ++x)
            if (u(rng) > 0.2) grid.at(x, y, z) = u(rng) < 0.01 ? 2.0f : -2.0f;
      GridUpdate update;
      encodeGridUpdate(grid, W_vehicle, &update);
      ASSERT_TRUE(map.integrate(update));
      bool all = false;
      std::vector<CellBox> regions;
      const std::vector<CellClassChange> changes = map.takeClassChanges(&all, &regions);
      EXPECT_EQ(all, round == 0);
      field.update(map.tree(), changes, regions, all, W_vehicle);
      // The brute force: the nearest obstacle cell of the window, or the outside's nearest cell.
      const Eigen::Vector3i first = (field.window().min() / kFine).array().round().cast<int>();
      const Eigen::Vector3i size = (field.window().sizes() / kFine).array().round().cast<int>();
      ASSERT_EQ(size, Eigen::Vector3i(16, 16, 16));
      std::vector<Eigen::Vector3i> obstacles;
      for (int z = 0; z < size.z(); ++z)
        for (int y = 0; y < size.y(); ++y)
          for (int x = 0; x < size.x(); ++x) {
            const CellClass c = classInTree(map.tree(), first + Eigen::Vector3i(x, y, z));
            if (c == CellClass::kOccupied || (uio && c == CellClass::kUnknown)) obstacles.emplace_back(x, y, z);
          }
      ASSERT_FALSE(obstacles.empty());
      const int saturated_sq = 40000;
      size_t wrong = 0;
      for (int z = 0; z < size.z(); ++z)
        for (int y = 0; y < size.y(); ++y)
          for (int x = 0; x < size.x(); ++x) {
            const Eigen::Vector3i l(x, y, z);
            int best = saturated_sq;
            for (const Eigen::Vector3i& o : obstacles) best = std::min(best, (o - l).squaredNorm());
            for (int a = 0; a < 3 && uio; ++a) {
              const int step = std::min(l[a] + 1, size[a] - l[a]);
              best = std::min(best, step * step);
            }
            const float expected = best >= saturated_sq ? 20.0f : std::sqrt(static_cast<float>(best)) * 0.1f;
            const Eigen::Vector3d W_centre = ((first + l).cast<double>() + Eigen::Vector3d::Constant(0.5)) * kFine;
            wrong += field.sample(W_centre).distance_m != expected;
          }
      EXPECT_EQ(wrong, 0u) << "unknown_is_occupied " << uio << ", round " << round;
    }
  }
}

// Obstacles on the window's faces, edges and corners and just beyond them, in
// a map known everywhere: those beyond do not count (unknown is not occupied)
// or the whole outside does (unknown is occupied), as the brute force says.
TEST(DistanceField, ObstaclesAtTheWindowsEdges) {
  for (bool uio : {false, true}) {
    FieldScene scene(smallWindow(uio, 2.0));
    const Eigen::Vector3d W_vehicle(0.1, 0.1, 0.1);
    scene.refresh(W_vehicle);  // places the window
    const Eigen::AlignedBox3d box = scene.field.window();
    const Eigen::Vector3i lo = (box.min() / kRes).array().round().cast<int>();
    const Eigen::Vector3i hi = (box.max() / kRes).array().round().cast<int>().matrix() - Eigen::Vector3i::Ones();
    LocalGrid grid;
    grid.reset(lo - Eigen::Vector3i::Constant(3), hi - lo + Eigen::Vector3i::Constant(7), kRes);
    for (int z = 0; z < grid.size().z(); ++z)
      for (int y = 0; y < grid.size().y(); ++y)
        for (int x = 0; x < grid.size().x(); ++x) grid.at(x, y, z) = -2.0f;
    auto occupy = [&](const Eigen::Vector3i& g) {
      const Eigen::Vector3i l = g - grid.originIndex();
      grid.at(l.x(), l.y(), l.z()) = 2.0f;
    };
    occupy(lo);                                                 // a corner
    occupy(hi);                                                 // the opposite one
    occupy(Eigen::Vector3i(lo.x(), (lo.y() + hi.y()) / 2, 3));  // a face
    occupy(Eigen::Vector3i(hi.x() + 1, 2, 1));                  // just beyond a face
    occupy(Eigen::Vector3i(4, lo.y() - 2, 0));                  // two beyond another
    occupy(Eigen::Vector3i(lo.x() + 5, hi.y(), hi.z()));        // on an edge
    GridUpdate update;
    encodeGridUpdate(grid, W_vehicle, &update);
    ASSERT_TRUE(scene.integrate(update, W_vehicle));
    EXPECT_TRUE(matchesBruteForce(scene)) << "unknown_is_occupied " << uio;
    // The corner's neighbour: 1 cell from the corner (and, unknown being
    // occupied, from the outside).
    const DistanceSample s = scene.field.sample(BruteForceField(scene.field, scene.map.tree()).centre({1, 0, 0}, kRes));
    EXPECT_FLOAT_EQ(s.distance_m, 0.25f);
    // Next to the obstacle one beyond the face: it does not count unless the outside does.
    const Eigen::Vector3d W_inside((hi.x() + 0.5) * kRes, 2.5 * kRes, 1.5 * kRes);
    EXPECT_FLOAT_EQ(scene.field.sample(W_inside).distance_m, uio ? 0.25f : 2.0f);  // none within 2 m
  }
}

// Work follows the changes: one cell in the middle recomputes its block and
// the neighbours within reach (27 blocks), an update that changes no class nothing.
TEST(DistanceField, WorkFollowsTheChanges) {
  DistanceFieldConfig config;  // the default 50 x 50 x 10 m window, 2 m
  FieldScene scene(config);
  const Eigen::Vector3d W_vehicle(0.1, 0.1, 0.1);
  std::mt19937 rng(3);
  ASSERT_TRUE(scene.integrate(randomUpdate(&rng, Eigen::Vector3i(-40, -40, -10), Eigen::Vector3i(80, 80, 20), 0.0, 0.0),
                              W_vehicle));
  const size_t window_cells = 200 * 200 * 40;
  EXPECT_EQ(scene.field.lastUpdatedCells(), window_cells);  // the first: all
  EXPECT_EQ(scene.map_reads, 1u);
  GridUpdate one = randomUpdate(&rng, Eigen::Vector3i(4, 4, 4), Eigen::Vector3i(1, 1, 1), 0.0, 1.0);
  ASSERT_TRUE(scene.integrate(one, W_vehicle));
  EXPECT_EQ(scene.field.lastUpdatedCells(), 27u * 512u);
  ASSERT_TRUE(scene.integrate(one, W_vehicle));  // occupied already: no class changes
  EXPECT_EQ(scene.field.lastUpdatedCells(), 0u);
  // The class changes come from the fusion: the map was not asked for (nor its cache written back).
  EXPECT_EQ(scene.map_reads, 1u);
  ASSERT_TRUE(scene.integrate(one, W_vehicle + Eigen::Vector3d(8.0, 0.0, 0.0)));  // the window moves
  EXPECT_EQ(scene.map_reads, 2u);
  EXPECT_EQ(scene.field.sample(Eigen::Vector3d(4.5, 4.5, 4.5) * kRes).distance_m, 0.0f);
}

/// The window's cells (global indices) from its box in metres.
CellBox windowCellsOf(const DistanceField& field) {
  const Eigen::AlignedBox3d w = field.window();
  return CellBox((w.min() / kRes).array().round().cast<int>().matrix(),
                 (w.max() / kRes).array().round().cast<int>().matrix() - Eigen::Vector3i::Ones());
}

// A move reads the slab that enters, and only its cells are made current:
// the fusion's cache holds the rest of its changes back.
TEST(DistanceField, AMoveReadsOnlyTheSlabThatEnters) {
  FieldScene scene(smallWindow(false));
  const Eigen::Vector3d W_vehicle(0.1, 0.1, 0.1);
  ASSERT_TRUE(scene.integrate(singleCell(Eigen::Vector3i(-10, -10, 2), 2.0f), W_vehicle));
  const CellBox before = windowCellsOf(scene.field);
  ASSERT_EQ(scene.read_boxes.size(), 1u);  // placed: the window
  EXPECT_TRUE(scene.read_boxes[0].isApprox(before));
  // New obstacles: one inside both windows, one in the slab that enters, one above the windows.
  const Eigen::Vector3i inside = before.center(), entering(before.max().x() + 3, before.center().y(), 0);
  const Eigen::Vector3i above = inside + Eigen::Vector3i(0, 0, 40);
  ASSERT_TRUE(scene.map.integrate(singleCell(above, 2.0f)));
  ASSERT_TRUE(scene.map.integrate(singleCell(inside, 2.0f)));
  ASSERT_TRUE(scene.map.integrate(singleCell(entering, 2.0f)));
  scene.refresh(W_vehicle + Eigen::Vector3d(4.0, 0.0, 0.0));  // two blocks along x
  const CellBox after = windowCellsOf(scene.field);
  ASSERT_EQ(after.min(), before.min() + Eigen::Vector3i(16, 0, 0));
  ASSERT_EQ(scene.read_boxes.size(), 1u);
  EXPECT_EQ(scene.read_boxes[0].min(), Eigen::Vector3i(before.max().x() + 1, after.min().y(), after.min().z()));
  EXPECT_EQ(scene.read_boxes[0].max(), after.max());
  // The slab's cell was written back for the field to read; the others wait in the cache.
  const octomap::OcTree& as_is = scene.map.leafTree(CellBox());
  EXPECT_EQ(classInTree(as_is, entering), CellClass::kOccupied);
  EXPECT_EQ(classInTree(as_is, inside), CellClass::kUnknown);
  EXPECT_EQ(classInTree(as_is, above), CellClass::kUnknown);
  // The field has both (the inner one from the fusion's class changes), as the whole map has.
  EXPECT_EQ(scene.field.sample((entering.cast<double>().array() + 0.5).matrix() * kRes).distance_m, 0.0f);
  EXPECT_EQ(scene.field.sample((inside.cast<double>().array() + 0.5).matrix() * kRes).distance_m, 0.0f);
  EXPECT_TRUE(matchesBruteForce(scene));
  EXPECT_EQ(classInTree(scene.map.leafTree(CellBox()), inside), CellClass::kOccupied);  // written back by tree()
}

// What changes the map besides the updates comes as regions: a prune far
// from the window leaves every value as it was and reads nothing from the
// map; a tile dropped inside the window (and loaded again) is read again,
// only its part of the window, and the distances follow it exactly.
TEST(DistanceField, RegionsReadOnlyTheirPartOfTheWindow) {
  for (bool uio : {false, true}) {
    SCOPED_TRACE(uio ? "unknown is occupied" : "unknown is free");
    FieldScene scene(smallWindow(uio));
    const Eigen::Vector3d W_vehicle(0.1, 0.1, 0.1);
    std::mt19937 rng(12);
    Eigen::Vector3i first, size;
    windowAndMargin(W_vehicle, &first, &size);
    ASSERT_TRUE(scene.integrate(randomUpdate(&rng, first, size, 0.3, 0.01), W_vehicle));
    // Seen 300 m away (beyond max_extent_m = 200 m), then kPruneOrigins updates near the window.
    ASSERT_TRUE(scene.integrate(randomUpdate(&rng, Eigen::Vector3i(1200, 0, 0), Eigen::Vector3i(8, 8, 8), 0.0, 0.5),
                                W_vehicle));
    const GridUpdate near = randomUpdate(&rng, Eigen::Vector3i(2, 2, 2), Eigen::Vector3i(2, 2, 2), 0.0, 0.5);
    for (size_t i = 0; i < MapAccumulator::kPruneOrigins; ++i) ASSERT_TRUE(scene.integrate(near, W_vehicle));
    ASSERT_TRUE(matchesBruteForce(scene));
    const BruteForceField before(scene.field, scene.map.tree());
    ASSERT_GT(scene.map.prune(), 0u);
    const size_t reads = scene.map_reads;
    scene.refresh(W_vehicle);
    EXPECT_EQ(scene.field.lastReadCells(), 0u);
    EXPECT_EQ(scene.map_reads, reads);  // its regions lie outside the window
    EXPECT_EQ(scene.field.lastUpdatedCells(), 0u);
    EXPECT_TRUE(matchesBruteForce(scene));
    const BruteForceField after(scene.field, scene.map.tree());
    EXPECT_EQ(after.sq, before.sq);
    // Tile 0 holds the window's positive octant: 2 x 2 x 1 of its 4 x 4 x 2 blocks.
    const MapAccumulator::TileIndex tile(0, 0, 0);
    const std::vector<MapAccumulator::Leaf> leaves = scene.map.tileLeaves(tile);
    ASSERT_GT(scene.map.dropTile(tile), 0u);
    scene.refresh(W_vehicle);
    EXPECT_EQ(scene.field.lastReadCells(), 4u * 512u);
    EXPECT_GT(scene.field.lastUpdatedCells(), 0u);
    EXPECT_TRUE(matchesBruteForce(scene)) << "tile dropped";
    scene.map.insertLeaves(leaves);
    scene.refresh(W_vehicle);
    EXPECT_EQ(scene.field.lastReadCells(), 4u * 512u);
    EXPECT_TRUE(matchesBruteForce(scene)) << "tile loaded";
    EXPECT_EQ(BruteForceField(scene.field, scene.map.tree()).sq, before.sq);
    // A cleared box (cells -8 .. -1 on each axis) reads its one block only.
    ASSERT_GT(scene.map.clearBox(Eigen::Vector3d(-2.0, -2.0, -2.0), Eigen::Vector3d(-0.1, -0.1, -0.1)), 0u);
    scene.refresh(W_vehicle);
    EXPECT_EQ(scene.field.lastReadCells(), 512u);
    EXPECT_TRUE(matchesBruteForce(scene)) << "box cleared";
  }
}

// --- queries ------------------------------------------------------------------

namespace {
/// A small window known free everywhere but one occupied cell at @p obstacle,
/// and the unknown box [unknown_first, +unknown_size) left out.
struct OneObstacle {
  explicit OneObstacle(const DistanceFieldConfig& config, const Eigen::Vector3i& obstacle = Eigen::Vector3i(0, 0, 0),
                       const Eigen::Vector3i& unknown_first = Eigen::Vector3i(8, 8, -8),
                       const Eigen::Vector3i& unknown_size = Eigen::Vector3i(4, 4, 16))
      : scene(config) {
    LocalGrid grid;
    grid.reset(Eigen::Vector3i(-20, -20, -10), Eigen::Vector3i(40, 40, 20), kRes);
    for (int z = 0; z < 20; ++z)
      for (int y = 0; y < 40; ++y)
        for (int x = 0; x < 40; ++x) {
          const Eigen::Vector3i g = grid.originIndex() + Eigen::Vector3i(x, y, z);
          const bool unknown =
              ((g - unknown_first).array() >= 0).all() && ((g - unknown_first).array() < unknown_size.array()).all();
          grid.at(x, y, z) = unknown ? LocalGrid::kUnknown : (g == obstacle ? 2.0f : -2.0f);
        }
    GridUpdate update;
    encodeGridUpdate(grid, Eigen::Vector3d(0.6, 0.6, 0.6), &update);
    EXPECT_TRUE(scene.integrate(update, Eigen::Vector3d(0.1, 0.1, 0.1)));
  }
  static Eigen::Vector3d centre(int x, int y, int z) {
    return (Eigen::Vector3d(x, y, z) + Eigen::Vector3d::Constant(0.5)) * kRes;
  }
  FieldScene scene;
};
}  // namespace

// The distance and its gradient near one obstacle: exact distances along
// the axes and a diagonal, a gradient pointing away from it of magnitude 1,
// zero where saturated; outside the window and at NaN: unknown.
TEST(DistanceField, SampleNearOneObstacle) {
  OneObstacle o(smallWindow(false, 1.0));
  const DistanceField& f = o.scene.field;
  EXPECT_EQ(f.sample(OneObstacle::centre(0, 0, 0)).cell_class, CellClass::kOccupied);
  EXPECT_EQ(f.sample(OneObstacle::centre(0, 0, 0)).distance_m, 0.0f);
  for (int k = 1; k <= 3; ++k) {
    const DistanceSample s = f.sample(OneObstacle::centre(k, 0, 0));
    EXPECT_TRUE(s.in_window);
    EXPECT_EQ(s.cell_class, CellClass::kFree);
    EXPECT_FLOAT_EQ(s.distance_m, k * 0.25f);
    EXPECT_NEAR(s.gradient.x(), 1.0f, 1e-5) << k;  // (d(k + 1) - d(k - 1)) / 2 cells
    EXPECT_NEAR(s.gradient.y(), 0.0f, 1e-5);
    EXPECT_NEAR(f.sample(OneObstacle::centre(0, -k, 0)).gradient.y(), -1.0f, 1e-5);
    EXPECT_NEAR(f.sample(OneObstacle::centre(0, 0, k)).gradient.z(), 1.0f, 1e-5);
  }
  EXPECT_FLOAT_EQ(f.sample(OneObstacle::centre(2, 2, 1)).distance_m, 3 * 0.25f);  // sqrt(4 + 4 + 1) cells
  EXPECT_FLOAT_EQ(f.sample(OneObstacle::centre(1, 1, 1)).distance_m, std::sqrt(3.0f) * 0.25f);
  const DistanceSample saturated = f.sample(OneObstacle::centre(4, 0, 0));  // 1 m = max_distance_m
  EXPECT_FLOAT_EQ(saturated.distance_m, 1.0f);
  EXPECT_EQ(saturated.gradient, Eigen::Vector3f::Zero());
  const DistanceSample near_diagonal = f.sample(OneObstacle::centre(2, 2, 0));
  EXPECT_GT(near_diagonal.gradient.x(), 0.0f);
  EXPECT_GT(near_diagonal.gradient.y(), 0.0f);
  EXPECT_EQ(f.sample(OneObstacle::centre(9, 9, 0)).cell_class, CellClass::kUnknown);  // the unknown box
  for (const Eigen::Vector3d& W_p :
       {Eigen::Vector3d(100.0, 0.0, 0.0), Eigen::Vector3d(0.0, 0.0, -3.0),
        Eigen::Vector3d(std::numeric_limits<double>::quiet_NaN(), 0.0, 0.0), Eigen::Vector3d(1e300, 1e300, 0.0)}) {
    const DistanceSample s = f.sample(W_p);
    EXPECT_FALSE(s.in_window) << W_p.transpose();
    EXPECT_EQ(s.cell_class, CellClass::kUnknown);
    EXPECT_TRUE(std::isnan(s.distance_m));
    EXPECT_EQ(s.gradient, Eigen::Vector3f::Zero());
  }
}

namespace {

uint32_t bitsOf(float v) {
  uint32_t b;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

/// @p batch is @p single bit for bit (a NaN distance the same NaN).
::testing::AssertionResult sameBits(const DistanceSample& batch, const DistanceSample& single) {
  bool same = batch.in_window == single.in_window && batch.cell_class == single.cell_class &&
              bitsOf(batch.distance_m) == bitsOf(single.distance_m);
  for (int a = 0; a < 3; ++a) same = same && bitsOf(batch.gradient[a]) == bitsOf(single.gradient[a]);
  if (same) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "batch: in_window " << batch.in_window << " class " << int(batch.cell_class)
                                       << " distance " << batch.distance_m << " gradient " << batch.gradient.transpose()
                                       << "; sample(): in_window " << single.in_window << " class "
                                       << int(single.cell_class) << " distance " << single.distance_m << " gradient "
                                       << single.gradient.transpose();
}

}  // namespace

// The batch sample() answers what sample() answers, bit for bit, for each
// point of a random map's window and beyond: random points, cell centres
// and faces next to the window's faces, the faces themselves, NaN, infinite
// and huge points; in batches shorter and longer than the prefetch distance
// (whose ring of points ahead must hand each answer to its own point), and
// an empty one.
TEST(DistanceField, BatchSampleEqualsSample) {
  for (bool uio : {false, true}) {
    FieldScene scene(smallWindow(uio, 1.0));
    std::mt19937 rng(4747);
    const Eigen::Vector3d W_vehicle(0.1, 0.1, 0.1);
    Eigen::Vector3i first, size;
    windowAndMargin(W_vehicle, &first, &size);
    ASSERT_TRUE(scene.integrate(randomUpdate(&rng, first, size, 0.3, 0.01), W_vehicle));
    const DistanceField& f = scene.field;
    const Eigen::AlignedBox3d box = f.window();
    const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();

    std::vector<Eigen::Vector3d> points;
    std::uniform_real_distribution<double> u(-0.2, 1.2);  // beyond each face too
    auto random = [&] {
      return Eigen::Vector3d(box.min() + (box.max() - box.min()).cwiseProduct(Eigen::Vector3d(u(rng), u(rng), u(rng))));
    };
    for (int k = 0; k < 3000; ++k) points.push_back(random());
    // The window's faces (the upper ones outside), the cells next to them, a cell's faces.
    for (int a = 0; a < 3; ++a)
      for (double along : {box.min()[a], box.min()[a] + 0.5 * kRes, box.max()[a] - 0.5 * kRes, box.max()[a],
                           box.max()[a] - 1e-9, box.min()[a] - 1e-9, std::round(box.center()[a] / kRes) * kRes}) {
        for (int k = 0; k < 20; ++k) {
          Eigen::Vector3d p = random().cwiseMax(box.min()).cwiseMin(box.max() - Eigen::Vector3d::Constant(1e-6));
          p[a] = along;
          points.push_back(p);
        }
      }
    points.push_back(box.min());
    points.push_back(box.max() - Eigen::Vector3d::Constant(0.5 * kRes));
    // Not finite or far: one coordinate or all.
    for (double bad : {nan, inf, -inf, 1e300, -1e300})
      for (int a = 0; a < 3; ++a) {
        Eigen::Vector3d p = box.center();
        p[a] = bad;
        points.push_back(p);
      }
    points.push_back(Eigen::Vector3d::Constant(nan));
    std::shuffle(points.begin(), points.end(), rng);

    std::vector<DistanceSample> single;
    size_t outside = 0, with_gradient = 0, occupied = 0;
    for (const Eigen::Vector3d& p : points) {
      single.push_back(f.sample(p));
      outside += !single.back().in_window;
      with_gradient += single.back().gradient != Eigen::Vector3f::Zero();
      occupied += single.back().cell_class == CellClass::kOccupied;
    }
    // The set reaches every kind of answer.
    EXPECT_GT(outside, 200u);
    EXPECT_GT(with_gradient, 500u);
    EXPECT_GT(occupied, 5u);

    std::vector<DistanceSample> batch = {DistanceSample(), DistanceSample()};  // resized to the points
    f.sample(points, &batch);
    ASSERT_EQ(batch.size(), points.size());
    size_t wrong = 0;
    for (size_t i = 0; i < points.size(); ++i) {
      const ::testing::AssertionResult same = sameBits(batch[i], single[i]);
      if (!same && wrong++ < 5)
        ADD_FAILURE() << "uio " << uio << " point " << i << " " << points[i].transpose() << ": " << same.message();
    }
    EXPECT_EQ(wrong, 0u) << "uio " << uio;

    // Short batches (below, at and just above the prefetch distance) at each offset of the points.
    for (size_t count : {size_t{1}, size_t{2}, DistanceField::kPrefetchPoints - 1, DistanceField::kPrefetchPoints,
                         DistanceField::kPrefetchPoints + 1, 2 * DistanceField::kPrefetchPoints + 3}) {
      std::vector<DistanceSample> out(count + 1);
      const DistanceSample sentinel = out.back();
      for (size_t offset = 0; offset + count <= points.size(); offset += 97) {
        f.sample(points.data() + offset, count, out.data());
        for (size_t i = 0; i < count; ++i)
          ASSERT_TRUE(sameBits(out[i], single[offset + i])) << "count " << count << " offset " << offset << " i " << i;
        ASSERT_TRUE(sameBits(out[count], sentinel)) << "count " << count << ": wrote past the end";
      }
    }
  }
  // An empty batch: nothing read, nothing written.
  OneObstacle o(smallWindow(false, 1.0));
  o.scene.field.sample(nullptr, 0, nullptr);
  std::vector<DistanceSample> out(3);
  o.scene.field.sample(std::vector<Eigen::Vector3d>(), &out);
  EXPECT_TRUE(out.empty());
}

// Path checks: clear with the smallest clearance along it, blocked at the
// right segment and where it enters the first cell too near, a radius that
// fits, radius 0 through the obstacle, unknown space (blocked if asked), the
// window's edge, one waypoint.
TEST(DistanceField, CheckPath) {
  OneObstacle o(smallWindow(false, 1.0));
  const DistanceField& f = o.scene.field;
  using V = Eigen::Vector3d;
  const double y_m = 0.125 + 0.5;  // the row of cells 2 from the obstacle's: 0.5 m
  // Along x at 0.5 m from the obstacle, in three segments; the second passes it.
  const std::vector<V> path = {V(-2.4, y_m, 0.125), V(-1.0, y_m, 0.125), V(1.0, y_m, 0.125), V(2.4, y_m, 0.125)};
  PathCheckResult r = f.checkPath(path, 0.5, false);
  EXPECT_EQ(r.verdict, PathVerdict::kClear);
  EXPECT_EQ(r.first_segment, -1);
  EXPECT_DOUBLE_EQ(r.min_clearance_m, 0.5);
  r = f.checkPath(path, 0.6, false);
  EXPECT_EQ(r.verdict, PathVerdict::kBlocked);
  EXPECT_EQ(r.first_segment, 1);
  // It enters cell (-1, 2, 0), sqrt(5) * 0.25 = 0.56 m from the obstacle, at x = -0.25 m.
  EXPECT_NEAR(r.W_point.x(), -0.25, 1e-9);
  EXPECT_NEAR(r.W_point.y(), y_m, 1e-9);
  EXPECT_LT(f.sample(r.W_point + V(1e-6, 0, 0)).distance_m, 0.6f);
  EXPECT_GE(f.sample(r.W_point - V(1e-6, 0, 0)).distance_m, 0.6f);
  EXPECT_NEAR(r.min_clearance_m, std::sqrt(5.0) * 0.25, 1e-6);
  // Through the obstacle's cell with radius 0: blocked there.
  r = f.checkPath({V(-1.0, 0.1, 0.1), V(1.0, 0.1, 0.1)}, 0.0, false);
  EXPECT_EQ(r.verdict, PathVerdict::kBlocked);
  EXPECT_NEAR(r.W_point.x(), 0.0, 1e-9);
  // Into the unknown box (cells 8..11 in x and y): unknown, or blocked if asked.
  const std::vector<V> into_unknown = {V(-1.0, 2.5, 0.1), V(1.0, 2.5, 0.1), V(3.0, 2.5, 0.1)};
  r = f.checkPath(into_unknown, 0.25, false);
  EXPECT_EQ(r.verdict, PathVerdict::kUnknown);
  EXPECT_EQ(r.first_segment, 1);
  EXPECT_NEAR(r.W_point.x(), 2.0, 1e-9);
  EXPECT_DOUBLE_EQ(r.min_clearance_m, 1.0);
  r = f.checkPath(into_unknown, 0.25, true);
  EXPECT_EQ(r.verdict, PathVerdict::kBlocked);
  EXPECT_EQ(r.first_segment, 1);
  EXPECT_NEAR(r.W_point.x(), 2.0, 1e-9);
  // Out of the window (x up to 4 m): unknown where it leaves it.
  r = f.checkPath({V(0.1, -2.0, 0.1), V(10.0, -2.0, 0.1)}, 0.25, false);
  EXPECT_EQ(r.verdict, PathVerdict::kUnknown);
  EXPECT_EQ(r.first_segment, 0);
  EXPECT_NEAR(r.W_point.x(), f.window().max().x(), 1e-9);
  // Starting outside: unknown at the start; a path entirely outside too.
  r = f.checkPath({V(-50.0, -2.0, 0.1), V(0.1, -2.0, 0.1)}, 0.25, false);
  EXPECT_EQ(r.verdict, PathVerdict::kUnknown);
  EXPECT_NEAR(r.W_point.x(), -50.0, 1e-9);
  EXPECT_EQ(f.checkPath({V(-50.0, 0, 0), V(-60.0, 0, 0)}, 0.0, false).verdict, PathVerdict::kUnknown);
  EXPECT_EQ(f.checkPath({V(-50.0, 0, 0), V(-60.0, 0, 0)}, 0.0, true).verdict, PathVerdict::kBlocked);
  // One waypoint: its cell.
  EXPECT_EQ(f.checkPath({OneObstacle::centre(0, 0, 0)}, 0.0, false).verdict, PathVerdict::kBlocked);
  r = f.checkPath({OneObstacle::centre(3, 0, 0)}, 0.5, false);
  EXPECT_EQ(r.verdict, PathVerdict::kClear);
  EXPECT_DOUBLE_EQ(r.min_clearance_m, 0.75);
  // A blocked segment after an unknown one: blocked wins.
  r = f.checkPath({V(-50.0, 0.1, 0.1), V(-1.0, 0.1, 0.1), V(1.0, 0.1, 0.1)}, 0.3, false);
  EXPECT_EQ(r.verdict, PathVerdict::kBlocked);
  EXPECT_EQ(r.first_segment, 1);
}

// A 1 km path (most of it outside the window) checks in well under 1 ms.
TEST(DistanceField, LongPathChecksFast) {
  OneObstacle o(DistanceFieldConfig{});
  std::vector<Eigen::Vector3d> path;
  for (int i = 0; i <= 100; ++i) path.emplace_back(-20.0 + 10.0 * i, 3.0 * std::sin(i * 0.3), 0.5);
  const auto t0 = std::chrono::steady_clock::now();
  const PathCheckResult r = o.scene.field.checkPath(path, 0.5, false);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.verdict, PathVerdict::kUnknown);  // it leaves the window
  EXPECT_LT(ms, 5.0);  // 1 ms is the goal (the benchmark measures it); loose here for loaded machines
}

// Ray casts: a hit at the obstacle's cell, free up to a short range, unknown
// at the unknown box, at the window's edge, and from outside.
TEST(DistanceField, CastRay) {
  OneObstacle o(smallWindow(false, 1.0));
  const DistanceField& f = o.scene.field;
  using V = Eigen::Vector3d;
  RayCastResult r = f.castRay(V(-1.0, 0.125, 0.125), V(2.0, 0.0, 0.0), 5.0);
  EXPECT_EQ(r.verdict, RayVerdict::kHit);
  EXPECT_TRUE(r.W_point.isApprox(OneObstacle::centre(0, 0, 0)));
  EXPECT_NEAR(r.range_m, 1.0, 1e-9);
  r = f.castRay(V(-1.0, 0.125, 0.125), V(1.0, 0.0, 0.0), 0.5);
  EXPECT_EQ(r.verdict, RayVerdict::kFree);
  EXPECT_NEAR(r.range_m, 0.5, 1e-12);
  EXPECT_TRUE(r.W_point.isApprox(V(-0.5, 0.125, 0.125)));
  r = f.castRay(V(2.1, 0.1, 0.1), V(0.0, 1.0, 0.0), 10.0);  // up into the unknown box at y = 2 m
  EXPECT_EQ(r.verdict, RayVerdict::kUnknown);
  EXPECT_NEAR(r.range_m, 1.9, 1e-9);
  EXPECT_TRUE(r.W_point.isApprox(OneObstacle::centre(8, 8, 0)));
  r = f.castRay(V(0.1, -1.1, 0.1), V(0.0, -1.0, 0.0), 100.0);  // down to the window's edge at y = -4 m
  EXPECT_EQ(r.verdict, RayVerdict::kUnknown);
  EXPECT_NEAR(r.range_m, 2.9, 1e-9);
  EXPECT_FALSE(f.window().contains(r.W_point));
  EXPECT_NEAR(r.W_point.y(), -4.125, 1e-9);                    // the first cell beyond it
  r = f.castRay(V(30.0, 0.0, 0.0), V(-1.0, 0.0, 0.0), 100.0);  // from outside
  EXPECT_EQ(r.verdict, RayVerdict::kUnknown);
  EXPECT_EQ(r.range_m, 0.0);
  r = f.castRay(OneObstacle::centre(0, 0, 0), V(0.0, 0.0, 1.0), 0.0);  // range 0 in the obstacle
  EXPECT_EQ(r.verdict, RayVerdict::kHit);
}

// Bad input is refused with std::invalid_argument, saying what is wrong.
TEST(DistanceField, RefusesBadInput) {
  OneObstacle o(smallWindow(false, 1.0));
  const DistanceField& f = o.scene.field;
  using V = Eigen::Vector3d;
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  auto refused = [](const std::function<void()>& call, const std::string& says) {
    try {
      call();
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
      return;
    }
    ADD_FAILURE() << "not refused: " << says;
  };
  const std::vector<V> ok = {V(0.5, 0.5, 0.5), V(1.0, 0.5, 0.5)};
  refused([&] { f.checkPath({}, 0.1, false); }, "0 waypoints");
  refused([&] { f.checkPath({V(0.5, 0.5, 0.5), V(nan, 0.0, 0.0)}, 0.1, false); }, "waypoint 1 is NaN");
  refused([&] { f.checkPath({V(inf, 0.0, 0.0)}, 0.1, false); }, "waypoint 0 is NaN or infinite");
  refused([&] { f.checkPath(ok, -0.1, false); }, "radius");
  refused([&] { f.checkPath(ok, 1.5, false); }, "max_distance_m");
  refused([&] { f.checkPath(ok, nan, false); }, "radius");
  {
    // 10^7 waypoints: refused by their count before anything is read (the
    // vector's pages are never touched: Eigen leaves them uninitialised).
    const std::vector<V> many(10000000);
    const auto t0 = std::chrono::steady_clock::now();
    refused([&] { f.checkPath(many, 0.1, false); }, "10000000 waypoints");
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 0.1);
  }
  refused([&] { f.castRay(V(nan, 0, 0), V(1, 0, 0), 1.0); }, "origin");
  refused([&] { f.castRay(V(0, 0, 0), V(inf, 0, 0), 1.0); }, "direction");
  refused([&] { f.castRay(V(0, 0, 0), V(0, 0, 0), 1.0); }, "direction is zero");
  refused([&] { f.castRay(V(0, 0, 0), V(1e-320, 0, 0), 1.0); }, "direction is zero");  // a denormal norm
  refused([&] { f.castRay(V(0, 0, 0), V(1, 0, 0), -1.0); }, "range");
  refused([&] { f.castRay(V(0, 0, 0), V(1, 0, 0), inf); }, "range");
  refused([&] { f.castRay(V(0, 0, 0), V(1, 0, 0), nan); }, "range");
  refused([&] { DistanceField(smallWindow(false), 0.0); }, "resolution");
  refused([&] { DistanceField(smallWindow(false), nan); }, "resolution");
  refused([&] { DistanceField(smallWindow(false, 0.01), 0.25); }, "max_distance_m");
  DistanceFieldConfig huge;
  huge.window_xy_m = 1000.0;
  refused([&] { DistanceField(huge, 0.05); }, "cells");
  DistanceField other(smallWindow(false), 0.5);
  refused([&] { other.update(o.scene.map.tree(), {}, true, V::Zero()); }, "resolution");
  // Through a map source: refused before the field changes (a jump would have moved the window).
  other.update(octomap::OcTree(0.5), {}, true, V::Zero());
  const Eigen::AlignedBox3d window = other.window();
  const DistanceField::MapSource source = [&](const CellBox&) -> const octomap::OcTree& {
    return o.scene.map.leafTree();
  };
  refused([&] { other.update(source, {}, {}, false, V(100.0, 0.0, 0.0)); }, "resolution");
  EXPECT_TRUE(other.window().isApprox(window));
}

// The slice: the layer's known cells with their distances; none outside the window.
TEST(DistanceField, SliceHoldsTheLayersKnownCells) {
  OneObstacle o(smallWindow(false, 1.0));
  const DistanceField& f = o.scene.field;
  std::vector<Eigen::Vector3f> centres;
  std::vector<float> distances;
  f.slice(0.1, &centres, &distances);
  const BruteForceField brute(f, o.scene.map.tree());
  size_t known = 0;
  const int lz = -brute.first.z();  // the layer of z = 0.1 m
  for (int y = 0; y < brute.size.y(); ++y)
    for (int x = 0; x < brute.size.x(); ++x) known += brute.classes[brute.index({x, y, lz})] != CellClass::kUnknown;
  ASSERT_EQ(centres.size(), known);
  ASSERT_EQ(distances.size(), known);
  EXPECT_LT(known, static_cast<size_t>(brute.size.x() * brute.size.y()));  // the unknown box is left out
  for (size_t i = 0; i < centres.size(); ++i) {
    EXPECT_FLOAT_EQ(centres[i].z(), 0.125f);
    EXPECT_EQ(distances[i], f.sample(centres[i].cast<double>()).distance_m);
  }
  f.slice(50.0, &centres, &distances);
  EXPECT_TRUE(centres.empty());
  EXPECT_TRUE(distances.empty());
}
