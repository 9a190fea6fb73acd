#pragma once
/// @file
/// The whole mission's map: the live MapAccumulator, a window around the
/// vehicle in RAM, and the tiles it flew away from in a TileStore on disk,
/// which come back when the vehicle returns.

#include <deque>
#include <memory>
#include <string>
#include <unordered_set>
#include <vector>

#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/store/map_snapshot.h"
#include "stereo_occupancy/store/tile_store.h"

namespace stereo_occupancy {

/// What MissionMap::maintain() did.
struct MaintainResult {
  size_t leaves_dropped = 0;  ///< gone for good (no store): MapAccumulator::prune
  size_t tiles_stored = 0;    ///< moved from RAM to the store
  size_t nodes_merged = 0;    ///< nodes whose eight equal leaves became one (MapAccumulator::mergeEqualLeaves)
};

/// When maintain() merges the changed tiles' equal leaves.
enum class MergeTiming {
  kNow,     ///< all in the call
  kSpread,  ///< queued: mergeStep() merges them over the next mergeSteps() calls
};

/// MapAccumulator + TileStore. Not thread-safe, as MapAccumulator; the
/// store it hands tiles to is.
class MissionMap {
 public:
  using TileIndex = MapAccumulator::TileIndex;
  /// The fewest mergeStep() calls over which maintain(MergeTiming::kSpread)'s merges are spread.
  static constexpr size_t kMergeSteps = 16;
  /// The merges are spread over 1/kMergeShare of the updates integrated
  /// between the last two maintain() calls (when that is more than
  /// kMergeSteps): at a higher frame rate each step is smaller, and if the
  /// rate halves the queue ends about when the next maintain() comes (which
  /// does what is left).
  static constexpr size_t kMergeShare = 2;

  /// @throws std::invalid_argument if the config is not valid.
  explicit MissionMap(const MapAccumulatorConfig& config);

  /// From now on, tiles beyond max_extent_m go to @p store instead of being
  /// dropped, and come back from it when an update reaches them. Tiles the
  /// live map holds now replace the store's on the next checkpoint().
  /// @throws std::invalid_argument for a store of another resolution.
  void attachStore(std::shared_ptr<TileStore> store);
  /// The store, or null.
  const std::shared_ptr<TileStore>& store() const { return store_; }

  /// The live map (the window around the vehicle).
  const MapAccumulator& live() const { return live_; }
  MapAccumulator& live() { return live_; }

  /// MapAccumulator::integrate, after taking back from the store the tiles
  /// the update reaches.
  bool integrate(const GridUpdateView& update, std::string* why = nullptr);
  /// Moves the tiles outside the window (MapAccumulator::keptBox, grown by
  /// kPruneSlack · max_extent_m) to the store (their equal leaves merged
  /// first); without one, prunes. Then, with compress_map, merges the equal
  /// leaves of the tiles changed since the last call (each cell keeps its
  /// value; clamped free space takes an eighth of the memory and of the
  /// store). See takeFreedMemory(). With MergeTiming::kSpread the merges
  /// wait for mergeStep() (each cell's value is the same either way; only
  /// when its node merges differs); merges still queued from an earlier
  /// call are done first.
  MaintainResult maintain(MergeTiming merges = MergeTiming::kNow);
  /// One mergeSteps()-th of the merges maintain(MergeTiming::kSpread) queued,
  /// a part (AccumulatingOcTree::kPartDepth node) at a time, so that no
  /// update waits for a whole map's merges and their frees. Nothing when
  /// none are queued.
  MaintainResult mergeStep();
  /// True while merges wait for mergeStep().
  bool mergesQueued() const { return !queued_merges_.empty(); }
  /// The mergeStep() calls the last maintain(MergeTiming::kSpread) spread
  /// its merges over: kMergeSteps, or more (kMergeShare); 0 before one (and
  /// after reset() or load()).
  size_t mergeSteps() const { return merge_steps_; }
  /// True once after maintain() moved tiles to the store or merged leaves,
  /// or after the last mergeStep() of a queue that merged some (with a
  /// store): their memory is free, but the allocator keeps it from the
  /// system until trimHeap().
  bool takeFreedMemory();
  /// Gives the allocator's free pages back to the system (glibc's
  /// malloc_trim). It walks the heap: call it outside the lock that
  /// serialises the map.
  static void trimHeap();
  /// Queues the live tiles changed since the last checkpoint in the store
  /// (its thread writes them): a crash then loses only what came after.
  /// Returns how many tiles were queued; 0 without a store.
  size_t checkpoint();
  /// The live tiles changed since the last call, each with its leaves (none:
  /// the tile left the live map), for a MapSnapshot; costs what changed.
  /// @p whole_map, or after a reset or load: every live tile, and
  /// @p *whole_map_out is true.
  std::vector<TileContent> takeChangedTiles(bool whole_map, bool* whole_map_out);
  /// MapAccumulator::clearBox over the whole mission: the store's tiles that
  /// overlap the box come back one at a time, are cleared, and go back to
  /// the store if they lie outside the window, or if there is no window yet
  /// (so memory stays bounded whatever the box, and a clear that finds
  /// nothing leaves nothing in RAM). Returns how many cells were cleared.
  size_t clearBox(const Eigen::Vector3d& W_min, const Eigen::Vector3d& W_max);
  /// Empties the map, the store's tiles too.
  void reset();
  /// MapAccumulator::load; the loaded tiles replace the store's at the next checkpoint().
  void load(const std::string& path);

  /// The whole mission: checkpoint(), then every tile of the store; without
  /// a store, the live map. Writes <directory>/<base_name>.bt and .ot as
  /// MapAccumulator::save does. @throws std::runtime_error as it does, and
  /// if the store cannot write its queue.
  std::vector<std::string> saveWhole(const std::string& directory, const std::string& base_name);
  /// saveWhole()'s second half, which needs no MissionMap (a caller can run
  /// it outside the lock that serialises the map): flushes @p store, then
  /// writes all its tiles.
  static std::vector<std::string> saveStore(TileStore& store, const std::string& directory,
                                            const std::string& base_name, double occupancy_threshold_prob);

  /// Writes every tile of @p store to @p path (.bt or .ot, atomically as
  /// writeOcTree) one tile at a time: the file of assemble()'s tree, byte for
  /// byte, in the memory of one tile. Cells at or above
  /// @p occupancy_threshold_prob are occupied in a .bt.
  /// @throws std::runtime_error naming the file and the reason.
  static void writeStore(const TileStore& store, const std::string& path, double occupancy_threshold_prob);

  /// The store's tiles that overlap [W_min, W_max], cut to it, as one tree
  /// (the whole store for an empty box). @throws std::runtime_error for an unreadable row.
  static std::unique_ptr<octomap::OcTree> assemble(const TileStore& store, const Eigen::AlignedBox3d& W_box);

 private:
  /// Takes @p tile back from the store unless the live map holds it.
  void makeResident(const TileIndex& tile);

  MapAccumulator live_;
  std::shared_ptr<TileStore> store_;
  std::unordered_set<uint64_t> resident_;     ///< tiles the live map holds (not the store's copy)
  std::unordered_set<uint64_t> unsaved_;      ///< resident tiles changed since their last checkpoint
  std::unordered_set<uint64_t> unpublished_;  ///< tiles changed or gone since takeChangedTiles()
  std::unordered_set<uint64_t> unmerged_;     ///< live tiles changed since maintain() merged their leaves
  bool all_unpublished_ = true;               ///< the next takeChangedTiles() gives the whole map
  bool freed_memory_ = false;                 ///< see takeFreedMemory()
  /// A tile whose merges maintain(MergeTiming::kSpread) queued.
  struct QueuedMerge {
    uint64_t tile = 0;                      ///< TileStore::pack
    std::vector<octomap::OcTreeKey> parts;  ///< MapAccumulator::partsToMerge, merged up to next
    size_t next = 0;
  };
  std::deque<QueuedMerge> queued_merges_;  ///< in the order maintain() met the tiles
  size_t parts_per_step_ = 0;              ///< a merge_steps_-th of the queue's parts, at least 1
  size_t merge_steps_ = 0;                 ///< see mergeSteps()
  size_t updates_since_maintain_ = 0;      ///< integrate() calls that fused, since the last maintain()
  size_t spread_merged_ = 0;               ///< nodes the queue's steps merged so far (freed_memory_ when it empties)
  /// The live map's kept box grown by kPruneSlack · max_extent_m; empty before the first update.
  Eigen::AlignedBox3d window() const;
  /// Moves the resident tile @p key to the store (written only if changed) and out of RAM.
  void storeTile(uint64_t key, MaintainResult* result);
  /// Moves the live map's dirty tiles to unsaved_ (with a store), unpublished_ and unmerged_.
  void collectDirtyTiles();
  /// MapAccumulator::mergeEqualLeaves for each tile of unmerged_ (tileMerged()).
  void mergeChangedTiles(MaintainResult* result);
  /// Queues the tiles of unmerged_ for mergeStep().
  void queueChangedTiles();
  /// Merges the rest of the queue's tiles now.
  void finishQueuedMerges(MaintainResult* result);
  /// Merges the queue's next @p parts parts, and the tiles above the ones
  /// whose parts are all merged. Returns how many nodes became leaves.
  size_t mergeQueued(size_t parts);
  /// After @p key's leaves merged: to the outputs, and to the store at the next checkpoint.
  void tileMerged(uint64_t key);
  /// Takes @p key out of the queue; true if it was there.
  bool unqueue(uint64_t key);
};

}  // namespace stereo_occupancy
