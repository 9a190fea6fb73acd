#include "stereo_occupancy/accumulating_octree.h"

#include <array>

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

void AccumulatingOcTree::collapse(octomap::OcTreeNode* node) {
  for (unsigned i = 0; i < 8; ++i) {
    if (!nodeChildExists(node, i))
      createNodeChild(node, i);
    else if (nodeHasChildren(getNodeChild(node, i)))
      collapse(getNodeChild(node, i));
  }
  for (unsigned i = 0; i < 8; ++i) getNodeChild(node, i)->setLogOdds(0.0f);
  pruneNode(node);  // deletes the eight equal leaves and the child array
}

bool AccumulatingOcTree::dropNode(const octomap::OcTreeKey& key, unsigned depth) {
  if (!root || depth == 0 || depth > tree_depth) return false;
  std::array<octomap::OcTreeNode*, 17> path{};
  path[0] = root;
  for (unsigned d = 0; d < depth; ++d) {
    const unsigned pos = octomap::computeChildIdx(key, static_cast<int>(tree_depth - 1 - d));
    if (!nodeChildExists(path[d], pos)) {
      if (nodeHasChildren(path[d])) return false;  // nothing there
      expandNode(path[d]);                        // a coarse leaf: keep its other parts
    }
    path[d + 1] = getNodeChild(path[d], pos);
  }
  if (nodeHasChildren(path[depth])) collapse(path[depth]);
  for (unsigned d = depth; d > 0; --d) {
    const unsigned pos = octomap::computeChildIdx(key, static_cast<int>(tree_depth - d));
    deleteNodeChild(path[d - 1], pos);
    if (nodeHasChildren(path[d - 1])) return true;
    if (d == 1) {
      clear();  // the root lost its last child
      return true;
    }
    collapse(path[d - 1]);  // frees its emptied child array before it is deleted
  }
  return true;
}

}  // namespace stereo_occupancy
