#include "stereo_occupancy/accumulating_octree.h"

#include <algorithm>
#include <array>
#include <utility>
#include <vector>

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
      expandNode(path[d]);                         // a coarse leaf: keep its other parts
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

const octomap::OcTreeNode* AccumulatingOcTree::nodeOnPath(const octomap::OcTreeKey& key, unsigned depth) const {
  if (!root || depth > tree_depth) return nullptr;
  const octomap::OcTreeNode* node = root;
  for (unsigned d = 0; d < depth; ++d) {
    const unsigned pos = octomap::computeChildIdx(key, static_cast<int>(tree_depth - 1 - d));
    if (!nodeChildExists(node, pos)) return nullptr;  // nothing there, or a coarser leaf
    node = getNodeChild(node, pos);
  }
  return node;
}

octomap::OcTreeNode* AccumulatingOcTree::nodeOnPath(const octomap::OcTreeKey& key, unsigned depth) {
  // One walk for both: the nodes are this (non-const) tree's own.
  return const_cast<octomap::OcTreeNode*>(std::as_const(*this).nodeOnPath(key, depth));
}

size_t AccumulatingOcTree::pruneBelow(const octomap::OcTreeKey& key, unsigned depth, unsigned deepest) {
  octomap::OcTreeNode* node = nodeOnPath(key, depth);
  if (!node) return 0;
  deepest = std::min(deepest, tree_depth - 1);
  size_t merged = 0;
  // Each level from the leaves' parents up: a node merged at one level may
  // make its parent mergeable at the next (as prune(), without its early end).
  for (unsigned level = deepest; level + 1 > depth && nodeHasChildren(node); --level) {
    unsigned pruned = 0;
    pruneRecurs(node, depth, level, pruned);
    merged += pruned;
  }
  return merged;
}

size_t AccumulatingOcTree::pruneBelow(const octomap::OcTreeKey& key, unsigned depth, unsigned deepest,
                                      const BeforeMerge& before_merge) {
  octomap::OcTreeNode* node = nodeOnPath(key, depth);
  return node ? mergeUp(node, key, depth, std::min(deepest, tree_depth - 1), before_merge) : 0;
}

size_t AccumulatingOcTree::mergeUp(octomap::OcTreeNode* node, const octomap::OcTreeKey& lo, unsigned depth,
                                   unsigned deepest, const BeforeMerge& before_merge) {
  if (!nodeHasChildren(node)) return 0;
  size_t merged = 0;
  // Children first: a node merged at one level may make its parent
  // mergeable at the next, as pruneBelow()'s passes from the deepest level up.
  if (depth < deepest) {
    const unsigned bit = tree_depth - 1 - depth;
    for (unsigned i = 0; i < 8; ++i) {
      if (!nodeChildExists(node, i)) continue;
      octomap::OcTreeKey child = lo;
      for (unsigned a = 0; a < 3; ++a)
        if (i & (1u << a)) child[a] = static_cast<octomap::key_type>(child[a] | (1u << bit));
      merged += mergeUp(getNodeChild(node, i), child, depth + 1, deepest, before_merge);
    }
  }
  if (!isNodeCollapsible(node)) return merged;
  before_merge(lo, depth);
  return merged + (pruneNode(node) ? 1 : 0);  // pruneNode() checks again
}

std::vector<octomap::OcTreeKey> AccumulatingOcTree::innerNodesBelow(const octomap::OcTreeKey& key, unsigned depth,
                                                                    unsigned part_depth) const {
  std::vector<octomap::OcTreeKey> keys;
  if (depth > part_depth || part_depth >= tree_depth) return keys;
  const octomap::OcTreeNode* node = nodeOnPath(key, depth);
  if (!node) return keys;  // nothing there, or a coarser leaf
  // Depth first, children in index order; a child's key sets its level's bit.
  struct Visit {
    const octomap::OcTreeNode* node;
    unsigned depth;
    octomap::OcTreeKey key;
  };
  std::vector<Visit> stack{{node, depth, key}};
  while (!stack.empty()) {
    const Visit v = stack.back();
    stack.pop_back();
    if (!nodeHasChildren(v.node)) continue;
    if (v.depth == part_depth) {
      keys.push_back(v.key);
      continue;
    }
    const unsigned bit = tree_depth - 1 - v.depth;
    for (unsigned i = 8; i-- > 0;) {  // pushed last to first: visited first to last
      if (!nodeChildExists(v.node, i)) continue;
      octomap::OcTreeKey child = v.key;
      for (unsigned a = 0; a < 3; ++a) {
        child[a] = static_cast<octomap::key_type>(child[a] & ~(1u << bit));
        if (i & (1u << a)) child[a] = static_cast<octomap::key_type>(child[a] | (1u << bit));
      }
      stack.push_back({getNodeChild(v.node, i), v.depth + 1, child});
    }
  }
  return keys;
}

octomap::OcTreeNode* AccumulatingOcTree::partRoot(const octomap::OcTreeKey& key, bool* created) {
  bool made = false;
  if (!root) {
    root = new octomap::OcTreeNode();
    ++tree_size;
    made = true;
  }
  octomap::OcTreeNode* node = root;
  for (int d = 0; d < kPartDepth; ++d) {
    const unsigned pos = octomap::computeChildIdx(key, static_cast<int>(tree_depth) - 1 - d);
    if (!nodeChildExists(node, pos)) {
      if (!nodeHasChildren(node) && !made) return nullptr;  // a pruned leaf: its parts' values decide
      createNodeChild(node, pos);
      made = true;
    }
    node = getNodeChild(node, pos);
  }
  *created = made;
  return node;
}

void AccumulatingOcTree::addSiblingsInParts(const std::vector<const std::vector<SiblingBlock>*>& parts,
                                            WorkerPool* pool, WorkerCounters* counters, ClassChangeLog* log,
                                            bool set_values) {
  const size_t num_parts = parts.size();
  struct Start {
    octomap::OcTreeNode* node;
    bool created;
  };
  std::vector<Start> starts(num_parts, Start{nullptr, false});
  std::vector<size_t> on_workers, here;
  for (size_t p = 0; p < num_parts; ++p) {
    starts[p].node = partRoot(parts[p]->front().first, &starts[p].created);
    (starts[p].node ? on_workers : here).push_back(p);
  }
  while (counters->size() < pool->size()) counters->push_back(std::make_unique<AccumulatingOcTree>(resolution));
  for (const auto& c : *counters) {
    c->clamping_thres_min = clamping_thres_min;  // updateNodeLogOdds() clamps by the counter's bounds
    c->clamping_thres_max = clamping_thres_max;
    c->tree_size = 0;
  }
  if (log) {
    log->per_worker.resize(pool->size());
    for (auto& w : log->per_worker) w.clear();  // keeps their memory
  }
  // Each worker appends to its own list, each at most its share of what the
  // log may still take; the lists follow the log's in worker order afterwards.
  std::vector<char> overflowed(log ? pool->size() : 0, 0);
  auto record = [&](LeafUpdater* updater, std::vector<CellClassChange>* changes, size_t share) {
    if (log) updater->recordClassChanges(changes, occ_prob_thres_log, (log->max_changes - log->changes.size()) / share);
  };
  auto countNodes = [&] {  // the nodes the workers created are this tree's
    for (const auto& c : *counters) {
      size_changed = size_changed || c->tree_size > 0;
      tree_size += c->tree_size;
      c->tree_size = 0;
    }
    if (!log) return;
    for (size_t w = 0; w < log->per_worker.size(); ++w) {
      const auto& changes = log->per_worker[w];
      log->overflowed = log->overflowed || overflowed[w] || log->changes.size() + changes.size() > log->max_changes;
      if (!log->overflowed) log->changes.insert(log->changes.end(), changes.begin(), changes.end());
    }
  };
  try {
    pool->run(on_workers.size(), [&](size_t i, unsigned worker) {
      const size_t p = on_workers[i];
      LeafUpdater updater((*counters)[worker].get(), starts[p].node, kPartDepth, parts[p]->front().first,
                          starts[p].created);
      if (set_values) updater.setValues();
      record(&updater, log ? &log->per_worker[worker] : nullptr, pool->size());
      for (const SiblingBlock& b : *parts[p]) updater.addSiblings(b.first, b.values);
      if (updater.overflowed()) overflowed[worker] = 1;
    });
  } catch (...) {
    countNodes();
    throw;
  }
  countNodes();
  LeafUpdater updater(this);
  if (set_values) updater.setValues();
  if (log && !log->overflowed) record(&updater, &log->changes, 1);
  for (size_t p : here)
    for (const SiblingBlock& b : *parts[p]) updater.addSiblings(b.first, b.values);
  if (log && updater.overflowed()) log->overflowed = true;
}

}  // namespace stereo_occupancy
