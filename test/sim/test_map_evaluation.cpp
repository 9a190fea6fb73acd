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

namespace {

/// A post (0.4 m, 6 m tall, its face at x = 10 m) on the ground, with a 10 cm
/// cable at 4 m height from the post's axis 5 m to the left, seen from
/// (0, 2, 3) looking along +x: one frame.
FlightScenario postAndWire() {
  FlightScenario s;
  s.scene.ground_height_m = 0.0;
  s.scene.addBox({10.0, -0.2, 0.0}, {10.4, 0.2, 6.0});     // 0: the post
  s.scene.addBox({10.15, 0.0, 3.95}, {10.25, 5.0, 4.05});  // 1: the cable, its end inside the post
  s.T_B_C = lookingAlongX(Eigen::Vector3d::Zero());
  Eigen::Isometry3d T_W_B = Eigen::Isometry3d::Identity();
  T_W_B.translation() = Eigen::Vector3d(0.0, 2.0, 3.0);
  s.T_W_B.push_back(T_W_B);
  return s;
}

}  // namespace

// An obstacle shows when an occupied cell lies at its surface or beside it,
// not where another solid's surface is: the ground at the post's foot does
// not show the post, nor the post's face below the cable the cable, and the
// cells where the cable meets the post show neither.
TEST(MapEvaluation, ObstaclesShowInTheirOwnZones) {
  const FlightScenario s = postAndWire();
  const ObstacleZones zones = observeObstacles(s, kCell, 25.0);
  ASSERT_EQ(zones.zones.size(), 2u);
  EXPECT_EQ(zones.observedCount(), 2u);
  auto inZone = [&](size_t k, const Eigen::Vector3d& p) {
    const uint64_t key = packCell(LocalGrid::globalIndex(p, kCell));
    return std::binary_search(zones.zones[k].begin(), zones.zones[k].end(), key);
  };
  EXPECT_TRUE(inZone(0, {10.1, 0.1, 5.1}));   // the post's face
  EXPECT_TRUE(inZone(0, {9.9, 0.1, 5.1}));    // one cell in front of it
  EXPECT_FALSE(inZone(0, {9.6, 0.1, 5.1}));   // two cells in front
  EXPECT_FALSE(inZone(0, {9.9, 0.1, -0.1}));  // the ground before its foot
  EXPECT_TRUE(inZone(1, {10.1, 2.6, 3.9}));   // the cable, 2.6 m left
  EXPECT_FALSE(inZone(1, {10.1, 0.1, 3.6}));  // the post's face below the cable
  EXPECT_FALSE(inZone(0, {10.1, 2.6, 3.9}));
  for (double z : {3.9, 4.1}) {  // the cells holding the post's face and the cable's end
    EXPECT_FALSE(inZone(0, {10.1, 0.1, z})) << z;
    EXPECT_FALSE(inZone(1, {10.1, 0.1, z})) << z;
  }

  DetectionTracker tracker(zones, s.scene);
  octomap::OcTree map(kCell);
  const Eigen::Vector3d W_camera = s.cameraPose(0).translation();
  tracker.update(map, 0, W_camera);
  occupy(&map, {9.9, 0.1, -0.1});  // the ground at the post's foot
  occupy(&map, {10.1, 0.1, 3.6});  // the post's face below the cable
  tracker.update(map, 1, W_camera);
  EXPECT_EQ(tracker.detections()[0].frame, 1);
  EXPECT_NEAR(tracker.detections()[0].distance_m, std::hypot(10.0, 1.8), 1e-9);  // to the post's nearest point
  EXPECT_FALSE(tracker.detections()[1].detected());
  occupy(&map, {10.1, 2.6, 3.9});  // the cable
  const Eigen::Vector3d W_nearer(4.0, 2.0, 3.0);
  tracker.update(map, 2, W_nearer);
  tracker.update(map, 3, W_nearer);
  EXPECT_EQ(tracker.detections()[0].frame, 1);  // the first detection stays
  EXPECT_EQ(tracker.detections()[1].frame, 2);
  EXPECT_NEAR(tracker.detections()[1].distance_m, std::hypot(6.15, 0.95), 1e-9);
}

// The summary counts an obstacle as later than the reference's when it
// showed more than the tolerance's frames after it or never.
TEST(MapEvaluation, DetectionSummaryAgainstAReference) {
  ObstacleZones zones;
  zones.resolution_m = kCell;
  zones.zones = {{1}, {2}, {}, {3}, {4}};  // box 2 was never seen: not counted
  const std::vector<Detection> mine = {{5, 20.0}, {3, 22.0}, {}, {}, {9, 14.0}};
  const std::vector<Detection> octomap = {{3, 23.0}, {3, 22.0}, {1, 30.0}, {7, 16.0}, {}};
  const DetectionSummary s = summarizeDetections(zones, mine, &octomap);
  EXPECT_EQ(s.observed, 4u);
  EXPECT_EQ(s.detected, 3u);
  EXPECT_DOUBLE_EQ(s.median_distance_m, 20.0);
  EXPECT_DOUBLE_EQ(s.min_distance_m, 14.0);
  EXPECT_EQ(s.later_than_reference, 2u);    // box 0 two frames later, box 3 never
  EXPECT_EQ(s.earlier_than_reference, 1u);  // box 4, which OctoMap never showed
  EXPECT_EQ(summarizeDetections(zones, mine, &octomap, 2).later_than_reference, 1u);
  EXPECT_EQ(summarizeDetections(zones, mine, nullptr).later_than_reference, 0u);
}
