// evaluate_map: scores a map file (.bt or .ot) against a simulated flight's
// ground truth and prints one JSON object. Optionally draws the map's top and
// side views. No roscore needed.

#include <opencv2/imgcodecs.hpp>

#include <iostream>
#include <memory>
#include <string>

#include "stereo_occupancy/map_evaluation.h"
#include "stereo_occupancy/map_rendering.h"

namespace so = stereo_occupancy;

int main(int argc, char** argv) {
  std::string map_path, scenario_name, views_prefix;
  double max_range = 25.0;
  long frames = -1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--map" && i + 1 < argc) map_path = argv[++i];
    else if (a == "--scenario" && i + 1 < argc) scenario_name = argv[++i];
    else if (a == "--max-range" && i + 1 < argc) max_range = std::stod(argv[++i]);
    else if (a == "--views" && i + 1 < argc) views_prefix = argv[++i];
    else if (a == "--frames" && i + 1 < argc) frames = std::stol(argv[++i]);
    else {
      std::cerr << "usage: evaluate_map --map FILE.bt|FILE.ot --scenario posts|houses|forest|wires [--max-range M]"
                   " [--frames N (the flight's first N frames were mapped)]\n"
                   "                    [--views PREFIX (writes PREFIX_top.png, PREFIX_side.png)]\n";
      return a == "--help" ? 0 : 2;
    }
  }
  if (map_path.empty() || scenario_name.empty()) {
    std::cerr << "evaluate_map: error: --map and --scenario are required\n";
    return 2;
  }
  try {
    std::unique_ptr<octomap::OcTree> map;
    if (map_path.size() > 3 && map_path.substr(map_path.size() - 3) == ".bt") {
      map = std::make_unique<octomap::OcTree>(0.1);
      if (!map->readBinary(map_path)) throw std::runtime_error("cannot read '" + map_path + "'");
    } else {
      std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(map_path));
      auto* oc = dynamic_cast<octomap::OcTree*>(tree.get());
      if (!oc) throw std::runtime_error("'" + map_path + "' holds no OcTree");
      tree.release();
      map.reset(oc);
    }
    so::FlightScenario scenario = so::makeScenario(scenario_name);
    if (frames > 0 && static_cast<size_t>(frames) < scenario.T_W_B.size()) scenario.T_W_B.resize(frames);
    const so::ObservedGroundTruth truth = so::observeGroundTruth(scenario, map->getResolution(), max_range, 5, 4);
    std::cout << so::evaluateMap(*map, scenario.scene, truth).toJson() << std::endl;
    if (!views_prefix.empty()) {
      cv::Mat top, side;
      so::renderMapViews(*map, 16.0, &top, &side);
      if (!cv::imwrite(views_prefix + "_top.png", top) || !cv::imwrite(views_prefix + "_side.png", side))
        throw std::runtime_error("cannot write the views under '" + views_prefix + "'");
    }
  } catch (const std::exception& e) {
    std::cerr << "evaluate_map: error: " << e.what() << std::endl;
    return 1;
  }
  return 0;
}
