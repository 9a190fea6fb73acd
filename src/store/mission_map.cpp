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
    if (live_.dropTile(tile) > 0) ++result.tiles_stored;
    resident_.erase(key);
  }
#ifdef __GLIBC__
  // A tile is ~10^5 small nodes freed at once; glibc keeps such pages
  // unless asked, so the process would grow as if the map had stayed.
  if (result.tiles_stored > 0) malloc_trim(0);
#endif
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
  return saveStore(*store_, directory, base_name, live_.config().occupancy_threshold_prob);
}

std::vector<std::string> MissionMap::saveStore(TileStore& store, const std::string& directory,
                                               const std::string& base_name, double occupancy_threshold_prob) {
  if (!store.flush())
    throw std::runtime_error("the tile database cannot be written: " + store.status().last_error);
  std::vector<std::string> paths = {directory + "/" + base_name + ".bt", directory + "/" + base_name + ".ot"};
  for (const auto& p : paths) writeStore(store, p, occupancy_threshold_prob);
  return paths;
}

namespace {

/// writeStore's walk: the octree's nodes above the tiles, in octomap's
/// pre-order, each tile's subtree from its row.
class StoreWriter {
 public:
  StoreWriter(const TileStore& store, bool full, double occupancy_threshold_prob)
      : store_(store), full_(full), rows_(store.rows()), threshold_prob_(occupancy_threshold_prob) {
    octomap::OcTree probe(store.resolution());  // the threshold as the tree keeps it
    probe.setOccupancyThres(occupancy_threshold_prob);
    threshold_log_ = probe.getOccupancyThresLog();
  }

  bool write(std::ostream& out) {
    // As AbstractOcTree::write and writeBinaryConst write their headers.
    out << (full_ ? "# Octomap OcTree file" : "# Octomap OcTree binary file")
        << "\n# (feel free to add / change comments, but leave the first line as it is!)\n#\n";
    out << "id OcTree" << std::endl;
    std::vector<size_t> all(rows_.size());
    for (size_t i = 0; i < all.size(); ++i) all[i] = i;
    out << "size " << (rows_.empty() ? 0 : countNodes(0, all)) << std::endl;
    out << "res " << store_.resolution() << std::endl;
    out << "data" << std::endl;
    if (!rows_.empty()) writeNode(0, all, out);
    return static_cast<bool>(out);
  }

 private:
  /// Child index (octomap::computeChildIdx) of @p row's tile at node depth @p depth.
  unsigned childOf(const TileRow& row, unsigned depth) const {
    unsigned idx = 0;
    for (int a = 0; a < 3; ++a) {
      const unsigned key = static_cast<unsigned>(row.tile[a] + (1 << MapAccumulator::kTileDepth) / 2);
      if (key & (1u << (MapAccumulator::kTileDepth - 1 - depth))) idx |= 1u << a;
    }
    return idx;
  }
  std::array<std::vector<size_t>, 8> split(unsigned depth, const std::vector<size_t>& rows) const {
    std::array<std::vector<size_t>, 8> children;
    for (size_t i : rows) children[childOf(rows_[i], depth)].push_back(i);
    return children;
  }
  size_t countNodes(unsigned depth, const std::vector<size_t>& rows) const {
    if (depth == MapAccumulator::kTileDepth) return rows_[rows.front()].nodes;
    size_t n = 1;
    for (const auto& child : split(depth, rows))
      if (!child.empty()) n += countNodes(depth + 1, child);
    return n;
  }
  void writeNode(unsigned depth, const std::vector<size_t>& rows, std::ostream& out) {
    if (depth == MapAccumulator::kTileDepth) return writeTile(rows_[rows.front()], out);
    const auto children = split(depth, rows);
    if (full_) {
      float value = -std::numeric_limits<float>::max();
      for (size_t i : rows) value = std::max(value, rows_[i].max_log_odds);
      out.write(reinterpret_cast<const char*>(&value), sizeof value);
      char bits = 0;
      for (unsigned c = 0; c < 8; ++c)
        if (!children[c].empty()) bits = static_cast<char>(bits | (1 << c));
      out.write(&bits, 1);
    } else {
      // OccupancyOcTreeBase::writeBinaryNode's two bits per child: 11 inner, 01 occupied, 10 free, 00 unknown.
      uint16_t bits = 0;
      for (unsigned c = 0; c < 8; ++c) {
        if (children[c].empty()) continue;
        const TileRow& first = rows_[children[c].front()];
        const bool leaf = depth + 1 == MapAccumulator::kTileDepth && first.nodes == 1;
        const unsigned code = !leaf ? 3u : first.max_log_odds >= threshold_log_ ? 2u : 1u;
        bits = static_cast<uint16_t>(bits | (code << (2 * c)));
      }
      const char bytes[2] = {static_cast<char>(bits & 0xff), static_cast<char>(bits >> 8)};
      out.write(bytes, 2);
    }
    for (const auto& child : children)
      if (!child.empty()) writeNode(depth + 1, child, out);
  }
  void writeTile(const TileRow& row, std::ostream& out) {
    if (!store_.rowData(row.tile, &bytes_)) throw std::runtime_error("a tile row went missing");
    const size_t path_bytes = MapAccumulator::kTileDepth * TileStore::kRowNodeBytes;
    if (full_) {  // the row is the tile's pre-order after its path
      out.write(bytes_.data() + path_bytes, static_cast<std::streamsize>(bytes_.size() - path_bytes));
      return;
    }
    if (row.nodes == 1) return;  // a leaf: its parent's bits said all
    octomap::OcTree tile(store_.resolution());
    tile.setOccupancyThres(threshold_prob_);
    std::istringstream in(bytes_);
    if (!tile.readData(in)) throw std::runtime_error("a tile row is not OcTree data");
    const octomap::OcTreeNode* node = tile.getRoot();
    for (unsigned d = 0; d < MapAccumulator::kTileDepth; ++d)
      for (unsigned c = 0; c < 8; ++c)
        if (tile.nodeChildExists(node, c)) {
          node = tile.getNodeChild(node, c);
          break;
        }
    tile.writeBinaryNode(out, node);
  }

  const TileStore& store_;
  bool full_;
  std::vector<TileRow> rows_;
  double threshold_prob_;
  float threshold_log_ = 0.0f;
  std::string bytes_;  ///< the current tile's row
};

}  // namespace

void MissionMap::writeStore(const TileStore& store, const std::string& path, double occupancy_threshold_prob) {
  const bool full = path.size() > 3 && path.compare(path.size() - 3, 3, ".ot") == 0;
  const bool binary = path.size() > 3 && path.compare(path.size() - 3, 3, ".bt") == 0;
  if (!full && !binary) throw std::runtime_error("'" + path + "': the map file must end in .ot or .bt");
  StoreWriter writer(store, full, occupancy_threshold_prob);
  writeFileAtomically(path, [&](std::ostream& out) { return writer.write(out); });
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
