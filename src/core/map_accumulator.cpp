#include "stereo_occupancy/map_accumulator.h"

#include <Eigen/Geometry>

#include <cmath>
#include <stdexcept>

#include "stereo_occupancy/accumulating_octree.h"
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

MapAccumulator::MapAccumulator(const MapAccumulatorConfig& config) : config_(config) {
  std::string why;
  if (!config_.isValid(&why)) throw std::invalid_argument(why);
  reset();
}

MapAccumulator::~MapAccumulator() = default;

const octomap::OcTree& MapAccumulator::tree() const {
  // Inner nodes are brought up to date only when someone looks: a full pass
  // over the tree per update would cost more than the update as the map grows.
  if (inner_stale_) {
    tree_->updateInnerOccupancy();
    inner_stale_ = false;
  }
  return *tree_;
}

void MapAccumulator::applyThresholds() {
  tree_->setClampingThresMin(config_.clamping_min_prob);
  tree_->setClampingThresMax(config_.clamping_max_prob);
  tree_->setOccupancyThres(config_.occupancy_threshold_prob);
}

void MapAccumulator::reset() {
  inner_stale_ = false;
  tree_ = std::make_unique<AccumulatingOcTree>(config_.resolution_m);
  applyThresholds();
  updates_ = 0;
  W_recent_origins_.clear();
  next_origin_ = 0;
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
    return fail("the update's box has " + std::to_string(cells) + " cells, more than max_update_cells = " +
                std::to_string(config_.max_update_cells));
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
  if (!admits(update, why)) return false;
  const int offset = static_cast<int>(tree_->coordToKey(0.0));  // key of global index 0
  // Sibling leaves one after another (an octree node's eight cells): the
  // updater descends from the previous key's common ancestor, mostly the
  // same parent, and a new node's children are created together, so they
  // lie together in memory for the next update too. Over a flight this walk
  // is about a third faster than the storage order (docs/performance.md).
  // admits() put every block inside the key range.
  AccumulatingOcTree::LeafUpdater updater(tree_.get());
  update.forEachSiblingBlock([&](const Eigen::Vector3i& g, const float(&values)[8]) {
    const octomap::OcTreeKey first(static_cast<octomap::key_type>(g.x() + offset),
                                   static_cast<octomap::key_type>(g.y() + offset),
                                   static_cast<octomap::key_type>(g.z() + offset));
    updater.addSiblings(first, values);  // = updateNode(key, log_odds, lazy) per cell
  });
  inner_stale_ = true;
  if (W_recent_origins_.size() < kPruneOrigins) {
    W_recent_origins_.push_back(update.W_sensor_origin);
  } else {
    W_recent_origins_[next_origin_] = update.W_sensor_origin;
    next_origin_ = (next_origin_ + 1) % kPruneOrigins;
  }
  ++updates_;
  return true;
}

size_t MapAccumulator::prune() {
  if (config_.max_extent_m <= 0.0 || W_recent_origins_.empty()) return 0;
  tree();  // inner nodes up to date before the leaves are copied
  Eigen::AlignedBox3d recent;
  for (const auto& p : W_recent_origins_) recent.extend(p);
  const Eigen::Array3d lo = recent.min().array() - config_.max_extent_m;
  const Eigen::Array3d hi = recent.max().array() + config_.max_extent_m;
  auto inside = [&](const octomap::OcTree::leaf_iterator& it) {
    const Eigen::Array3d p(it.getX(), it.getY(), it.getZ());
    return (p >= lo).all() && (p <= hi).all();
  };
  size_t outside = 0;
  for (auto it = tree_->begin_leafs(), end = tree_->end_leafs(); it != end; ++it) outside += !inside(it);
  if (outside == 0) return 0;
  auto kept = std::make_unique<AccumulatingOcTree>(config_.resolution_m);
  for (auto it = tree_->begin_leafs(), end = tree_->end_leafs(); it != end; ++it)
    if (inside(it)) kept->setLeaf(it.getKey(), it.getDepth(), it->getLogOdds());
  kept->updateInnerOccupancy();
  tree_ = std::move(kept);
  applyThresholds();
  return outside;
}

std::vector<std::string> MapAccumulator::save(const std::string& directory, const std::string& base_name) const {
  std::vector<std::string> paths = {directory + "/" + base_name + ".bt", directory + "/" + base_name + ".ot"};
  for (const auto& p : paths) writeOcTree(tree(), p);
  return paths;
}

}  // namespace stereo_occupancy
