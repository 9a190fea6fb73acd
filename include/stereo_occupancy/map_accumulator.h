#pragma once
/// @file
/// Fusion of local grids into one global octomap::OcTree (additive log-odds
/// with clamping), bounded in extent, with atomic saving.

#include <octomap/OcTree.h>

#include <Eigen/Geometry>

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_set>
#include <vector>

#include "stereo_occupancy/cell_class.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/parameter_table.h"

namespace stereo_occupancy {

class AccumulatingOcTree;
class FusionCache;
class WorkerPool;
struct ClassChangeLog;

/// Parameters of the global map.
struct MapAccumulatorConfig {
  double resolution_m = 0.25;             ///< cell edge; updates at another resolution are refused [m]
  double clamping_min_prob = 0.12;        ///< lower clamping bound of a cell (probability)
  double clamping_max_prob = 0.97;        ///< upper clamping bound of a cell (probability)
  double occupancy_threshold_prob = 0.5;  ///< cells above it are occupied (probability)
  /// Half edge of the box around the vehicle's recent positions that the
  /// live map keeps; cells outside it are dropped on prune() (or moved to a
  /// mission's database, store/mission_map.h). 0 keeps everything [m].
  double max_extent_m = 200.0;
  /// Largest box an update may claim (nx·ny·nz); larger ones are refused
  /// before anything is allocated. As DrawingConfig::max_grid_cells.
  uint64_t max_update_cells = uint64_t{64} << 20;
  /// Merge eight sibling leaves of one value into their parent in the tiles
  /// that changed, at each MissionMap::maintain() or over the steps after it (octomap_server's
  /// compress_map): about half the memory and a quarter of the disk, each
  /// cell's value the same; the fusion costs more (docs/mission.md).
  bool compress_map = true;
  /// Threads that fuse one update (0: the machine's cores, at most
  /// WorkerPool::kMaxDefaultThreads); the map is the same bit for bit for any number.
  int threads = 0;

  /// The parameters (parameter_table.h): f(spec, member) for each.
  template <typename Self, typename F>
  static void forEachParameter(Self& c, F&& f) {
    f(numberParameter("resolution_m", "m", 0.01, 10.0, "map cell edge; updates at another resolution are refused"),
      c.resolution_m);
    f(numberParameter("clamping_min_prob", "", 0.01, 0.49, "lower clamping bound of a cell"), c.clamping_min_prob);
    f(numberParameter("clamping_max_prob", "", 0.51, 0.99, "upper clamping bound of a cell"), c.clamping_max_prob);
    f(numberParameter("occupancy_threshold_prob", "", 0.01, 0.99,
                      "cells above it are occupied; between the clamping bounds"),
      c.occupancy_threshold_prob);
    f(numberParameter("max_extent_m", "m", 0.0, 100000.0,
                      "the live map keeps this half edge around the vehicle's last positions; 0: everything"),
      c.max_extent_m);
    f(numberParameter("max_update_cells", "cells", 1.0, 2147483647.0, "updates claiming a larger box are refused"),
      c.max_update_cells);
    f(textParameter("compress_map", "merge equal sibling leaves of the changed tiles (octomap_server's compress_map)"),
      c.compress_map);
    f(numberParameter("threads", "", 0.0, 64.0, "threads that fuse an update (0: the machine's cores, at most 4)"),
      c.threads);
  }

  /// The ranges of forEachParameter(), and the threshold between the clamping bounds.
  bool isValid(std::string* why = nullptr) const;
};

/// The global map. Not thread-safe: callers serialise access.
class MapAccumulator {
 public:
  /// @throws std::invalid_argument if the config is not valid.
  explicit MapAccumulator(const MapAccumulatorConfig& config);
  ~MapAccumulator();

  const MapAccumulatorConfig& config() const { return config_; }
  /// The map, the fusion's cache written back and its inner nodes brought up to date first.
  const octomap::OcTree& tree() const;
  /// The map as the fusion left it: its leaves current, its inner nodes'
  /// values perhaps not (tree() updates them in a pass over the whole tree).
  /// For readers of leaves only (the distance field), so that they do not
  /// pay that pass after every update. The cache is written back first.
  const octomap::OcTree& leafTree() const;
  /// The same with the leaves current inside @p cells (global cell indices,
  /// CellClassChange's) only: the cache's blocks that overlap the box are
  /// written back, the others stay (an empty box: none). For a reader of one
  /// part of the map (the distance field's entering slabs).
  const octomap::OcTree& leafTree(const CellBox& cells) const;

  /// True if integrate() would take @p update: consistent (GridUpdateView::isConsistent),
  /// of the map's resolution, a box of at most max_update_cells cells that lies
  /// inside the OcTree's key range, and a sensor origin near the box (within
  /// its largest edge). Costs O(runs), allocates nothing. Otherwise false
  /// and @p why says what is wrong.
  bool admits(const GridUpdateView& update, std::string* why = nullptr) const;

  /// Adds every cell's log-odds to the map (octomap's clamped update). Work
  /// and memory follow the cells carried, not the box claimed. The cells go
  /// into dense blocks in front of the tree (fusion_cache.h), which the tree
  /// takes when a block's changes are 16 to 23 updates old (FusionCache::kMinUnwrittenUpdates, its stagger),
  /// when the block goes idle, or when anything reads the tree: every
  /// method here sees the map of every update so far. Returns false,
  /// leaving the map unchanged, if admits() refuses the update.
  bool integrate(const GridUpdateView& update, std::string* why = nullptr);

  /// Drops the cells farther than max_extent_m (per axis) from the bounding
  /// box of the last kPruneOrigins sensor origins: no single update, however
  /// far its origin, can make the map drop what the vehicle is near. Does
  /// nothing while the map lies within kPruneSlack · max_extent_m beyond
  /// that (a prune rebuilds the tree). Returns how many leaves were dropped.
  size_t prune();

  /// Sensor origins that prune() keeps the map around.
  static constexpr size_t kPruneOrigins = 100;
  /// How far beyond max_extent_m the map may grow before prune() drops
  /// anything, as a share of max_extent_m.
  static constexpr double kPruneSlack = 0.25;

  /// Empties the map.
  void reset();

  /// Replaces the map by the one in @p path (.bt: occupied / free, .ot: with
  /// log-odds), clamped to this map's bounds. The number of updates starts
  /// at 0. The file is checked before it is read (readOcTreeFile).
  /// @throws std::runtime_error if the file cannot be read, is damaged,
  /// truncated or of another resolution; the map is then unchanged.
  void load(const std::string& path);

  /// Leaves no occupied cell in the box [W_min, W_max] (metres, in the map's
  /// frame): each is set to the lower clamping bound, as octomap_server's
  /// clear_bbx does. Returns how many cells were cleared.
  size_t clearBox(const Eigen::Vector3d& W_min, const Eigen::Vector3d& W_max);

  /// Number of updates integrated since the last reset.
  size_t updates() const { return updates_; }

  /// Edge of the blocks whose changes the map tracks, for outputs that cost
  /// what changed [cells].
  static constexpr int kBlockCells = 16;
  /// A block's index: global cell index / kBlockCells per axis.
  using BlockIndex = Eigen::Vector3i;
  /// The blocks changed since takeChangedBlocks() last returned them; all of
  /// the map's blocks after a reset, load, clearBox or prune (@p all then true).
  std::vector<BlockIndex> takeChangedBlocks(bool* all);
  /// The next takeChangedBlocks() returns all blocks (a new subscriber wants the whole map).
  void markAllChanged() { all_changed_ = true; }

  /// Starts (@p on) or stops recording the cells whose class (unknown, free,
  /// occupied: cell_class.h) each integrate() changes, for the distance field
  /// (distance_field.h): the fusion compares each cell's class before and
  /// after its log-odds add, on its own threads. Off, the fusion costs what it
  /// did without it. Starting makes the next takeClassChanges() say all.
  void recordClassChanges(bool on);
  /// The cells whose class the integrate() calls since the last call changed,
  /// each with its class after the update that changed it, in the order of
  /// the updates (a cell two updates changed comes twice, the later last;
  /// within one update a cell comes once, in an order that depends on the
  /// threads), and in @p regions the boxes in which anything else changed
  /// cells since (clearBox: its box; a prune() that dropped leaves: the
  /// space outside the box it kept, as up to six slabs, and any dropped
  /// coarse leaf that reached into that box; dropTile: the tile;
  /// insertLeaves: the leaves' bounding box). The map's cells in the
  /// regions are what the caller reads again; the changes of cells outside
  /// them are the whole story. @p all is set true instead, and both lists
  /// are empty, after a reset or load, when recording started, or when more
  /// than kMaxClassChanges changes or kMaxClassRegions regions piled up: the
  /// caller then reads the map again. Empty with @p all false when not recording.
  std::vector<CellClassChange> takeClassChanges(bool* all, std::vector<CellBox>* regions);
  /// The same with the regions given as all: for callers that read the whole map anyway.
  std::vector<CellClassChange> takeClassChanges(bool* all);
  /// Most class changes kept between two takeClassChanges() (16 bytes each);
  /// beyond, they give way to all.
  static constexpr size_t kMaxClassChanges = size_t{1} << 21;
  /// Most regions kept between two takeClassChanges(); beyond, they give way to all.
  static constexpr size_t kMaxClassRegions = 256;

  /// Tiles: the octree's nodes at depth kTileDepth, kTileCells cells on an
  /// edge (64 m at 0.25 m). A mission keeps the tiles it flew away from on
  /// disk (store/mission_map.h); the accumulator only hands them over.
  static constexpr unsigned kTileDepth = 8;
  static constexpr int kTileCells = 1 << (16 - kTileDepth);
  /// A tile's index: global cell index / kTileCells per axis (rounded down).
  using TileIndex = Eigen::Vector3i;
  /// One leaf of the tree: any key inside it, its depth (16: one cell), its log-odds.
  struct Leaf {
    octomap::OcTreeKey key;
    uint8_t depth = 16;
    float log_odds = 0.0f;
  };
  /// The tiles the box of @p update overlaps.
  std::vector<TileIndex> tilesOf(const GridUpdateView& update) const;
  /// The tiles that hold leaves.
  std::vector<TileIndex> tiles() const;
  /// Box of @p tile in the map's frame [m].
  Eigen::AlignedBox3d tileBox(const TileIndex& tile) const;
  /// The box prune() keeps: the last sensor origins' box grown by
  /// max_extent_m; empty before the first update [m].
  Eigen::AlignedBox3d keptBox() const;
  /// Copies of @p tile's leaves (a coarser leaf contributes the tile's part).
  std::vector<Leaf> tileLeaves(const TileIndex& tile) const;
  /// Deletes @p tile's leaves; costs what the tile holds. Returns how many went.
  size_t dropTile(const TileIndex& tile);
  /// Merges eight sibling leaves of one value into their parent, bottom up,
  /// inside @p tile (octomap's prune: every cell keeps its value, the map
  /// takes less memory; clamped free space mostly goes from eight leaves to
  /// one). Costs what the tile holds. Returns how many nodes became leaves.
  size_t mergeEqualLeaves(const TileIndex& tile);
  /// mergeEqualLeaves() in steps of one part at a time: the keys of
  /// @p tile's parts (AccumulatingOcTree::kPartDepth nodes) that have
  /// children, for mergePart(); then mergeTileAbove() merges what lies
  /// between the parts and the tile. The steps in turn, with nothing fused
  /// between them, give mergeEqualLeaves()' tree. The parts are those the
  /// tile would have with the fusion's cache written back, in the tree's
  /// depth-first order, but nothing is written back: each step writes back
  /// its own part.
  std::vector<octomap::OcTreeKey> partsToMerge(const TileIndex& tile) const;
  /// Merges the equal leaves below one part of partsToMerge(); a part gone
  /// since (a prune, a dropped or cleared tile) merges nothing, so a queue
  /// of parts stays valid whatever happens to the tree. Returns how many
  /// nodes became leaves.
  size_t mergePart(const octomap::OcTreeKey& part);
  /// Merges @p tile's nodes above its parts (depths kTileDepth to kPartDepth - 1).
  /// Of the fusion's blocks with changes the tree has not taken, it writes
  /// back only those below a node about to merge (which then merges only if
  /// it still can); the others wait for their turn. The same nodes merge as
  /// with the whole tile written back first.
  size_t mergeTileAbove(const TileIndex& tile);
  /// The fusion's blocks whose changes the tree has not taken yet (fusion_cache.h).
  size_t unwrittenBlocks() const;
  /// Sets leaves, clamped, in tiles that hold nothing (a tile back from disk).
  void insertLeaves(const std::vector<Leaf>& leaves);
  /// The tiles changed since the last call (by updates, clearBox, or leaves
  /// prune() dropped; not the tiles dropTile() removed): every tile after a load.
  std::vector<TileIndex> takeDirtyTiles();

  /// Writes <directory>/<base_name>.bt and .ot, each through a temporary file
  /// that is synced to disk and then renamed into place (writeOcTree), so a
  /// crash or a full disk never leaves a half-written map.
  /// @return the two paths. @throws std::runtime_error naming the file and the
  /// reason (e.g. "No space left on device"); the previous file then stays.
  std::vector<std::string> save(const std::string& directory, const std::string& base_name) const;

 private:
  struct Fusion;  // the workers that write the cache back
  void applyThresholds();
  /// The fusion's workers and their node counters; null when it runs on the calling thread.
  WorkerPool* pool() const;
  std::vector<std::unique_ptr<AccumulatingOcTree>>* counters() const;
  /// The cache's changes into the tree: all of them, or the blocks that the
  /// keys [lo, hi] overlap (what a reader of that box needs).
  void writeBack() const;
  void writeBack(const octomap::OcTreeKey& lo, const octomap::OcTreeKey& hi) const;
  /// Adds the blocks of @p edge_cells (kBlockCells, or kTileCells for tiles) that the leaf of
  /// @p key at @p depth spans to @p blocks (packed).
  void insertBlocksOf(const octomap::OcTreeKey& key, unsigned depth, std::unordered_set<uint64_t>* blocks,
                      int edge_cells = kBlockCells) const;

  MapAccumulatorConfig config_;
  std::unique_ptr<AccumulatingOcTree> tree_;
  /// Box of everything the map may hold (the updates' boxes, a loaded map's
  /// bounds), cut to the extent by prune() [m].
  Eigen::AlignedBox3d W_extent_;
  std::vector<Eigen::Vector3d> W_recent_origins_;  ///< ring of the last kPruneOrigins sensor origins
  size_t next_origin_ = 0;                         ///< where the next one goes in the ring
  size_t updates_ = 0;
  mutable bool inner_stale_ = false;             ///< inner nodes lag the leaves until tree() is called
  std::unordered_set<uint64_t> changed_blocks_;  ///< packed BlockIndex of the blocks changed
  std::unordered_set<uint64_t> dirty_tiles_;     ///< packed TileIndex of the tiles changed
  bool all_dirty_ = false;                       ///< every tile changed (load)
  bool all_changed_ = true;                      ///< the whole map changed (reset, load)
  std::unique_ptr<Fusion> fusion_;               ///< null: write-backs on the calling thread
  /// The updates' cells in front of the tree (fusion_cache.h); every reader
  /// of the tree writes it back first, hence mutable.
  std::unique_ptr<FusionCache> cache_;
  std::vector<Eigen::Vector3i> touched_blocks_;  ///< integrate()'s blocks, kept for their memory
  /// Recording class changes: the changes since the last take; null: not recording.
  std::unique_ptr<ClassChangeLog> class_log_;
  bool classes_all_ = false;  ///< recording, and the map changed otherwise than by integrate()
  /// The regions of class changes since the last take (recording, not all).
  std::vector<CellBox> class_regions_;
  /// The map changed otherwise than by integrate(): the class changes give way to all.
  void classesChangedEverywhere();
  /// The map changed otherwise than by integrate() inside @p cells only.
  void classesChangedIn(const CellBox& cells);
  /// prune()'s regions: the complement of the kept cells @p kept (six slabs),
  /// and the boxes of dropped leaves that reach into it.
  void classesChangedOutside(const CellBox& kept, const std::vector<CellBox>& dropped_inside);
  /// The log the fusion records into; null when not recording, or when all is due anyway.
  ClassChangeLog* recordingLog() { return classes_all_ ? nullptr : class_log_.get(); }
};

}  // namespace stereo_occupancy
