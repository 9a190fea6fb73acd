// draw_distance_slice: a saved map's distance field (distance_field.h, the
// accumulator's DistanceField with the default parameters of
// config/mapping.yaml) around a flight's last camera position, drawn as the
// horizontal slice the accumulator publishes on distance_slice: each known
// cell of the layer coloured by its distance to the nearest obstacle (red
// near, blue at max_distance_m and beyond), unknown cells dark grey, the
// scene's true boxes in that layer outlined in white, the camera as a white
// dot. For the README's picture after the demo flight. No roscore needed.
//
//   draw_distance_slice --map MAP.bt --scenario posts [--z 2] [--pixels-per-m 10] --out slice.png

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <iostream>
#include <string>
#include <vector>

#include "stereo_occupancy/distance_field.h"
#include "stereo_occupancy/octomap_io.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "tool_support.h"

namespace so = stereo_occupancy;
namespace tools = stereo_occupancy::tools;

namespace {

const char* const kUsage =
    "usage: draw_distance_slice --map MAP.bt|.ot --scenario NAME --out FILE.png [--z M] [--pixels-per-m N]\n"
    "  the map's distance field (the accumulator's defaults: 50 x 50 x 10 m window, 2 m) around the\n"
    "  scenario's last camera position, its layer at height --z (default 2 m) as a picture\n";

int run(int argc, char** argv) {
  std::string map_path, scenario_name, out;
  double z_m = 2.0, pixels_per_m = 10.0;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (arg == "--map") {
      map_path = tools::nextValue(argc, argv, &i);
    } else if (arg == "--scenario") {
      scenario_name = tools::nextValue(argc, argv, &i);
    } else if (arg == "--out") {
      out = tools::nextValue(argc, argv, &i);
    } else if (arg == "--z") {
      z_m = tools::parseNumber(arg, tools::nextValue(argc, argv, &i));
    } else if (arg == "--pixels-per-m") {
      pixels_per_m = static_cast<double>(tools::parseWhole(arg, tools::nextValue(argc, argv, &i), 1, 100));
    } else {
      throw tools::UsageError("unknown option '" + arg + "'");
    }
  }
  if (map_path.empty() || scenario_name.empty() || out.empty())
    throw tools::UsageError("--map, --scenario and --out are needed");
  const std::unique_ptr<octomap::OcTree> map = so::readOcTreeFile(map_path);
  const so::FlightScenario scenario = so::makeScenario(scenario_name);
  const Eigen::Vector3d W_camera = scenario.cameraPose(scenario.T_W_B.size() - 1).translation();

  so::DistanceField field(so::DistanceFieldConfig(), map->getResolution());
  field.update(*map, {}, /*all=*/true, W_camera);
  std::vector<Eigen::Vector3f> W_centres;
  std::vector<float> distances_m;
  field.slice(z_m, &W_centres, &distances_m);

  const Eigen::AlignedBox3d window = field.window();
  const double res = field.resolution(), max_m = field.config().max_distance_m;
  const int width = static_cast<int>(std::lround(window.sizes().x() * pixels_per_m));
  const int height = static_cast<int>(std::lround(window.sizes().y() * pixels_per_m));
  // x to the right, y up (the map seen from above).
  auto px = [&](double x, double y) {
    return cv::Point(static_cast<int>(std::lround((x - window.min().x()) * pixels_per_m)),
                     static_cast<int>(std::lround((window.max().y() - y) * pixels_per_m)));
  };
  cv::Mat image(height, width, CV_8UC3, cv::Scalar(40, 40, 40));
  cv::Mat value(1, 1, CV_8UC1), colour;
  for (size_t i = 0; i < W_centres.size(); ++i) {
    // JET runs from blue (0) to red (255): near obstacles red.
    value.at<uint8_t>(0) = static_cast<uint8_t>(std::lround(255.0 * (1.0 - std::min(1.0, distances_m[i] / max_m))));
    cv::applyColorMap(value, colour, cv::COLORMAP_JET);
    const double h = 0.5 * res;
    cv::rectangle(image, px(W_centres[i].x() - h, W_centres[i].y() + h), px(W_centres[i].x() + h, W_centres[i].y() - h),
                  cv::Scalar(colour.at<cv::Vec3b>(0)), cv::FILLED);
  }
  for (const Eigen::AlignedBox3d& box : scenario.scene.boxes)
    if (box.min().z() <= z_m && box.max().z() >= z_m)
      cv::rectangle(image, px(box.min().x(), box.max().y()), px(box.max().x(), box.min().y()),
                    cv::Scalar(255, 255, 255), 1);
  cv::circle(image, px(W_camera.x(), W_camera.y()), 4, cv::Scalar(255, 255, 255), cv::FILLED);
  char legend[2][200];
  std::snprintf(legend[0], sizeof legend[0], "distance field at z = %.2f m: red 0, blue >= %.1f m", z_m, max_m);
  std::snprintf(legend[1], sizeof legend[1], "grey unknown; white: true boxes, the camera");
  for (int line = 0; line < 2; ++line)
    cv::putText(image, legend[line], cv::Point(8, height - 30 + 20 * line), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  if (!cv::imwrite(out, image)) throw std::runtime_error("cannot write '" + out + "'");
  std::cout << "draw_distance_slice: " << W_centres.size() << " known cells of the layer at z = " << z_m << " m in "
            << out << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return tools::runTool("draw_distance_slice", [&] { return run(argc, argv); });
}
