// The OcTree the accumulator fuses into (accumulating_octree.h): its leaf
// updater against octomap's updateNode.

#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <limits>
#include <random>
#include <utility>
#include <vector>

#include "octree_text.h"
#include "stereo_occupancy/accumulating_octree.h"

using namespace stereo_occupancy;

// The accumulator's fast path against octomap's own updateNode(key, value,
// lazy_eval = true): the same trees, node for node, from a tree holding
// pruned leaves (clamped and not) and with keys in storage order, repeated
// (so that leaves clamp) and in random order.
TEST(AccumulatingOcTree, LeafUpdaterEqualsUpdateNode) {
  const double res = 0.25;
  AccumulatingOcTree fast(res);
  octomap::OcTree plain(res);
  auto both = [&](const octomap::OcTreeKey& key, float value) {
    AccumulatingOcTree::LeafUpdater(&fast).add(key, value);
    plain.updateNode(key, value, true);
  };
  const uint16_t o = 32768;
  // Two pruned 2x2x2 blocks (one clamped occupied, one at 0.4) and a
  // pruned 4x4x4 block of clamped free space, next to single leaves.
  for (int i = 0; i < 8; ++i) {
    const octomap::OcTreeKey a(o + (i & 1), o + ((i >> 1) & 1), o + (i >> 2));
    for (int r = 0; r < 5; ++r) both(a, 0.85f);
    both(octomap::OcTreeKey(o + 4 + (i & 1), o + ((i >> 1) & 1), o + (i >> 2)), 0.4f);
  }
  for (int i = 0; i < 64; ++i)
    for (int r = 0; r < 6; ++r) both(octomap::OcTreeKey(o + 8 + (i & 3), o + ((i >> 2) & 3), o + (i >> 4)), -0.4f);
  both(octomap::OcTreeKey(o + 2, o + 2, o + 2), 0.3f);
  fast.updateInnerOccupancy();
  plain.updateInnerOccupancy();
  fast.prune();
  plain.prune();
  ASSERT_EQ(fullTree(fast), fullTree(plain));
  ASSERT_LT(plain.size(), 8u * 16u) << "the blocks were not pruned";
  // Updates that push the clamped blocks further change nothing (updateNode
  // returns early at the pruned node), others expand them.
  const size_t pruned_size = plain.size();
  both(octomap::OcTreeKey(o + 1, o, o + 1), 0.85f);
  both(octomap::OcTreeKey(o + 9, o + 3, o + 2), -0.4f);
  both(octomap::OcTreeKey(o + 9, o + 3, o + 2), 0.0f);
  EXPECT_EQ(plain.size(), pruned_size);
  ASSERT_EQ(fullTree(fast), fullTree(plain));
  both(octomap::OcTreeKey(o + 5, o + 1, o), 0.3f);
  EXPECT_GT(plain.size(), pruned_size);
  ASSERT_EQ(fullTree(fast), fullTree(plain));

  // A 16x6x5 grid over all of it, in storage order, three times.
  std::mt19937 rng(7);
  const float values[] = {-0.4f, 0.0f, 0.17f, 0.85f, 2.5f, -2.5f};
  std::vector<std::pair<octomap::OcTreeKey, float>> cells;
  for (int z = -1; z < 4; ++z)
    for (int y = -1; y < 5; ++y)
      for (int x = -1; x < 15; ++x) cells.push_back({octomap::OcTreeKey(o + x, o + y, o + z), values[rng() % 6]});
  for (int pass = 0; pass < 3; ++pass) {
    AccumulatingOcTree::LeafUpdater updater(&fast);
    for (const auto& [key, value] : cells) {
      updater.add(key, value);
      plain.updateNode(key, value, true);
    }
    ASSERT_EQ(fullTree(fast), fullTree(plain)) << "pass " << pass;
  }
  // The same grid's 2x2x2 blocks with addSiblings(), some cells missing
  // (NaN), three times: it clamps leaves, and walks from pruned clamped
  // nodes (where the first sibling stops) to siblings of either sign.
  for (int pass = 0; pass < 3; ++pass) {
    AccumulatingOcTree::LeafUpdater updater(&fast);
    for (int z = -2; z < 4; z += 2)
      for (int y = -2; y < 6; y += 2)
        for (int x = -2; x < 16; x += 2) {
          float block[8];
          for (int i = 0; i < 8; ++i) {
            block[i] = rng() % 4 == 0 ? std::numeric_limits<float>::quiet_NaN() : values[rng() % 6];
            if (block[i] == block[i])
              plain.updateNode(octomap::OcTreeKey(o + x + (i & 1), o + y + ((i >> 1) & 1), o + z + (i >> 2)), block[i],
                               true);
          }
          updater.addSiblings(octomap::OcTreeKey(o + x, o + y, o + z), block);
        }
    ASSERT_EQ(fullTree(fast), fullTree(plain)) << "block pass " << pass;
    fast.updateInnerOccupancy();
    plain.updateInnerOccupancy();
    fast.prune();
    plain.prune();
    ASSERT_EQ(fullTree(fast), fullTree(plain)) << "block pass " << pass << ", pruned";
  }
  // Random keys, far apart and close, with repeats.
  AccumulatingOcTree::LeafUpdater updater(&fast);
  for (int i = 0; i < 20000; ++i) {
    const int spread = i % 2 ? 40 : 40000;
    const octomap::OcTreeKey key(o - spread / 2 + rng() % spread, o - spread / 2 + rng() % spread, o - 5 + rng() % 10);
    const float value = values[rng() % 6];
    updater.add(key, value);
    plain.updateNode(key, value, true);
  }
  EXPECT_EQ(fast.size(), plain.size());
  EXPECT_EQ(fullTree(fast), fullTree(plain));
}

// addSiblings() in a pruned 4x4x4 block of clamped free space: the first
// sibling stops at the pruned node (depth 14, above the leaves' parent), the
// next one, occupied, must walk on from there and expand it.
TEST(AccumulatingOcTree, SiblingsWalkOnFromAPrunedNode) {
  const double res = 0.25;
  AccumulatingOcTree fast(res);
  octomap::OcTree plain(res);
  const uint16_t o = 32768;
  for (int i = 0; i < 64; ++i)
    for (int r = 0; r < 6; ++r) {
      const octomap::OcTreeKey key(o + (i & 3), o + ((i >> 2) & 3), o + (i >> 4));
      AccumulatingOcTree::LeafUpdater(&fast).add(key, -0.4f);
      plain.updateNode(key, -0.4f, true);
    }
  for (octomap::OcTree* tree : {static_cast<octomap::OcTree*>(&fast), &plain}) {
    tree->updateInnerOccupancy();
    tree->prune();
  }
  ASSERT_EQ(fullTree(fast), fullTree(plain));
  ASSERT_EQ(plain.getNumLeafNodes(), 1u) << "the block was not pruned";
  AccumulatingOcTree::LeafUpdater updater(&fast);
  const octomap::OcTreeKey elsewhere(o + 40, o, o);  // a walk to another leaf first
  updater.add(elsewhere, 0.3f);
  plain.updateNode(elsewhere, 0.3f, true);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float block[8] = {-0.4f, 0.85f, nan, -0.4f, 0.3f, nan, nan, -0.4f};
  const octomap::OcTreeKey first(o + 2, o + 2, o);
  updater.addSiblings(first, block);
  for (int i = 0; i < 8; ++i)
    if (block[i] == block[i])
      plain.updateNode(octomap::OcTreeKey(first[0] + (i & 1), first[1] + ((i >> 1) & 1), first[2] + (i >> 2)), block[i],
                       true);
  EXPECT_GT(plain.getNumLeafNodes(), 2u) << "the pruned block was not expanded";
  EXPECT_EQ(fullTree(fast), fullTree(plain));
}

// pruneBelow() is octomap's prune() inside one subtree: a tile's equal
// siblings merge bottom up (a 16-cell cube of one value to one leaf, a
// 2x2x2 block to one), the other tile stays as it was, and every cell keeps
// its value.
TEST(AccumulatingOcTree, PruneBelowPrunesOneTileOnly) {
  const double res = 0.25;
  const int o = 32768, tile = 1 << (16 - 8);  // tiles at depth 8: 64 cells
  std::mt19937 rng(3);
  auto fill = [&](int x0, std::vector<octomap::OcTree*> trees) {
    for (int z = 0; z < 16; ++z)
      for (int y = 0; y < 16; ++y)
        for (int x = 0; x < 16; ++x)
          for (auto* t : trees) t->setNodeValue(octomap::OcTreeKey(o + x0 + x, o + y, o + z), -2.0f, true);
    for (int i = 0; i < 8; ++i)
      for (auto* t : trees)
        t->setNodeValue(octomap::OcTreeKey(o + x0 + 20 + (i & 1), o + ((i >> 1) & 1), o + (i >> 2)), 1.5f, true);
    for (int i = 0; i < 300; ++i) {
      const octomap::OcTreeKey k(o + x0 + 24 + rng() % 30, o + rng() % 40, o + rng() % 20);
      const float v = 0.1f * static_cast<float>(rng() % 20) - 1.0f;
      for (auto* t : trees) t->setNodeValue(k, v, true);  // lazy: setNodeValue would prune
    }
  };
  AccumulatingOcTree both(res);
  octomap::OcTree only_a(res), only_b(res);
  fill(0, {&both, &only_a});
  fill(tile, {&both, &only_b});
  const size_t nodes_before = both.size();
  const size_t merged = both.pruneBelow(octomap::OcTreeKey(o, o, o), 8);
  only_a.prune();
  EXPECT_GT(merged, 512u);  // the cube: 512 + 64 + 8 + 1 merges, the block one more
  EXPECT_EQ(both.size(), nodes_before - 8 * merged);
  EXPECT_EQ(both.size(), both.calcNumNodes());
  // Expected: tile A as octomap prunes it alone, tile B untouched.
  AccumulatingOcTree expected(res);
  for (const octomap::OcTree* part : {&only_a, &only_b})
    for (auto it = part->begin_leafs(), end = part->end_leafs(); it != end; ++it)
      expected.setLeaf(it.getKey(), it.getDepth(), it->getLogOdds());
  both.updateInnerOccupancy();
  expected.updateInnerOccupancy();
  EXPECT_TRUE(fullTree(both) == fullTree(expected)) << "not octomap's prune of tile A alone";
  EXPECT_EQ(both.pruneBelow(octomap::OcTreeKey(o, o, o), 8), 0u) << "pruned already";
  EXPECT_EQ(both.pruneBelow(octomap::OcTreeKey(o - 1, o, o), 8), 0u) << "an empty tile";
}
