// distance_field_benchmark: the planners' distance field (issue 47) over the
// simulated flights, at 0.25 m in a 50 x 50 x 10 m window (max distance 2 m),
// one thread: each frame drawn and fused as the mapper does (untimed), then
// the field's update from the fusion's class changes (timed: median, p90,
// max, and the cells recomputed), sample() per point (one at a time and in a
// batch), a 1 km path check; and beside it DynamicEDTOctomap's incremental
// update() after the same frames' changes (if dynamicEDT3D was found at build
// time). A benchmark: it prints figures and asserts nothing.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <limits>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#ifdef STEREO_OCCUPANCY_HAVE_DYNAMICEDT3D
#include <dynamicEDT3D/dynamicEDTOctomap.h>
#endif

#include "scenario_support.h"
#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/distance_field.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "tool_support.h"

namespace so = stereo_occupancy;

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

/// Median, 90th percentile and maximum of @p v.
struct Spread {
  double median = 0.0, p90 = 0.0, max = 0.0;
  static Spread of(std::vector<double> v) {
    Spread s;
    if (v.empty()) return s;
    std::sort(v.begin(), v.end());
    s.median = v[v.size() / 2];
    s.p90 = v[std::min(v.size() - 1, v.size() * 9 / 10)];
    s.max = v.back();
    return s;
  }
  std::string text(int precision) const {
    std::ostringstream o;
    o << std::fixed << std::setprecision(precision) << median << " / " << p90 << " / " << max;
    return o.str();
  }
};

struct FlightFigures {
  std::string name;
  size_t frames = 0;
  double first_ms = 0.0;  // the first frame: the whole window read and computed
  std::vector<double> update_ms, cells, changes, edt_ms;
  std::vector<double> read_cells;  // cells read from the map (the blocks that entered the window)
  std::vector<double> moved_ms;    // update_ms of the frames whose window moved
  std::vector<double> inner_ms;    // the accumulator's pass over the inner nodes (MapAccumulator::tree())
  double sample_ns = 0.0, sample_lines_ns = 0.0;  // sample() one point at a time [ns per point]
  double batch_ns = 0.0, batch_lines_ns = 0.0;    // the batch sample() [ns per point]
  double path_in_window_ms = 0.0, path_straight_ms = 0.0;
  std::string path_verdicts;
  std::string edt_box;
};

const char* verdictName(so::PathVerdict v) {
  switch (v) {
    case so::PathVerdict::kClear:
      return "clear";
    case so::PathVerdict::kBlocked:
      return "blocked";
    default:
      return "unknown";
  }
}

/// @p n points of the window: at random (@p along_lines false: mostly cache
/// misses), or along random 20 m lines every 5 cm (a planner's queries along
/// a trajectory).
std::vector<Eigen::Vector3d> samplePoints(const so::DistanceField& field, size_t n, bool along_lines) {
  std::mt19937 rng(5);
  const Eigen::AlignedBox3d box = field.window();
  auto anywhere = [&] {
    return Eigen::Vector3d(box.min() + (box.max() - box.min())
                                           .cwiseProduct(Eigen::Vector3d(std::generate_canonical<double, 32>(rng),
                                                                         std::generate_canonical<double, 32>(rng),
                                                                         std::generate_canonical<double, 32>(rng))));
  };
  std::vector<Eigen::Vector3d> points(n);
  constexpr size_t kLine = 400;  // 20 m at 5 cm
  for (size_t i = 0; i < n; i += kLine) {
    const Eigen::Vector3d a = anywhere(), b = anywhere();
    for (size_t k = 0; k < kLine && i + k < n; ++k)
      points[i + k] =
          along_lines ? Eigen::Vector3d(a + (b - a).normalized() * std::min((b - a).norm(), 0.05 * k)) : anywhere();
  }
  return points;
}

/// Runs of each query timing; the fastest counts (the first may find the window's cells colder than the rest).
constexpr int kSampleRuns = 3;

/// [ns per point] sample() over @p points one at a time, or (@p batch) the
/// batch sample() over all of them at once: the fastest of kSampleRuns runs.
double sampleNs(const so::DistanceField& field, const std::vector<Eigen::Vector3d>& points, bool batch) {
  std::vector<so::DistanceSample> out(points.size());  // allocated and touched before the clock starts
  float sink = 0.0f;
  double best_ms = std::numeric_limits<double>::infinity();
  for (int run = 0; run < kSampleRuns; ++run) {
    const auto t0 = Clock::now();
    if (batch) {
      field.sample(points, &out);
      for (const so::DistanceSample& s : out) sink += s.distance_m + s.gradient.x();
    } else {
      for (const auto& p : points) {
        const so::DistanceSample s = field.sample(p);
        sink += s.distance_m + s.gradient.x();
      }
    }
    best_ms = std::min(best_ms, msSince(t0));
  }
  if (sink == 12345.678f) std::cout << "";  // keeps the loops
  return best_ms * 1e6 / static_cast<double>(points.size());
}

FlightFigures fly(const std::string& name, size_t max_frames, bool with_edt) {
  FlightFigures f;
  f.name = name;
  const so::FlightScenario scenario = so::tools::scenarioNamed(name);
  so::DrawingConfig drawing = so::DrawingConfig::mapperDefaults();
  drawing.threads = 1;
  so::DisparityDrawer drawer(scenario.camera, drawing);
  so::MapAccumulatorConfig map_config;
  map_config.threads = 1;
  so::MapAccumulator map(map_config);
  map.recordClassChanges(true);
  so::DistanceField field(so::DistanceFieldConfig{}, map_config.resolution_m);
  so::LocalGrid grid;
  so::GridUpdate update;
  const size_t frames = std::min(max_frames, scenario.T_W_B.size());
  (void)with_edt;
#ifdef STEREO_OCCUPANCY_HAVE_DYNAMICEDT3D
  // DynamicEDTOctomap's box cannot move: the flight's positions grown by the
  // field's half window. It reads the changes from its tree's change
  // detection: a copy of the map's classes that takes the same class changes.
  std::unique_ptr<octomap::OcTree> mirror;
  std::unique_ptr<DynamicEDTOctomap> edt;
  if (with_edt) {
    Eigen::AlignedBox3d flight;
    for (size_t i = 0; i < frames; ++i) flight.extend(scenario.T_W_B[i].translation());
    const Eigen::Vector3d half(25.0, 25.0, 5.0);
    const Eigen::Vector3d lo = flight.min() - half, hi = flight.max() + half;
    mirror = std::make_unique<octomap::OcTree>(map_config.resolution_m);
    mirror->setOccupancyThres(map_config.occupancy_threshold_prob);
    edt = std::make_unique<DynamicEDTOctomap>(
        static_cast<float>(field.config().max_distance_m), mirror.get(), octomap::point3d(lo.x(), lo.y(), lo.z()),
        octomap::point3d(hi.x(), hi.y(), hi.z()), field.config().unknown_is_occupied);
    std::ostringstream box;
    box << std::fixed << std::setprecision(0) << (hi - lo).x() << " x " << (hi - lo).y() << " x " << (hi - lo).z()
        << " m";
    f.edt_box = box.str();
  }
#endif
  for (size_t i = 0; i < frames; ++i) {
    const Eigen::Isometry3d T_W_C = scenario.cameraPose(i);
    drawer.draw(so::renderStereoFrame(scenario, i, 1), T_W_C, &grid);
    so::encodeGridUpdate(grid, T_W_C.translation(), &update);
    if (!map.integrate(update)) continue;
    bool all = false;
    std::vector<so::CellBox> regions;
    const std::vector<so::CellClassChange> changes = map.takeClassChanges(&all, &regions);
    // The field reads leaves only (MapAccumulator::leafTree()); the pass over
    // the inner nodes is the outputs' (timed apart: what the field used to wait for).
    const auto i0 = Clock::now();
    map.tree();
    const double inner_ms = msSince(i0);
    const auto t0 = Clock::now();
    field.update(map.leafTree(), changes, regions, all, scenario.T_W_B[i].translation());
    const double ms = msSince(t0);
    if (i == 0) {
      f.first_ms = ms;
    } else {
      f.update_ms.push_back(ms);
      f.cells.push_back(static_cast<double>(field.lastUpdatedCells()));
      f.changes.push_back(static_cast<double>(changes.size()));
      f.read_cells.push_back(static_cast<double>(field.lastReadCells()));
      if (field.lastReadCells() > 0) f.moved_ms.push_back(ms);  // no regions here: cells read = a move
      f.inner_ms.push_back(inner_ms);
    }
#ifdef STEREO_OCCUPANCY_HAVE_DYNAMICEDT3D
    if (edt) {
      const int offset = static_cast<int>(mirror->coordToKey(0.0));
      for (const so::CellClassChange& c : changes)
        mirror->setNodeValue(octomap::OcTreeKey(static_cast<octomap::key_type>(c.cell.x() + offset),
                                                static_cast<octomap::key_type>(c.cell.y() + offset),
                                                static_cast<octomap::key_type>(c.cell.z() + offset)),
                             c.now == so::CellClass::kOccupied ? 1.0f : -1.0f, /*lazy_eval=*/true);
      const auto e0 = Clock::now();
      edt->update();
      if (i > 0) f.edt_ms.push_back(msSince(e0));
    }
#endif
    ++f.frames;
  }
  const std::vector<Eigen::Vector3d> random_points = samplePoints(field, 1000000, false);
  const std::vector<Eigen::Vector3d> line_points = samplePoints(field, 1000000, true);
  f.sample_ns = sampleNs(field, random_points, false);
  f.batch_ns = sampleNs(field, random_points, true);
  f.sample_lines_ns = sampleNs(field, line_points, false);
  f.batch_lines_ns = sampleNs(field, line_points, true);
  // 1 km in the window: 50 legs of 20 m across it in its top layer (the walk
  // visits every cell: unknown cells do not stop it, radius 0) ...
  const Eigen::Vector3d W_v = scenario.T_W_B[frames - 1].translation();
  std::vector<Eigen::Vector3d> zigzag;
  for (int k = 0; k <= 50; ++k)
    zigzag.emplace_back(W_v.x() + (k % 2 ? 10.0 : -10.0), W_v.y() - 12.0 + 0.48 * k, field.window().max().z() - 0.1);
  auto t0 = Clock::now();
  const so::PathCheckResult in_window = field.checkPath(zigzag, 0.0, false);
  f.path_in_window_ms = msSince(t0);
  // ... and straight ahead, 101 waypoints 10 m apart (most of it beyond the window).
  std::vector<Eigen::Vector3d> straight;
  for (int k = 0; k <= 100; ++k) straight.push_back(W_v + Eigen::Vector3d(10.0 * k, 0.3 * k, 0.0));
  t0 = Clock::now();
  const so::PathCheckResult ahead = field.checkPath(straight, 0.5, false);
  f.path_straight_ms = msSince(t0);
  f.path_verdicts = std::string(verdictName(in_window.verdict)) + " / " + verdictName(ahead.verdict);
  return f;
}

int run(int argc, char** argv) {
  std::vector<std::string> names;
  size_t max_frames = 100000;
  bool with_edt = true;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--scenario") {
      names.push_back(so::tools::nextValue(argc, argv, &i));
    } else if (a == "--frames") {
      max_frames = static_cast<size_t>(so::tools::parseWhole(a, so::tools::nextValue(argc, argv, &i), 2, 100000));
    } else if (a == "--no-dynamicedt") {
      with_edt = false;
    } else if (a == "--help") {
      std::cout
          << "usage: distance_field_benchmark [--scenario NAME]... [--frames N] [--no-dynamicedt]\n"
             "Flies the simulated flights (default posts, forest, houses, wires) as the mapper maps them "
             "and times the distance field's update per fused frame (50 x 50 x 10 m window, 0.25 m, 2 m), "
             "sample() (one at a time and in a batch) and a 1 km path check; and DynamicEDTOctomap's update() on the "
             "same changes.\n";
      return 0;
    } else {
      throw so::tools::UsageError("unknown option '" + a + "'");
    }
  }
  if (names.empty()) names = {"posts", "forest", "houses", "wires"};
#ifndef STEREO_OCCUPANCY_HAVE_DYNAMICEDT3D
  with_edt = false;
#endif
  std::cout << "Distance field: 50 x 50 x 10 m window at 0.25 m (200 x 200 x 40 cells), max distance 2 m, unknown "
               "not occupied, one thread; the frames drawn and fused as the mapper does (untimed).\n"
               "Per frame after the first (which reads and computes the whole window): the field's update from "
               "the fusion's class changes [ms], the cells it recomputed, the class changes it took"
            << (with_edt ? "; DynamicEDTOctomap's update() after the same changes [ms]" : "") << ".\n\n";
  std::cout << "| flight | frames | first frame ms | update ms median / p90 / max | cells recomputed median / p90 / "
               "max | class changes median / p90 / max |"
            << (with_edt ? " DynamicEDTOctomap ms median / p90 / max |" : "") << "\n|---|---:|---:|---|---|---|"
            << (with_edt ? "---|" : "") << "\n";
  std::vector<FlightFigures> all;
  for (const std::string& name : names) {
    all.push_back(fly(name, max_frames, with_edt));
    const FlightFigures& f = all.back();
    std::cout << "| " << f.name << " | " << f.frames << " | " << std::fixed << std::setprecision(1) << f.first_ms
              << " | " << Spread::of(f.update_ms).text(2) << " | " << Spread::of(f.cells).text(0) << " | "
              << Spread::of(f.changes).text(0) << " |";
    if (with_edt) std::cout << " " << Spread::of(f.edt_ms).text(2) << " (box " << f.edt_box << ") |";
    std::cout << std::endl;
  }
  std::cout << "\nWhere the time goes: the frames whose window moved (the blocks that enter are read from the "
               "octree), the cells read on them, and the accumulator's pass over the octree's inner nodes "
               "(MapAccumulator::tree(), which the field does not wait for: it reads leaves only).\n\n"
               "| flight | frames moved | update ms when moved median / p90 / max | cells read when moved median / "
               "max | inner-node pass ms median / p90 / max |\n|---|---:|---|---|---|\n";
  for (const FlightFigures& f : all) {
    std::vector<double> read;
    for (double c : f.read_cells)
      if (c > 0) read.push_back(c);
    const Spread r = Spread::of(read);
    std::cout << "| " << f.name << " | " << f.moved_ms.size() << " | " << Spread::of(f.moved_ms).text(2) << " | "
              << std::setprecision(0) << r.median << " / " << r.max << " | " << Spread::of(f.inner_ms).text(2)
              << " |\n";
  }
  std::cout << "\n| flight | sample() ns per point, random / along lines | batch sample() ns per point, random / "
               "along lines | 1 km path check in the window ms | 1 km straight ahead ms | verdicts "
               "|\n|---|---:|---:|---:|---:|---|\n";
  for (const FlightFigures& f : all)
    std::cout << "| " << f.name << " | " << std::fixed << std::setprecision(1) << f.sample_ns << " / "
              << f.sample_lines_ns << " | " << f.batch_ns << " / " << f.batch_lines_ns << " | " << std::setprecision(3)
              << f.path_in_window_ms << " | " << f.path_straight_ms << " | " << f.path_verdicts << " |\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return so::tools::runTool("distance_field_benchmark", [&] { return run(argc, argv); });
}
