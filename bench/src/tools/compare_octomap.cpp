// compare_octomap: the same simulated flight mapped by the six algorithms
// and by OctoMap's own insertPointCloud (what octomap_server does, with and
// without discretize), in one run, at the same resolutions and range: time
// per frame and map quality against the ground truth, as a Markdown table.
// A benchmark: it prints figures and asserts nothing.

#include <octomap/octomap.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "scenario_support.h"
#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "stereo_occupancy/sim/map_evaluation.h"
#include "tool_support.h"

namespace so = stereo_occupancy;
namespace tools = stereo_occupancy::tools;
using Clock = std::chrono::steady_clock;

namespace {

double ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

std::string pct(double v) {
  std::ostringstream o;
  o << std::fixed << std::setprecision(1) << 100.0 * v;
  return o.str();
}

std::string num(double v, int digits = 2) {
  std::ostringstream o;
  o << std::fixed << std::setprecision(digits) << v;
  return o.str();
}

/// The reference of the detection comparison.
const char* kOctomapName = "OctoMap insertPointCloud";

/// "#3 (15.0, 3.5) 0.4x0.4x8 m": an obstacle's index, ground position and size.
std::string describeBox(size_t k, const Eigen::AlignedBox3d& box) {
  const Eigen::Vector3d c = box.center(), size = box.sizes();
  return "#" + std::to_string(k) + " (" + num(c.x(), 1) + ", " + num(c.y(), 1) + ") " + num(size.x(), 2) + "x" +
         num(size.y(), 2) + "x" + num(size.z(), 2) + " m";
}

/// One resolution's detection figures: a summary row per method into
/// @p summary and a row per observed obstacle into @p table (its header
/// first if it is empty).
void reportDetections(double res, const so::SyntheticScene& scene, const so::ObstacleZones& zones,
                      const std::vector<std::pair<std::string, std::vector<so::Detection>>>& detections,
                      std::ostringstream* summary, std::ostringstream* table) {
  const std::vector<so::Detection>* reference = nullptr;
  for (const auto& [name, found] : detections)
    if (name == kOctomapName) reference = &found;
  auto distance = [](double v) { return std::isfinite(v) ? num(v, 1) : std::string("-"); };
  for (const auto& [name, found] : detections) {
    const so::DetectionSummary d = so::summarizeDetections(zones, found, reference);
    *summary << "| " << res << " m | " << name << " | " << d.detected << " of " << d.observed << " | "
             << distance(d.median_distance_m) << " | " << distance(d.min_distance_m) << " | "
             << (reference ? std::to_string(d.later_than_reference) : "-") << " | "
             << (reference ? std::to_string(d.earlier_than_reference) : "-") << " |\n";
  }
  if (table->tellp() == 0) {
    *table << "\n| cell | obstacle |";
    for (const auto& method : detections) *table << " " << method.first << " |";
    *table << "\n|---|---|";
    for (size_t m = 0; m < detections.size(); ++m) *table << "---:|";
    *table << "\n";
  }
  for (size_t k = 0; k < zones.zones.size(); ++k) {
    if (zones.zones[k].empty()) continue;
    *table << "| " << res << " m | " << describeBox(k, scene.boxes[k]) << " |";
    for (const auto& method : detections) {
      const so::Detection& d = method.second[k];
      *table << " " << (d.detected() ? num(d.distance_m, 1) + " (" + std::to_string(d.frame) + ")" : "-") << " |";
    }
    *table << "\n";
  }
}

const char* kUsage =
    "usage: compare_octomap [--scenario NAME] [--frame-step N] [--seed N] [--matcher gaussian|sgbm]\n"
    "                       [--resolution M [--resolution M ...]] [--truth-pixel-step N]\n"
    "                       [--algorithm NAME [--algorithm NAME ...]] [--no-octomap]\n"
    "NAME: posts, houses, forest, wires, posts_far, forest_far\n"
    "--matcher: the flight's disparities: gaussian (default; exact with Gaussian noise) or sgbm (StereoSGBM\n"
    "  with stereo_image_proc's defaults on rendered left and right images)\n"
    "--truth-pixel-step: true surface cells from every N-th pixel (default 4; 1 finds wires)\n"
    "--algorithm: only these drawing algorithms (default all six); --no-octomap: leave OctoMap out\n"
    "--model NAME=VALUE: a numeric parameter of the sensor model (k_m, p_hit, ... as in config/mapping.yaml),\n"
    "  surface (1: the surface profile) or delta_d_px of the drawing (repeatable)\n"
    "--map NAME=VALUE: a numeric parameter of the map (clamping_min_prob, ...; repeatable)\n";

int run(int argc, char** argv) {
  std::string scenario_name = "posts";
  int frame_step = 4;
  uint32_t seed = 1;
  std::vector<double> resolutions = {1.0, 0.5, 0.25};
  bool resolution_given = false;
  int truth_pixel_step = 4;
  std::vector<so::DrawingAlgorithm> algorithms;
  std::map<std::string, double> model_values, map_values;
  bool with_octomap = true;
  so::StereoMatcher matcher = so::StereoMatcher::kGaussian;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--scenario") {
      scenario_name = tools::nextValue(argc, argv, &i);
    } else if (a == "--frame-step") {
      frame_step = static_cast<int>(tools::parseWhole(a, tools::nextValue(argc, argv, &i), 1, 10000));
    } else if (a == "--seed") {
      seed = static_cast<uint32_t>(tools::parseWhole(a, tools::nextValue(argc, argv, &i), 0, 4294967295L));
    } else if (a == "--truth-pixel-step") {
      truth_pixel_step = static_cast<int>(tools::parseWhole(a, tools::nextValue(argc, argv, &i), 1, 64));
    } else if (a == "--algorithm") {  // repeatable
      so::DrawingAlgorithm algorithm;
      const std::string name = tools::nextValue(argc, argv, &i);
      if (!so::parseDrawingAlgorithm(name, &algorithm))
        throw tools::UsageError("--algorithm must be one of " + so::drawingAlgorithmNames());
      algorithms.push_back(algorithm);
    } else if (a == "--model" || a == "--map") {  // name=value of the sensor model or the map, repeatable
      tools::addNameValue(argc, argv, &i, a == "--model" ? &model_values : &map_values);
    } else if (a == "--matcher") {
      if (!so::parseStereoMatcher(tools::nextValue(argc, argv, &i), &matcher))
        throw tools::UsageError("--matcher must be gaussian or sgbm");
    } else if (a == "--no-octomap") {
      with_octomap = false;
    } else if (a == "--resolution") {  // repeatable
      if (!resolution_given) resolutions.clear();
      resolution_given = true;
      resolutions.push_back(tools::parseNumber(a, tools::nextValue(argc, argv, &i)));
      if (!(resolutions.back() >= 0.05 && resolutions.back() <= 10.0))
        throw tools::UsageError("--resolution must be in [0.05, 10] m");
    } else {
      throw tools::UsageError("unknown option '" + a + "'");
    }
  }
  if (algorithms.empty()) algorithms = so::allDrawingAlgorithms();
  so::FlightScenario scenario = tools::scenarioNamed(scenario_name);
  so::useMatcher(&scenario, matcher);
  // Only every frame_step-th frame is mapped (OctoMap takes seconds a frame).
  std::vector<Eigen::Isometry3d> poses;
  std::vector<cv::Mat> images;
  for (size_t i = 0; i < scenario.T_W_B.size(); i += frame_step) {
    poses.push_back(scenario.cameraPose(i));
    images.push_back(so::renderStereoFrame(scenario, i, seed));
  }
  so::FlightScenario truth_flight = scenario;
  truth_flight.T_W_B.clear();
  for (size_t i = 0; i < scenario.T_W_B.size(); i += frame_step) truth_flight.T_W_B.push_back(scenario.T_W_B[i]);
  const double max_range = scenario.camera.max_range_m;
  const so::StereoCameraModel camera(scenario.camera);

  const std::string matcher_text = scenario.matcher == so::StereoMatcher::kSgbm
                                       ? "matcher sgbm: " + scenario.sgbm.describe()
                                       : std::string("matcher gaussian: exact disparities with Gaussian noise");
  std::cout << "Scenario '" << scenario_name << "' (seed " << seed << ", " << matcher_text << "): " << images.size()
            << " frames (every " << frame_step << "th of " << scenario.T_W_B.size()
            << "), 640x480, 25 m range. One thread. Time per frame, median over the frames.\n"
            << "Ours: draw (incl. pyramid) + encode, then fusion into the OcTree (MapAccumulator), with the paper's "
               "Gaussian profile (eqs. 9-10) unless named \"surface\" (the mapper's default). OctoMap: "
               "insertPointCloud of the valid pixels' points (zero disparity has no point), max range 25 m.\n"
            << "Quality within one cell against the ground truth of the mapped frames (surface cells from "
            << (truth_pixel_step == 1 ? std::string("every pixel")
                                      : "every " + std::to_string(truth_pixel_step) + "th pixel")
            << ", empty cells from every 4th).\n\n"
            << "\"frame: surface called free\" counts, over the frames, the cells of each frame's own true "
               "surfaces (every pixel) that the frame's local grid calls free: the drawing alone, before fusion.\n\n"
            << "| cell | method | draw ms | fusion ms | total ms | occupied precision % | occupied recall % | "
               "F1 | phantom % | surface called free % | free coverage % | frame: surface called free % |\n"
               "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  // Per range band (distance to the nearest viewpoint), printed after the main table.
  std::ostringstream bands;
  bands << "\nBy range band (a cell's distance to the nearest viewpoint of the mapped frames):\n\n"
        << "| cell | method | band | F1 | occupied precision % | occupied recall % | phantom % | "
           "surface called free % | occupied cells |\n|---|---|---|---:|---:|---:|---:|---:|---:|\n";

  // Detection range per method, printed last.
  std::ostringstream detection_summary, detection_table;
  detection_summary
      << "\nDetection range: for each obstacle (each box of the scene; the ground is none) that the mapped "
         "frames see within range, the distance from the camera centre to the obstacle at the first mapped "
         "frame after whose fusion an occupied cell lies in its zone: the cells holding its surface "
         "points seen in the exact images ("
      << (truth_pixel_step == 1 ? std::string("every pixel") : "every " + std::to_string(truth_pixel_step) + "th pixel")
      << "), with their 26 neighbours, less the cells holding another box's or the ground's "
         "surface points. Later / earlier: obstacles this method detects more than one mapped frame "
         "later / earlier than OctoMap insertPointCloud, or never / OctoMap never.\n\n"
         "| cell | method | obstacles detected | median distance m | min distance m | later than OctoMap | "
         "earlier than OctoMap |\n|---|---|---:|---:|---:|---:|---:|\n";
  for (double res : resolutions) {
    const so::ObservedGroundTruth truth = so::observeGroundTruth(truth_flight, res, max_range, 1, 4, truth_pixel_step);
    const so::ObstacleZones zones = so::observeObstacles(truth_flight, res, max_range, 1, truth_pixel_step);
    std::vector<std::pair<std::string, std::vector<so::Detection>>> detections;  // per method, in the table's order
    std::vector<std::vector<Eigen::Vector3i>> frame_surfaces;
    size_t frame_surface_cells = 0;
    for (size_t i = 0; i < truth_flight.T_W_B.size(); ++i) {
      frame_surfaces.push_back(so::frameSurfaceCells(truth_flight, i, res, max_range));
      frame_surface_cells += frame_surfaces.back().size();
    }
    auto report = [&](const std::string& name, std::vector<double> draw, std::vector<double> fuse,
                      const octomap::OcTree& tree, const std::string& frame_called_free) {
      auto median = [](std::vector<double> v) {
        if (v.empty()) return 0.0;
        std::sort(v.begin(), v.end());
        return v[v.size() / 2];
      };
      std::vector<double> total(draw.size());
      for (size_t i = 0; i < draw.size(); ++i) total[i] = draw[i] + fuse[i];
      const so::MapQuality q = so::evaluateMap(tree, scenario.scene, truth);
      std::cout << "| " << res << " m | " << name << " | " << num(median(draw), 3) << " | " << num(median(fuse), 3)
                << " | " << num(median(total), 3) << " | " << pct(q.occupiedPrecision()) << " | "
                << pct(q.occupiedRecall()) << " | " << num(q.f1(), 3) << " | " << pct(q.phantomShare()) << " | "
                << pct(q.surfaceCalledFree()) << " | " << pct(q.freeCoverage()) << " | " << frame_called_free << " |"
                << std::endl;
      for (const so::RangeBand& band : so::standardRangeBands()) {
        const so::MapQuality b = so::evaluateMap(tree, scenario.scene, truth, band);
        bands << "| " << res << " m | " << name << " | " << band.name() << " | " << num(b.f1(), 3) << " | "
              << pct(b.occupiedPrecision()) << " | " << pct(b.occupiedRecall()) << " | " << pct(b.phantomShare())
              << " | " << pct(b.surfaceCalledFree()) << " | " << b.occupied_cells << " |\n";
      }
    };
    // Each algorithm with the paper's profile, and the mapper's default
    // (line_pyramid_bounded with the surface profile) when it is asked for.
    std::vector<std::pair<so::DrawingAlgorithm, so::SensorProfile>> methods;
    for (so::DrawingAlgorithm algorithm : algorithms) {
      methods.emplace_back(algorithm, so::SensorProfile::kGaussian);
      if (algorithm == so::DrawingAlgorithm::kLinePyramidBounded)
        methods.emplace_back(algorithm, so::SensorProfile::kSurface);
    }
    for (const auto& [algorithm, profile] : methods) {
      so::DrawingConfig config;
      config.algorithm = algorithm;
      config.resolution_m = res;
      config.sensor_model.profile = profile;
      so::StereoCameraConfig camera_config = scenario.camera;
      for (const auto& [name, value] : model_values) {
        if (name == "surface")
          config.sensor_model.profile = value != 0.0 ? so::SensorProfile::kSurface : so::SensorProfile::kGaussian;
        else if (name == "delta_d_px")
          camera_config.delta_d_px = value;
        else if (!so::setNumberParameter(&config.sensor_model, name, value))
          throw tools::UsageError("--model: unknown name '" + name + "'");
      }
      so::DisparityDrawer drawer(camera_config, config);
      so::MapAccumulatorConfig map_config;
      for (const auto& [name, value] : map_values)
        if (!so::setNumberParameter(&map_config, name, value))
          throw tools::UsageError("--map: unknown name '" + name + "'");
      map_config.resolution_m = res;
      std::string why;
      if (!map_config.isValid(&why)) throw tools::UsageError("--map: " + why);
      so::MapAccumulator map(map_config);
      so::LocalGrid grid;
      so::GridUpdate update;
      std::vector<double> draw, fuse;
      size_t called_free = 0;
      so::DetectionTracker tracker(zones, scenario.scene);
      for (size_t i = 0; i < images.size(); ++i) {
        const auto t0 = Clock::now();
        drawer.draw(images[i], poses[i], &grid);
        so::encodeGridUpdate(grid, poses[i].translation(), &update);
        const auto t1 = Clock::now();
        map.integrate(update);
        const auto t2 = Clock::now();
        draw.push_back(ms(t0, t1));
        fuse.push_back(ms(t1, t2));
        called_free += so::countCalledFree(grid, frame_surfaces[i]);
        tracker.update(map.tree(), static_cast<long>(i), poses[i].translation());
      }
      const std::string name = std::string(so::toString(algorithm)) +
                               (config.sensor_model.profile == so::SensorProfile::kSurface ? ", surface" : "");
      report(name, draw, fuse, map.tree(),
             pct(frame_surface_cells ? static_cast<double>(called_free) / frame_surface_cells : 0.0));
      detections.emplace_back(name, tracker.detections());
    }
    for (bool discretize : {false, true}) {
      if (!with_octomap) break;
      octomap::OcTree tree(res);
      std::vector<double> draw, fuse;
      so::DetectionTracker tracker(zones, scenario.scene);
      for (size_t i = 0; i < images.size(); ++i) {
        const auto t0 = Clock::now();
        const octomap::Pointcloud cloud = so::worldPointCloud(images[i], camera, poses[i]);
        const Eigen::Vector3d o = poses[i].translation();
        const auto t1 = Clock::now();
        tree.insertPointCloud(cloud, octomap::point3d(o.x(), o.y(), o.z()), max_range, /*lazy_eval=*/false, discretize);
        const auto t2 = Clock::now();
        draw.push_back(ms(t0, t1));
        fuse.push_back(ms(t1, t2));
        tracker.update(tree, static_cast<long>(i), o);
      }
      const std::string name = discretize ? "OctoMap insertPointCloud, discretize" : "OctoMap insertPointCloud";
      report(name, draw, fuse, tree, "-");  // no grid of its own per frame
      detections.emplace_back(name, tracker.detections());
    }
    reportDetections(res, scenario.scene, zones, detections, &detection_summary, &detection_table);
  }
  std::cout
      << bands.str() << detection_summary.str()
      << "\nPer obstacle: the distance [m] at which each method first shows it, and the mapped frame (-: never).\n"
      << detection_table.str();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return so::tools::runTool("compare_octomap", [&] { return run(argc, argv); });
}
