#include "stereo_occupancy/map_accumulator.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_map>

#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/fusion_cache.h"
#include "stereo_occupancy/octomap_io.h"

namespace stereo_occupancy {

bool MapAccumulatorConfig::isValid(std::string* why) const {
  if (!parametersInRange(*this, why)) return false;
  if (!(occupancy_threshold_prob > clamping_min_prob && occupancy_threshold_prob < clamping_max_prob)) {
    if (why) *why = "occupancy_threshold_prob must lie between clamping_min_prob and clamping_max_prob";
    return false;
  }
  return true;
}

/// The workers that add an update into the cache and write its blocks into the tree.
struct MapAccumulator::Fusion {
  explicit Fusion(unsigned threads) : pool(threads) {}
  WorkerPool pool;
  AccumulatingOcTree::WorkerCounters counters;
};

MapAccumulator::MapAccumulator(const MapAccumulatorConfig& config) : config_(config) {
  std::string why;
  if (!config_.isValid(&why)) throw std::invalid_argument(why);
  const unsigned threads = config_.threads == 0 ? WorkerPool::defaultThreads() : static_cast<unsigned>(config_.threads);
  if (threads > 1) fusion_ = std::make_unique<Fusion>(threads);
  cache_ = std::make_unique<FusionCache>();
  reset();
}

MapAccumulator::~MapAccumulator() = default;

WorkerPool* MapAccumulator::pool() const { return fusion_ ? &fusion_->pool : nullptr; }

AccumulatingOcTree::WorkerCounters* MapAccumulator::counters() const { return fusion_ ? &fusion_->counters : nullptr; }

void MapAccumulator::writeBack() const {
  const size_t cells = cache_->writeBack(tree_.get(), pool(), counters());
  inner_stale_ = inner_stale_ || cells > 0;
}

void MapAccumulator::writeBack(const octomap::OcTreeKey& lo, const octomap::OcTreeKey& hi) const {
  inner_stale_ = cache_->writeBack(tree_.get(), lo, hi) > 0 || inner_stale_;
}

const octomap::OcTree& MapAccumulator::tree() const {
  writeBack();
  // Inner nodes are brought up to date only when someone looks: a full pass
  // over the tree per update would cost more than the update as the map grows.
  if (inner_stale_) {
    tree_->updateInnerOccupancy();
    inner_stale_ = false;
  }
  return *tree_;
}

const octomap::OcTree& MapAccumulator::leafTree() const {
  writeBack();
  return *tree_;
}

const octomap::OcTree& MapAccumulator::leafTree(const CellBox& cells) const {
  octomap::OcTreeKey lo, hi;
  if (!keysOfCells(cells, static_cast<int>(tree_->coordToKey(0.0)), &lo, &hi)) return *tree_;
  inner_stale_ = cache_->writeBack(tree_.get(), lo, hi, pool(), counters()) > 0 || inner_stale_;
  return *tree_;
}

void MapAccumulator::applyThresholds() {
  tree_->setClampingThresMin(config_.clamping_min_prob);
  tree_->setClampingThresMax(config_.clamping_max_prob);
  tree_->setOccupancyThres(config_.occupancy_threshold_prob);
}

namespace {

/// A block index packed into 64 bits (21 bits per axis, offset to be >= 0).
constexpr int kPackBits = 21;
constexpr int64_t kPackOffset = int64_t{1} << (kPackBits - 1);
uint64_t packBlock(const Eigen::Vector3i& b) {
  const uint64_t mask = (uint64_t{1} << kPackBits) - 1;
  return ((static_cast<uint64_t>(b.x() + kPackOffset) & mask) << (2 * kPackBits)) |
         ((static_cast<uint64_t>(b.y() + kPackOffset) & mask) << kPackBits) |
         (static_cast<uint64_t>(b.z() + kPackOffset) & mask);
}
Eigen::Vector3i unpackBlock(uint64_t p) {
  const uint64_t mask = (uint64_t{1} << kPackBits) - 1;
  return Eigen::Vector3i(static_cast<int>(static_cast<int64_t>((p >> (2 * kPackBits)) & mask) - kPackOffset),
                         static_cast<int>(static_cast<int64_t>((p >> kPackBits) & mask) - kPackOffset),
                         static_cast<int>(static_cast<int64_t>(p & mask) - kPackOffset));
}
/// floor(g / n) for negative g too.
int floorDiv(int g, int n) { return g >= 0 ? g / n : -((-g + n - 1) / n); }
int blockOf(int g) { return floorDiv(g, MapAccumulator::kBlockCells); }
int tileOfBlock(int b) { return floorDiv(b, MapAccumulator::kTileCells / MapAccumulator::kBlockCells); }
/// The packed TileIndex of the tile that block @p b lies in.
uint64_t packedTileOf(const Eigen::Vector3i& b) {
  return packBlock(Eigen::Vector3i(tileOfBlock(b.x()), tileOfBlock(b.y()), tileOfBlock(b.z())));
}
/// The global cells of the leaf of @p key at @p depth in a tree of
/// @p tree_depth whose key @p offset is global cell 0.
CellBox leafCells(const octomap::OcTreeKey& key, unsigned depth, unsigned tree_depth, int offset) {
  const int side = 1 << (tree_depth - depth);
  Eigen::Vector3i first;
  for (int a = 0; a < 3; ++a) first[a] = (static_cast<int>(key[a]) & ~(side - 1)) - offset;
  return CellBox(first, first + Eigen::Vector3i::Constant(side - 1));
}

}  // namespace

void MapAccumulator::insertBlocksOf(const octomap::OcTreeKey& key, unsigned depth, std::unordered_set<uint64_t>* blocks,
                                    int edge_cells) const {
  // A coarse leaf: each block it spans.
  const int offset = static_cast<int>(tree_->coordToKey(0.0));
  const int side = 1 << (tree_->getTreeDepth() - depth);
  const int mask = ~(side - 1);  // the leaf's lowest key
  const int step = std::min(side, edge_cells);
  for (int dz = 0; dz < side; dz += step)
    for (int dy = 0; dy < side; dy += step)
      for (int dx = 0; dx < side; dx += step)
        blocks->insert(packBlock(Eigen::Vector3i(floorDiv((key[0] & mask) + dx - offset, edge_cells),
                                                 floorDiv((key[1] & mask) + dy - offset, edge_cells),
                                                 floorDiv((key[2] & mask) + dz - offset, edge_cells))));
}

std::vector<MapAccumulator::BlockIndex> MapAccumulator::takeChangedBlocks(bool* all) {
  *all = all_changed_;
  std::vector<BlockIndex> blocks;
  if (all_changed_) {
    std::unordered_set<uint64_t> seen;  // every block that holds a leaf
    for (auto it = tree().begin_leafs(), end = tree().end_leafs(); it != end; ++it)
      insertBlocksOf(it.getKey(), it.getDepth(), &seen);
    for (uint64_t p : seen) blocks.push_back(unpackBlock(p));
  } else {
    for (uint64_t p : changed_blocks_) blocks.push_back(unpackBlock(p));
  }
  changed_blocks_.clear();
  all_changed_ = false;
  return blocks;
}

void MapAccumulator::recordClassChanges(bool on) {
  if (!on) {
    class_log_.reset();
    classes_all_ = false;
    class_regions_.clear();
    return;
  }
  if (class_log_) return;
  class_log_ = std::make_unique<ClassChangeLog>();
  class_log_->max_changes = kMaxClassChanges;
  classes_all_ = true;  // the caller has seen nothing yet
}

std::vector<CellClassChange> MapAccumulator::takeClassChanges(bool* all, std::vector<CellBox>* regions) {
  std::vector<CellClassChange> changes;
  *all = false;
  regions->clear();
  if (!class_log_) return changes;
  *all = classes_all_;
  if (!classes_all_) {
    changes.swap(class_log_->changes);
    regions->swap(class_regions_);
  }
  class_log_->changes.clear();
  class_regions_.clear();
  classes_all_ = false;
  return changes;
}

std::vector<CellClassChange> MapAccumulator::takeClassChanges(bool* all) {
  std::vector<CellBox> regions;
  std::vector<CellClassChange> changes = takeClassChanges(all, &regions);
  if (regions.empty()) return changes;
  *all = true;
  return {};
}

void MapAccumulator::classesChangedEverywhere() {
  if (!class_log_) return;
  classes_all_ = true;
  class_log_->changes.clear();
  class_log_->overflowed = false;
  class_regions_.clear();
}

void MapAccumulator::classesChangedIn(const CellBox& cells) {
  if (!class_log_ || classes_all_ || cells.isEmpty()) return;
  if (class_regions_.size() >= kMaxClassRegions) return classesChangedEverywhere();
  class_regions_.push_back(cells);
}

void MapAccumulator::classesChangedOutside(const CellBox& kept, const std::vector<CellBox>& dropped_inside) {
  if (kept.isEmpty()) return classesChangedEverywhere();
  // The key range's cells minus the kept box: below and above it along x,
  // then along y within its x range, then along z within its x and y ranges.
  const int offset = static_cast<int>(tree_->coordToKey(0.0));
  CellBox rest(Eigen::Vector3i::Constant(-offset), Eigen::Vector3i::Constant(offset - 1));
  for (int a = 0; a < 3; ++a) {
    CellBox below = rest, above = rest;
    below.max()[a] = kept.min()[a] - 1;
    above.min()[a] = kept.max()[a] + 1;
    classesChangedIn(below);
    classesChangedIn(above);
    rest.min()[a] = std::max(rest.min()[a], kept.min()[a]);
    rest.max()[a] = std::min(rest.max()[a], kept.max()[a]);
  }
  for (const CellBox& leaf : dropped_inside) classesChangedIn(leaf);
}

void MapAccumulator::reset() {
  classesChangedEverywhere();
  all_changed_ = true;
  changed_blocks_.clear();
  all_dirty_ = false;
  dirty_tiles_.clear();
  inner_stale_ = false;
  cache_->clear();
  tree_ = std::make_unique<AccumulatingOcTree>(config_.resolution_m);
  applyThresholds();
  updates_ = 0;
  W_recent_origins_.clear();
  next_origin_ = 0;
  W_extent_.setEmpty();
}

void MapAccumulator::load(const std::string& path) {
  const std::unique_ptr<octomap::OcTree> file = readOcTreeFile(path);
  if (std::abs(file->getResolution() - config_.resolution_m) > 1e-9 * config_.resolution_m)
    throw std::runtime_error("'" + path + "' has " + std::to_string(file->getResolution()) + " m cells, the map " +
                             std::to_string(config_.resolution_m) + " m");
  auto loaded = std::make_unique<AccumulatingOcTree>(config_.resolution_m);
  loaded->setClampingThresMin(config_.clamping_min_prob);
  loaded->setClampingThresMax(config_.clamping_max_prob);
  const float lo = loaded->getClampingThresMinLog(), hi = loaded->getClampingThresMaxLog();
  for (auto it = file->begin_leafs(), end = file->end_leafs(); it != end; ++it)
    loaded->setLeaf(it.getKey(), it.getDepth(), std::clamp(it->getLogOdds(), lo, hi));
  loaded->updateInnerOccupancy();
  reset();
  if (loaded->size() > 0) {
    double x0, y0, z0, x1, y1, z1;
    loaded->getMetricMin(x0, y0, z0);
    loaded->getMetricMax(x1, y1, z1);
    W_extent_ = Eigen::AlignedBox3d(Eigen::Vector3d(x0, y0, z0), Eigen::Vector3d(x1, y1, z1));
  }
  tree_ = std::move(loaded);
  applyThresholds();
  all_dirty_ = true;
  classesChangedEverywhere();
}

size_t MapAccumulator::clearBox(const Eigen::Vector3d& W_min, const Eigen::Vector3d& W_max) {
  tree();  // inner nodes up to date: the box's iterator skips free subtrees by them
  const octomap::point3d lo(static_cast<float>(W_min.x()), static_cast<float>(W_min.y()),
                            static_cast<float>(W_min.z()));
  const octomap::point3d hi(static_cast<float>(W_max.x()), static_cast<float>(W_max.y()),
                            static_cast<float>(W_max.z()));
  octomap::OcTreeKey key_lo, key_hi;
  if (!tree_->coordToKeyChecked(lo, key_lo) || !tree_->coordToKeyChecked(hi, key_hi)) {
    // Clamp the box to the key range instead of giving up on it.
    const double edge = tree_->getNodeSize(0) / 2.0 - config_.resolution_m;
    const Eigen::Vector3d a = W_min.cwiseMax(-edge).cwiseMin(edge), b = W_max.cwiseMax(-edge).cwiseMin(edge);
    key_lo = tree_->coordToKey(a.x(), a.y(), a.z());
    key_hi = tree_->coordToKey(b.x(), b.y(), b.z());
  }
  // The occupied leaves' cells inside the box; a pruned (coarse) leaf
  // contributes only the cells the box holds.
  std::vector<octomap::OcTreeKey> cells;
  const unsigned depth = tree_->getTreeDepth();
  for (auto it = tree_->begin_leafs_bbx(key_lo, key_hi), end = tree_->end_leafs_bbx(); it != end; ++it) {
    if (!tree_->isNodeOccupied(*it)) continue;
    // The part of the leaf that the box holds, per axis [from, to].
    const octomap::OcTreeKey first = it.getIndexKey();  // the leaf's lowest key
    const unsigned side = 1u << (depth - it.getDepth());
    unsigned from[3], to[3];
    for (int a = 0; a < 3; ++a) {
      from[a] = std::max<unsigned>(first[a], key_lo[a]);
      to[a] = std::min<unsigned>(first[a] + side - 1, key_hi[a]);
    }
    for (unsigned z = from[2]; z <= to[2]; ++z)
      for (unsigned y = from[1]; y <= to[1]; ++y)
        for (unsigned x = from[0]; x <= to[0]; ++x)
          cells.emplace_back(static_cast<octomap::key_type>(x), static_cast<octomap::key_type>(y),
                             static_cast<octomap::key_type>(z));
  }
  const float cleared = tree_->getClampingThresMinLog();
  const int offset = static_cast<int>(tree_->coordToKey(0.0));
  if (!cells.empty()) cache_->drop(key_lo, key_hi);  // tree() wrote them back
  for (const octomap::OcTreeKey& k : cells) {
    tree_->setNodeValue(k, cleared, /*lazy_eval=*/true);
    const Eigen::Vector3i b(blockOf(k[0] - offset), blockOf(k[1] - offset), blockOf(k[2] - offset));
    if (!all_changed_) changed_blocks_.insert(packBlock(b));  // the outputs redo these blocks only
    dirty_tiles_.insert(packedTileOf(b));
  }
  inner_stale_ = inner_stale_ || !cells.empty();
  if (!cells.empty()) {
    Eigen::Vector3i first, last;
    for (int a = 0; a < 3; ++a) {
      first[a] = key_lo[a] - offset;
      last[a] = key_hi[a] - offset;
    }
    classesChangedIn(CellBox(first, last));
  }
  return cells.size();
}

bool MapAccumulator::admits(const GridUpdateView& update, std::string* why) const {
  auto fail = [why](const std::string& text) {
    if (why) *why = text;
    return false;
  };
  if (!update.isConsistent(why)) return false;
  if (std::abs(update.resolution_m - config_.resolution_m) > 1e-9 * config_.resolution_m)
    return fail("update resolution " + std::to_string(update.resolution_m) + " m differs from the map's " +
                std::to_string(config_.resolution_m) + " m");
  const uint64_t cells = static_cast<uint64_t>(update.size.x()) * update.size.y() * update.size.z();
  if (cells > config_.max_update_cells)
    return fail("the update's box has " + std::to_string(cells) +
                " cells, more than max_update_cells = " + std::to_string(config_.max_update_cells));
  // Global index g is OcTree key g + offset, a 16-bit number.
  const int64_t offset = tree_->coordToKey(0.0), key_max = 2 * offset - 1;
  for (int a = 0; a < 3; ++a) {
    const int64_t first = int64_t{update.origin_index[a]} + offset, last = first + update.size[a] - 1;
    if (first < 0 || last > key_max)
      return fail("the update's box leaves the map's key range (" + std::to_string(-offset * config_.resolution_m) +
                  " .. " + std::to_string(offset * config_.resolution_m) + " m along each axis)");
  }
  const Eigen::Vector3d lo = update.origin_index.cast<double>() * config_.resolution_m;
  const Eigen::Vector3d hi = lo + update.size.cast<double>() * config_.resolution_m;
  const double margin_m = (hi - lo).maxCoeff() + config_.resolution_m;
  const Eigen::Vector3d outside = (lo - update.W_sensor_origin).cwiseMax(update.W_sensor_origin - hi).cwiseMax(0.0);
  if (outside.norm() > margin_m)
    return fail("the sensor origin lies " + std::to_string(outside.norm()) + " m from the update's box (at most " +
                std::to_string(margin_m) + " m)");
  return true;
}

bool MapAccumulator::integrate(const GridUpdateView& update, std::string* why) {
  static_assert(FusionCache::kEdge == kBlockCells, "the cache's blocks are the change-tracking blocks");
  if (!admits(update, why)) return false;
  // admits() put every cell inside the key range.
  size_t written = cache_->add(update, tree_.get(), static_cast<int>(tree_->coordToKey(0.0)), recordingLog(),
                               &touched_blocks_, pool(), counters());
  for (const Eigen::Vector3i& b : touched_blocks_) {
    if (!all_changed_) changed_blocks_.insert(packBlock(b));
    dirty_tiles_.insert(packedTileOf(b));
  }
  written += cache_->maintain(tree_.get(), pool(), counters());
  if (class_log_ && class_log_->overflowed) classesChangedEverywhere();  // too many to keep
  inner_stale_ = inner_stale_ || written > 0;
  if (W_recent_origins_.size() < kPruneOrigins) {
    W_recent_origins_.push_back(update.W_sensor_origin);
  } else {
    W_recent_origins_[next_origin_] = update.W_sensor_origin;
    next_origin_ = (next_origin_ + 1) % kPruneOrigins;
  }
  const Eigen::Vector3d W_lo = update.origin_index.cast<double>() * config_.resolution_m;
  W_extent_.extend(W_lo).extend(W_lo + update.size.cast<double>() * config_.resolution_m);
  ++updates_;
  return true;
}

size_t MapAccumulator::prune() {
  // The leaves are copied as they are: the inner nodes may stay stale (the
  // kept tree computes its own), so a prune that keeps everything costs nothing.
  if (config_.max_extent_m <= 0.0 || W_recent_origins_.empty()) return 0;
  Eigen::AlignedBox3d recent;
  for (const auto& p : W_recent_origins_) recent.extend(p);
  const Eigen::Array3d lo = recent.min().array() - config_.max_extent_m;
  const Eigen::Array3d hi = recent.max().array() + config_.max_extent_m;
  // Nothing to do until the map reaches a slack beyond the extent: each
  // prune rebuilds the tree, which must not happen at every update of a long flight.
  const double slack_m = kPruneSlack * config_.max_extent_m;
  if (W_extent_.isEmpty() ||
      ((W_extent_.min().array() >= lo - slack_m).all() && (W_extent_.max().array() <= hi + slack_m).all()))
    return 0;
  writeBack();
  W_extent_ = W_extent_.intersection(Eigen::AlignedBox3d(lo.matrix(), hi.matrix()));
  auto inside = [&](const octomap::OcTree::leaf_iterator& it) {
    const Eigen::Array3d p(it.getX(), it.getY(), it.getZ());
    return (p >= lo).all() && (p <= hi).all();
  };
  // The cells whose centres the kept box holds, one cell less on each side
  // (rounding): a dropped leaf inside them is a coarse one that reaches in.
  const int offset = static_cast<int>(tree_->coordToKey(0.0));
  const CellBox kept_cells((lo / config_.resolution_m - 0.5).ceil().cast<int>().matrix() + Eigen::Vector3i::Ones(),
                           (hi / config_.resolution_m - 0.5).floor().cast<int>().matrix() - Eigen::Vector3i::Ones());
  std::vector<CellBox> dropped_inside;
  // The dropped leaves' blocks and tiles change (the outputs delete them); the rest do not.
  size_t outside = 0;
  for (auto it = tree_->begin_leafs(), end = tree_->end_leafs(); it != end; ++it) {
    if (inside(it)) continue;
    ++outside;
    if (!all_changed_) insertBlocksOf(it.getKey(), it.getDepth(), &changed_blocks_);
    insertBlocksOf(it.getKey(), it.getDepth(), &dirty_tiles_, kTileCells);
    const CellBox cells = leafCells(it.getKey(), it.getDepth(), tree_->getTreeDepth(), offset);
    if (!cells.intersection(kept_cells).isEmpty()) dropped_inside.push_back(cells);
  }
  if (outside == 0) return 0;
  classesChangedOutside(kept_cells, dropped_inside);
  auto kept = std::make_unique<AccumulatingOcTree>(config_.resolution_m);
  for (auto it = tree_->begin_leafs(), end = tree_->end_leafs(); it != end; ++it)
    if (inside(it)) kept->setLeaf(it.getKey(), it.getDepth(), it->getLogOdds());
  kept->updateInnerOccupancy();
  tree_ = std::move(kept);
  applyThresholds();
  cache_->clear();  // its blocks may hold dropped cells
  return outside;
}

std::vector<std::string> MapAccumulator::save(const std::string& directory, const std::string& base_name) const {
  std::vector<std::string> paths = {directory + "/" + base_name + ".bt", directory + "/" + base_name + ".ot"};
  for (const auto& p : paths) writeOcTree(tree(), p);
  return paths;
}

namespace {
/// The lowest and highest key of @p tile along each axis.
void tileKeys(const MapAccumulator::TileIndex& tile, int offset, octomap::OcTreeKey* lo, octomap::OcTreeKey* hi) {
  for (int a = 0; a < 3; ++a) {
    (*lo)[a] = static_cast<octomap::key_type>(tile[a] * MapAccumulator::kTileCells + offset);
    (*hi)[a] = static_cast<octomap::key_type>((*lo)[a] + MapAccumulator::kTileCells - 1);
  }
}
/// The key range holds 2^kTileDepth tiles per axis, centred on 0.
bool tileInKeyRange(const MapAccumulator::TileIndex& tile) {
  constexpr int kHalf = (1 << MapAccumulator::kTileDepth) / 2;
  return (tile.array() >= -kHalf).all() && (tile.array() < kHalf).all();
}
}  // namespace

std::vector<MapAccumulator::TileIndex> MapAccumulator::tilesOf(const GridUpdateView& update) const {
  const Eigen::Vector3i lo = update.origin_index, hi = update.origin_index + update.size - Eigen::Vector3i::Ones();
  std::vector<TileIndex> tiles;
  for (int z = floorDiv(lo.z(), kTileCells); z <= floorDiv(hi.z(), kTileCells); ++z)
    for (int y = floorDiv(lo.y(), kTileCells); y <= floorDiv(hi.y(), kTileCells); ++y)
      for (int x = floorDiv(lo.x(), kTileCells); x <= floorDiv(hi.x(), kTileCells); ++x) tiles.emplace_back(x, y, z);
  return tiles;
}

std::vector<MapAccumulator::TileIndex> MapAccumulator::tiles() const {
  writeBack();
  const int offset = static_cast<int>(tree_->coordToKey(0.0));
  std::unordered_set<uint64_t> seen;
  // Leaves at most kTileDepth deep: the tile nodes, and coarser leaves that span several.
  for (auto it = tree_->begin_leafs(kTileDepth), end = tree_->end_leafs(); it != end; ++it) {
    const octomap::OcTreeKey first = it.getIndexKey();
    const int side = 1 << (tree_->getTreeDepth() - it.getDepth());
    for (int dz = 0; dz < side; dz += kTileCells)
      for (int dy = 0; dy < side; dy += kTileCells)
        for (int dx = 0; dx < side; dx += kTileCells)
          seen.insert(packBlock(Eigen::Vector3i(floorDiv(first[0] + dx - offset, kTileCells),
                                                floorDiv(first[1] + dy - offset, kTileCells),
                                                floorDiv(first[2] + dz - offset, kTileCells))));
  }
  std::vector<TileIndex> tiles;
  for (uint64_t p : seen) tiles.push_back(unpackBlock(p));
  return tiles;
}

Eigen::AlignedBox3d MapAccumulator::tileBox(const TileIndex& tile) const {
  const Eigen::Vector3d lo = tile.cast<double>() * (kTileCells * config_.resolution_m);
  return Eigen::AlignedBox3d(lo, lo + Eigen::Vector3d::Constant(kTileCells * config_.resolution_m));
}

Eigen::AlignedBox3d MapAccumulator::keptBox() const {
  Eigen::AlignedBox3d recent;
  for (const auto& p : W_recent_origins_) recent.extend(p);
  if (recent.isEmpty()) return recent;
  const Eigen::Vector3d grow = Eigen::Vector3d::Constant(config_.max_extent_m);
  return Eigen::AlignedBox3d(recent.min() - grow, recent.max() + grow);
}

std::vector<MapAccumulator::Leaf> MapAccumulator::tileLeaves(const TileIndex& tile) const {
  std::vector<Leaf> leaves;
  if (!tileInKeyRange(tile)) return leaves;
  octomap::OcTreeKey lo, hi;
  tileKeys(tile, static_cast<int>(tree_->coordToKey(0.0)), &lo, &hi);
  writeBack(lo, hi);
  for (auto it = tree_->begin_leafs_bbx(lo, hi), end = tree_->end_leafs_bbx(); it != end; ++it) {
    if (!leafOverlaps(it, tree_->getTreeDepth(), lo, hi)) continue;
    Leaf leaf;
    // A leaf coarser than the tile gives the tile's part of it.
    leaf.key = it.getDepth() < kTileDepth ? lo : it.getKey();
    leaf.depth = static_cast<uint8_t>(std::max(it.getDepth(), kTileDepth));
    leaf.log_odds = it->getLogOdds();
    leaves.push_back(leaf);
  }
  return leaves;
}

size_t MapAccumulator::mergeEqualLeaves(const TileIndex& tile) {
  if (!tileInKeyRange(tile)) return 0;
  octomap::OcTreeKey lo, hi;
  tileKeys(tile, static_cast<int>(tree_->coordToKey(0.0)), &lo, &hi);
  writeBack(lo, hi);
  const size_t merged = tree_->pruneBelow(lo, kTileDepth);
  inner_stale_ = inner_stale_ || merged > 0;
  return merged;
}

namespace {
/// The position of the part @p key in the octree's depth-first walk (children
/// in index order, x the lowest bit): its bits interleaved, z y x from the top level down.
uint64_t depthFirstRank(const octomap::OcTreeKey& key) {
  uint64_t rank = 0;
  for (int b = 15; b >= 0; --b)
    rank = (rank << 3) | (((key[2] >> b) & 1u) << 2) | (((key[1] >> b) & 1u) << 1) | ((key[0] >> b) & 1u);
  return rank;
}
}  // namespace

std::vector<octomap::OcTreeKey> MapAccumulator::partsToMerge(const TileIndex& tile) const {
  if (!tileInKeyRange(tile)) return {};
  octomap::OcTreeKey lo, hi;
  tileKeys(tile, static_cast<int>(tree_->coordToKey(0.0)), &lo, &hi);
  std::vector<octomap::OcTreeKey> parts = tree_->innerNodesBelow(lo, kTileDepth, AccumulatingOcTree::kPartDepth);
  // A cached block with unwritten changes (a part: FusionCache::kEdge ==
  // kBlockCells) has children once written back, and a write-back makes no
  // other part's node inner: the parts a write-back of the tile would leave,
  // without the write-back, which all of a mission's dirty tiles at once
  // would make one update wait for.
  const std::vector<octomap::OcTreeKey> cached = cache_->unwrittenBlocks(lo, hi);
  if (cached.empty()) return parts;
  parts.insert(parts.end(), cached.begin(), cached.end());
  std::sort(parts.begin(), parts.end(), [](const octomap::OcTreeKey& a, const octomap::OcTreeKey& b) {
    return depthFirstRank(a) < depthFirstRank(b);
  });
  parts.erase(std::unique(parts.begin(), parts.end()), parts.end());
  return parts;
}

size_t MapAccumulator::mergePart(const octomap::OcTreeKey& part) {
  // A part is one of the cache's blocks.
  octomap::OcTreeKey lo = part, hi = part;
  for (int a = 0; a < 3; ++a) {
    lo[a] = static_cast<octomap::key_type>(part[a] & ~(FusionCache::kEdge - 1));
    hi[a] = static_cast<octomap::key_type>(lo[a] + FusionCache::kEdge - 1);
  }
  writeBack(lo, hi);
  const size_t merged = tree_->pruneBelow(part, AccumulatingOcTree::kPartDepth);
  inner_stale_ = inner_stale_ || merged > 0;
  return merged;
}

size_t MapAccumulator::mergeTileAbove(const TileIndex& tile) {
  if (!tileInKeyRange(tile)) return 0;
  octomap::OcTreeKey lo, hi;
  tileKeys(tile, static_cast<int>(tree_->coordToKey(0.0)), &lo, &hi);
  // Only the blocks below a node about to merge are written back; the
  // tile's other changed blocks, mostly below nodes that cannot merge, wait
  // for the cache's own write-backs (docs/performance.md).
  const std::vector<octomap::OcTreeKey> unwritten = cache_->unwrittenBlocks(lo, hi);
  const auto write_back_below = [&](const octomap::OcTreeKey& node_lo, unsigned depth) {
    const int edge = 1 << (tree_->getTreeDepth() - depth);
    octomap::OcTreeKey node_hi;
    for (int a = 0; a < 3; ++a) node_hi[a] = static_cast<octomap::key_type>(node_lo[a] + edge - 1);
    const auto below = [&](const octomap::OcTreeKey& block) {
      for (int a = 0; a < 3; ++a)
        if (block[a] < node_lo[a] || block[a] > node_hi[a]) return false;
      return true;
    };
    if (std::any_of(unwritten.begin(), unwritten.end(), below)) writeBack(node_lo, node_hi);
  };
  const size_t merged = tree_->pruneBelow(lo, kTileDepth, AccumulatingOcTree::kPartDepth - 1, write_back_below);
  inner_stale_ = inner_stale_ || merged > 0;
  return merged;
}

size_t MapAccumulator::unwrittenBlocks() const { return cache_->unwrittenBlocks(); }

size_t MapAccumulator::dropTile(const TileIndex& tile) {
  if (!tileInKeyRange(tile)) return 0;
  octomap::OcTreeKey lo, hi;
  tileKeys(tile, static_cast<int>(tree_->coordToKey(0.0)), &lo, &hi);
  writeBack(lo, hi);
  cache_->drop(lo, hi);
  size_t leaves = 0;
  for (auto it = tree_->begin_leafs_bbx(lo, hi), end = tree_->end_leafs_bbx(); it != end; ++it) {
    if (!leafOverlaps(it, tree_->getTreeDepth(), lo, hi)) continue;
    ++leaves;
    if (!all_changed_) insertBlocksOf(it.getKey(), it.getDepth(), &changed_blocks_);
  }
  if (leaves == 0) return 0;
  tree_->dropNode(lo, kTileDepth);
  inner_stale_ = true;
  const Eigen::Vector3i first = tile * kTileCells;
  classesChangedIn(CellBox(first, first + Eigen::Vector3i::Constant(kTileCells - 1)));
  dirty_tiles_.erase(packBlock(tile));
  return leaves;
}

void MapAccumulator::insertLeaves(const std::vector<Leaf>& leaves) {
  if (!leaves.empty()) {
    // The cache's blocks there hold the cells before these leaves.
    octomap::OcTreeKey key_lo(0xffff, 0xffff, 0xffff), key_hi(0, 0, 0);
    for (const Leaf& leaf : leaves) {
      const unsigned side = 1u << (tree_->getTreeDepth() - leaf.depth);
      for (int a = 0; a < 3; ++a) {
        const unsigned first = leaf.key[a] & ~(side - 1);
        key_lo[a] = static_cast<octomap::key_type>(std::min<unsigned>(key_lo[a], first));
        key_hi[a] = static_cast<octomap::key_type>(std::max<unsigned>(key_hi[a], first + side - 1));
      }
    }
    writeBack(key_lo, key_hi);
    cache_->drop(key_lo, key_hi);
  }
  const float lo = tree_->getClampingThresMinLog(), hi = tree_->getClampingThresMaxLog();
  for (const Leaf& leaf : leaves) tree_->setLeaf(leaf.key, leaf.depth, std::clamp(leaf.log_odds, lo, hi));
  if (leaves.empty()) return;
  inner_stale_ = true;
  const int offset = static_cast<int>(tree_->coordToKey(0.0));
  CellBox cells;  // empty
  for (const Leaf& leaf : leaves) cells.extend(leafCells(leaf.key, leaf.depth, tree_->getTreeDepth(), offset));
  classesChangedIn(cells);
  if (all_changed_) return;
  for (const Leaf& leaf : leaves) insertBlocksOf(leaf.key, leaf.depth, &changed_blocks_);
}

std::vector<MapAccumulator::TileIndex> MapAccumulator::takeDirtyTiles() {
  std::vector<TileIndex> tiles;
  if (all_dirty_) {
    tiles = this->tiles();
  } else {
    for (uint64_t p : dirty_tiles_) tiles.push_back(unpackBlock(p));
  }
  dirty_tiles_.clear();
  all_dirty_ = false;
  return tiles;
}

}  // namespace stereo_occupancy
