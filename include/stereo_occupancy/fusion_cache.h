#pragma once
/// @file
/// The fusion's write-back cache: the cells the recent updates carried, in
/// dense blocks in front of the octree. Consecutive frames see mostly the
/// same cells (at 10 Hz, ten updates carry about eight times the cells they
/// touch), and an add to a dense array costs a fraction of a walk through the
/// tree's nodes, so the updates add into the blocks and the tree takes each
/// block's changed cells once, when it is written back (docs/performance.md).

#include <octomap/OcTree.h>

#include <array>
#include <cstdint>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/worker_pool.h"

namespace stereo_occupancy {

/// Dense blocks of log-odds in front of an AccumulatingOcTree. add() does
/// what LeafUpdater::add() (updateNode(key, log_odds, lazy_eval = true))
/// does to a cell's value, in the block; writeBack() then gives the tree the
/// nodes and values that those adds would have given it: a cell that any add
/// changed is created, or the pruned leaf above it expanded, and set to its
/// value. Which nodes exist does not depend on the order of those writes, so
/// the tree after a write-back is the tree of the adds, node for node.
///
/// The cached values are the tree's: whoever changes the tree otherwise
/// (clearing, dropping, loading, rebuilding) writes back first and drops the
/// blocks concerned. Merging equal leaves changes no value and needs neither.
/// Not thread-safe.
class FusionCache {
 public:
  /// A block's edge [cells]: the parts of AccumulatingOcTree::addSiblingsInParts().
  static constexpr int kEdge = 1 << (16 - AccumulatingOcTree::kPartDepth);
  static constexpr int kCells = kEdge * kEdge * kEdge;
  /// A block's changes wait this many updates after its first unwritten
  /// change before the tree takes them (the write-backs spread over the updates) ...
  static constexpr size_t kMinUnwrittenUpdates = 16;
  /// ... plus 0 .. kStaggerUpdates - 1 more, picked by its key, so that the
  /// blocks one update brought (a whole first frame's, all new to the tree)
  /// fall due over several updates, not all in one.
  static constexpr size_t kStaggerUpdates = 8;
  /// The tree lags the updates by at most this many.
  static constexpr size_t kMaxUnwrittenUpdates = kMinUnwrittenUpdates + kStaggerUpdates - 1;
  /// A block no update touched for this many updates is let go (after its write-back).
  static constexpr size_t kIdleUpdates = 8;
  /// The most blocks held (16.6 kB each, 68 MB): add() writes them all back
  /// and lets them go before it might pass this. At least a row of blocks
  /// across the key range (65536 keys / kEdge), so that one row always fits;
  /// far above what a flight's updates hold (docs/performance.md).
  static constexpr size_t kMaxBlocks = 4096;
  static_assert(kMaxBlocks >= (size_t{1} << 16) / kEdge, "a row of blocks fits");

  FusionCache();
  ~FusionCache();

  /// One cube of kEdge cells, x fastest.
  struct Block {
    octomap::OcTreeKey first;            ///< its lowest key
    std::array<float, kCells> log_odds;  ///< NaN: no leaf in the tree
    /// Cells an add changed since the last write-back: the tree takes these.
    std::array<uint64_t, kCells / 64> changed;
    size_t last_update = 0;  ///< the update that touched it last
    size_t write_due = 0;    ///< the update after which its unwritten changes are written back
    bool unwritten = false;  ///< changed holds a cell
  };

  /// Adds @p update's cells (GridUpdateView::isConsistent(), its keys inside
  /// the key range) to the blocks, reading the blocks it had not cached from
  /// @p tree. @p key_offset: the key of global index 0. With @p log, appends
  /// each cell whose class (unknown, free, occupied) changes, as
  /// LeafUpdater::recordClassChanges() does, up to its max_changes (then
  /// sets its overflowed). @p touched_blocks gets the global block index
  /// (global cell index / kEdge) of each block that the update's cells lie
  /// in, once each.
  /// On @p pool's workers (null: this thread), the same blocks and values,
  /// and the same class changes and touched blocks in the same order, for any number.
  /// The blocks stay within kMaxBlocks: before a row of blocks that might
  /// pass it (counting each of its blocks as new), every block is written
  /// into @p tree and let go. Returns the cells so written (usually none).
  size_t add(const GridUpdateView& update, AccumulatingOcTree* tree, int key_offset, ClassChangeLog* log,
             std::vector<Eigen::Vector3i>* touched_blocks, WorkerPool* pool = nullptr,
             AccumulatingOcTree::WorkerCounters* counters = nullptr);

  /// Writes every block's changed cells into @p tree (on @p pool's workers,
  /// null: this thread), then lets go of the idle blocks. Returns the cells written.
  size_t writeBack(AccumulatingOcTree* tree, WorkerPool* pool, AccumulatingOcTree::WorkerCounters* counters);
  /// The same for the blocks that the keys [@p lo, @p hi] overlap only; none let go.
  size_t writeBack(AccumulatingOcTree* tree, const octomap::OcTreeKey& lo, const octomap::OcTreeKey& hi,
                   WorkerPool* pool = nullptr, AccumulatingOcTree::WorkerCounters* counters = nullptr);
  /// After add(): the write-backs due (kMinUnwrittenUpdates, kStaggerUpdates),
  /// and the idle blocks let go. Returns the cells written.
  size_t maintain(AccumulatingOcTree* tree, WorkerPool* pool, AccumulatingOcTree::WorkerCounters* counters);

  /// Lets go of the blocks that the keys [@p lo, @p hi] overlap, written back or not.
  void drop(const octomap::OcTreeKey& lo, const octomap::OcTreeKey& hi);
  /// Lets go of every block, written back or not.
  void clear();

  /// Blocks held, and those with changes the tree has not taken.
  size_t blocks() const { return blocks_.size(); }
  size_t unwrittenBlocks() const;
  /// The lowest keys of the blocks with changes the tree has not taken that
  /// the keys [@p lo, @p hi] overlap (in no particular order).
  std::vector<octomap::OcTreeKey> unwrittenBlocks(const octomap::OcTreeKey& lo, const octomap::OcTreeKey& hi) const;

 private:
  struct RowOutput;
  /// The block whose lowest key is @p first, read from @p tree if new. Thread-safe.
  Block* blockAt(const octomap::OcTreeKey& first, const AccumulatingOcTree& tree);
  /// add() for the update's local cells y in [y0, y1), z in [z0, z1): one
  /// row of blocks. @p record: class changes, at most @p max_changes.
  void addRowOfBlocks(const GridUpdateView& update, const AccumulatingOcTree& tree, int key_offset, int64_t y0,
                      int64_t y1, int64_t z0, int64_t z1, bool record, size_t max_changes, RowOutput* out);
  /// Fills @p b with the tree's values (NaN where it holds no leaf).
  static void read(const AccumulatingOcTree& tree, Block* b);
  /// @p b's changed cells into @p part as sibling blocks, marked written. Returns how many.
  static size_t gatherChanged(Block* b, std::vector<AccumulatingOcTree::SiblingBlock>* part);
  /// Writes the blocks for which @p due is true.
  template <typename Due>
  size_t writeBackIf(AccumulatingOcTree* tree, WorkerPool* pool, AccumulatingOcTree::WorkerCounters* counters, Due due);
  /// Lets go of the blocks for which @p gone is true.
  template <typename Gone>
  void dropIf(Gone gone);

  std::unordered_map<uint64_t, std::unique_ptr<Block>> blocks_;  ///< by packed key / kEdge
  size_t updates_ = 0;                                           ///< add() calls
  std::mutex blocks_mutex_;                                      ///< blocks_ while add()'s workers look up blocks
  std::vector<std::unique_ptr<RowOutput>> rows_;                 ///< add()'s rows of blocks
  std::vector<size_t> value_start_;                              ///< add()'s first value of each run
  /// A row of blocks that holds cells: its id (z then y) and the cells in it.
  struct RowOfBlocks {
    int64_t id, cells;
  };
  std::vector<RowOfBlocks> rows_of_blocks_;  ///< add()'s
  /// writeBack()'s parts, kept from call to call for their memory.
  std::vector<std::vector<AccumulatingOcTree::SiblingBlock>> parts_;
  std::vector<Block*> due_;         ///< writeBack()'s blocks
  std::vector<size_t> part_cells_;  ///< writeBack()'s cells per block
};

}  // namespace stereo_occupancy
