// The surface profile (beyond the paper): occupied only at the measured
// surface, a gap of no information before it, free before the gap, nothing
// behind. The exact model, its table, the bound it gives the bounded
// pyramid, and what it draws.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "stereo_occupancy/surface_guards.h"
#include "stereo_occupancy/worker_pool.h"

using namespace stereo_occupancy;

namespace {

constexpr double kCell = 0.25;

double logit(double p) { return std::log(p / (1.0 - p)); }

InverseSensorModelConfig surfaceConfig() {
  InverseSensorModelConfig c;
  c.profile = SensorProfile::kSurface;
  return c;
}

DrawingConfig surfaceDrawing(DrawingAlgorithm algorithm) {
  DrawingConfig d;
  d.algorithm = algorithm;
  d.resolution_m = kCell;
  d.sensor_model = surfaceConfig();
  return d;
}

/// Camera 2 m above ground level looking along +x.
Eigen::Isometry3d camera() { return lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0)); }

float valueAt(const LocalGrid& grid, const Eigen::Vector3d& W_point) {
  const Eigen::Vector3i local = LocalGrid::globalIndex(W_point, kCell) - grid.originIndex();
  return grid.contains(local) ? grid.at(local.x(), local.y(), local.z()) : LocalGrid::kUnknown;
}

}  // namespace

TEST(SurfaceProfile, NamesAndValidation) {
  SensorProfile p;
  ASSERT_TRUE(parseSensorProfile("surface", &p));
  EXPECT_EQ(p, SensorProfile::kSurface);
  ASSERT_TRUE(parseSensorProfile("gaussian", &p));
  EXPECT_EQ(p, SensorProfile::kGaussian);
  EXPECT_FALSE(parseSensorProfile("bresenham", &p));
  EXPECT_STREQ(toString(SensorProfile::kSurface), "surface");
  InverseSensorModelConfig c = surfaceConfig();
  EXPECT_TRUE(c.isValid());
  c.p_hit = 0.5;
  EXPECT_FALSE(c.isValid());
  c = surfaceConfig();
  c.p_free = 0.5;
  EXPECT_FALSE(c.isValid());
  c = surfaceConfig();
  c.p_sky = 0.2;  // stronger than p_free: refused
  EXPECT_FALSE(c.isValid());
  c = surfaceConfig();
  c.free_gap_sigmas = 4.5;
  EXPECT_FALSE(c.isValid());
  EXPECT_FALSE(InverseSensorModelConfig() == surfaceConfig());
}

// The exact model: p_hit where the cell's window holds l_p, 0.5 (log-odds 0)
// in the gap and behind, p_free before the gap; the table serves the same.
TEST(SurfaceProfile, ExactModelAndTableAgree) {
  const InverseSensorModel model(surfaceConfig());
  const LogOddsTable table(model, kCell);
  const double l_p = 15.0, dl = 0.6;
  EXPECT_NEAR(model.logOddsHat(l_p, l_p, dl, kCell), logit(0.68), 1e-12);
  EXPECT_NEAR(model.logOddsHat(l_p - 0.12, l_p, dl, kCell), logit(0.68), 1e-12);  // the window holds l_p
  EXPECT_NEAR(model.logOddsHat(l_p + 0.12, l_p, dl, kCell), logit(0.68), 1e-12);
  EXPECT_EQ(model.logOddsHat(l_p - 0.125 - 0.3, l_p, dl, kCell), 0.0);                   // in the gap (0.6 m)
  EXPECT_NEAR(model.logOddsHat(l_p - 0.125 - 0.61, l_p, dl, kCell), logit(0.3), 1e-12);  // before it
  EXPECT_EQ(model.logOddsHat(l_p + 0.2, l_p, dl, kCell), 0.0);                           // behind: nothing
  const RangeProfile profile = table.profile(static_cast<float>(l_p), static_cast<float>(dl));
  EXPECT_NEAR(profile.endRange(), l_p + 0.125 + dl / LogOddsTable::kSamplesPerSigma, 1e-5);
  for (double l = l_p - 3.5; l <= profile.endRange(); l += 0.013) {
    const double e = l < l_p - 0.125 ? l - l_p + 0.125 : (l > l_p + 0.125 ? l - l_p - 0.125 : 0.0);
    if (e != 0.0 && std::abs(e) < dl / 32.0) continue;  // within one table sample of the window's edge
    if (std::abs(e + dl) < dl / 32.0) continue;         // ... of the gap's start
    EXPECT_NEAR(profile.at(static_cast<float>(l)), model.logOddsHat(l, l_p, dl, kCell), 1e-4) << l;
  }
  // A ray without a range (zero disparity): p_sky, by default p_free.
  EXPECT_NEAR(table.freeProfile().at(10.0f), logit(0.3), 1e-6);
  InverseSensorModelConfig weak_sky = surfaceConfig();
  weak_sky.p_sky = 0.45;
  EXPECT_NEAR(LogOddsTable(InverseSensorModel(weak_sky), kCell).freeProfile().at(10.0f), logit(0.45), 1e-6);
  // The paper's profile keeps its free value for the sky.
  const LogOddsTable paper(InverseSensorModel(InverseSensorModelConfig()), kCell);
  EXPECT_NEAR(paper.freeProfile().at(10.0f), logit(0.35), 1e-6);
}

// The surface profile's table is one step (free, then 0): stepSample(), which
// the lines' windows use, gives sample()'s value bit for bit at every
// position and gap width; the paper's profile has no step.
TEST(SurfaceProfile, StepSampleIsTheTablesSample) {
  for (double gap : {0.0, 0.4, 1.0, 2.5, 3.9}) {
    InverseSensorModelConfig c = surfaceConfig();
    c.free_gap_sigmas = gap;
    const LogOddsTable table(InverseSensorModel(c), kCell);
    for (float dl : {0.02f, 0.6f, 3.0f}) {
      const RangeProfile profile = table.profile(15.0f, dl);
      ASSERT_GE(profile.step_sample, 0) << gap;
      EXPECT_EQ(profile.row[0], table.freeLogOdds());
      const float last = (LogOddsTable::kFrontSigmas + LogOddsTable::kTailSigmas) * LogOddsTable::kSamplesPerSigma;
      size_t free = 0, zero = 0, between = 0;
      for (float x = 0.0f; x <= last; x = std::nextafter(x + 1.0f / 64.0f, last + 1.0f)) {
        const float a = profile.sample(x), b = profile.stepSample(x);
        ASSERT_EQ(std::memcmp(&a, &b, sizeof(float)), 0) << "x " << x << " gap " << gap << ": " << a << " " << b;
        free += a == table.freeLogOdds();
        zero += a == 0.0f;
        between += a != 0.0f && a != table.freeLogOdds();
      }
      EXPECT_GT(free, 0u);
      EXPECT_GT(zero, 0u);
      EXPECT_GT(between, 0u) << "the step's own sample interpolates";
    }
  }
  const LogOddsTable paper(InverseSensorModel(InverseSensorModelConfig()), kCell);
  EXPECT_EQ(paper.profile(15.0f, 0.6f).step_sample, -1);
}

// The bounded pyramid's bound: a nearer pixel must lie where the far line
// does not call it free, that is within c/2 + the gap.
TEST(SurfaceProfile, BoundReachesOverTheGap) {
  const StereoCameraModel cam{StereoCameraConfig()};
  const InverseSensorModel model(surfaceConfig());
  const DisparityBlockBound bound(cam, model, kCell);
  const auto d = [&](double z) { return static_cast<float>(cam.disparityFromDepth(z)); };
  for (double z_far : {5.0, 12.0, 20.0}) {
    SCOPED_TRACE(z_far);
    const double reach = 0.5 * kCell + cam.depthUncertainty(z_far);  // free_gap_sigmas = 1
    EXPECT_TRUE(bound.isFaithful(d(z_far), d(z_far - 0.97 * reach)));
    EXPECT_FALSE(bound.isFaithful(d(z_far), d(z_far - 1.03 * reach)));
  }
  EXPECT_FALSE(bound.isFaithful(d(20.0), d(8.0)));  // a post before a wall
  EXPECT_FALSE(bound.isFaithful(0.0f, d(10.0)));    // a wire against the sky
}

// A wall at 12 m: the surface profile leaves everything behind it untouched
// (the paper's draws a tail of occupied cells into it), and calls no cell
// in front of it occupied beyond one cell.
TEST(SurfaceProfile, NothingBehindTheSurfaceAndNoSlabBeforeIt) {
  SyntheticScene scene;
  scene.addBox({12.0, -20.0, -5.0}, {14.0, 20.0, 10.0});
  const cv::Mat disparity = renderDisparity(scene, StereoCameraModel(StereoCameraConfig()), camera());
  auto draw = [&](const DrawingConfig& config) {
    DisparityDrawer drawer(StereoCameraConfig(), config);
    LocalGrid grid;
    drawer.draw(disparity, camera(), &grid);
    return grid;
  };
  DrawingConfig paper_config = surfaceDrawing(DrawingAlgorithm::kLinePyramidBounded);
  paper_config.sensor_model = InverseSensorModelConfig();
  const LocalGrid surface = draw(surfaceDrawing(DrawingAlgorithm::kLinePyramidBounded));
  const LocalGrid paper = draw(paper_config);
  int surface_behind = 0, paper_behind = 0, surface_front = 0, at_wall = 0, wall_cells = 0;
  for (double y = -2.0; y < 2.0; y += kCell)
    for (double z = 1.0; z < 3.0; z += kCell) {
      for (double x = 12.6; x < 14.0; x += kCell) {  // more than one cell behind the wall's face
        surface_behind += valueAt(surface, {x, y, z}) != LocalGrid::kUnknown && valueAt(surface, {x, y, z}) != 0.0f;
        paper_behind += valueAt(paper, {x, y, z}) > 0.0f;
      }
      for (double x = 2.0; x < 11.7; x += kCell) surface_front += valueAt(surface, {x, y, z}) > 0.0f;
      ++wall_cells;
      at_wall += valueAt(surface, {12.1, y, z}) > 0.0f || valueAt(surface, {11.9, y, z}) > 0.0f;
    }
  EXPECT_EQ(surface_behind, 0);
  EXPECT_GT(paper_behind, 100);  // the tail of eq. 9 reaches 3 Δl (1 m at 12 m) into the wall
  EXPECT_EQ(surface_front, 0);
  EXPECT_EQ(at_wall, wall_cells);
}

// A wall seen by a camera yawed 45 degrees to the grid's axes: every
// pixel's hit lands in the cell that holds its measured point, and next to
// no other cell is occupied (points on a cell's face aside).
// A line's walk takes one cell per slab of its major axis (up to 1.4 cells
// of range here); a cell-wide window around the slab's centre misses the
// point in 1 - |d_major| of a slab's range, and its cell is not always the
// point's.
TEST(SurfaceProfile, EachHitLandsInItsPointsCell) {
  SyntheticScene scene;
  scene.addBox({14.0, -40.0, -5.0}, {16.0, 40.0, 10.0});
  const StereoCameraModel cam{StereoCameraConfig()};
  const Eigen::Isometry3d T_W_C = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0), M_PI / 4.0);
  const cv::Mat disparity = renderDisparity(scene, cam, T_W_C);
  DisparityDrawer drawer(StereoCameraConfig(), surfaceDrawing(DrawingAlgorithm::kLine));
  LocalGrid grid;
  drawer.draw(disparity, T_W_C, &grid);
  std::vector<char> point_cell(grid.numCells(), 0);
  int pixels = 0, hit = 0;
  for (int y = 0; y < disparity.rows; ++y)
    for (int x = 0; x < disparity.cols; ++x) {
      const float d = disparity.at<float>(y, x);
      if (!cam.isValidDisparity(d) || !measuresRange(cam, d)) continue;
      const Eigen::Vector3d C_point = cam.rayThroughPixel(x, y) * cam.depthFromDisparity(d);
      if (C_point.norm() > cam.config().max_range_m) continue;
      const Eigen::Vector3i local = LocalGrid::globalIndex(T_W_C * C_point, kCell) - grid.originIndex();
      ASSERT_TRUE(grid.contains(local));
      ++pixels;
      hit += grid.at(local.x(), local.y(), local.z()) > 0.0f;
      point_cell[grid.linearIndex(local.x(), local.y(), local.z())] = 1;
    }
  // The drawing computes the point as this test does, T_W_C·(z·C_ray), and
  // multiplies it by 1/c, here 4 exactly: every point's cell (the hit at the
  // float range along the unit ray, before, missed one in 2·10^5).
  ASSERT_GT(pixels, 50000);
  EXPECT_EQ(hit, pixels);
  size_t occupied = 0, occupied_elsewhere = 0;
  for (size_t i = 0; i < grid.numCells(); ++i) {
    occupied += grid.data()[i] > 0.0f;
    occupied_elsewhere += grid.data()[i] > 0.0f && !point_cell[i];
  }
  ASSERT_GT(occupied, 1000u);
  EXPECT_LE(occupied_elsewhere, occupied / 100);
}

namespace {

/// The cells with a point hit (log-odds > 0) as global indices, sorted.
std::vector<Eigen::Vector3i> occupiedCells(const LocalGrid& grid) {
  std::vector<Eigen::Vector3i> cells;
  const Eigen::Vector3i size = grid.size();
  for (int z = 0; z < size.z(); ++z)
    for (int y = 0; y < size.y(); ++y)
      for (int x = 0; x < size.x(); ++x)
        if (grid.at(x, y, z) > 0.0f) cells.push_back(grid.originIndex() + Eigen::Vector3i(x, y, z));
  return cells;
}

/// A real matcher's errors, roughly: streaks of disparity spread by up to
/// @p spread_px, outliers, and holes.
cv::Mat withMatcherErrors(const cv::Mat& disparity, double spread_px, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> spread(-static_cast<float>(spread_px), static_cast<float>(spread_px));
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  cv::Mat out = disparity.clone();
  for (int y = 0; y < out.rows; ++y)
    for (int x = 0; x < out.cols; ++x) {
      float& d = out.at<float>(y, x);
      const float u = unit(rng);
      if (u < 0.05f)
        d = std::numeric_limits<float>::quiet_NaN();  // no match
      else if (u < 0.07f)
        d = 1.0f + 60.0f * unit(rng);  // an outlier
      else if (d > 0.0f)
        d = std::max(0.5f, d + spread(rng));
    }
  return out;
}

}  // namespace

// The default (bounded pyramid, surface profile) draws each pixel's hit,
// not one per block: its occupied cells are per-pixel line's exactly, and
// each is the cell of one pixel's point T_W_C·(z·C_ray) (eqs. 1, 2), for
// any pose (cells off the origin, a wall on a cell face, turned cameras),
// real-matcher-like disparities and 1 or 2 threads. One hit per block, at
// its farthest disparity, lost the nearer ones (a real matcher's
// disparities in a block spread over more than a cell of depth).
TEST(SurfaceProfile, BoundedPyramidOccupiesThePixelLinesCells) {
  SyntheticScene scene;
  scene.addBox({-50.0, -50.0, -1.0}, {100.0, 50.0, 0.0});  // the ground, on a cell face
  scene.addBox({14.0, -40.0, -5.0}, {16.0, 40.0, 10.0});   // its faces on cell faces
  scene.addBox({6.3, -1.1, 0.0}, {6.7, -0.7, 3.0});
  const StereoCameraConfig camera_config;
  const StereoCameraModel cam(camera_config);
  const std::vector<Eigen::Isometry3d> poses = {
      lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0)),
      lookingAlongX(Eigen::Vector3d(0.37, -0.81, 2.13), 0.3, 0.1),
      lookingAlongX(Eigen::Vector3d(-3.0, 2.0, 6.0), -0.4, 0.35),
  };
  size_t checked = 0;
  for (size_t i = 0; i < poses.size(); ++i)
    for (double spread_px : {0.0, 1.5}) {
      SCOPED_TRACE(::testing::Message() << "pose " << i << ", spread " << spread_px << " px");
      const cv::Mat disparity = withMatcherErrors(renderDisparity(scene, cam, poses[i]), spread_px, 7 + i);
      DisparityDrawer line(camera_config, surfaceDrawing(DrawingAlgorithm::kLine));
      LocalGrid line_grid;
      line.draw(disparity, poses[i], &line_grid);
      const std::vector<Eigen::Vector3i> expected = occupiedCells(line_grid);
      ASSERT_GT(expected.size(), 1000u);
      for (int threads : {1, 2}) {
        DrawingConfig config = surfaceDrawing(DrawingAlgorithm::kLinePyramidBounded);
        config.threads = threads;
        DisparityDrawer bounded(camera_config, config);
        LocalGrid grid;
        bounded.draw(disparity, poses[i], &grid);
        EXPECT_EQ(occupiedCells(grid), expected) << threads << " threads";
        ++checked;
      }
      // Each occupied cell holds a pixel's point.
      std::vector<Eigen::Vector3i> point_cells;
      for (int y = 0; y < disparity.rows; ++y)
        for (int x = 0; x < disparity.cols; ++x) {
          const float d = disparity.at<float>(y, x);
          if (!cam.isValidDisparity(d) || !measuresRange(cam, d)) continue;
          const Eigen::Vector3d C_point = cam.rayThroughPixel(x, y) * cam.depthFromDisparity(d);
          if (C_point.norm() <= camera_config.max_range_m)
            point_cells.push_back(LocalGrid::globalIndex(poses[i] * C_point, kCell));
        }
      auto less = [](const Eigen::Vector3i& a, const Eigen::Vector3i& b) {
        return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
      };
      std::sort(point_cells.begin(), point_cells.end(), less);
      point_cells.erase(std::unique(point_cells.begin(), point_cells.end()), point_cells.end());
      std::vector<Eigen::Vector3i> sorted = expected;
      std::sort(sorted.begin(), sorted.end(), less);
      EXPECT_EQ(sorted, point_cells);
    }
  EXPECT_EQ(checked, 12u);
}

// The thin obstacles of the bounded-pyramid tests: with the surface profile
// the bounded pyramid still keeps the post before the wall and the wire
// against the sky, none of their cells called free.
TEST(SurfaceProfile, BoundedPyramidKeepsThinObstacles) {
  struct Case {
    const char* what;
    SyntheticScene scene;
    Eigen::Vector3d lo, hi;
  };
  std::vector<Case> cases(2);
  cases[0].what = "post before a wall";
  cases[0].scene.addBox({20.0, -15.0, -5.0}, {21.0, 15.0, 10.0});
  cases[0].scene.addBox({8.1 - 0.025, 0.37 - 0.025, -1.0}, {8.1 + 0.025, 0.37 + 0.025, 5.0});
  cases[0].lo = {8.1, 0.37, 1.0};
  cases[0].hi = {8.1, 0.37, 2.99};
  cases[1].what = "wire against the sky";
  cases[1].scene.addBox({10.1 - 0.01, -4.0, 3.1 - 0.01}, {10.1 + 0.01, 4.0, 3.1 + 0.01});
  cases[1].lo = {10.1, -3.5, 3.1};
  cases[1].hi = {10.1, 3.49, 3.1};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    const cv::Mat disparity = renderDisparity(c.scene, StereoCameraModel(StereoCameraConfig()), camera());
    DisparityDrawer drawer(StereoCameraConfig(), surfaceDrawing(DrawingAlgorithm::kLinePyramidBounded));
    LocalGrid grid;
    drawer.draw(disparity, camera(), &grid);
    const Eigen::Vector3i lo = LocalGrid::globalIndex(c.lo, kCell), hi = LocalGrid::globalIndex(c.hi, kCell);
    int cells = 0, occupied = 0, free = 0;
    for (int z = lo.z(); z <= hi.z(); ++z)
      for (int y = lo.y(); y <= hi.y(); ++y)
        for (int x = lo.x(); x <= hi.x(); ++x) {
          const Eigen::Vector3i local = Eigen::Vector3i(x, y, z) - grid.originIndex();
          ASSERT_TRUE(grid.contains(local));
          const float v = grid.at(local.x(), local.y(), local.z());
          ++cells;
          occupied += v > 0.0f;
          free += v < 0.0f && v != LocalGrid::kUnknown;
        }
    EXPECT_GT(cells, 7);
    EXPECT_EQ(occupied, cells);
    EXPECT_EQ(free, 0);
  }
}

// A 2 cm wire against the sky that the matcher misses in every other stretch
// of 40 pixel columns (too thin to match there: zero disparity, as sky). The
// missed pixels' sky rays cross the wire's cells beside the matched ones:
// without the sky guard they call some of them free; with it (the default,
// one cell) none, while the sky a metre above the wire stays free.
TEST(SurfaceProfile, SkyGuardKeepsAPartlyMatchedWire) {
  SyntheticScene scene;
  scene.addBox({10.1 - 0.01, -4.0, 3.1 - 0.01}, {10.1 + 0.01, 4.0, 3.1 + 0.01});
  const StereoCameraModel cam{StereoCameraConfig()};
  cv::Mat disparity = renderDisparity(scene, cam, camera());
  int matched = 0, missed = 0;
  for (int y = 0; y < disparity.rows; ++y)
    for (int x = 0; x < disparity.cols; ++x) {
      float& d = disparity.at<float>(y, x);
      if (!(d > 0.0f)) continue;
      if ((x / 40) % 2) {
        d = 0.0f;
        ++missed;
      } else {
        ++matched;
      }
    }
  ASSERT_GT(matched, 50);
  ASSERT_GT(missed, 50);
  auto wireCellsCalledFree = [&](int guard_cells, int* sky_free) {
    DrawingConfig config = surfaceDrawing(DrawingAlgorithm::kLinePyramidBounded);
    config.sensor_model.sky_guard_cells = guard_cells;
    DisparityDrawer drawer(StereoCameraConfig(), config);
    LocalGrid grid;
    drawer.draw(disparity, camera(), &grid);
    int free = 0;
    *sky_free = 0;
    for (double y = -3.5; y < 3.5; y += kCell) {
      const float wire = valueAt(grid, {10.1, y, 3.1}), sky = valueAt(grid, {10.1, y, 4.1});
      free += wire < 0.0f && wire != LocalGrid::kUnknown;
      *sky_free += sky < 0.0f && sky != LocalGrid::kUnknown;
    }
    return free;
  };
  int sky_free_unguarded = 0, sky_free_guarded = 0;
  EXPECT_GT(wireCellsCalledFree(0, &sky_free_unguarded), 3);
  EXPECT_EQ(wireCellsCalledFree(1, &sky_free_guarded), 0);
  EXPECT_EQ(sky_free_guarded, sky_free_unguarded);
  EXPECT_GT(sky_free_guarded, 20);
}

// The gap guard: a wall at 20.1 m, where the gap is Δl = 0.95 m deep (four
// cells). Without the guard the whole gap says nothing, so a noise hit two
// cells in front of the wall would never be cleared by later views of it;
// with one cell of guard the gap is free there and says nothing only in the
// cell next to the wall's.
TEST(SurfaceProfile, GapGuardFreesTheGapAwayFromHits) {
  SyntheticScene scene;
  scene.addBox({20.1, -20.0, -5.0}, {22.0, 20.0, 10.0});
  const cv::Mat disparity = renderDisparity(scene, StereoCameraModel(StereoCameraConfig()), camera());
  auto draw = [&](int gap_guard_cells) {
    DrawingConfig config = surfaceDrawing(DrawingAlgorithm::kLinePyramidBounded);
    config.sensor_model.gap_guard_cells = gap_guard_cells;
    DisparityDrawer drawer(StereoCameraConfig(), config);
    LocalGrid grid;
    drawer.draw(disparity, camera(), &grid);
    return grid;
  };
  const LocalGrid whole_gap = draw(0), guarded = draw(1);
  const float free = static_cast<float>(logit(surfaceConfig().p_free));
  int columns = 0;
  for (double y = -1.0; y < 1.0; y += kCell)
    for (double z = 1.0; z < 3.0; z += kCell) {
      ++columns;
      EXPECT_GT(valueAt(whole_gap, {20.15, y, z}), 0.0f);  // the wall's cell
      EXPECT_GT(valueAt(guarded, {20.15, y, z}), 0.0f);
      EXPECT_EQ(valueAt(whole_gap, {19.9, y, z}), 0.0f);  // next to it: the gap in both
      EXPECT_EQ(valueAt(guarded, {19.9, y, z}), 0.0f);
      EXPECT_EQ(valueAt(whole_gap, {19.6, y, z}), 0.0f);  // two cells in front
      EXPECT_EQ(valueAt(guarded, {19.6, y, z}), free);
      EXPECT_EQ(valueAt(whole_gap, {15.0, y, z}), free);  // before the gap: free in both
      EXPECT_EQ(valueAt(guarded, {15.0, y, z}), free);
    }
  EXPECT_EQ(columns, 64);
}

// A 0.2 m post 0.3-0.6 m in front of a wall at 20 m lies in the gap of the
// wall's line, over which the bounded pyramid's bound lets one line cover
// the block. The post's pixels still give their own hits: its face is
// occupied in the cells per-pixel drawing gives it and none of the post is
// called free, with the gap guard off (the default) or on. (One hit per
// block, at its farthest disparity, left the post unknown, and the guard
// freed it.)
TEST(SurfaceProfile, BoundedPyramidKeepsAPostBeforeAWall) {
  for (double gap_m : {0.3, 0.45, 0.6}) {
    SCOPED_TRACE(gap_m);
    SyntheticScene scene;
    scene.addBox({20.1, -20.0, -5.0}, {22.0, 20.0, 10.0});
    scene.addBox({19.9 - gap_m, -0.1, 0.0}, {20.1 - gap_m, 0.1, 4.0});
    const cv::Mat disparity = renderDisparity(scene, StereoCameraModel(StereoCameraConfig()), camera());
    auto postCells = [&](DrawingAlgorithm algorithm, int gap_guard_cells) {
      DrawingConfig config = surfaceDrawing(algorithm);
      config.sensor_model.gap_guard_cells = gap_guard_cells;
      DisparityDrawer drawer(StereoCameraConfig(), config);
      LocalGrid grid;
      drawer.draw(disparity, camera(), &grid);
      std::array<int, 3> free_zero_occupied{0, 0, 0};
      for (double x = 19.91 - gap_m; x < 20.1 - gap_m; x += 0.05)
        for (double z = 0.05; z < 4.0; z += 0.05) {
          const float v = valueAt(grid, {x, 0.0, z});
          ++free_zero_occupied[v < 0.0f ? 0 : (v == 0.0f ? 1 : 2)];
        }
      return free_zero_occupied;
    };
    const int default_guard = InverseSensorModelConfig().gap_guard_cells;
    const std::array<int, 3> line = postCells(DrawingAlgorithm::kLine, default_guard);
    EXPECT_EQ(line[0], 0);
    EXPECT_GE(line[2], 80);  // at least the cell of the face: one column of sample points
    EXPECT_EQ(postCells(DrawingAlgorithm::kLinePyramidBounded, default_guard), line);
    EXPECT_EQ(postCells(DrawingAlgorithm::kLinePyramidBounded, 1)[0], 0);
  }
}

// Spans (LineDrawer::setSurfaceSpans()): a block of oblique ground is drawn
// as one free line and its leaves' hits instead of a line per leaf. The
// occupied cells are the descent's, cell for cell and value for value; the
// cells written are fewer; a block with a hole in its depths (the post
// before the wall) is still descended, so the free space beside the post
// stays. The matcher's noise is what splits the ground's blocks.
TEST(SurfaceProfile, SpansDrawTheDescentsOccupiedCellsWritingFewer) {
  SyntheticScene scene;
  scene.addBox({-5.0, -40.0, -1.0}, {60.0, 40.0, 0.0});   // the ground
  scene.addBox({20.1, -20.0, -5.0}, {22.0, 20.0, 10.0});  // a wall
  scene.addBox({14.9, -0.1, 0.0}, {15.1, 0.1, 4.0});      // a post before it
  for (const Eigen::Isometry3d& T_W_C :
       {camera(), lookingAlongX({0.0, 0.0, 6.0}, 0.1, 0.25), lookingAlongX({2.0, 1.0, 10.0}, -0.2, 0.5)}) {
    cv::Mat disparity = renderDisparity(scene, StereoCameraModel(StereoCameraConfig()), T_W_C);
    std::mt19937 random(7);
    std::normal_distribution<float> matcher_noise_px(0.0f, 0.2f);
    for (int y = 0; y < disparity.rows; ++y)
      for (float& d : cv::Mat_<float>(disparity.row(y)))
        if (d > 0.0f) d = std::max(d + matcher_noise_px(random), 0.01f);
    auto draw = [&](bool spans, LocalGrid* grid) {
      DrawingConfig config = surfaceDrawing(DrawingAlgorithm::kLinePyramidBounded);
      config.surface_spans = spans;
      config.threads = 1;
      DisparityDrawer drawer(StereoCameraConfig(), config);
      return drawer.draw(disparity, T_W_C, grid);
    };
    LocalGrid with, without;
    const DrawStatistics with_stats = draw(true, &with), without_stats = draw(false, &without);
    ASSERT_EQ(with.originIndex(), without.originIndex());
    ASSERT_EQ(with.size(), without.size());
    int occupied = 0, occupied_differ = 0, free_with = 0, free_without = 0;
    for (size_t i = 0; i < with.numCells(); ++i) {
      const float a = with.data()[i], b = without.data()[i];
      occupied += b > 0.0f;
      occupied_differ += (a > 0.0f || b > 0.0f) && a != b;
      free_with += a < 0.0f && a != LocalGrid::kUnknown;
      free_without += b < 0.0f && b != LocalGrid::kUnknown;
    }
    EXPECT_GT(occupied, 1000);
    EXPECT_EQ(occupied_differ, 0);
    // A leaf's hit is a coordinate transfer too, but one cell instead of a line.
    EXPECT_LT(with_stats.grid_cells_drawn, 0.7 * without_stats.grid_cells_drawn);
    EXPECT_GT(free_with, 0.9 * free_without);  // what is left out lies within a cell of the surface
    // Between the post and the wall, a metre and more above the ground.
    auto freeBesideThePost = [&](const LocalGrid& grid) {
      int free = 0;
      for (double x = 15.6; x < 19.6; x += kCell)
        for (double y = -1.5; y < 1.5; y += kCell)
          for (double z = 1.1; z < 3.5; z += kCell) {
            const float v = valueAt(grid, {x, y, z});
            free += v < 0.0f && v != LocalGrid::kUnknown;
          }
      return free;
    };
    // Without the hole test the post's blocks would be spans: 10-16 % less.
    EXPECT_GE(freeBesideThePost(with), 0.98 * freeBesideThePost(without));
  }
}

// The lines flag the blocks where they put their hits (LineDrawer::
// hitBlocks()), and the sky guard looks only there: the grid is the one a
// guard over the whole grid gives, for each line algorithm, on one thread
// and on two, where the guard silences about two hundred sky cells.
TEST(SurfaceProfile, SkyGuardOverTheHitBlocksIsTheGuardOverTheGrid) {
  SyntheticScene scene;
  scene.addBox({-5.0, -40.0, -1.0}, {60.0, 40.0, 0.0});  // the ground
  scene.addBox({20.1, -20.0, -5.0}, {22.0, 20.0, 5.0});  // a wall, the sky above it
  scene.addBox({14.9, -0.1, 0.0}, {15.1, 0.1, 4.0});     // a post before it
  const Eigen::Isometry3d T_W_C = lookingAlongX({0.0, 0.0, 3.0}, 0.1, 0.05);
  const cv::Mat disparity = renderDisparity(scene, StereoCameraModel(StereoCameraConfig()), T_W_C);
  for (DrawingAlgorithm algorithm :
       {DrawingAlgorithm::kLine, DrawingAlgorithm::kLinePyramid, DrawingAlgorithm::kLinePyramidBounded})
    for (int threads : {1, 2}) {
      const std::string what = std::string(toString(algorithm)) + ", threads " + std::to_string(threads);
      DrawingConfig config = surfaceDrawing(algorithm);
      config.threads = threads;
      auto drawUnblurred = [&](LocalGrid* grid) {
        DisparityDrawer drawer(StereoCameraConfig(), config);
        drawer.prepareGrid(T_W_C, grid);
        drawer.drawInto(disparity, T_W_C, grid);
      };
      LocalGrid guarded, expected;
      drawUnblurred(&guarded);
      config.sensor_model.sky_guard_cells = 0;  // unguarded, then guarded over the whole grid
      drawUnblurred(&expected);
      const LogOddsTable table(InverseSensorModel(config.sensor_model), kCell);
      const size_t silenced = silenceNearOccupied(&expected, table.skyLogOdds(), 1);
      EXPECT_GT(silenced, 100u) << what;
      ASSERT_EQ(guarded.size(), expected.size()) << what;
      EXPECT_EQ(std::memcmp(guarded.data(), expected.data(), expected.numCells() * sizeof(float)), 0) << what;
    }
}

// The hole test walks a span's leaves by their largest disparity. The order
// by rank (up to kRankOrderedKeys leaves) and the insertion sort above it
// are a stable sort's order, also where leaves share a disparity (the
// matcher's disparities are quantised) and for every count up to kMaxLeaves.
TEST(SurfaceProfile, LeavesAreOrderedAsAStableSortOrdersThem) {
  std::mt19937 random(11);
  std::uniform_int_distribution<int> quantised(0, 12);
  for (int count = 0; count <= 64; ++count)
    for (int trial = 0; trial < 20; ++trial) {
      std::vector<float> keys(static_cast<size_t>(count));
      for (float& key : keys) key = 4.0f + 0.25f * static_cast<float>(quantised(random));
      std::vector<int> order(static_cast<size_t>(count), -1), expected(static_cast<size_t>(count));
      std::iota(expected.begin(), expected.end(), 0);
      std::stable_sort(expected.begin(), expected.end(), [&](int a, int b) { return keys[a] < keys[b]; });
      stableOrderAscending(keys.data(), count, order.data());
      ASSERT_EQ(order, expected) << count << " keys";
    }
}
