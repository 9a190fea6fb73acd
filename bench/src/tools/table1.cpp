// table1: reproduces the paper's Table I on the synthetic Fig. 6-like test
// image (640x480, b = 0.3 m, f = 700 px, Δd = 0.5 px, 25 m range) for the
// four algorithms at 1.0, 0.5 and 0.25 m cells, and prints a Markdown table
// with the paper's figures beside ours. A benchmark: it prints figures and
// asserts nothing.

#include <algorithm>
#include <cstdlib>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "drawing_benchmark.h"
#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/sim/disparity_files.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "tool_support.h"

namespace so = stereo_occupancy;

namespace {

struct PaperRow {
  double resolution;
  const char* algorithm;
  long transfers, pixels, drawn, different;
  double ms;
};

// Table I of the paper (1.8 GHz Pentium 4, no SIMD).
const PaperRow kPaper[] = {
    {1.0, "line", 194048, 194047, 2002640, 943, 207.},
    {1.0, "line_pyramid", 653, 652, 5487, 921, 0.62},
    {1.0, "raytrace", 11405, 7939260, 11400, 11400, 50.0},
    {1.0, "raytrace_pyramid", 11405, 13752, 11400, 11400, 6.09},
    {0.5, "line", 194048, 194047, 4013218, 5287, 352.},
    {0.5, "line_pyramid", 1710, 1709, 27942, 4739, 2.50},
    {0.5, "raytrace", 86405, 62875230, 86400, 86400, 395.},
    {0.5, "raytrace_pyramid", 86405, 106172, 86400, 86400, 44.8},
    {0.25, "line", 194048, 194047, 7832833, 32985, 632.},
    {0.25, "line_pyramid", 5392, 5391, 189446, 31946, 15.9},
    {0.25, "raytrace", 674505, 505599749, 674500, 674500, 3171.},
    {0.25, "raytrace_pyramid", 674505, 861312, 674500, 674500, 346.},
};

int repeatsFor(so::DrawingAlgorithm a, int base) {
  switch (a) {
    case so::DrawingAlgorithm::kLinePyramid:
    case so::DrawingAlgorithm::kRayTracePyramid:
    case so::DrawingAlgorithm::kLinePyramidBounded:
    case so::DrawingAlgorithm::kRayTracePyramidBounded:
      return base;
    default:
      return std::max(3, base / 10);
  }
}

int run(int argc, char** argv) {
  int repeat = 50;
  std::string save_image;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--repeat") {
      repeat = static_cast<int>(so::tools::parseWhole(a, so::tools::nextValue(argc, argv, &i), 1, 100000));
    } else if (a == "--save-image") {
      save_image = so::tools::nextValue(argc, argv, &i);
    } else if (a == "--help") {
      std::cout << "usage: table1 [--repeat N] [--save-image FILE.pfm]\n";
      return 0;
    } else {
      throw so::tools::UsageError("unknown option '" + a + "'");
    }
  }

  so::StereoCameraConfig camera;  // defaults: the paper's camera
  Eigen::Isometry3d T_W_C;
  const cv::Mat image = so::table1Image(so::StereoCameraModel(camera), &T_W_C);
  if (!save_image.empty()) so::writePfm(save_image, image);
  size_t valid = 0, sky = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      const float d = image.at<float>(y, x);
      valid += d >= 0.0f;
      sky += d == 0.0f;
    }

  std::cout << "Test image: 640x480, " << valid << " valid pixels (" << sky << " sky, zero disparity), "
            << image.total() - valid << " invalid; b = 0.3 m, f = 700 px, dd = 0.5 px, range 25 m.\n"
            << "Median time of " << repeat << " runs for the pyramidal algorithms, " << std::max(3, repeat / 10)
            << " for the others (min-max in brackets); one thread; drawing only, no blur.\n\n";
  std::cout << "| cell | algorithm | grid cells | coordinate transfers | used image pixels | grid cells drawn | "
               "different grid cells | time [ms] | paper: transfers | pixels | drawn | different | time [ms] |\n"
            << "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";

  for (double resolution : {1.0, 0.5, 0.25}) {
    for (so::DrawingAlgorithm algorithm : so::allDrawingAlgorithms()) {  // the paper's four, then the bounded
      so::DisparityDrawer drawer(camera, so::tools::drawingConfig(algorithm, resolution));
      so::LocalGrid grid;
      so::DrawStatistics stats;
      const std::vector<double> ms = so::tools::timeDrawing(&drawer, image, T_W_C, repeatsFor(algorithm, repeat),
                                                            /*time_grid_preparation=*/true, &grid, &stats);
      stats.different_grid_cells = grid.countKnown();  // the last run's grid, counted outside the timing
      const double median = ms[ms.size() / 2];
      const PaperRow* paper = nullptr;
      for (const auto& row : kPaper)
        if (row.resolution == resolution && so::toString(algorithm) == std::string(row.algorithm)) paper = &row;
      std::ostringstream time;
      time << std::fixed << std::setprecision(median < 10 ? 3 : 1) << median << " (" << ms.front() << "-" << ms.back()
           << ")";
      std::cout << "| " << resolution << " m | " << so::toString(algorithm) << " | " << grid.numCells() << " | "
                << stats.coordinate_transfers << " | " << stats.used_image_pixels << " | " << stats.grid_cells_drawn
                << " | " << stats.different_grid_cells << " | " << time.str() << " | ";
      if (paper) {
        std::cout << paper->transfers << " | " << paper->pixels << " | " << paper->drawn << " | " << paper->different
                  << " | " << paper->ms << " |" << std::endl;
      } else {  // beyond the paper
        std::cout << "- | - | - | - | - |" << std::endl;
      }
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return so::tools::runTool("table1", [&] { return run(argc, argv); });
}
