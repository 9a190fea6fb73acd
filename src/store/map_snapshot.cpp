#include "stereo_occupancy/store/map_snapshot.h"

#include <sstream>
#include <stdexcept>

#include "stereo_occupancy/accumulating_octree.h"
#include "tile_tree_writer.h"

namespace stereo_occupancy {

MapSnapshot::MapSnapshot(const MapSnapshotConfig& config) : config_(config) {}

void MapSnapshot::setKeepFull(bool keep) {
  if (keep && !keep_full_) needs_whole_map_ = true;
  if (!keep && keep_full_)
    for (auto& kv : tiles_) std::string().swap(kv.second.full);  // its memory back
  keep_full_ = keep;
}

MapSnapshot::Tile MapSnapshot::encode(const TileContent& content) const {
  // The tile alone in a tree: its nodes and values are the map's (a tile is
  // a subtree), the nodes above it a path of kTileDepth.
  AccumulatingOcTree tree(config_.resolution_m);
  tree.setOccupancyThres(config_.occupancy_threshold_prob);
  for (const auto& leaf : content.leaves) tree.setLeaf(leaf.key, leaf.depth, leaf.log_odds);
  tree.updateInnerOccupancy();
  const octomap::OcTreeNode* node = tileNode(tree);
  Tile tile;
  tile.row.tile = content.tile;
  tile.row.nodes = tree.calcNumNodes() - MapAccumulator::kTileDepth;
  tile.row.max_log_odds = node->getLogOdds();
  std::ostringstream binary;
  if (tile.row.nodes > 1) tree.writeBinaryNode(binary, node);  // a leaf: its parent's bits say all
  tile.binary = binary.str();
  if (keep_full_) {
    std::ostringstream full;
    tree.writeData(full);
    tile.full = full.str().substr(MapAccumulator::kTileDepth * TileStore::kRowNodeBytes);
  }
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it)
    if (tree.isNodeOccupied(*it)) tile.occupied.push_back(it.getCoordinate());
  tile.projected = projectedLeaves(tree, config_.projection_min_z_m, config_.projection_max_z_m);
  return tile;
}

void MapSnapshot::apply(const std::vector<TileContent>& changes, bool whole_map) {
  if (whole_map) {
    tiles_.clear();
    needs_whole_map_ = false;
  }
  for (const TileContent& content : changes) {
    const uint64_t key = TileStore::pack(content.tile);
    if (content.leaves.empty())
      tiles_.erase(key);
    else
      tiles_[key] = encode(content);
  }
}

void MapSnapshot::writeData(bool binary, std::ostream& out) const {
  if (!binary && !keep_full_) throw std::logic_error("MapSnapshot: the full data is not kept");
  std::vector<TileRow> rows;
  rows.reserve(tiles_.size());
  for (const auto& kv : tiles_) rows.push_back(kv.second.row);
  const TileTreeWriter writer(std::move(rows), !binary,
                              thresholdLog(config_.resolution_m, config_.occupancy_threshold_prob),
                              [this, binary](const TileRow& row, std::ostream& s) {
                                const Tile& tile = tiles_.at(TileStore::pack(row.tile));
                                const std::string& bytes = binary ? tile.binary : tile.full;
                                s.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
                              });
  writer.writeData(out);
}

size_t MapSnapshot::dataBytesBound(bool binary) const {
  // Each tile's bytes, and at most kTileDepth nodes above each tile (a
  // binary node is 2 bytes, a full one kRowNodeBytes).
  size_t bytes = tiles_.size() * MapAccumulator::kTileDepth * TileStore::kRowNodeBytes;
  for (const auto& kv : tiles_) bytes += (binary ? kv.second.binary : kv.second.full).size();
  return bytes;
}

size_t MapSnapshot::numOccupied() const {
  size_t n = 0;
  for (const auto& kv : tiles_) n += kv.second.occupied.size();
  return n;
}

void MapSnapshot::forEachOccupiedCentre(const std::function<void(const octomap::point3d&)>& f) const {
  for (const auto& kv : tiles_)
    for (const octomap::point3d& p : kv.second.occupied) f(p);
}

ProjectedMap MapSnapshot::projection() const {
  std::vector<const std::vector<ProjectedLeaf>*> sets;
  sets.reserve(tiles_.size());
  for (const auto& kv : tiles_) sets.push_back(&kv.second.projected);
  return composeProjection(config_.resolution_m, sets);
}

}  // namespace stereo_occupancy
