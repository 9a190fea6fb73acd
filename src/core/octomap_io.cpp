#include "stereo_occupancy/octomap_io.h"

#include <dirent.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <vector>

namespace stereo_occupancy {

std::unique_ptr<octomap::OcTree> localGridToOcTree(const LocalGrid& grid) {
  auto tree = std::make_unique<octomap::OcTree>(grid.resolution());
  const Eigen::Vector3i& size = grid.size();
  const Eigen::Vector3i& origin = grid.originIndex();
  const int offset = static_cast<int>(tree->coordToKey(0.0));  // key of global index 0 (2^15)
  for (int z = 0; z < size.z(); ++z) {
    for (int y = 0; y < size.y(); ++y) {
      for (int x = 0; x < size.x(); ++x) {
        const float value = grid.at(x, y, z);
        if (value == LocalGrid::kUnknown || value == 0.0f) continue;
        const Eigen::Vector3i g = origin + Eigen::Vector3i(x, y, z);
        const Eigen::Vector3i k = g.array() + offset;
        if ((k.array() < 0).any() || (k.array() > 65535).any()) continue;  // outside OcTree's extent
        tree->setNodeValue(octomap::OcTreeKey(k.x(), k.y(), k.z()), value, /*lazy_eval=*/true);
      }
    }
  }
  tree->updateInnerOccupancy();
  return tree;
}

int removeStaleTemporaries(const std::string& path) {
  const size_t slash = path.rfind('/');
  const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
  const std::string prefix = (slash == std::string::npos ? path : path.substr(slash + 1)) + ".tmp";
  DIR* d = ::opendir(dir.c_str());
  if (!d) return 0;
  std::vector<std::string> stale;
  while (const dirent* entry = ::readdir(d)) {
    const std::string name = entry->d_name;
    if (name.size() <= prefix.size() || name.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.size() > 9 || digits.find_first_not_of("0123456789") != std::string::npos) continue;
    const pid_t pid = static_cast<pid_t>(std::atol(digits.c_str()));
    if (pid > 0 && ::kill(pid, 0) != 0 && errno == ESRCH) stale.push_back(name);  // its writer is gone
  }
  ::closedir(d);
  int removed = 0;
  for (const std::string& name : stale) removed += std::remove((dir + "/" + name).c_str()) == 0 ? 1 : 0;
  return removed;
}

void writeOcTree(const octomap::OcTree& tree, const std::string& path) {
  const bool full = path.size() >= 3 && path.compare(path.size() - 3, 3, ".ot") == 0;
  const bool binary = path.size() >= 3 && path.compare(path.size() - 3, 3, ".bt") == 0;
  if (!full && !binary) throw std::runtime_error("'" + path + "': the map file must end in .ot or .bt");
  // Write a temporary file beside the target, then rename it into place: a
  // crash or kill during the write leaves the previous file intact.
  removeStaleTemporaries(path);
  const std::string tmp = path + ".tmp" + std::to_string(::getpid());
  const bool ok = full ? tree.write(tmp) : tree.writeBinaryConst(tmp);
  if (!ok) {
    std::remove(tmp.c_str());
    throw std::runtime_error("cannot write '" + path + "'");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw std::runtime_error("cannot rename '" + tmp + "' to '" + path + "'");
  }
}

}  // namespace stereo_occupancy
