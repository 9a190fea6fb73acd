// export_map: writes the whole mission in a tile database (the accumulator's
// <save_dir>/<map_name>.db), or a box of it, to one .bt or .ot file.
// No roscore needed; not while an accumulator holds the database.

#include <unistd.h>

#include <iostream>
#include <string>

#include "stereo_occupancy/octomap_io.h"
#include "stereo_occupancy/store/mission_map.h"
#include "tool_support.h"

namespace so = stereo_occupancy;
namespace tools = stereo_occupancy::tools;

namespace {

const char* kUsage =
    "usage: export_map --database FILE.db --out FILE.bt|FILE.ot [--min X Y Z --max X Y Z]\n"
    "                  [--occupancy-threshold P]\n"
    "  --min, --max: the box to export, in the map's frame [m]; default: everything\n"
    "  --occupancy-threshold: cells at or above it are occupied in a .bt (default 0.5, the accumulator's)\n";

Eigen::Vector3d parsePoint(const std::string& option, int argc, char** argv, int* i) {
  Eigen::Vector3d p;
  for (int a = 0; a < 3; ++a) p[a] = tools::parseNumber(option, tools::nextValue(argc, argv, i));
  return p;
}

int run(int argc, char** argv) {
  std::string database, out;
  Eigen::AlignedBox3d box;
  bool has_min = false, has_max = false;
  double threshold = so::MapAccumulatorConfig().occupancy_threshold_prob;
  Eigen::Vector3d lo, hi;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--database") {
      database = tools::nextValue(argc, argv, &i);
    } else if (a == "--out") {
      out = tools::nextValue(argc, argv, &i);
    } else if (a == "--occupancy-threshold") {
      threshold = tools::parseNumber(a, tools::nextValue(argc, argv, &i));
      if (!(threshold > 0.0 && threshold < 1.0)) throw tools::UsageError("--occupancy-threshold must be in (0, 1)");
    } else if (a == "--min") {
      lo = parsePoint(a, argc, argv, &i);
      has_min = true;
    } else if (a == "--max") {
      hi = parsePoint(a, argc, argv, &i);
      has_max = true;
    } else {
      throw tools::UsageError("unknown option '" + a + "'");
    }
  }
  if (database.empty() || out.empty()) throw tools::UsageError("--database and --out are required");
  if (has_min != has_max) throw tools::UsageError("--min and --max go together");
  if (has_min) {
    if ((lo.array() > hi.array()).any()) throw tools::UsageError("--min must not exceed --max");
    box = Eigen::AlignedBox3d(lo, hi);
  }
  const bool bt = out.size() > 3 && out.compare(out.size() - 3, 3, ".bt") == 0;
  const bool ot = out.size() > 3 && out.compare(out.size() - 3, 3, ".ot") == 0;
  if (!bt && !ot) throw tools::UsageError("--out must end in .bt or .ot");
  if (access(database.c_str(), R_OK) != 0) throw std::runtime_error("cannot read '" + database + "'");
  // Read-only, at its own resolution: exporting never changes the database.
  so::TileStore store(database, 0.0, so::TileStore::Access::kReadOnly);
  if (box.isEmpty()) {
    // The whole mission, a tile at a time: it may not fit in memory at once.
    so::MissionMap::writeStore(store, out, threshold);
  } else {
    so::writeOcTree(*so::MissionMap::assemble(store, box), out);
  }
  std::cout << "{\"tiles\": " << store.tiles().size() << ", \"resolution_m\": " << store.resolution() << ", \"out\": \""
            << out << "\"}" << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return tools::runTool("export_map", [&] { return run(argc, argv); });
}
