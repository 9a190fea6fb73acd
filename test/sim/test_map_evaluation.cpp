// Scoring a map against ground truth: precision, recall, F1, phantom
// obstacles (occupied cells in free air, more than a cell from any surface)
// and the range bands.

#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <cmath>
#include <limits>

#include "stereo_occupancy/sim/map_evaluation.h"

using namespace stereo_occupancy;

namespace {

constexpr double kCell = 0.25;

/// A 3 m cube at x 10..13 and the truth that one surface cell of it was seen
/// from the origin.
struct Fixture {
  SyntheticScene scene;
  ObservedGroundTruth truth;
  Fixture() {
    scene.addBox({10.0, 0.0, 0.0}, {13.0, 3.0, 3.0});
    truth.resolution_m = kCell;
    truth.surface.insert(packCell(LocalGrid::globalIndex({10.1, 0.6, 0.6}, kCell)));
    truth.viewpoints.push_back(Eigen::Vector3d::Zero());
  }
};

void occupy(octomap::OcTree* map, const Eigen::Vector3d& p) { map->updateNode(p.x(), p.y(), p.z(), 2.0f); }

}  // namespace

TEST(MapEvaluation, PhantomsAreOccupiedCellsInFreeAirAwayFromSurfaces) {
  Fixture f;
  octomap::OcTree map(kCell);
  occupy(&map, {10.1, 0.6, 0.6});  // at the surface: found, precise
  occupy(&map, {9.9, 0.6, 0.6});   // one cell in front: within one cell, precise
  occupy(&map, {11.6, 1.6, 1.6});  // inside the solid (distance 0 to a solid): no phantom
  occupy(&map, {8.1, 0.6, 0.6});   // 2 m in front, in free air: a phantom
  occupy(&map, {10.6, 4.6, 1.6});  // beside the cube, in free air: a phantom
  const MapQuality q = evaluateMap(map, f.scene, f.truth);
  EXPECT_EQ(q.occupied_cells, 5u);
  EXPECT_EQ(q.occupied_at_surface, 3u);
  EXPECT_EQ(q.occupied_phantom, 2u);
  EXPECT_DOUBLE_EQ(q.phantomShare(), 0.4);
  EXPECT_EQ(q.surface_found, 1u);
  EXPECT_DOUBLE_EQ(q.occupiedPrecision(), 0.6);
  EXPECT_DOUBLE_EQ(q.occupiedRecall(), 1.0);
  EXPECT_NEAR(q.f1(), 2 * 0.6 / 1.6, 1e-12);
  EXPECT_NE(q.toJson().find("\"occupied_phantom\": 2"), std::string::npos) << q.toJson();
}

// A band counts the cells whose nearest viewpoint lies within it.
TEST(MapEvaluation, RangeBandsSplitByTheNearestViewpoint) {
  Fixture f;
  octomap::OcTree map(kCell);
  occupy(&map, {10.1, 0.6, 0.6});  // 10.1 m from the origin: band 10-20
  occupy(&map, {8.1, 0.6, 0.6});   // 8.1 m: band 0-10
  occupy(&map, {22.1, 0.6, 0.6});  // 22.1 m: band 20+
  const std::vector<RangeBand> bands = standardRangeBands();
  ASSERT_EQ(bands.size(), 3u);
  EXPECT_EQ(bands[0].name(), "0-10 m");
  EXPECT_EQ(bands[2].name(), "20+ m");
  const MapQuality near = evaluateMap(map, f.scene, f.truth, bands[0]);
  const MapQuality mid = evaluateMap(map, f.scene, f.truth, bands[1]);
  const MapQuality far = evaluateMap(map, f.scene, f.truth, bands[2]);
  EXPECT_EQ(near.occupied_cells, 1u);
  EXPECT_EQ(near.occupied_phantom, 1u);
  EXPECT_EQ(near.truth_surface_cells, 0u);
  EXPECT_EQ(mid.occupied_cells, 1u);
  EXPECT_EQ(mid.occupied_at_surface, 1u);
  EXPECT_EQ(mid.truth_surface_cells, 1u);
  EXPECT_EQ(far.occupied_cells, 1u);
  EXPECT_EQ(near.occupied_cells + mid.occupied_cells + far.occupied_cells,
            evaluateMap(map, f.scene, f.truth).occupied_cells);
  // A second viewpoint 9 m along x brings the cell at 10.1 m into the first band.
  f.truth.viewpoints.push_back(Eigen::Vector3d(9.0, 0.6, 0.6));
  EXPECT_EQ(evaluateMap(map, f.scene, f.truth, bands[0]).occupied_cells, 2u);
}

// observeGroundTruth keeps the viewpoints it observed from.
TEST(MapEvaluation, GroundTruthKeepsItsViewpoints) {
  const FlightScenario scenario = makeScenario("posts_far");
  const ObservedGroundTruth truth = observeGroundTruth(scenario, 0.5, 25.0, 50, 16);
  ASSERT_EQ(truth.viewpoints.size(), 4u);  // frames 0, 50, 100, 150
  EXPECT_NEAR(truth.viewpoints[0].x(), scenario.cameraPose(0).translation().x(), 1e-12);
  // The far-view flight stays 12-40 m before its first gate (x = 15 m).
  EXPECT_NEAR(scenario.T_W_B.front().translation().x(), 14.8 - 40.0, 1e-9);
  EXPECT_LT(scenario.T_W_B.back().translation().x(), 14.8 - 12.0 + 0.01);
  EXPECT_GT(truth.surface.size(), 100u);
}
