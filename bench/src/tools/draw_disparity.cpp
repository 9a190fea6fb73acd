// draw_disparity: draws one disparity image into a local occupancy grid with
// one of the paper's four algorithms and prints the Table I counters as JSON.
// No roscore needed.

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/octomap_io.h"
#include "stereo_occupancy/sim/disparity_files.h"
#include "stereo_occupancy/sim/local_grid_octree.h"

namespace so = stereo_occupancy;

namespace {

const char* kUsage =
    "usage: draw_disparity --disparity FILE [--disparity-scale S] --focal F [--cx CX --cy CY]\n"
    "                      --baseline B [--delta-d DD] [--pose \"tx ty tz qx qy qz qw\"]\n"
    "                      [--resolution M] [--max-range M]\n"
    "                      [--algorithm line|line_pyramid|raytrace|raytrace_pyramid|\n"
    "                                   line_pyramid_bounded|raytrace_pyramid_bounded]\n"
    "                      [--blur SIGMA_TRANS_M SIGMA_ANGLE_RAD] [--repeat N] [--output FILE.ot|FILE.bt]\n"
    "Draws a disparity image (PFM float: NaN/negative invalid, 0 infinitely far; or 16-bit PNG,\n"
    "disparity = value / S) seen from the pose (optical frame in the world, p_W = q p_C + t)\n"
    "into a local occupancy grid and prints the Table I counters as one JSON object.\n";

struct Options {
  std::string disparity;
  double disparity_scale = 0.0;
  double focal = 0.0, cx = -1.0, cy = -1.0, baseline = 0.0, delta_d = 0.5;
  bool has_cx = false, has_cy = false;
  std::vector<double> pose = {0, 0, 0, 0, 0, 0, 1};
  double resolution = 0.25, max_range = 25.0;
  std::string algorithm = "line_pyramid";
  double sigma_trans = 0.0, sigma_angle = 0.0;
  int repeat = 1;
  std::string output;
};

double parseNumber(const std::string& option, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !std::isfinite(v))
    throw std::invalid_argument(option + " expects a finite number, got '" + text + "'");
  return v;
}

Options parse(int argc, char** argv) {
  Options o;
  bool have_disparity = false, have_focal = false, have_baseline = false;
  auto value = [&](int& i, const std::string& name) -> std::string {
    if (i + 1 >= argc) throw std::invalid_argument(name + " needs a value");
    return argv[++i];
  };
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      std::exit(0);
    } else if (a == "--disparity") {
      o.disparity = value(i, a);
      have_disparity = true;
    } else if (a == "--disparity-scale") {
      o.disparity_scale = parseNumber(a, value(i, a));
    } else if (a == "--focal") {
      o.focal = parseNumber(a, value(i, a));
      have_focal = true;
    } else if (a == "--cx") {
      o.cx = parseNumber(a, value(i, a));
      o.has_cx = true;
    } else if (a == "--cy") {
      o.cy = parseNumber(a, value(i, a));
      o.has_cy = true;
    } else if (a == "--baseline") {
      o.baseline = parseNumber(a, value(i, a));
      have_baseline = true;
    } else if (a == "--delta-d") {
      o.delta_d = parseNumber(a, value(i, a));
    } else if (a == "--pose") {
      std::istringstream in(value(i, a));
      std::vector<double> p;
      std::string token;
      while (in >> token) p.push_back(parseNumber(a, token));
      if (p.size() != 7) throw std::invalid_argument("--pose expects 7 numbers \"tx ty tz qx qy qz qw\"");
      o.pose = p;
    } else if (a == "--resolution") {
      o.resolution = parseNumber(a, value(i, a));
    } else if (a == "--max-range") {
      o.max_range = parseNumber(a, value(i, a));
    } else if (a == "--algorithm") {
      o.algorithm = value(i, a);
    } else if (a == "--blur") {
      o.sigma_trans = parseNumber(a, value(i, a));
      o.sigma_angle = parseNumber(a, value(i, a));
    } else if (a == "--repeat") {
      const double n = parseNumber(a, value(i, a));
      if (n < 1 || n > 100000 || n != static_cast<int>(n))
        throw std::invalid_argument("--repeat expects a whole number in [1, 100000]");
      o.repeat = static_cast<int>(n);
    } else if (a == "--output") {
      o.output = value(i, a);
    } else {
      throw std::invalid_argument("unknown option '" + a + "' (see --help)");
    }
  }
  if (!have_disparity) throw std::invalid_argument("--disparity FILE is required");
  if (!have_focal) throw std::invalid_argument("--focal F is required");
  if (!have_baseline) throw std::invalid_argument("--baseline B is required");
  return o;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

int run(int argc, char** argv) {
  const Options o = parse(argc, argv);

  so::DrawingConfig drawing;
  if (!so::parseDrawingAlgorithm(o.algorithm, &drawing.algorithm))
    throw std::invalid_argument("--algorithm must be one of " + so::drawingAlgorithmNames());
  drawing.resolution_m = o.resolution;
  drawing.blur.sigma_trans_m = o.sigma_trans;
  drawing.blur.sigma_angle_rad = o.sigma_angle;
  drawing.count_different_cells = true;  // printed with the other Table I counters
  if (!o.output.empty() && o.output.size() < 3) throw std::invalid_argument("--output must end in .ot or .bt");

  const cv::Mat disparity = so::readDisparity(o.disparity, o.disparity_scale);

  so::StereoCameraConfig camera;
  camera.width_px = disparity.cols;
  camera.height_px = disparity.rows;
  camera.focal_length_px = o.focal;
  camera.cx_px = o.has_cx ? o.cx : 0.5 * (disparity.cols - 1);
  camera.cy_px = o.has_cy ? o.cy : 0.5 * (disparity.rows - 1);
  camera.baseline_m = o.baseline;
  camera.delta_d_px = o.delta_d;
  camera.max_range_m = o.max_range;
  camera.min_range_m = std::min(camera.min_range_m, 0.5 * o.max_range);

  const Eigen::Quaterniond q(o.pose[6], o.pose[3], o.pose[4], o.pose[5]);
  if (std::abs(q.norm() - 1.0) > 1e-3)
    throw std::invalid_argument("--pose quaternion must have unit norm (got " + std::to_string(q.norm()) + ")");
  Eigen::Isometry3d T_W_C = Eigen::Isometry3d::Identity();
  T_W_C.linear() = q.normalized().toRotationMatrix();
  T_W_C.translation() = Eigen::Vector3d(o.pose[0], o.pose[1], o.pose[2]);

  so::DisparityDrawer drawer(camera, drawing);  // validates both configs
  so::LocalGrid grid;
  so::DrawStatistics stats;
  std::vector<double> times_ms;
  using Clock = std::chrono::steady_clock;
  for (int r = 0; r < o.repeat; ++r) {
    const auto t0 = Clock::now();
    drawer.prepareGrid(T_W_C, &grid);
    stats = drawer.drawInto(disparity, T_W_C, &grid);
    times_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  }
  const auto t_blur = Clock::now();
  drawer.blur(T_W_C, &grid);
  const double blur_ms = std::chrono::duration<double, std::milli>(Clock::now() - t_blur).count();

  size_t occupied = 0, free_cells = 0;
  for (size_t i = 0; i < grid.numCells(); ++i) {
    const float v = grid.data()[i];
    if (v == so::LocalGrid::kUnknown) continue;
    occupied += v > 0.0f;
    free_cells += v < 0.0f;
  }
  if (!o.output.empty()) so::writeOcTree(*so::localGridToOcTree(grid), o.output);

  const auto& size = grid.size();
  std::cout << "{\"algorithm\": \"" << so::toString(drawing.algorithm) << "\""
            << ", \"resolution_m\": " << o.resolution << ", \"coordinate_transfers\": " << stats.coordinate_transfers
            << ", \"used_image_pixels\": " << stats.used_image_pixels
            << ", \"grid_cells_drawn\": " << stats.grid_cells_drawn
            << ", \"different_grid_cells\": " << stats.different_grid_cells << ", \"grid_size\": [" << size.x() << ", "
            << size.y() << ", " << size.z() << "]"
            << ", \"grid_cells\": " << grid.numCells() << ", \"occupied_cells\": " << occupied
            << ", \"free_cells\": " << free_cells << ", \"repeat\": " << o.repeat
            << ", \"time_ms\": " << median(times_ms)
            << ", \"time_min_ms\": " << *std::min_element(times_ms.begin(), times_ms.end())
            << ", \"time_max_ms\": " << *std::max_element(times_ms.begin(), times_ms.end())
            << ", \"blur_ms\": " << blur_ms;
  if (!o.output.empty()) std::cout << ", \"output\": \"" << o.output << "\"";
  std::cout << "}" << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::string text = e.what();
    std::replace(text.begin(), text.end(), '\n', ' ');
    std::cerr << "draw_disparity: error: " << text << std::endl;
    return 2;
  }
}
