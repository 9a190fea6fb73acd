// compare_wavemap: the whole path against its peers on the same frames, one
// thread each, one after the other in one run (issue 48): the nodelets' path
// (WholePath: a DisparityImage in, the map fused), wavemap's projective
// integrator into its hashed chunked wavelet octree (the same frame as a
// depth image), and OctoMap's insertPointCloud (as a point cloud), each
// into its own map of the flight; and, as a floor, the paper's line_pyramid
// drawing alone (no encoding, no fusion). Built only where CMake finds wavemap.
// A benchmark: it prints figures and asserts nothing.

#include <octomap/octomap.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "drawing_benchmark.h"
#include "scenario_support.h"
#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "stereo_occupancy/sim/wavemap_integrator.h"
#include "stereo_occupancy/time_statistics.h"
#include "tool_support.h"
#include "whole_path.h"

namespace so = stereo_occupancy;

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

/// Per frame of one flight [ms], and the peers' time over ours.
struct FlightTimes {
  std::vector<double> ours, wavemap, octomap, wavemap_ratio, octomap_ratio;
  std::vector<double> paper;  ///< the paper's line_pyramid drawing alone (grid, pyramids, lines)
  /// Frames where the paper's drawing alone takes longer than wavemap's
  /// time ÷ 5 (OctoMap's ÷ 50): with this drawing, no speed-up of the
  /// stages after it reaches the goal there, even with them free.
  size_t paper_over_wavemap_goal = 0, paper_over_octomap_goal = 0;
};

constexpr double kWavemapGoal = 5.0;   ///< issue 48: the whole path ≥ 5× wavemap's speed
constexpr double kOctomapGoal = 50.0;  ///< and ≥ 50× OctoMap's

/// Each method over the whole flight in turn, into its own map, from inputs
/// made beforehand: interleaved frame by frame, each would evict the
/// others' maps from the caches (OctoMap's most), which costs the nodelets'
/// path half its time again on this VM.
FlightTimes timeFlight(const so::FlightScenario& scenario) {
  so::tools::WholePath ours(1);
  const double cell_m = ours.mapper().drawing.resolution_m;
  // Each method's input as its users hand it over (untimed): the message
  // with its pose on tf, a depth image, a point cloud in the world.
  std::vector<stereo_msgs::DisparityImageConstPtr> images;
  std::vector<cv::Mat> disparities, depths;
  std::vector<octomap::Pointcloud> clouds;
  for (size_t i = 0; i < scenario.T_W_B.size(); ++i) {
    const cv::Mat disparity = so::renderStereoFrame(scenario, i, 1);
    images.push_back(ours.prepare(scenario, i, disparity, i));
    disparities.push_back(disparity);
    depths.push_back(so::tools::depthFromDisparity(disparity, scenario.camera));
    clouds.push_back(so::tools::disparityCloud(disparity, scenario.camera, scenario.cameraPose(i)));
  }
  FlightTimes t;
  for (size_t i = 0; i < images.size(); ++i) {
    const auto t0 = Clock::now();
    if (!ours.run(images[i], nullptr)) throw std::runtime_error("frame " + std::to_string(i) + " was not mapped");
    t.ours.push_back(msSince(t0));
  }
  so::WavemapIntegrator wavemap(scenario.camera, cell_m, 1);
  for (size_t i = 0; i < depths.size(); ++i) {
    const auto t0 = Clock::now();
    wavemap.integrate(depths[i], scenario.cameraPose(i));
    t.wavemap.push_back(msSince(t0));
  }
  octomap::OcTree octree(cell_m);
  for (size_t i = 0; i < clouds.size(); ++i) {
    const Eigen::Vector3d o = scenario.cameraPose(i).translation();
    const auto t0 = Clock::now();
    octree.insertPointCloud(
        clouds[i], octomap::point3d(static_cast<float>(o.x()), static_cast<float>(o.y()), static_cast<float>(o.z())),
        scenario.camera.max_range_m, /*lazy_eval=*/false, /*discretize=*/true);
    t.octomap.push_back(msSince(t0));
  }
  // The paper's profile and pyramids.
  so::DisparityDrawer paper(scenario.camera, so::tools::drawingConfig(so::DrawingAlgorithm::kLinePyramid, cell_m, 1));
  so::LocalGrid grid;
  for (size_t i = 0; i < disparities.size(); ++i) {
    const auto t0 = Clock::now();
    paper.draw(disparities[i], scenario.cameraPose(i), &grid);
    t.paper.push_back(msSince(t0));
  }
  for (size_t i = 0; i < t.ours.size(); ++i) {
    t.wavemap_ratio.push_back(t.wavemap[i] / t.ours[i]);
    t.octomap_ratio.push_back(t.octomap[i] / t.ours[i]);
    t.paper_over_wavemap_goal += t.paper[i] > t.wavemap[i] / kWavemapGoal;
    t.paper_over_octomap_goal += t.paper[i] > t.octomap[i] / kOctomapGoal;
  }
  return t;
}

std::string medianMax(const std::vector<double>& ms) {
  const so::TimeStatistics t = so::TimeStatistics::of(ms);
  std::ostringstream s;
  s << std::fixed << std::setprecision(2) << t.median_ms << " / " << t.max_ms;
  return s.str();
}

std::string minMedian(const std::vector<double>& ratio) {
  const so::TimeStatistics t = so::TimeStatistics::of(ratio);
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << t.min_ms << "× / " << t.median_ms << "×";
  return s.str();
}

int run(int argc, char** argv) {
  std::vector<std::string> flights;
  std::string per_frame_path;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--flight") {
      flights.push_back(so::tools::nextValue(argc, argv, &i));
    } else if (a == "--per-frame") {
      per_frame_path = so::tools::nextValue(argc, argv, &i);
    } else if (a == "--help") {
      std::cout << "usage: compare_wavemap [--flight NAME]... [--per-frame FILE.csv]\n"
                   "Times, per frame, one thread each: the nodelets' whole path (image in to map fused), "
                   "wavemap's projective integrator and OctoMap's insertPointCloud, each into its own map of "
                   "the flight (default: every flight), one method after the other. --per-frame writes each "
                   "frame's times (flight, frame, ours_ms, wavemap_ms, octomap_ms, paper_ms) as CSV. The paper's "
                   "line_pyramid drawing alone (no encoding, no fusion) is timed too: the frames where it takes "
                   "longer than wavemap ÷ 5 (OctoMap ÷ 50) are those where, with this drawing, no speed-up of the "
                   "stages after it reaches issue 48's goals.\n";
      return 0;
    } else {
      throw so::tools::UsageError("unknown option '" + a + "'");
    }
  }
  if (flights.empty()) flights = so::scenarioNames();
  std::ofstream per_frame;
  if (!per_frame_path.empty()) {
    per_frame.open(per_frame_path);
    if (!per_frame) throw std::runtime_error("cannot write " + per_frame_path);
    per_frame << "flight,frame,ours_ms,wavemap_ms,octomap_ms,paper_ms\n";
  }
  std::cout << "Per frame, one thread each, 0.25 m cells, 25 m range [ms: median / max]; the peers' time over "
               "ours per frame [min / median]; the paper's line_pyramid drawing alone, and the frames where it "
               "alone takes longer than wavemap ÷ 5 / OctoMap ÷ 50.\n\n"
               "| flight | frames | ours | wavemap | OctoMap | wavemap / ours | OctoMap / ours | paper's drawing | "
               "over wavemap ÷ 5 / OctoMap ÷ 50 |\n"
               "|---|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const std::string& name : flights) {
    const so::FlightScenario scenario = so::tools::scenarioNamed(name);
    const FlightTimes t = timeFlight(scenario);
    for (size_t i = 0; per_frame.is_open() && i < t.ours.size(); ++i)
      per_frame << name << ',' << i << ',' << t.ours[i] << ',' << t.wavemap[i] << ',' << t.octomap[i] << ','
                << t.paper[i] << '\n';
    std::cout << "| " << name << " | " << t.ours.size() << " | " << medianMax(t.ours) << " | " << medianMax(t.wavemap)
              << " | " << medianMax(t.octomap) << " | " << minMedian(t.wavemap_ratio) << " | "
              << minMedian(t.octomap_ratio) << " | " << medianMax(t.paper) << " | " << t.paper_over_wavemap_goal
              << " / " << t.paper_over_octomap_goal << " |" << std::endl;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return so::tools::runTool("compare_wavemap", [&] { return run(argc, argv); });
}
