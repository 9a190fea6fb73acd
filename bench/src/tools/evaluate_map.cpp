// evaluate_map: scores a map file (.bt or .ot) against a simulated flight's
// ground truth and prints one JSON object. Optionally draws the map's top and
// side views. No roscore needed.

#include <opencv2/imgcodecs.hpp>

#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "scenario_support.h"
#include "stereo_occupancy/octomap_io.h"
#include "stereo_occupancy/sim/map_evaluation.h"
#include "stereo_occupancy/sim/map_rendering.h"
#include "tool_support.h"

namespace so = stereo_occupancy;
namespace tools = stereo_occupancy::tools;

namespace {

const char* kUsage =
    "usage: evaluate_map --map FILE.bt|FILE.ot --scenario NAME [--max-range M]\n"
    "  NAME: posts, houses, forest, wires, posts_far, forest_far\n"
    "                    [--frames N (the flight's first N frames were mapped)]\n"
    "                    [--views PREFIX (writes PREFIX_top.png, PREFIX_side.png)]\n";

int run(int argc, char** argv) {
  std::string map_path, scenario_name, views_prefix;
  double max_range = 25.0;
  long frames = -1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--map") {
      map_path = tools::nextValue(argc, argv, &i);
    } else if (a == "--scenario") {
      scenario_name = tools::nextValue(argc, argv, &i);
    } else if (a == "--max-range") {
      max_range = tools::parseNumber(a, tools::nextValue(argc, argv, &i));
      if (!(max_range > 0.0 && max_range <= 200.0)) throw tools::UsageError("--max-range must be in (0, 200] m");
    } else if (a == "--views") {
      views_prefix = tools::nextValue(argc, argv, &i);
    } else if (a == "--frames") {
      frames = tools::parseWhole(a, tools::nextValue(argc, argv, &i), 1, 1000000);
    } else {
      throw tools::UsageError("unknown option '" + a + "'");
    }
  }
  if (map_path.empty() || scenario_name.empty()) throw tools::UsageError("--map and --scenario are required");
  so::FlightScenario scenario = tools::scenarioNamed(scenario_name);
  const std::unique_ptr<octomap::OcTree> map = so::readOcTreeFile(map_path);
  if (!(map->getResolution() >= 0.01)) throw std::runtime_error("'" + map_path + "' has no usable resolution");
  if (frames > 0 && static_cast<size_t>(frames) < scenario.T_W_B.size()) scenario.T_W_B.resize(frames);
  const so::ObservedGroundTruth truth = so::observeGroundTruth(scenario, map->getResolution(), max_range, 5, 4);
  // The whole map, then the same scores per range band (distance to the nearest viewpoint).
  std::string json = so::evaluateMap(*map, scenario.scene, truth).toJson();
  json.pop_back();
  json += ", \"bands\": {";
  const std::vector<so::RangeBand> bands = so::standardRangeBands();
  for (size_t b = 0; b < bands.size(); ++b)
    json += (b ? ", \"" : "\"") + bands[b].name() +
            "\": " + so::evaluateMap(*map, scenario.scene, truth, bands[b]).toJson();
  std::cout << json << "}}" << std::endl;
  if (!views_prefix.empty()) {
    cv::Mat top, side;
    so::renderMapViews(*map, 16.0, &top, &side);
    if (!cv::imwrite(views_prefix + "_top.png", top) || !cv::imwrite(views_prefix + "_side.png", side))
      throw std::runtime_error("cannot write the views under '" + views_prefix + "'");
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return so::tools::runTool("evaluate_map", [&] { return run(argc, argv); });
}
