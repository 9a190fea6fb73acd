#include "stereo_occupancy/store/mission_map.h"

#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/octomap_io.h"
#include "tile_tree_writer.h"

namespace stereo_occupancy {

MissionMap::MissionMap(const MapAccumulatorConfig& config) : live_(config) {}

void MissionMap::attachStore(std::shared_ptr<TileStore> store) {
  if (store && std::abs(store->resolution() - live_.config().resolution_m) > 1e-9 * live_.config().resolution_m)
    throw std::invalid_argument("the tile database has " + std::to_string(store->resolution()) + " m cells, the map " +
                                std::to_string(live_.config().resolution_m) + " m");
  store_ = std::move(store);
  resident_.clear();
  unsaved_.clear();
  for (const TileIndex& t : live_.tiles()) {
    resident_.insert(TileStore::pack(t));
    unsaved_.insert(TileStore::pack(t));
  }
}

void MissionMap::makeResident(const TileIndex& tile) {
  if (!resident_.insert(TileStore::pack(tile)).second) return;
  std::vector<MapAccumulator::Leaf> leaves;
  try {
    if (store_->get(tile, &leaves)) live_.insertLeaves(leaves);
  } catch (const std::runtime_error& e) {
    // A row damaged since the store opened: the tile starts empty, the row is kept aside.
    store_->setAside(tile, e.what());
  }
}

bool MissionMap::integrate(const GridUpdateView& update, std::string* why) {
  if (store_) {
    if (!live_.admits(update, why)) return false;  // bounds the box before its tiles are asked for
    for (const TileIndex& t : live_.tilesOf(update)) makeResident(t);
  }
  if (!live_.integrate(update, why)) return false;
  ++updates_since_maintain_;
  return true;
}

MaintainResult MissionMap::maintain(MergeTiming merges) {
  MaintainResult result;
  collectDirtyTiles();
  if (!store_) {
    result.leaves_dropped = live_.prune();
  } else {
    const Eigen::AlignedBox3d kept = window();
    if (!kept.isEmpty() && live_.config().max_extent_m > 0.0) {
      const std::vector<uint64_t> resident(resident_.begin(), resident_.end());
      for (uint64_t key : resident)
        if (!kept.intersects(live_.tileBox(TileStore::unpack(key)))) storeTile(key, &result);
    }
  }
  finishQueuedMerges(&result);
  // Merges of an earlier queue's steps, not yet counted for the trim.
  const bool steps_merged = spread_merged_ > 0;
  spread_merged_ = 0;
  if (merges == MergeTiming::kSpread && live_.config().compress_map)
    queueChangedTiles();
  else
    mergeChangedTiles(&result);
  freed_memory_ = freed_memory_ || (store_ && (result.tiles_stored > 0 || result.nodes_merged > 0 || steps_merged));
  updates_since_maintain_ = 0;
  return result;
}

void MissionMap::queueChangedTiles() {
  size_t parts = 0;
  for (uint64_t key : unmerged_) {
    QueuedMerge q;
    q.tile = key;
    q.parts = live_.partsToMerge(TileStore::unpack(key));
    parts += q.parts.size();
    queued_merges_.push_back(std::move(q));
  }
  unmerged_.clear();
  merge_steps_ = std::max(kMergeSteps, updates_since_maintain_ / kMergeShare);
  parts_per_step_ = std::max<size_t>(1, (parts + merge_steps_ - 1) / merge_steps_);
}

MaintainResult MissionMap::mergeStep() {
  MaintainResult result;
  result.nodes_merged = mergeQueued(parts_per_step_);
  spread_merged_ += result.nodes_merged;
  if (queued_merges_.empty()) {  // the last step: one trim for the whole queue
    freed_memory_ = freed_memory_ || (store_ && spread_merged_ > 0);
    spread_merged_ = 0;
  }
  return result;
}

void MissionMap::finishQueuedMerges(MaintainResult* result) {
  result->nodes_merged += mergeQueued(std::numeric_limits<size_t>::max());
}

size_t MissionMap::mergeQueued(size_t parts) {
  size_t merged = 0;
  while (!queued_merges_.empty()) {
    QueuedMerge& q = queued_merges_.front();
    size_t n = 0;
    for (; q.next < q.parts.size() && parts > 0; ++q.next, --parts) n += live_.mergePart(q.parts[q.next]);
    const bool done = q.next == q.parts.size();
    if (done) n += live_.mergeTileAbove(TileStore::unpack(q.tile));
    if (n > 0) tileMerged(q.tile);
    merged += n;
    if (!done) break;  // the budget is spent
    queued_merges_.pop_front();
    if (parts == 0) break;
  }
  return merged;
}

void MissionMap::tileMerged(uint64_t key) {
  unpublished_.insert(key);          // the outputs encode the tile's new leaves
  if (store_) unsaved_.insert(key);  // a checkpoint may have stored it before the merges
}

bool MissionMap::unqueue(uint64_t key) {
  const auto it =
      std::find_if(queued_merges_.begin(), queued_merges_.end(), [&](const QueuedMerge& q) { return q.tile == key; });
  if (it == queued_merges_.end()) return false;
  queued_merges_.erase(it);
  return true;
}

Eigen::AlignedBox3d MissionMap::window() const {
  Eigen::AlignedBox3d kept = live_.keptBox();
  if (kept.isEmpty()) return kept;
  const double slack_m = MapAccumulator::kPruneSlack * live_.config().max_extent_m;
  return Eigen::AlignedBox3d(kept.min().array() - slack_m, kept.max().array() + slack_m);
}

void MissionMap::storeTile(uint64_t key, MaintainResult* result) {
  const TileIndex tile = TileStore::unpack(key);
  const bool queued = unqueue(key);  // the merges still queued for it are done here, in one go
  bool changed = unsaved_.erase(key) > 0;
  if ((unmerged_.erase(key) > 0 || queued) && live_.config().compress_map) {
    const size_t merged = live_.mergeEqualLeaves(tile);
    result->nodes_merged += merged;
    changed = changed || merged > 0;
  }
  // Unchanged since the store had it: its copy is current.
  if (changed) store_->put(tile, live_.tileLeaves(tile));
  if (live_.dropTile(tile) > 0) ++result->tiles_stored;
  resident_.erase(key);
  unmerged_.erase(key);
  unpublished_.insert(key);
}

void MissionMap::mergeChangedTiles(MaintainResult* result) {
  if (!live_.config().compress_map) {
    unmerged_.clear();
    return;
  }
  for (uint64_t key : unmerged_) {
    const size_t merged = live_.mergeEqualLeaves(TileStore::unpack(key));
    if (merged > 0) tileMerged(key);
    result->nodes_merged += merged;
  }
  unmerged_.clear();
}

bool MissionMap::takeFreedMemory() {
  const bool freed = freed_memory_;
  freed_memory_ = false;
  return freed;
}

void MissionMap::trimHeap() {
#ifdef __GLIBC__
  // A tile is ~10^5 small nodes freed at once; glibc keeps such pages
  // unless asked, so the process would grow as if the map had stayed.
  malloc_trim(0);
#endif
}

void MissionMap::collectDirtyTiles() {
  for (const TileIndex& t : live_.takeDirtyTiles()) {
    if (store_) unsaved_.insert(TileStore::pack(t));
    unpublished_.insert(TileStore::pack(t));
    unmerged_.insert(TileStore::pack(t));
  }
}

std::vector<TileContent> MissionMap::takeChangedTiles(bool whole_map, bool* whole_map_out) {
  collectDirtyTiles();
  *whole_map_out = whole_map || all_unpublished_;
  std::vector<TileIndex> tiles;
  if (*whole_map_out) {
    tiles = live_.tiles();
  } else {
    for (uint64_t key : unpublished_) tiles.push_back(TileStore::unpack(key));
  }
  unpublished_.clear();
  all_unpublished_ = false;
  std::vector<TileContent> changes(tiles.size());
  for (size_t i = 0; i < tiles.size(); ++i) {
    changes[i].tile = tiles[i];
    changes[i].leaves = live_.tileLeaves(tiles[i]);
  }
  return changes;
}

size_t MissionMap::checkpoint() {
  if (!store_) return 0;
  collectDirtyTiles();
  for (uint64_t key : unsaved_) store_->put(TileStore::unpack(key), live_.tileLeaves(TileStore::unpack(key)));
  const size_t queued = unsaved_.size();
  unsaved_.clear();
  return queued;
}

size_t MissionMap::clearBox(const Eigen::Vector3d& W_min, const Eigen::Vector3d& W_max) {
  size_t cleared = 0;
  if (store_) {
    const Eigen::AlignedBox3d box(W_min, W_max);
    const Eigen::AlignedBox3d kept = window();
    const bool unbounded = live_.config().max_extent_m <= 0.0;
    for (const TileIndex& tile : store_->tiles()) {
      const uint64_t key = TileStore::pack(tile);
      if (resident_.count(key) || !box.intersects(live_.tileBox(tile))) continue;
      makeResident(tile);
      cleared += live_.clearBox(W_min, W_max);  // costs the box's leaves in the live map
      collectDirtyTiles();
      // Back to the store unless the window holds it; before the first
      // update there is no window, and no tile stays for a clear alone.
      MaintainResult ignored;
      if (!unbounded && (kept.isEmpty() || !kept.intersects(live_.tileBox(tile)))) storeTile(key, &ignored);
    }
  }
  return cleared + live_.clearBox(W_min, W_max);
}

void MissionMap::reset() {
  live_.reset();
  unmerged_.clear();
  queued_merges_.clear();
  spread_merged_ = 0;
  updates_since_maintain_ = 0;
  merge_steps_ = 0;
  parts_per_step_ = 0;
  resident_.clear();
  unsaved_.clear();
  unpublished_.clear();
  all_unpublished_ = true;
  if (store_) store_->clear();
}

void MissionMap::load(const std::string& path) {
  live_.load(path);
  unmerged_.clear();
  queued_merges_.clear();
  spread_merged_ = 0;
  updates_since_maintain_ = 0;
  merge_steps_ = 0;
  parts_per_step_ = 0;
  resident_.clear();
  unsaved_.clear();
  unpublished_.clear();
  all_unpublished_ = true;
  if (!store_) return;
  for (const TileIndex& t : live_.tiles()) resident_.insert(TileStore::pack(t));
}

std::vector<std::string> MissionMap::saveWhole(const std::string& directory, const std::string& base_name) {
  if (!store_) return live_.save(directory, base_name);
  checkpoint();
  return saveStore(*store_, directory, base_name, live_.config().occupancy_threshold_prob);
}

std::vector<std::string> MissionMap::saveStore(TileStore& store, const std::string& directory,
                                               const std::string& base_name, double occupancy_threshold_prob) {
  if (!store.flush()) throw std::runtime_error("the tile database cannot be written: " + store.status().last_error);
  std::vector<std::string> paths = {directory + "/" + base_name + ".bt", directory + "/" + base_name + ".ot"};
  for (const auto& p : paths) writeStore(store, p, occupancy_threshold_prob);
  return paths;
}

namespace {

/// The subtree of a tile row's tile (@p bytes: TileStore::rowData) as
/// @p full asks: the row's part after the path, or its binary encoding.
void writeTileRow(const TileRow& row, const std::string& bytes, bool full, double resolution_m,
                  double occupancy_threshold_prob, std::ostream& out) {
  const size_t path_bytes = MapAccumulator::kTileDepth * TileStore::kRowNodeBytes;
  if (full) {  // the row is the tile's pre-order after its path
    out.write(bytes.data() + path_bytes, static_cast<std::streamsize>(bytes.size() - path_bytes));
    return;
  }
  if (row.nodes == 1) return;  // a leaf: its parent's bits said all
  const std::unique_ptr<octomap::OcTree> tile = readOcTreeData(bytes, OcTreeEncoding::kFull, resolution_m);
  tile->setOccupancyThres(occupancy_threshold_prob);
  tile->writeBinaryNode(out, tileNode(*tile));
}

}  // namespace

void MissionMap::writeStore(const TileStore& store, const std::string& path, double occupancy_threshold_prob) {
  const bool full = path.size() > 3 && path.compare(path.size() - 3, 3, ".ot") == 0;
  const bool binary = path.size() > 3 && path.compare(path.size() - 3, 3, ".bt") == 0;
  if (!full && !binary) throw std::runtime_error("'" + path + "': the map file must end in .ot or .bt");
  std::string bytes;  // the current tile's row
  const TileTreeWriter writer(store.rows(), full, thresholdLog(store.resolution(), occupancy_threshold_prob),
                              [&](const TileRow& row, std::ostream& out) {
                                if (!store.rowData(row.tile, &bytes))
                                  throw std::runtime_error("a tile row went missing");
                                writeTileRow(row, bytes, full, store.resolution(), occupancy_threshold_prob, out);
                              });
  writeFileAtomically(path, [&](std::ostream& out) {
    // As AbstractOcTree::write and writeBinaryConst write their headers.
    out << (full ? "# Octomap OcTree file" : "# Octomap OcTree binary file")
        << "\n# (feel free to add / change comments, but leave the first line as it is!)\n#\n";
    out << "id OcTree" << std::endl;
    out << "size " << writer.numNodes() << std::endl;
    out << "res " << store.resolution() << std::endl;
    out << "data" << std::endl;
    writer.writeData(out);
    return static_cast<bool>(out);
  });
}

std::unique_ptr<octomap::OcTree> MissionMap::assemble(const TileStore& store, const Eigen::AlignedBox3d& W_box) {
  auto tree = std::make_unique<AccumulatingOcTree>(store.resolution());
  const double tile_m = MapAccumulator::kTileCells * store.resolution();
  std::vector<MapAccumulator::Leaf> leaves;
  for (const TileIndex& t : store.tiles()) {
    const Eigen::Vector3d lo = t.cast<double>() * tile_m;
    if (!W_box.isEmpty() && !W_box.intersects(Eigen::AlignedBox3d(lo, lo + Eigen::Vector3d::Constant(tile_m))))
      continue;
    if (!store.get(t, &leaves)) continue;
    for (const auto& leaf : leaves) {
      if (!W_box.isEmpty()) {
        const octomap::point3d c = tree->keyToCoord(leaf.key, leaf.depth);
        if (!W_box.contains(Eigen::Vector3d(c.x(), c.y(), c.z()))) continue;
      }
      tree->setLeaf(leaf.key, leaf.depth, leaf.log_odds);
    }
  }
  tree->updateInnerOccupancy();
  return tree;
}

}  // namespace stereo_occupancy
