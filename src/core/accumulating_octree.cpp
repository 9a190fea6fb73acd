#include "stereo_occupancy/accumulating_octree.h"

namespace stereo_occupancy {

void AccumulatingOcTree::LeafUpdater::add(const octomap::OcTreeKey& key, float log_odds) {
  AccumulatingOcTree& t = *tree_;
  const int leaf_depth = static_cast<int>(t.tree_depth);
  bool created = false;  // the node of the walk below was created by this call
  if (!t.root) {
    t.root = new octomap::OcTreeNode();
    ++t.tree_size;
    created = true;
    known_depth_ = -1;
  }
  if (known_depth_ < 0) {
    path_[0] = t.root;
    known_depth_ = 0;
  }
  // The deepest common ancestor with the previous key: node depth d is
  // fixed by each key component's d highest bits.
  int depth = 0;
  if (known_depth_ > 0) {
    const unsigned differ = static_cast<unsigned>((key[0] ^ previous_[0]) | (key[1] ^ previous_[1]) |
                                                  (key[2] ^ previous_[2]));
    depth = differ == 0 ? leaf_depth : leaf_depth - 1 - (31 - __builtin_clz(differ));
    if (depth > known_depth_) depth = known_depth_;
  }
  previous_ = key;
  // A clamped node takes no update (updateNode's early return). search()
  // would return the deepest existing node on the path if it has no
  // children (a leaf, possibly pruned), nothing if a child is missing.
  auto saturated = [&](const octomap::OcTreeNode* node) {
    return (log_odds >= 0.0f && node->getLogOdds() >= t.clamping_thres_max) ||
           (log_odds <= 0.0f && node->getLogOdds() <= t.clamping_thres_min);
  };
  octomap::OcTreeNode* node = path_[depth];
  for (; depth < leaf_depth; ++depth) {
    const unsigned pos = octomap::computeChildIdx(key, leaf_depth - 1 - depth);
    if (!t.nodeChildExists(node, pos)) {
      if (!t.nodeHasChildren(node) && !created) {  // a pruned leaf
        if (saturated(node)) {
          known_depth_ = depth;
          return;
        }
        t.expandNode(node);
      } else {
        t.createNodeChild(node, pos);
        created = true;
      }
    }
    node = t.getNodeChild(node, pos);
    path_[depth + 1] = node;
  }
  known_depth_ = leaf_depth;
  if (!created && saturated(node)) return;
  t.updateNodeLogOdds(node, log_odds);
}

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
