#pragma once
/// @file
/// Test helper: a whole OcTree as text, to compare two trees node for node.

#include <octomap/OcTree.h>

#include <sstream>
#include <string>

namespace stereo_occupancy {

/// The whole tree, every node's value included (.ot format).
inline std::string fullTree(const octomap::OcTree& tree) {
  std::ostringstream out;
  tree.write(out);
  return out.str();
}

}  // namespace stereo_occupancy
