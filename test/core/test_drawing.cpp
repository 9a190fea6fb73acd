// Geometry of the six drawing algorithms (the paper's four and the bounded pyramids) on scenes with a known answer.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "stereo_occupancy/surface_guards.h"

using namespace stereo_occupancy;

namespace {

const std::vector<DrawingAlgorithm>& kAll = allDrawingAlgorithms();

DrawingConfig config(DrawingAlgorithm a, double resolution = 0.25) {
  DrawingConfig c;
  c.algorithm = a;
  c.resolution_m = resolution;
  c.count_different_cells = true;  // Table I's counter, asserted below
  return c;
}

std::vector<Eigen::Isometry3d> testPoses() {
  std::vector<Eigen::Isometry3d> poses;
  poses.push_back(lookingAlongX(Eigen::Vector3d(0.1, 0.2, 5.3)));
  poses.push_back(lookingAlongX(Eigen::Vector3d(-3.0, 7.7, 2.0), 0.6, 0.3));
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = (Eigen::AngleAxisd(2.1, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(-0.7, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(12.3, -4.4, 30.0);
  poses.push_back(T);
  return poses;
}

/// The Table I scene seen from testPoses() and Table I's pose: lines along
/// every axis in both directions, close and far surfaces.
struct EquivalenceFrames {
  std::vector<Eigen::Isometry3d> poses;
  std::vector<cv::Mat> images;
};
EquivalenceFrames equivalenceFrames(const StereoCameraConfig& cam_cfg) {
  const StereoCameraModel cam(cam_cfg);
  Eigen::Isometry3d T_table1;
  const SyntheticScene scene = table1Scene(&T_table1);
  EquivalenceFrames frames;
  frames.poses = testPoses();
  frames.poses.push_back(T_table1);
  for (const Eigen::Isometry3d& T : frames.poses) frames.images.push_back(renderDisparity(scene, cam, T));
  return frames;
}

/// A cell's depth, image position and range as seen from T_W_C.
struct CellView {
  double z, u, v, l;
};
CellView view(const LocalGrid& g, int x, int y, int z, const Eigen::Isometry3d& T_W_C, const StereoCameraModel& cam) {
  const Eigen::Vector3d C_p = T_W_C.inverse() * g.cellCentre(x, y, z);
  const auto& cfg = cam.config();
  return {C_p.z(), cfg.focal_length_px * C_p.x() / C_p.z() + cfg.cx_px,
          cfg.focal_length_px * C_p.y() / C_p.z() + cfg.cy_px, C_p.norm()};
}
bool wellInside(const CellView& cv, const StereoCameraConfig& cfg, double margin_px) {
  return cv.z > 0.0 && cv.u > margin_px && cv.u < cfg.width_px - margin_px && cv.v > margin_px &&
         cv.v < cfg.height_px - margin_px;
}

using Key = std::tuple<int, int, int>;
std::set<Key> occupiedCells(const LocalGrid& g) {
  std::set<Key> out;
  for (int z = 0; z < g.size().z(); ++z)
    for (int y = 0; y < g.size().y(); ++y)
      for (int x = 0; x < g.size().x(); ++x)
        if (g.at(x, y, z) > 0.0f) {
          const Eigen::Vector3i k = g.originIndex() + Eigen::Vector3i(x, y, z);
          out.insert({k.x(), k.y(), k.z()});
        }
  return out;
}

/// A LineDrawer for the paper's camera and 0.25 m cells.
class LineDrawing : public ::testing::Test {
 protected:
  StereoCameraModel cam{StereoCameraConfig()};
  InverseSensorModel model{InverseSensorModelConfig()};
  LogOddsTable table{model, 0.25};
  PyramidLevelTable levels{cam, 0.25};
  LineDrawer drawer{cam, table, levels};
};

}  // namespace

// A fronto-parallel wall 10 m in front fills the image (constant disparity
// 21 px): occupied at the wall, free in front, unknown behind, for all six
// algorithms and three camera poses.
TEST(Drawing, FrontoParallelWall) {
  StereoCameraConfig cam_cfg;
  const StereoCameraModel cam(cam_cfg);
  const double wall_z = 10.0;
  const cv::Mat image(480, 640, CV_32FC1, cv::Scalar(cam.disparityFromDepth(wall_z)));
  const double dz = cam.depthUncertainty(wall_z);

  for (const auto& T : testPoses()) {
    std::map<DrawingAlgorithm, std::set<Key>> occupied;
    for (DrawingAlgorithm a : kAll) {
      DisparityDrawer drawer(cam_cfg, config(a));
      LocalGrid grid;
      const DrawStatistics stats = drawer.draw(image, T, &grid);
      const double c = grid.resolution();
      size_t front = 0, front_free = 0, front_occupied = 0, at_wall = 0, at_wall_occupied = 0, behind_known = 0;
      for (int z = 0; z < grid.size().z(); ++z)
        for (int y = 0; y < grid.size().y(); ++y)
          for (int x = 0; x < grid.size().x(); ++x) {
            const CellView cv = view(grid, x, y, z, T, cam);
            const float L = grid.at(x, y, z);
            const double n = cv.l / std::max(cv.z, 1e-9);
            if (cv.z > wall_z + c * 0.87 + 3.0 * dz * 1.16 + 0.01) {
              behind_known += L != LocalGrid::kUnknown;  // nothing is drawn behind the tail
              continue;
            }
            if (!wellInside(cv, cam_cfg, 40.0)) continue;
            if (cv.z > 1.0 && cv.z < wall_z - c * 0.87 * n - 1.3 * dz * n) {
              ++front;
              front_free += L < 0.0f && L != LocalGrid::kUnknown;
              front_occupied += L > 0.0f;
            } else if (std::abs(cv.z - wall_z) < 0.25 * c) {
              ++at_wall;
              at_wall_occupied += L > 0.0f;
            }
          }
      SCOPED_TRACE(std::string(toString(a)) + " at pose " + std::to_string(T.translation().x()));
      EXPECT_GT(stats.different_grid_cells, 0u);
      EXPECT_EQ(behind_known, 0u);
      ASSERT_GT(front, 1000u);
      EXPECT_EQ(front_occupied, 0u);
      // Pyramidal line drawing spaces its lines up to one cell apart (eq. 13)
      // and a Bresenham line takes one cell per slab: on oblique views a few
      // cells fall between the lines (the paper's "risk of remaining holes").
      // So does its bounded variant: on one depth, every block is faithful.
      const bool sparse = a == DrawingAlgorithm::kLinePyramid || a == DrawingAlgorithm::kLinePyramidBounded;
      EXPECT_GT(static_cast<double>(front_free) / front, sparse ? 0.95 : 0.97) << front_free << " of " << front;
      ASSERT_GT(at_wall, 50u);
      if (sparse) {
        EXPECT_GT(static_cast<double>(at_wall_occupied) / at_wall, 0.8) << at_wall_occupied << " of " << at_wall;
      } else {
        EXPECT_EQ(at_wall_occupied, at_wall);
      }
      // Keep only the interior for the comparison between algorithms.
      std::set<Key> interior;
      for (const Key& k : occupiedCells(grid)) {
        const Eigen::Vector3i g(std::get<0>(k), std::get<1>(k), std::get<2>(k));
        const Eigen::Vector3i l = g - grid.originIndex();
        if (wellInside(view(grid, l.x(), l.y(), l.z(), T, cam), cam_cfg, 40.0)) interior.insert(k);
      }
      occupied[a] = interior;
    }
    // All agree on the wall's occupied cells within one cell (allowing
    // 0.1 % at the edge of the compared region).
    for (DrawingAlgorithm a : kAll)
      for (DrawingAlgorithm b : kAll) {
        if (a == b) continue;
        size_t missing = 0;
        for (const Key& k : occupied[a]) {
          bool found = false;
          for (int dx = -1; dx <= 1 && !found; ++dx)
            for (int dy = -1; dy <= 1 && !found; ++dy)
              for (int dz2 = -1; dz2 <= 1 && !found; ++dz2)
                found = occupied[b].count({std::get<0>(k) + dx, std::get<1>(k) + dy, std::get<2>(k) + dz2}) > 0;
          missing += !found;
        }
        EXPECT_LE(missing, occupied[a].size() / 1000)
            << toString(a) << " vs " << toString(b) << ": " << occupied[a].size() << " cells";
      }
  }
}

// Zero disparity is infinitely far: free space out to the maximum range.
TEST(Drawing, ZeroDisparityIsFreeToMaxRange) {
  StereoCameraConfig cam_cfg;
  const StereoCameraModel cam(cam_cfg);
  const cv::Mat sky(480, 640, CV_32FC1, cv::Scalar(0.0f));
  for (DrawingAlgorithm a : kAll) {
    for (const auto& T : testPoses()) {
      DisparityDrawer drawer(cam_cfg, config(a, 0.5));
      LocalGrid grid;
      drawer.draw(sky, T, &grid);
      size_t inside = 0, free_cells = 0, beyond = 0, occupied = 0;
      for (int z = 0; z < grid.size().z(); ++z)
        for (int y = 0; y < grid.size().y(); ++y)
          for (int x = 0; x < grid.size().x(); ++x) {
            const CellView cv = view(grid, x, y, z, T, cam);
            const float L = grid.at(x, y, z);
            occupied += L > 0.0f;
            if (cv.l > 25.0 + 0.87 * 0.5) beyond += L != LocalGrid::kUnknown;
            if (cv.l < 24.0 && cv.l > 1.0 && wellInside(cv, cam_cfg, 20.0)) {
              ++inside;
              free_cells += L < 0.0f;
            }
          }
      SCOPED_TRACE(toString(a));
      EXPECT_EQ(occupied, 0u);
      EXPECT_EQ(beyond, 0u);
      ASSERT_GT(inside, 1000u);
      EXPECT_GT(static_cast<double>(free_cells) / inside, 0.97) << free_cells << " of " << inside;
    }
  }
}

// Invalid pixels carry no information.
TEST(Drawing, InvalidPixelsChangeNothing) {
  StereoCameraConfig cam_cfg;
  cam_cfg.max_disparity_px = 128.0;
  const Eigen::Isometry3d T = testPoses()[1];
  for (float bad : {std::nanf(""), -1.0f, -INFINITY, INFINITY, 129.0f, 1e9f}) {
    const cv::Mat image(480, 640, CV_32FC1, cv::Scalar(bad));
    for (DrawingAlgorithm a : kAll) {
      DisparityDrawer drawer(cam_cfg, config(a));
      LocalGrid grid;
      const DrawStatistics stats = drawer.draw(image, T, &grid);
      EXPECT_EQ(grid.countKnown(), 0u) << toString(a) << " value " << bad;
      EXPECT_EQ(stats.grid_cells_drawn, 0u);
    }
  }
  // Left half invalid: nothing is drawn where only the left half looks.
  const StereoCameraModel cam(cam_cfg);
  cv::Mat half(480, 640, CV_32FC1, cv::Scalar(cam.disparityFromDepth(12.0)));
  half(cv::Rect(0, 0, 320, 480)).setTo(std::nanf(""));
  for (DrawingAlgorithm a : kAll) {
    DisparityDrawer drawer(cam_cfg, config(a));
    LocalGrid grid;
    drawer.draw(half, T, &grid);
    size_t left = 0;
    for (int z = 0; z < grid.size().z(); ++z)
      for (int y = 0; y < grid.size().y(); ++y)
        for (int x = 0; x < grid.size().x(); ++x) {
          if (grid.at(x, y, z) == LocalGrid::kUnknown) continue;
          const CellView cv = view(grid, x, y, z, T, cam);
          // A cell's footprint is about c·f/z px wide; beyond that it sees only the left half.
          if (cv.z > 2.0 && cv.u < 320.0 - 0.25 * 700.0 / cv.z * 1.5 - 2.0) ++left;
        }
    EXPECT_EQ(left, 0u) << toString(a);
  }
}

// Where lines overlap the larger value stays, whatever the order (V-A, 2b).
TEST_F(LineDrawing, ObstaclePriority) {
  const Eigen::Vector3d origin(0.1, 0.1, 0.1), dir = Eigen::Vector3d(1, 0.2, 0.1).normalized();
  const RangeProfile obstacle = table.profile(8.0f, static_cast<float>(cam.depthUncertainty(8.0)));
  const RangeProfile free_ray = table.freeProfile();
  LocalGrid a, b;
  a.reset(Eigen::Vector3i(-4, -4, -4), Eigen::Vector3i(120, 40, 40), 0.25);
  b = a;
  drawer.drawRay(origin, dir, free_ray, &a);
  drawer.drawRay(origin, dir, obstacle, &a);
  drawer.drawRay(origin, dir, obstacle, &b);
  drawer.drawRay(origin, dir, free_ray, &b);
  const Eigen::Vector3i hit = LocalGrid::globalIndex(origin + 8.0 * dir, 0.25) - a.originIndex();
  EXPECT_GT(a.at(hit.x(), hit.y(), hit.z()), 0.5f);
  for (size_t i = 0; i < a.numCells(); ++i) ASSERT_EQ(a.data()[i], b.data()[i]);
  // The free ray continues past the obstacle to the maximum range.
  const Eigen::Vector3i far = LocalGrid::globalIndex(origin + 20.0 * dir, 0.25) - a.originIndex();
  EXPECT_NEAR(a.at(far.x(), far.y(), far.z()), model.freeLogOdds(), 1e-5);
}

// A worker's grid follows the grids drawn: after one huge grid it does not
// keep that memory for the small grids that follow.
TEST_F(LineDrawing, WorkerGridsLetGoOfAHugeGrid) {
  WorkerPool pool(2);
  drawer.setWorkers(&pool);
  cv::Mat image(480, 640, CV_32FC1, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  image.row(240).setTo(cv::Scalar(21.0));  // one row of a wall 10 m ahead
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(1.0, 1.0, 1.0);
  DrawStatistics stats;
  LocalGrid huge, small;
  huge.reset(Eigen::Vector3i(-100, -100, 0), Eigen::Vector3i(200, 200, 130), 0.25);  // 5.2 M cells
  drawer.drawImage(image, T, &huge, &stats);
  EXPECT_EQ(drawer.workerCellsHeld(), huge.numCells());
  EXPECT_GT(huge.countKnown(), 100u);
  small.reset(Eigen::Vector3i(-40, -40, 0), Eigen::Vector3i(80, 80, 60), 0.25);  // 384 k cells
  drawer.drawImage(image, T, &small, &stats);
  EXPECT_EQ(drawer.workerCellsHeld(), small.numCells());
  EXPECT_GT(small.countKnown(), 100u);
}

// A segment [l_begin, l_stop] of a line (the bounded pyramid's shared free
// stretch and the lines of its children) draws exactly the cells of the whole
// line whose slab centre planes lie inside it, with the same values.
TEST_F(LineDrawing, SegmentsDrawThePartOfTheLine) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0), range(2.0, 24.0), cut(0.0, 1.0);
  for (int trial = 0; trial < 12; ++trial) {
    const Eigen::Vector3d origin(u(rng), u(rng), u(rng));
    const Eigen::Vector3d dir = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    const double lp = range(rng);
    const RangeProfile profile =
        trial % 4 == 0 ? table.freeProfile() : table.profile(static_cast<float>(lp), cam.depthUncertainty(lp));
    const double l_end = std::min<double>(profile.endRange(), 25.0);
    const double l_begin = cut(rng) * l_end, l_stop = l_begin + cut(rng) * (l_end - l_begin);
    LocalGrid whole, part;
    whole.reset(Eigen::Vector3i(-110, -110, -110), Eigen::Vector3i(220, 220, 220), 0.25);
    part = whole;
    drawer.drawRay(origin, dir, profile, &whole);
    const uint64_t n = drawer.drawRay(origin, dir, profile, &part, l_begin, l_stop);
    ASSERT_EQ(part.countKnown(), n);
    int m = 0;
    dir.cwiseAbs().maxCoeff(&m);
    size_t inner = 0, off_line = 0;
    for (size_t i = 0; i < part.numCells(); ++i) {
      const int x = static_cast<int>(i % 220), y = static_cast<int>(i / 220 % 220), z = static_cast<int>(i / 48400);
      const double l = (part.cellCentre(x, y, z)[m] - origin[m]) / dir[m];  // the slab's centre plane
      if (l > l_begin + 0.01 && l < l_stop - 0.01 && whole.data()[i] != LocalGrid::kUnknown) {
        // Every inner cell, with the same value (the runs accumulate in float from another start).
        ASSERT_NEAR(part.data()[i], whole.data()[i], 1e-4) << "trial " << trial << " l " << l;
        ++inner;
      }
      if (part.data()[i] == LocalGrid::kUnknown) continue;
      // Only the first and the last slab sample the segment's ends instead of
      // the centre plane, so only their cells may lie off the whole line.
      ASSERT_GT(l, l_begin - 0.25 * 1.8) << "trial " << trial;
      ASSERT_LT(l, l_stop + 0.25 * 1.8) << "trial " << trial;
      off_line += whole.data()[i] == LocalGrid::kUnknown;
    }
    EXPECT_LE(off_line, 2u) << "trial " << trial;
    EXPECT_GE(n, inner);
    EXPECT_LE(n, inner + 2);
  }
}

// Every cell of a line gets L̂ at the range where the ray crosses the cell's
// centre plane along the major axis (the fast runs of drawRay agree with the
// table's plain look-up).
TEST_F(LineDrawing, LineCellsCarryTheModelValue) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(-1.0, 1.0), range(2.0, 24.0);
  for (int trial = 0; trial < 40; ++trial) {
    const Eigen::Vector3d origin(u(rng), u(rng), u(rng));
    const Eigen::Vector3d dir = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    const double lp = range(rng);
    const RangeProfile profile =
        trial % 8 == 0 ? table.freeProfile() : table.profile(static_cast<float>(lp), cam.depthUncertainty(lp));
    LocalGrid grid;
    grid.reset(Eigen::Vector3i(-110, -110, -110), Eigen::Vector3i(220, 220, 220), 0.25);
    const uint64_t n = drawer.drawRay(origin, dir, profile, &grid);
    ASSERT_EQ(grid.countKnown(), n);  // one cell per slab, no cell twice
    int m = 0;
    dir.cwiseAbs().maxCoeff(&m);
    const Eigen::Vector3d g0 = (origin - grid.originPosition()) / 0.25;
    const double l_end = std::min<double>(profile.endRange(), 25.0);
    size_t checked = 0;
    for (size_t i = 0; i < grid.numCells(); ++i) {
      const float value = grid.data()[i];
      if (value == LocalGrid::kUnknown) continue;
      const int x = static_cast<int>(i % 220), y = static_cast<int>(i / 220 % 220), z = static_cast<int>(i / 48400);
      const double l = (grid.cellCentre(x, y, z)[m] - origin[m]) / dir[m];
      if (l <= 0.0 || l >= l_end) continue;  // the first and last cell sample the segment's end
      ASSERT_NEAR(value, profile.at(static_cast<float>(l)), 2e-3) << "trial " << trial << " l " << l;
      // The cell is the one the ray crosses on its slab's centre plane.
      const Eigen::Vector3d on_ray = g0 + dir * (l / 0.25);
      const Eigen::Vector3i cell(x, y, z);
      for (int axis = 0; axis < 3; ++axis)
        if (axis != m) {
          ASSERT_EQ(cell[axis], static_cast<int>(std::floor(on_ray[axis]))) << "trial " << trial;
        }
      ++checked;
    }
    ASSERT_GE(checked + 2, n);
  }
}

// A line leaving the grid writes only the cells inside it.
TEST_F(LineDrawing, LineLeavingTheGridSkipsOutsideCells) {
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(10, 10, 10), 0.25);  // 2.5 m
  // The obstacle lies 8 m out, far outside the grid.
  const RangeProfile obstacle = table.profile(8.0f, static_cast<float>(cam.depthUncertainty(8.0)));
  const uint64_t written =
      drawer.drawRay(Eigen::Vector3d(0.3, 1.2, 1.2), Eigen::Vector3d(1, 0.1, 0).normalized(), obstacle, &grid);
  EXPECT_EQ(grid.countKnown(), written);
  EXPECT_LE(written, 10u);
  EXPECT_GE(written, 8u);
  for (size_t i = 0; i < grid.numCells(); ++i)
    if (grid.data()[i] != LocalGrid::kUnknown) {
      EXPECT_NEAR(grid.data()[i], model.freeLogOdds(), 1e-5);
    }
  // A ray starting outside the grid writes nothing.
  LocalGrid far;
  far.reset(Eigen::Vector3i(100, 100, 100), Eigen::Vector3i(4, 4, 4), 0.25);
  EXPECT_EQ(drawer.drawRay(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 0, 0), obstacle, &far), 0u);
  EXPECT_EQ(far.countKnown(), 0u);
}

// Positive disparities too small for their depth to be represented are
// infinitely far: free space, and no out-of-range table look-up.
TEST(Drawing, TinyPositiveDisparitiesAreInfinitelyFar) {
  StereoCameraConfig cam_cfg;
  const StereoCameraModel cam(cam_cfg);
  const Eigen::Isometry3d T = testPoses()[1];
  for (float tiny :
       {1e-6f, 1e-20f, 1e-30f, std::numeric_limits<float>::min(), std::numeric_limits<float>::denorm_min()}) {
    const cv::Mat image(480, 640, CV_32FC1, cv::Scalar(tiny));
    for (DrawingAlgorithm a : kAll) {
      DisparityDrawer drawer(cam_cfg, config(a, 0.5));
      LocalGrid grid;
      const DrawStatistics stats = drawer.draw(image, T, &grid);
      size_t occupied = 0;
      for (size_t i = 0; i < grid.numCells(); ++i) occupied += grid.data()[i] > 0.0f;
      EXPECT_EQ(occupied, 0u) << toString(a) << " " << tiny;
      if (tiny >= std::numeric_limits<float>::min()) {  // a denormal counts as no measurement
        EXPECT_GT(stats.different_grid_cells, 1000u) << toString(a) << " " << tiny;
      }
    }
  }
}

// Table I's "different grid cells" is one more pass over the grid: counted
// on request only (the mapper never reads it), then equal to the known cells
// before the blur, here counted cell by cell on the values.
TEST(Drawing, DifferentCellsCountedOnRequest) {
  StereoCameraConfig cam_cfg;
  const StereoCameraModel cam(cam_cfg);
  Eigen::Isometry3d T;
  const cv::Mat image = table1Image(cam, &T);
  for (bool count : {false, true}) {
    DrawingConfig c = config(DrawingAlgorithm::kLinePyramid);
    c.count_different_cells = count;
    DisparityDrawer drawer(cam_cfg, c);
    LocalGrid grid;
    drawer.prepareGrid(T, &grid);
    const DrawStatistics stats = drawer.drawInto(image, T, &grid);
    EXPECT_GT(stats.grid_cells_drawn, 100000u);
    size_t known = 0;  // not LocalGrid::countKnown(), which the drawer uses
    for (size_t i = 0; i < grid.numCells(); ++i) known += grid.data()[i] != LocalGrid::kUnknown;
    EXPECT_EQ(stats.different_grid_cells, count ? known : 0u) << count;
    EXPECT_GT(known, 40000u);
  }
}

// The free run's SSE2 (x86-64) and NEON (aarch64) kernels draw the same
// grids as the plain loop, bit for bit, for every line drawing algorithm,
// from poses whose lines run along every axis in both directions.
TEST(Drawing, SimdLevelsDrawTheSameGrids) {
  const StereoCameraConfig cam_cfg;
  const EquivalenceFrames frames = equivalenceFrames(cam_cfg);
  const SimdLevel best = availableSimdLevel();
  std::printf("[          ] free run: this target allows %s\n", toString(best));
#if defined(__x86_64__) || defined(__aarch64__)
  EXPECT_NE(best, SimdLevel::kScalar) << "both targets have a two-cell free run";
#endif
  for (DrawingAlgorithm algorithm :
       {DrawingAlgorithm::kLine, DrawingAlgorithm::kLinePyramid, DrawingAlgorithm::kLinePyramidBounded}) {
    DrawingConfig scalar_config = config(algorithm);
    scalar_config.simd = SimdLevel::kScalar;
    DisparityDrawer scalar(cam_cfg, scalar_config);
    for (size_t p = 0; p < frames.poses.size(); ++p) {
      const cv::Mat& image = frames.images[p];
      LocalGrid plain;
      const DrawStatistics plain_stats = scalar.draw(image, frames.poses[p], &plain);
      EXPECT_GT(plain_stats.different_grid_cells, 20000u) << toString(algorithm) << " pose " << p;
      for (SimdLevel level : {SimdLevel::kSse2, SimdLevel::kNeon}) {
        if (!isAvailable(level)) continue;
        DrawingConfig simd_config = config(algorithm);
        simd_config.simd = level;
        DisparityDrawer drawer(cam_cfg, simd_config);
        LocalGrid simd;
        const DrawStatistics stats = drawer.draw(image, frames.poses[p], &simd);
        EXPECT_EQ(stats.grid_cells_drawn, plain_stats.grid_cells_drawn);
        ASSERT_EQ(simd.numCells(), plain.numCells());
        EXPECT_EQ(std::memcmp(simd.data(), plain.data(), plain.numCells() * sizeof(float)), 0)
            << toString(algorithm) << " pose " << p << " " << toString(level);
      }
    }
  }
}

// Drawing and blurring on several threads gives the grid of one thread, bit
// for bit, and the same counters, for every algorithm (the ray tracers run
// on one thread whatever the number), on frames with close and far surfaces.
TEST(Drawing, ThreadCountsDrawTheSameGrids) {
  const StereoCameraConfig cam_cfg;
  const EquivalenceFrames frames = equivalenceFrames(cam_cfg);
  auto blurred = [](DrawingAlgorithm algorithm, int threads) {
    DrawingConfig c = config(algorithm);
    c.threads = threads;
    c.blur.sigma_trans_m = 0.1;  // eq. 17 on: the blur's passes are shared too
    c.blur.sigma_angle_rad = 0.01;
    return c;
  };
  for (DrawingAlgorithm algorithm : kAll) {
    DisparityDrawer one(cam_cfg, blurred(algorithm, 1));
    for (int threads : {2, 3, 5}) {
      const DrawingConfig many_config = blurred(algorithm, threads);
      DisparityDrawer many(cam_cfg, many_config);
      for (size_t p = 0; p < frames.poses.size(); ++p) {
        LocalGrid a, b;
        const DrawStatistics sa = one.draw(frames.images[p], frames.poses[p], &a);
        const DrawStatistics sb = many.draw(frames.images[p], frames.poses[p], &b);
        const std::string what =
            std::string(toString(algorithm)) + " threads " + std::to_string(threads) + " pose " + std::to_string(p);
        EXPECT_GT(sa.different_grid_cells, 20000u) << what;
        EXPECT_EQ(sb.coordinate_transfers, sa.coordinate_transfers) << what;
        EXPECT_EQ(sb.used_image_pixels, sa.used_image_pixels) << what;
        EXPECT_EQ(sb.grid_cells_drawn, sa.grid_cells_drawn) << what;
        EXPECT_EQ(sb.different_grid_cells, sa.different_grid_cells) << what;
        ASSERT_EQ(b.numCells(), a.numCells()) << what;
        EXPECT_EQ(std::memcmp(b.data(), a.data(), a.numCells() * sizeof(float)), 0) << what;
      }
    }
  }
}

// The mapper's default (the bounded pyramid with the surface profile and its
// sky guard): its two pyramids and the sky guard on the workers draw the
// same grid as one thread.
TEST(Drawing, ThreadCountsDrawTheSameDefaultGrids) {
  const StereoCameraConfig cam_cfg;
  const EquivalenceFrames frames = equivalenceFrames(cam_cfg);
  for (int guard : {1, 2}) {
    DrawingConfig c = DrawingConfig::mapperDefaults();
    c.sensor_model.sky_guard_cells = guard;
    c.threads = 1;
    DisparityDrawer one(cam_cfg, c);
    for (int threads : {2, 3, 5}) {
      c.threads = threads;
      DisparityDrawer many(cam_cfg, c);
      for (size_t p = 0; p < frames.poses.size(); ++p) {
        LocalGrid a, b;
        one.draw(frames.images[p], frames.poses[p], &a);
        many.draw(frames.images[p], frames.poses[p], &b);
        const std::string what =
            "guard " + std::to_string(guard) + " threads " + std::to_string(threads) + " pose " + std::to_string(p);
        ASSERT_EQ(b.numCells(), a.numCells()) << what;
        EXPECT_EQ(std::memcmp(b.data(), a.data(), a.numCells() * sizeof(float)), 0) << what;
      }
    }
  }
}

// The sky guard on a pool's workers silences the same cells, and as many.
TEST(Drawing, SkyGuardOnWorkersSilencesTheSameCells) {
  const StereoCameraConfig cam_cfg;
  const EquivalenceFrames frames = equivalenceFrames(cam_cfg);
  DrawingConfig c = DrawingConfig::mapperDefaults();
  c.sensor_model.sky_guard_cells = 0;  // the guard below, by hand
  DisparityDrawer drawer(cam_cfg, c);
  const float sky = LogOddsTable(InverseSensorModel(c.sensor_model), c.resolution_m).skyLogOdds();
  size_t silenced_in_all = 0;
  for (size_t p = 0; p < frames.poses.size(); ++p) {
    LocalGrid drawn;
    drawer.draw(frames.images[p], frames.poses[p], &drawn);
    ASSERT_GE(drawn.size().z(), 4 * (2 * 2 + 1)) << "thick enough for chunks of slabs on two workers";
    for (int radius : {1, 2}) {
      LocalGrid alone = drawn;
      const size_t expected = silenceNearOccupied(&alone, sky, radius);
      silenced_in_all += expected;
      for (unsigned threads : {2u, 3u, 5u}) {
        WorkerPool pool(threads);
        LocalGrid shared = drawn;
        const std::string what =
            "pose " + std::to_string(p) + " radius " + std::to_string(radius) + " threads " + std::to_string(threads);
        EXPECT_EQ(silenceNearOccupied(&shared, sky, radius, &pool), expected) << what;
        EXPECT_EQ(std::memcmp(shared.data(), alone.data(), alone.numCells() * sizeof(float)), 0) << what;
      }
    }
  }
  EXPECT_GT(silenced_in_all, 1000u) << "the frames must put sky next to hits";
}

// Table I's shape: the pyramid reads far fewer pixels and draws far fewer
// cells for nearly the same map; counters have the paper's meaning.
TEST(Drawing, Table1Counters) {
  StereoCameraConfig cam_cfg;
  const StereoCameraModel cam(cam_cfg);
  Eigen::Isometry3d T;
  const cv::Mat image = table1Image(cam, &T);
  size_t valid = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) valid += cam.isValidDisparity(image.at<float>(y, x));

  std::map<DrawingAlgorithm, DrawStatistics> stats;
  std::map<DrawingAlgorithm, LocalGrid> grids;
  for (DrawingAlgorithm a : kAll) {
    DisparityDrawer drawer(cam_cfg, config(a));
    stats[a] = drawer.draw(image, T, &grids[a]);
  }
  const auto& line = stats[DrawingAlgorithm::kLine];
  const auto& line_pyr = stats[DrawingAlgorithm::kLinePyramid];
  EXPECT_EQ(line.used_image_pixels, valid);
  EXPECT_EQ(line.coordinate_transfers, valid + 1);
  // One transfer per drawn line (each read one pyramid pixel) plus the camera centre.
  EXPECT_GT(line_pyr.coordinate_transfers, 1u);
  EXPECT_LE(line_pyr.coordinate_transfers, line_pyr.used_image_pixels + 1);
  EXPECT_LT(line_pyr.used_image_pixels * 10, line.used_image_pixels);
  EXPECT_LT(line_pyr.grid_cells_drawn * 10, line.grid_cells_drawn);
  EXPECT_GT(line.grid_cells_drawn, line.different_grid_cells);
  // Nearly equal outputs: the different cells agree within 15 %.
  EXPECT_NEAR(static_cast<double>(line_pyr.different_grid_cells) / line.different_grid_cells, 1.0, 0.15);
  const auto& rt = stats[DrawingAlgorithm::kRayTrace];
  const auto& rt_pyr = stats[DrawingAlgorithm::kRayTracePyramid];
  EXPECT_EQ(rt.coordinate_transfers, grids[DrawingAlgorithm::kRayTrace].numCells() + 5);
  EXPECT_EQ(rt.coordinate_transfers, rt_pyr.coordinate_transfers);
  EXPECT_LT(rt_pyr.used_image_pixels * 50, rt.used_image_pixels);
}

TEST(Drawing, RejectsBadInput) {
  StereoCameraConfig cam_cfg;
  DisparityDrawer drawer(cam_cfg, config(DrawingAlgorithm::kLinePyramid));
  LocalGrid grid;
  const Eigen::Isometry3d T = testPoses()[0];
  EXPECT_THROW(drawer.draw(cv::Mat(480, 640, CV_16UC1, cv::Scalar(0)), T, &grid), std::invalid_argument);
  EXPECT_THROW(drawer.draw(cv::Mat(240, 640, CV_32FC1, cv::Scalar(0)), T, &grid), std::invalid_argument);
  Eigen::Isometry3d bad = T;
  bad.linear() *= 1.1;
  EXPECT_THROW(drawer.draw(cv::Mat(480, 640, CV_32FC1, cv::Scalar(0)), bad, &grid), std::invalid_argument);
  bad = T;
  bad.translation().x() = std::nan("");
  EXPECT_THROW(drawer.draw(cv::Mat(480, 640, CV_32FC1, cv::Scalar(0)), bad, &grid), std::invalid_argument);
  DrawingConfig c = config(DrawingAlgorithm::kLine);
  c.resolution_m = 0.0;
  EXPECT_THROW(DisparityDrawer(cam_cfg, c), std::invalid_argument);
  // A fine grid over a long range is refused before it is allocated.
  StereoCameraConfig far_cam = cam_cfg;
  far_cam.max_range_m = 200.0;
  DrawingConfig fine = config(DrawingAlgorithm::kRayTracePyramid, 0.01);
  DisparityDrawer huge(far_cam, fine);
  EXPECT_THROW(huge.draw(cv::Mat(480, 640, CV_32FC1, cv::Scalar(0)), T, &grid), std::invalid_argument);
  DrawingAlgorithm parsed;
  EXPECT_TRUE(parseDrawingAlgorithm("raytrace_pyramid", &parsed));
  EXPECT_EQ(parsed, DrawingAlgorithm::kRayTracePyramid);
  EXPECT_FALSE(parseDrawingAlgorithm("bresenham", &parsed));
}

// Pyramidal line drawing below level 0 draws 4^-i lines per pixel (eq. 15): a
// grid much finer than the pixels' spacing at the maximum range is refused
// when the drawer is built (found by the fuzzer: level -20 never finished),
// ray tracing (a constant cost per cell at any level) is not.
TEST(Drawing, RefusesLinePyramidsFinerThanEightByEightLinesPerPixel) {
  StereoCameraConfig cam;  // f = 700 px
  cam.max_range_m = 200.0;
  // Level of the maximum range: floor(log2(c·f/z)); c·f/z = 0.105 -> -4, 0.126 -> -3.
  for (DrawingAlgorithm a : {DrawingAlgorithm::kLinePyramid, DrawingAlgorithm::kLinePyramidBounded}) {
    SCOPED_TRACE(toString(a));
    try {
      DisparityDrawer refused(cam, config(a, 0.03));
      ADD_FAILURE() << "level -4 accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("4^4 lines per pixel"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("at least 0.035714 m"), std::string::npos) << e.what();  // 200 / 700 / 8
    }
    DisparityDrawer accepted(cam, config(a, 0.036));
    EXPECT_EQ(accepted.levelTable().minLevel(), PyramidLevelTable::kLowestLevel);
  }
  for (DrawingAlgorithm a : {DrawingAlgorithm::kLine, DrawingAlgorithm::kRayTrace, DrawingAlgorithm::kRayTracePyramid,
                             DrawingAlgorithm::kRayTracePyramidBounded})
    EXPECT_NO_THROW(DisparityDrawer(cam, config(a, 0.03))) << toString(a);
}
