#pragma once
/// @file
/// An octomap::OcTree that takes a grid's cells fast: the fusion step of the
/// accumulator (not in the paper, which stops at the local grid).

#include <octomap/OcTree.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <vector>

#include "stereo_occupancy/cell_class.h"
#include "stereo_occupancy/worker_pool.h"

namespace stereo_occupancy {

/// True if the leaf at @p it overlaps the keys [lo, hi] on every axis.
/// octomap 1.9's leaf_bbx_iterator also hands out a coarse leaf that ends
/// just before the box: loops over a box's leaves skip those.
inline bool leafOverlaps(const octomap::OcTree::leaf_bbx_iterator& it, unsigned tree_depth,
                         const octomap::OcTreeKey& lo, const octomap::OcTreeKey& hi) {
  const octomap::OcTreeKey first = it.getIndexKey();
  const int side = 1 << (tree_depth - it.getDepth());
  for (int a = 0; a < 3; ++a)
    if (first[a] + side - 1 < lo[a] || first[a] > hi[a]) return false;
  return true;
}

/// The keys of the global cells @p cells (a key is a cell + @p key_offset),
/// cut to the key range into [@p lo, @p hi]; false if none lie in it (or
/// the box is empty): beyond it the map holds nothing.
inline bool keysOfCells(const CellBox& cells, int key_offset, octomap::OcTreeKey* lo, octomap::OcTreeKey* hi) {
  if (cells.isEmpty()) return false;
  constexpr int64_t kKeyMax = std::numeric_limits<octomap::key_type>::max();
  for (int a = 0; a < 3; ++a) {
    const int64_t k_lo = int64_t{cells.min()[a]} + key_offset, k_hi = int64_t{cells.max()[a]} + key_offset;
    if (k_hi < 0 || k_lo > kKeyMax) return false;
    (*lo)[a] = static_cast<octomap::key_type>(std::max<int64_t>(k_lo, 0));
    (*hi)[a] = static_cast<octomap::key_type>(std::min(k_hi, kKeyMax));
  }
  return true;
}

/// The class changes of fusions (AccumulatingOcTree::LeafUpdater::recordClassChanges()).
struct ClassChangeLog {
  std::vector<CellClassChange> changes;                  ///< in the order of the fusions
  std::vector<std::vector<CellClassChange>> per_worker;  ///< addSiblingsInParts()'s workers' (kept for their memory)
  size_t max_changes = 0;                                ///< changes holds at most this many
  bool overflowed = false;                               ///< a change did not fit: changes is incomplete
};

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
    /// Adds below @p subtree only, the node at @p depth on the path of every
    /// key given (@p inside is one of them); @p created: that node is new.
    /// Nodes are created through @p counter, a tree of the same depth and
    /// clamping bounds whose node count grows instead (one per worker).
    LeafUpdater(AccumulatingOcTree* counter, octomap::OcTreeNode* subtree, int depth, const octomap::OcTreeKey& inside,
                bool created)
        : tree_(counter), floor_depth_(depth), known_depth_(depth), previous_(inside), next_created_(created) {
      path_[static_cast<size_t>(depth)] = subtree;
    }
    void add(const octomap::OcTreeKey& key, float log_odds);
    /// From now on, add() and addSiblings() set each leaf to the value given
    /// instead of adding it: the leaf is created, or a pruned leaf above it
    /// expanded, whatever the values (no clamped early return). A write-back
    /// of values computed with add()'s semantics elsewhere (FusionCache).
    void setValues() { set_values_ = true; }
    /// From now on, appends each cell whose class (unknown, free, occupied
    /// by @p occupied_log_odds) an add() changes to @p changes, with its class
    /// after the add (a created leaf was unknown, an expanded pruned leaf's
    /// cells had its class); at most @p max_changes, then only sets
    /// overflowed(). Null: no recording (the fusion as without it).
    void recordClassChanges(std::vector<CellClassChange>* changes, float occupied_log_odds, size_t max_changes) {
      changes_ = changes;
      occupied_log_odds_ = occupied_log_odds;
      max_changes_ = max_changes;
    }
    /// A change was not recorded because @p changes held max_changes.
    bool overflowed() const { return overflowed_; }
    /// add() for each of a node's eight leaves that has a value, in child
    /// order: leaf i has the key @p first + (i & 1, (i >> 1) & 1, i >> 2)
    /// (@p first's components even) and the log-odds values[i], NaN for none.
    void addSiblings(const octomap::OcTreeKey& first, const float (&values)[8]);

   private:
    /// add()'s walk from the node at @p depth on the previous key's path
    /// (a common ancestor of the two keys); @p created: that node is new.
    void descend(const octomap::OcTreeKey& key, float log_odds, int depth, bool created);
    /// @p node takes no update of @p log_odds: it is clamped that way
    /// already (updateNode's early return).
    bool clamped(const octomap::OcTreeNode* node, float log_odds) const {
      return (log_odds >= 0.0f && node->getLogOdds() >= tree_->clamping_thres_max) ||
             (log_odds <= 0.0f && node->getLogOdds() <= tree_->clamping_thres_min);
    }
    /// The log-odds update of @p leaf (of @p key; @p created: new), unless it
    /// is clamped already, recording its class change.
    void updateLeaf(const octomap::OcTreeKey& key, octomap::OcTreeNode* leaf, float log_odds, bool created);
    /// OccupancyOcTreeBase::updateNodeLogOdds() with the same operations,
    /// inline: it is virtual and calls OcTreeNode::addValue() out of line,
    /// two calls for every cell of every update.
    void addLogOdds(octomap::OcTreeNode* node, float update) const {
      node->setLogOdds(node->getLogOdds() + update);
      if (node->getLogOdds() < tree_->clamping_thres_min) {
        node->setLogOdds(tree_->clamping_thres_min);
        return;
      }
      if (node->getLogOdds() > tree_->clamping_thres_max) node->setLogOdds(tree_->clamping_thres_max);
    }
    /// updateLeaf()'s update when recording.
    void updateRecording(const octomap::OcTreeKey& key, octomap::OcTreeNode* node, float log_odds, bool created);

    AccumulatingOcTree* tree_;
    std::array<octomap::OcTreeNode*, 17> path_{};  ///< path_[d]: the previous key's node at depth d
    int floor_depth_ = 0;                          ///< the walks start at this depth or below
    int known_depth_ = -1;                         ///< path_[floor_depth_ .. known_depth_] is valid
    octomap::OcTreeKey previous_;
    bool next_created_ = false;                        ///< the next add()'s first node is new (a worker's subtree)
    bool set_values_ = false;                          ///< setValues(): leaves take the value given
    std::vector<CellClassChange>* changes_ = nullptr;  ///< null: not recording
    float occupied_log_odds_ = 0.0f;
    size_t max_changes_ = 0;
    bool overflowed_ = false;
  };

  /// One sibling block of an update: addSiblings()'s arguments.
  struct SiblingBlock {
    octomap::OcTreeKey first;
    float values[8];
  };
  /// Depth of the subtrees whose blocks are one worker's part: cubes of
  /// 2^(16 - kPartDepth) = 16 cells, MapAccumulator::kBlockCells.
  static constexpr int kPartDepth = 12;
  /// Trees that count the nodes each worker creates (LeafUpdater's counter).
  using WorkerCounters = std::vector<std::unique_ptr<AccumulatingOcTree>>;

  /// addSiblings() for every block of the @p parts, each part the blocks of
  /// one subtree at kPartDepth, on @p pool's workers. The path to
  /// each subtree is made first on this thread, as the first update below it
  /// would make it; the parts below a pruned leaf above kPartDepth (whether
  /// it is expanded depends on their values) go on this thread after the
  /// others. The tree is the same, bit for bit, as addSiblings() on one thread.
  /// @p log (null: none) gets the class changes: each worker's, in worker
  /// order, then this thread's (the same set as on one thread; another order).
  /// @p set_values: the leaves take the values given instead (LeafUpdater::setValues()).
  void addSiblingsInParts(const std::vector<const std::vector<SiblingBlock>*>& parts, WorkerPool* pool,
                          WorkerCounters* counters, ClassChangeLog* log = nullptr, bool set_values = false);

  /// Sets the leaf of @p key at @p depth (pruned leaves keep their size).
  /// octomap 1.9's deleteNode leaves the emptied inner nodes' child arrays
  /// behind and trips an assertion, so dropping cells copies the ones to keep.
  void setLeaf(const octomap::OcTreeKey& key, unsigned depth, float log_odds);

  /// octomap's prune() below the node of @p key at @p depth only: every
  /// node whose eight children are leaves of one value becomes a leaf of
  /// it, bottom up; each cell keeps its value. Work follows the subtree.
  /// With @p deepest, only nodes at depths [depth, deepest] merge (the
  /// ones below were merged already: their parts, one at a time).
  /// Returns how many nodes became leaves.
  size_t pruneBelow(const octomap::OcTreeKey& key, unsigned depth,
                    unsigned deepest = std::numeric_limits<unsigned>::max());
  /// Called with a node's lowest key and its depth just before the node
  /// merges; the node then merges only if its children are still eight
  /// leaves of one value.
  using BeforeMerge = std::function<void(const octomap::OcTreeKey& lo, unsigned depth)>;
  /// pruneBelow(key, depth, deepest) with @p before_merge called for each
  /// node about to merge. The same nodes merge as after @p before_merge's
  /// changes everywhere first, provided that it changes only cells of the
  /// node's own subtree that lie below the node's children (as cells of
  /// depth 16 do below nodes up to depth 14): such a change expands a child
  /// and can only keep the node from merging. @p key is the lowest key of
  /// the node at @p depth.
  size_t pruneBelow(const octomap::OcTreeKey& key, unsigned depth, unsigned deepest, const BeforeMerge& before_merge);

  /// The keys of the nodes at @p part_depth below the node of @p key at
  /// @p depth that have children (the ones pruneBelow() could merge), in
  /// the tree's child order.
  std::vector<octomap::OcTreeKey> innerNodesBelow(const octomap::OcTreeKey& key, unsigned depth,
                                                  unsigned part_depth) const;

  /// Deletes the node of @p key at @p depth with everything below it, and
  /// the ancestors left without children (a childless inner node would read
  /// as a coarse leaf). A pruned leaf above @p depth is expanded first, so
  /// only the node's part of it goes. Work follows the nodes deleted, not the
  /// tree. Inner nodes are left stale. Returns false if nothing was there.
  bool dropNode(const octomap::OcTreeKey& key, unsigned depth);

 private:
  /// Frees everything below @p node, which becomes a leaf: octomap frees a
  /// node's child array only in pruneNode(), so each level is made prunable.
  void collapse(octomap::OcTreeNode* node);
  /// The node of @p key at @p depth; null if there is none, or a coarser leaf holds the key.
  const octomap::OcTreeNode* nodeOnPath(const octomap::OcTreeKey& key, unsigned depth) const;
  octomap::OcTreeNode* nodeOnPath(const octomap::OcTreeKey& key, unsigned depth);
  /// pruneBelow()'s merges with @p before_merge, below @p node (lowest key @p lo, at @p depth).
  size_t mergeUp(octomap::OcTreeNode* node, const octomap::OcTreeKey& lo, unsigned depth, unsigned deepest,
                 const BeforeMerge& before_merge);
  /// The node at kPartDepth on @p key's path, the path made as LeafUpdater
  /// would (@p created: the node is new); null if a pruned leaf lies above it.
  octomap::OcTreeNode* partRoot(const octomap::OcTreeKey& key, bool* created);
};

// Inline: the accumulator calls it for every cell of every update.
inline void AccumulatingOcTree::LeafUpdater::add(const octomap::OcTreeKey& key, float log_odds) {
  AccumulatingOcTree& t = *tree_;
  const int leaf_depth = static_cast<int>(t.tree_depth);
  bool created = next_created_;  // the node of the walk below was created by this call
  next_created_ = false;
  if (known_depth_ < 0) {
    if (!t.root) {
      t.root = new octomap::OcTreeNode();
      ++t.tree_size;
      created = true;
    }
    path_[0] = t.root;
    known_depth_ = 0;
  }
  // The deepest common ancestor with the previous key: node depth d is
  // fixed by each key component's d highest bits.
  int depth = floor_depth_;
  if (known_depth_ > floor_depth_) {
    const unsigned differ =
        static_cast<unsigned>((key[0] ^ previous_[0]) | (key[1] ^ previous_[1]) | (key[2] ^ previous_[2]));
    depth = differ == 0 ? leaf_depth : leaf_depth - 1 - (31 - __builtin_clz(differ));
    if (depth > known_depth_) depth = known_depth_;
  }
  previous_ = key;
  descend(key, log_odds, depth, created);
}

inline void AccumulatingOcTree::LeafUpdater::descend(const octomap::OcTreeKey& key, float log_odds, int depth,
                                                     bool created) {
  AccumulatingOcTree& t = *tree_;
  const int leaf_depth = static_cast<int>(t.tree_depth);
  octomap::OcTreeNode* node = path_[depth];
  for (; depth < leaf_depth; ++depth) {
    const unsigned pos = octomap::computeChildIdx(key, leaf_depth - 1 - depth);
    if (!t.nodeChildExists(node, pos)) {
      if (!t.nodeHasChildren(node) && !created) {  // a pruned leaf
        // A clamped one takes no update: updateNode's search() returns the
        // deepest existing node on the path if it has no children.
        if (!set_values_ && clamped(node, log_odds)) {
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
  updateLeaf(key, node, log_odds, created);
}

inline void AccumulatingOcTree::LeafUpdater::updateLeaf(const octomap::OcTreeKey& key, octomap::OcTreeNode* leaf,
                                                        float log_odds, bool created) {
  if (set_values_) {
    leaf->setLogOdds(log_odds);
    return;
  }
  if (!created && clamped(leaf, log_odds)) return;
  if (changes_) {  // the only cost of recording when it is off
    updateRecording(key, leaf, log_odds, created);
    return;
  }
  addLogOdds(leaf, log_odds);
}

inline void AccumulatingOcTree::LeafUpdater::updateRecording(const octomap::OcTreeKey& key, octomap::OcTreeNode* node,
                                                             float log_odds, bool created) {
  // A created leaf was unknown; an expanded pruned leaf's cell holds its value already.
  const CellClass before = created ? CellClass::kUnknown : classOfLogOdds(node->getLogOdds(), occupied_log_odds_);
  addLogOdds(node, log_odds);
  const CellClass after = classOfLogOdds(node->getLogOdds(), occupied_log_odds_);
  if (after == before) return;
  if (changes_->size() >= max_changes_) {
    overflowed_ = true;
    return;
  }
  const int offset = static_cast<int>(tree_->tree_max_val);  // key of global index 0
  changes_->push_back(CellClassChange{Eigen::Vector3i(key[0] - offset, key[1] - offset, key[2] - offset), after});
}

inline void AccumulatingOcTree::LeafUpdater::addSiblings(const octomap::OcTreeKey& first, const float (&values)[8]) {
  auto keyOf = [&first](int i) {
    return octomap::OcTreeKey(static_cast<octomap::key_type>(first[0] + (i & 1)),
                              static_cast<octomap::key_type>(first[1] + ((i >> 1) & 1)),
                              static_cast<octomap::key_type>(first[2] + (i >> 2)));
  };
  int i = 0;
  while (i < 8 && !(values[i] == values[i])) ++i;
  if (i == 8) return;
  add(keyOf(i), values[i]);
  const int leaf_depth = static_cast<int>(tree_->tree_depth);
  if (known_depth_ < leaf_depth) {
    // The walk stopped at a clamped pruned leaf above: each sibling's walk
    // stops there too (their deepest common ancestor is the parent).
    for (++i; i < 8; ++i) {
      if (!(values[i] == values[i])) continue;
      previous_ = keyOf(i);
      descend(previous_, values[i], std::min(leaf_depth - 1, known_depth_), false);
    }
    return;
  }
  // The siblings are the children of the first leaf's parent, child i for
  // values[i] (first's components are even): no walk, the parent is known.
  AccumulatingOcTree& t = *tree_;
  octomap::OcTreeNode* parent = path_[static_cast<size_t>(leaf_depth - 1)];
  for (++i; i < 8; ++i) {
    if (!(values[i] == values[i])) continue;
    const bool exists = t.nodeChildExists(parent, static_cast<unsigned>(i));
    octomap::OcTreeNode* leaf =
        exists ? t.getNodeChild(parent, static_cast<unsigned>(i)) : t.createNodeChild(parent, static_cast<unsigned>(i));
    previous_ = keyOf(i);
    path_[static_cast<size_t>(leaf_depth)] = leaf;
    updateLeaf(previous_, leaf, values[i], !exists);
  }
}

}  // namespace stereo_occupancy
