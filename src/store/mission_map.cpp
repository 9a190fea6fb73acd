#include "stereo_occupancy/store/mission_map.h"

#include <cmath>
#include <stdexcept>

#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/octomap_io.h"

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
  if (store_->get(tile, &leaves)) live_.insertLeaves(leaves);
}

bool MissionMap::integrate(const GridUpdateView& update, std::string* why) {
  if (store_) {
    if (!live_.admits(update, why)) return false;  // bounds the box before its tiles are asked for
    for (const TileIndex& t : live_.tilesOf(update)) makeResident(t);
  }
  return live_.integrate(update, why);
}

MaintainResult MissionMap::maintain() {
  MaintainResult result;
  if (!store_) {
    result.leaves_dropped = live_.prune();
    return result;
  }
  Eigen::AlignedBox3d window = live_.keptBox();
  if (window.isEmpty() || live_.config().max_extent_m <= 0.0) return result;
  const double slack_m = MapAccumulator::kPruneSlack * live_.config().max_extent_m;
  window = Eigen::AlignedBox3d(window.min().array() - slack_m, window.max().array() + slack_m);
  for (const TileIndex& t : live_.takeDirtyTiles()) unsaved_.insert(TileStore::pack(t));
  const std::vector<uint64_t> resident(resident_.begin(), resident_.end());
  for (uint64_t key : resident) {
    const TileIndex tile = TileStore::unpack(key);
    if (window.intersects(live_.tileBox(tile))) continue;
    // Unchanged since the store had it: its copy is current.
    if (unsaved_.erase(key)) store_->put(tile, live_.tileLeaves(tile));
    live_.dropTile(tile);
    resident_.erase(key);
    ++result.tiles_stored;
  }
  return result;
}

size_t MissionMap::checkpoint() {
  if (!store_) return 0;
  for (const TileIndex& t : live_.takeDirtyTiles()) unsaved_.insert(TileStore::pack(t));
  for (uint64_t key : unsaved_) store_->put(TileStore::unpack(key), live_.tileLeaves(TileStore::unpack(key)));
  const size_t queued = unsaved_.size();
  unsaved_.clear();
  return queued;
}

void MissionMap::reset() {
  live_.reset();
  resident_.clear();
  unsaved_.clear();
  if (store_) store_->clear();
}

void MissionMap::load(const std::string& path) {
  live_.load(path);
  resident_.clear();
  unsaved_.clear();
  if (!store_) return;
  for (const TileIndex& t : live_.tiles()) resident_.insert(TileStore::pack(t));
}

std::vector<std::string> MissionMap::saveWhole(const std::string& directory, const std::string& base_name) {
  if (!store_) return live_.save(directory, base_name);
  checkpoint();
  return saveStore(*store_, directory, base_name);
}

std::vector<std::string> MissionMap::saveStore(TileStore& store, const std::string& directory,
                                               const std::string& base_name) {
  if (!store.flush())
    throw std::runtime_error("the tile database cannot be written: " + store.status().last_error);
  const std::unique_ptr<octomap::OcTree> tree = assemble(store, Eigen::AlignedBox3d());
  std::vector<std::string> paths = {directory + "/" + base_name + ".bt", directory + "/" + base_name + ".ot"};
  for (const auto& p : paths) writeOcTree(*tree, p);
  return paths;
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
