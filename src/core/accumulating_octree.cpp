#include "stereo_occupancy/accumulating_octree.h"

namespace stereo_occupancy {

void AccumulatingOcTree::setLeaf(const octomap::OcTreeKey& key, unsigned depth, float log_odds) {
  if (!root) {
    root = new octomap::OcTreeNode();
    ++tree_size;
  }
  octomap::OcTreeNode* node = root;
  for (unsigned d = 0; d < depth; ++d) {
    const unsigned pos = octomap::computeChildIdx(key, static_cast<int>(tree_depth - 1 - d));
    node = nodeChildExists(node, pos) ? getNodeChild(node, pos) : createNodeChild(node, pos);
  }
  node->setLogOdds(log_odds);
}

}  // namespace stereo_occupancy
