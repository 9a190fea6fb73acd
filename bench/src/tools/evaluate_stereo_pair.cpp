// evaluate_stereo_pair: one real rectified stereo pair with its true
// disparities (by default the Middlebury "Aloe" pair that Debian's opencv-doc
// ships), matched by OpenCV's StereoSGBM (a 5 px block, or stereo_image_proc's
// defaults with --sgbm stereo_image_proc), then mapped from the same
// disparity image by the mapper (its defaults), by the per-pixel line drawing
// and by OctoMap's insertPointCloud: occupied precision, recall and surface
// called free against the surface the true disparities give, overall and per
// range band, as a Markdown table.
// A benchmark: it prints figures and asserts nothing.

#include <octomap/octomap.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <unordered_set>
#include <vector>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/sim/map_evaluation.h"
#include "stereo_occupancy/sim/stereo_matching.h"
#include "tool_support.h"

namespace so = stereo_occupancy;
namespace tools = stereo_occupancy::tools;

namespace {

const char* kUsage =
    "usage: evaluate_stereo_pair [--left FILE --right FILE --truth FILE] [--truth-scale S]\n"
    "                            [--focal F_FULL_PX] [--baseline B_M] [--shrink N] [--max-range M]\n"
    "                            [--resolution M [--resolution M ...]] [--algorithm NAME] [--model NAME=VALUE ...]\n"
    "                            [--sgbm fine|stereo_image_proc]\n"
    "Defaults: opencv-doc's aloeL.jpg, aloeR.jpg and aloeGT.png (disparity = value / S, S = 1 at full size;\n"
    "a floating-point truth, e.g. a TIFF, is read as disparities),\n"
    "the Middlebury 2006 focal length 3740 px and baseline 0.16 m, images shrunk by 4 (as a 64-disparity\n"
    "matcher needs), max range 15 m, cells of 0.1 and 0.05 m. --model: a numeric sensor-model parameter.\n"
    "--sgbm: StereoSGBM with a 5 px block (fine, the default) or stereo_image_proc's defaults (a 15 px block).\n";

const std::string kData = "/usr/share/doc/opencv-doc/examples/data/";

std::string pct(double v) {
  std::ostringstream o;
  o << std::fixed << std::setprecision(1) << 100.0 * v;
  return o.str();
}

/// Range bands: near, middle and far thirds of the true surface's points.
constexpr int kBands = 3;
const char* const kBandNames[kBands] = {"near", "middle", "far"};
constexpr double kEverywhere = std::numeric_limits<double>::infinity();

/// The bands' edges [m]: 0, the points' range tertiles, infinity.
std::vector<double> bandEdges(const std::vector<Eigen::Vector3d>& W_points, const Eigen::Isometry3d& T_W_C) {
  std::vector<double> ranges_m;
  ranges_m.reserve(W_points.size());
  for (const Eigen::Vector3d& W_p : W_points) ranges_m.push_back((W_p - T_W_C.translation()).norm());
  std::sort(ranges_m.begin(), ranges_m.end());
  std::vector<double> edges_m{0.0};
  for (int band = 1; band < kBands; ++band)
    edges_m.push_back(ranges_m.empty() ? 0.0 : ranges_m[ranges_m.size() * band / kBands]);
  edges_m.push_back(kEverywhere);
  return edges_m;
}

std::string bandLimits(const std::vector<double>& edges_m) {
  std::ostringstream o;
  o << std::fixed << std::setprecision(2) << "near below " << edges_m[1] << " m, far from " << edges_m[2] << " m";
  return o.str();
}

/// The true disparities at full size [px] as CV_32F: an 8-bit image's
/// values / @p scale (Middlebury's PNGs), a float image's as they are
/// (a TIFF such as Pandora's).
cv::Mat readTruth(const std::string& file, double scale) {
  cv::Mat image = cv::imread(file, cv::IMREAD_UNCHANGED);
  if (image.empty()) throw std::runtime_error("cannot read '" + file + "' (is opencv-doc installed?)");
  if (image.channels() != 1) throw std::runtime_error("'" + file + "' has more than one channel");
  cv::Mat disparity;
  if (image.depth() == CV_32F || image.depth() == CV_64F)
    image.convertTo(disparity, CV_32F);
  else if (image.depth() == CV_8U)
    image.convertTo(disparity, CV_32F, 1.0 / scale);
  else
    throw std::runtime_error("'" + file + "' is neither 8-bit nor floating point");
  return disparity;
}

cv::Mat readGray(const std::string& file) {
  cv::Mat image = cv::imread(file, cv::IMREAD_GRAYSCALE);
  if (image.empty()) throw std::runtime_error("cannot read '" + file + "' (is opencv-doc installed?)");
  return image;
}

int run(int argc, char** argv) {
  std::string left_file = kData + "aloeL.jpg", right_file = kData + "aloeR.jpg", truth_file = kData + "aloeGT.png";
  double truth_scale = 1.0, focal_full_px = 3740.0, baseline_m = 0.16, max_range_m = 15.0;
  int shrink = 4;
  std::vector<double> resolutions;
  std::map<std::string, double> model_values;
  so::DrawingAlgorithm algorithm = so::DrawingConfig::mapperDefaults().algorithm;
  so::SgbmParameters sgbm = so::SgbmParameters::fineBlock();
  std::string sgbm_name = "fine";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--left")
      left_file = tools::nextValue(argc, argv, &i);
    else if (a == "--right")
      right_file = tools::nextValue(argc, argv, &i);
    else if (a == "--truth")
      truth_file = tools::nextValue(argc, argv, &i);
    else if (a == "--truth-scale")
      truth_scale = tools::parseNumber(a, tools::nextValue(argc, argv, &i));
    else if (a == "--focal")
      focal_full_px = tools::parseNumber(a, tools::nextValue(argc, argv, &i));
    else if (a == "--baseline")
      baseline_m = tools::parseNumber(a, tools::nextValue(argc, argv, &i));
    else if (a == "--max-range")
      max_range_m = tools::parseNumber(a, tools::nextValue(argc, argv, &i));
    else if (a == "--shrink")
      shrink = static_cast<int>(tools::parseWhole(a, tools::nextValue(argc, argv, &i), 1, 16));
    else if (a == "--resolution") {
      resolutions.push_back(tools::parseNumber(a, tools::nextValue(argc, argv, &i)));
      if (!(resolutions.back() >= 0.01 && resolutions.back() <= 10.0))
        throw tools::UsageError("--resolution must be in [0.01, 10] m");
    } else if (a == "--algorithm") {
      if (!so::parseDrawingAlgorithm(tools::nextValue(argc, argv, &i), &algorithm))
        throw tools::UsageError("--algorithm must be one of " + so::drawingAlgorithmNames());
    } else if (a == "--sgbm") {
      sgbm_name = tools::nextValue(argc, argv, &i);
      if (sgbm_name == "stereo_image_proc")
        sgbm = so::SgbmParameters();
      else if (sgbm_name != "fine")
        throw tools::UsageError("--sgbm must be fine or stereo_image_proc");
    } else if (a == "--model") {
      tools::addNameValue(argc, argv, &i, &model_values);
    } else {
      throw tools::UsageError("unknown option '" + a + "'");
    }
  }
  if (resolutions.empty()) resolutions = {0.1, 0.05};
  if (!(truth_scale > 0.0)) throw tools::UsageError("--truth-scale must be > 0");

  cv::Mat left = readGray(left_file), right = readGray(right_file), truth = readTruth(truth_file, truth_scale);
  if (left.size() != right.size() || left.size() != truth.size())
    throw std::runtime_error("the left, right and truth images differ in size");
  const cv::Size size(left.cols / shrink, left.rows / shrink);
  cv::resize(left, left, size, 0, 0, cv::INTER_AREA);
  cv::resize(right, right, size, 0, 0, cv::INTER_AREA);
  cv::resize(truth, truth, size, 0, 0, cv::INTER_NEAREST);
  const cv::Mat disparity = so::matchSgbm(left, right, sgbm);

  so::StereoCameraConfig camera_config;
  camera_config.width_px = size.width;
  camera_config.height_px = size.height;
  camera_config.focal_length_px = focal_full_px / shrink;
  camera_config.cx_px = 0.5 * (size.width - 1);
  camera_config.cy_px = 0.5 * (size.height - 1);
  camera_config.baseline_m = baseline_m;
  camera_config.max_range_m = max_range_m;
  camera_config.min_disparity_px = 0.0;
  camera_config.max_disparity_px = sgbm.maxDisparityPx();
  std::string why;
  if (!camera_config.isValid(&why)) throw tools::UsageError(why);
  const so::StereoCameraModel camera(camera_config);
  const Eigen::Isometry3d T_W_C = Eigen::Isometry3d::Identity();  // the map in the left camera's optical frame

  // The true surface: every pixel's true disparity within range.
  std::vector<Eigen::Vector3d> truth_points;
  cv::Mat truth_known(size, CV_8U, cv::Scalar(0));
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double d = truth.at<float>(y, x) / shrink;
      if (!(d > 0.0)) continue;  // 0 or NaN: no true disparity (occluded)
      truth_known.at<uchar>(y, x) = 1;
      const Eigen::Vector3d p = camera.pointFromDisparity(x, y, d);
      if (p.norm() <= max_range_m) truth_points.push_back(T_W_C * p);
    }
  const std::vector<double> band_edges_m = bandEdges(truth_points, T_W_C);
  size_t matched = 0;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) matched += camera.isValidDisparity(disparity.at<float>(y, x));

  std::cout << "Real stereo: " << left_file << " and " << right_file << ", " << size.width << " x " << size.height
            << " px (shrunk by " << shrink << "), f = " << camera_config.focal_length_px << " px, b = " << baseline_m
            << " m; " << sgbm.describe() << " (" << sgbm_name << ") matched " << pct(double(matched) / size.area())
            << " % of the pixels; the truth from " << truth_file << " (" << truth_points.size() << " points within "
            << max_range_m << " m).\n\n"
            << "Each method overall and per range band (near, middle, far: thirds of the true surface\n"
            << "by its points' range from the camera, " << bandLimits(band_edges_m) << ").\n\n"
            << "| cell | method | band | occupied precision % | occupied recall % | F1 | surface called free % | "
               "occupied cells |\n|---|---|---|---:|---:|---:|---:|---:|\n";
  // Occupied cells count where the truth knows what the pixel sees, within the band's ranges.
  auto counted = [&](const Eigen::Vector3d& W_p, double min_m, double max_m) {
    const Eigen::Vector3d C_p = T_W_C.inverse() * W_p;
    if (!(C_p.z() > 0.0)) return false;
    const double range_m = C_p.norm();
    if (range_m < min_m || range_m >= max_m) return false;
    const double f = camera_config.focal_length_px;
    const int x = static_cast<int>(std::lround(f * C_p.x() / C_p.z() + camera_config.cx_px));
    const int y = static_cast<int>(std::lround(f * C_p.y() / C_p.z() + camera_config.cy_px));
    return x >= 0 && y >= 0 && x < size.width && y < size.height && truth_known.at<uchar>(y, x);
  };
  for (double res : resolutions) {
    // The true surface's cells, all (band -1) and of each band's points.
    std::vector<std::unordered_set<uint64_t>> surfaces;
    for (int band = -1; band < kBands; ++band) {
      const double min_m = band < 0 ? 0.0 : band_edges_m[band], max_m = band < 0 ? kEverywhere : band_edges_m[band + 1];
      std::vector<Eigen::Vector3d> in_band;
      for (const Eigen::Vector3d& W_p : truth_points) {
        const double range_m = (W_p - T_W_C.translation()).norm();
        if (range_m >= min_m && range_m < max_m) in_band.push_back(W_p);
      }
      surfaces.push_back(so::surfaceCells(in_band, res));
    }
    auto report = [&](const std::string& name, const octomap::OcTree& tree) {
      for (int band = -1; band < kBands; ++band) {
        const double min_m = band < 0 ? 0.0 : band_edges_m[band],
                     max_m = band < 0 ? kEverywhere : band_edges_m[band + 1];
        const so::MapQuality q = so::evaluateAgainstSurface(
            tree, surfaces[band + 1], [&](const Eigen::Vector3d& W_p) { return counted(W_p, min_m, max_m); });
        std::cout << "| " << res << " m | " << name << " | " << (band < 0 ? "all" : kBandNames[band]) << " | "
                  << pct(q.occupiedPrecision()) << " | " << pct(q.occupiedRecall()) << " | " << std::fixed
                  << std::setprecision(3) << q.f1() << std::defaultfloat << " | " << pct(q.surfaceCalledFree()) << " | "
                  << q.occupied_cells << " |\n";
      }
    };
    auto mapper = [&](so::DrawingAlgorithm drawn_by) {
      so::DrawingConfig config = so::DrawingConfig::mapperDefaults();
      config.resolution_m = res;
      config.algorithm = drawn_by;
      tools::applyModelValues(model_values, &config);
      so::DisparityDrawer drawer(camera_config, config);
      so::LocalGrid grid;
      so::GridUpdate update;
      drawer.draw(disparity, T_W_C, &grid);
      so::encodeGridUpdate(grid, T_W_C.translation(), &update);
      so::MapAccumulatorConfig map_config;
      map_config.resolution_m = res;
      so::MapAccumulator map(map_config);
      map.integrate(update);
      report(std::string(so::toString(config.algorithm)) + ", " + so::toString(config.sensor_model.profile) +
                 (drawn_by == so::DrawingConfig::mapperDefaults().algorithm ? " (default)" : ""),
             map.tree());
    };
    mapper(algorithm);
    if (algorithm != so::DrawingAlgorithm::kLine) mapper(so::DrawingAlgorithm::kLine);  // one line per pixel

    octomap::OcTree octree(res);  // octomap_server's insertion of the same disparity's points
    const Eigen::Vector3d o = T_W_C.translation();
    octree.insertPointCloud(so::worldPointCloud(disparity, camera, T_W_C), octomap::point3d(o.x(), o.y(), o.z()),
                            max_range_m);
    report("OctoMap insertPointCloud", octree);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return so::tools::runTool("evaluate_stereo_pair", [&] { return run(argc, argv); });
}
