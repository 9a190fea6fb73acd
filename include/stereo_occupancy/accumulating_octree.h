#pragma once
/// @file
/// An octomap::OcTree that takes a grid's cells fast: the fusion step of the
/// accumulator (not in the paper, which stops at the local grid).

#include <octomap/OcTree.h>

#include <array>

namespace stereo_occupancy {

/// An OcTree with two additions the accumulator needs: adding log-odds to
/// many leaves in a row without descending from the root for each, and
/// rebuilding a tree leaf by leaf.
class AccumulatingOcTree : public octomap::OcTree {
 public:
  using octomap::OcTree::OcTree;

  /// Adds log-odds to leaves exactly as updateNode(key, log_odds,
  /// lazy_eval = true) does (the same nodes created, pruned leaves expanded,
  /// clamping, and the early return at a clamped leaf), key after key. It
  /// keeps the path to the previous key's leaf, so a key next to the previous
  /// one (a grid's cells in storage order) descends from their common
  /// ancestor only: about two levels instead of 2 x 16 (updateNode searches,
  /// then descends). Inner nodes are left stale, as with lazy_eval.
  /// Valid while the tree is changed only through it.
  class LeafUpdater {
   public:
    explicit LeafUpdater(AccumulatingOcTree* tree) : tree_(tree) {}
    void add(const octomap::OcTreeKey& key, float log_odds);

   private:
    AccumulatingOcTree* tree_;
    std::array<octomap::OcTreeNode*, 17> path_{};  ///< path_[d]: the previous key's node at depth d
    int known_depth_ = -1;                         ///< path_[0 .. known_depth_] is valid
    octomap::OcTreeKey previous_;
  };

  /// Sets the leaf of @p key at @p depth (pruned leaves keep their size).
  /// octomap 1.9's deleteNode leaves the emptied inner nodes' child arrays
  /// behind and trips an assertion, so dropping cells copies the ones to keep.
  void setLeaf(const octomap::OcTreeKey& key, unsigned depth, float log_odds);
};

}  // namespace stereo_occupancy
