// scaling: how each algorithm's time and work grow with the cell size and
// with the image size, on the Table I scene (a camera 2 m above the ground
// looking at posts, boxes and a house between 6 and 26 m). A benchmark: it
// prints Markdown tables and asserts nothing.

#include <algorithm>
#include <chrono>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "drawing_benchmark.h"
#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "tool_support.h"

namespace so = stereo_occupancy;
namespace tools = stereo_occupancy::tools;

namespace {

const char* kUsage =
    "usage: scaling [--repeat N] [--threads N,M,...]\n"
    "Times the six algorithms on the Table I scene against the cell size (1.0, 0.5, 0.25, 0.1 m at\n"
    "640x480) and the image size (640x480, 1280x960, 1920x1200 at 0.25 m; f scaled with the width),\n"
    "with the Table I counters. Median of N runs (default 7) for the pyramids, of 3 for the others.\n"
    "Then the line algorithms and the blur at 640x480 and 1280x960, 0.25 m, on each number of threads\n"
    "of --threads (default 1,2), with the speed-up over the first.\n";

/// The Table I scene seen by a camera of the given size: sky matched at zero
/// disparity, 3 % of the pixels unmatched.
cv::Mat sceneImage(const so::StereoCameraConfig& camera, Eigen::Isometry3d* T_W_C) {
  const so::SyntheticScene scene = so::table1Scene(T_W_C);
  cv::Mat image = so::renderDisparity(scene, so::StereoCameraModel(camera), *T_W_C);
  so::addInvalidSpeckle(&image, 0.03, 7);
  return image;
}

void row(const so::StereoCameraConfig& camera, double resolution, int repeat) {
  Eigen::Isometry3d T_W_C;
  const cv::Mat image = sceneImage(camera, &T_W_C);
  for (so::DrawingAlgorithm algorithm : so::allDrawingAlgorithms()) {
    so::DisparityDrawer drawer(camera, so::tools::drawingConfig(algorithm, resolution));
    so::LocalGrid grid;
    so::DrawStatistics stats;
    const bool plain = algorithm == so::DrawingAlgorithm::kLine || algorithm == so::DrawingAlgorithm::kRayTrace;
    const std::vector<double> ms =
        tools::timeDrawing(&drawer, image, T_W_C, plain ? 3 : repeat, /*time_grid_preparation=*/false, &grid, &stats);
    stats.different_grid_cells = grid.countKnown();  // the last run's grid, counted outside the timing
    std::ostringstream time;
    time << std::fixed << std::setprecision(ms[ms.size() / 2] < 10 ? 2 : 0) << ms[ms.size() / 2] << " (" << ms.front()
         << "-" << ms.back() << ")";
    // Line drawing's work is the cells it draws; ray tracing's, the cells of the box it projects.
    const bool line = algorithm == so::DrawingAlgorithm::kLine || algorithm == so::DrawingAlgorithm::kLinePyramid ||
                      algorithm == so::DrawingAlgorithm::kLinePyramidBounded;
    const double cells = static_cast<double>(line ? stats.grid_cells_drawn : grid.numCells());
    std::ostringstream per_cell;
    per_cell << std::fixed << std::setprecision(1) << (cells > 0 ? 1e6 * ms[ms.size() / 2] / cells : 0.0);
    std::cout << "| " << camera.width_px << "x" << camera.height_px << " | " << resolution << " m | "
              << so::toString(algorithm) << " | " << grid.numCells() << " | " << stats.coordinate_transfers << " | "
              << stats.used_image_pixels << " | " << stats.grid_cells_drawn << " | " << stats.different_grid_cells
              << " | " << time.str() << " | " << per_cell.str() << " |" << std::endl;
  }
}

so::StereoCameraConfig cameraOfWidth(int w, int h) {
  so::StereoCameraConfig camera;
  camera.width_px = w;
  camera.height_px = h;
  camera.focal_length_px = 700.0 * w / 640.0;
  camera.cx_px = 0.5 * (w - 1);
  camera.cy_px = 0.5 * (h - 1);
  return camera;
}

/// Median time [ms] of @p repeat blurs of @p drawn (eq. 17, σ_trans 0.1 m, σ_angle 0.01 rad).
double blurMs(so::DisparityDrawer* drawer, const so::LocalGrid& drawn, const Eigen::Isometry3d& T_W_C, int repeat) {
  std::vector<double> ms;
  so::LocalGrid grid;
  for (int r = 0; r < repeat; ++r) {
    grid = drawn;
    const auto t0 = std::chrono::steady_clock::now();
    drawer->blur(T_W_C, &grid);
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ms.begin(), ms.end());
  return ms[ms.size() / 2];
}

/// The line algorithms and the blur on each number of @p threads, with the speed-up over the first.
void threadRows(const so::StereoCameraConfig& camera, const std::vector<int>& threads, int repeat) {
  Eigen::Isometry3d T_W_C;
  const cv::Mat image = sceneImage(camera, &T_W_C);
  for (const char* stage : {"line", "line_pyramid", "line_pyramid_bounded", "blur"}) {
    double first_ms = 0.0;
    for (size_t k = 0; k < threads.size(); ++k) {
      const bool blur = std::string(stage) == "blur";
      so::DrawingAlgorithm algorithm = so::DrawingAlgorithm::kLinePyramid;  // the blur's grid
      if (!blur) so::parseDrawingAlgorithm(stage, &algorithm);
      so::DrawingConfig config = tools::drawingConfig(algorithm, 0.25, threads[k]);
      config.blur.sigma_trans_m = 0.1;
      config.blur.sigma_angle_rad = 0.01;
      so::DisparityDrawer drawer(camera, config);
      so::LocalGrid grid;
      so::DrawStatistics stats;
      const int runs = std::string(stage) == "line" ? 3 : repeat;
      const std::vector<double> ms =
          tools::timeDrawing(&drawer, image, T_W_C, runs, /*time_grid_preparation=*/false, &grid, &stats);
      const double median = blur ? blurMs(&drawer, grid, T_W_C, runs) : ms[ms.size() / 2];
      if (k == 0) first_ms = median;
      std::cout << "| " << camera.width_px << "x" << camera.height_px << " | " << stage << " | " << threads[k] << " | "
                << std::fixed << std::setprecision(median < 10 ? 2 : 1) << median << " | " << std::setprecision(2)
                << first_ms / median << " |" << std::endl;
    }
  }
}

int run(int argc, char** argv) {
  int repeat = 7;
  std::vector<int> threads = {1, 2};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--repeat") {
      repeat = static_cast<int>(tools::parseWhole(a, tools::nextValue(argc, argv, &i), 1, 1000));
    } else if (a == "--threads") {
      threads.clear();
      std::stringstream list(tools::nextValue(argc, argv, &i));
      for (std::string n; std::getline(list, n, ',');)
        threads.push_back(static_cast<int>(tools::parseWhole(a, n, 1, 64)));
    } else if (a == "--help") {
      std::cout << kUsage;
      return 0;
    } else {
      throw tools::UsageError("unknown option '" + a + "'");
    }
  }
  const char* header =
      "| image | cell | algorithm | grid cells | coordinate transfers | used image pixels | grid cells drawn | "
      "different grid cells | time ms (min-max) | ns per cell (line: drawn, ray tracing: of the box) |\n"
      "|---|---|---|---:|---:|---:|---:|---:|---:|---:|\n";
  std::cout << "## Against the cell size (640x480)\n\n" << header;
  for (double resolution : {1.0, 0.5, 0.25, 0.1}) row(so::StereoCameraConfig(), resolution, repeat);
  std::cout << "\n## Against the image size (0.25 m)\n\n" << header;
  for (const auto& [w, h] : {std::make_pair(640, 480), std::make_pair(1280, 960), std::make_pair(1920, 1200)})
    row(cameraOfWidth(w, h), 0.25, repeat);
  std::cout << "\n## Against the threads (0.25 m)\n\n"
               "| image | stage | threads | time ms | speed-up |\n|---|---|---:|---:|---:|\n";
  for (const auto& [w, h] : {std::make_pair(640, 480), std::make_pair(1280, 960)})
    threadRows(cameraOfWidth(w, h), threads, repeat);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return tools::runTool("scaling", [&] { return run(argc, argv); });
}
