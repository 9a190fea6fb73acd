#include "stereo_occupancy/map_accumulator.h"

#include <cmath>
#include <stdexcept>

#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/octomap_io.h"

namespace stereo_occupancy {

bool MapAccumulatorConfig::isValid(std::string* why) const {
  auto fail = [why](const char* text) {
    if (why) *why = text;
    return false;
  };
  if (!(std::isfinite(resolution_m) && resolution_m >= 0.01 && resolution_m <= 10.0))
    return fail("resolution_m must be in [0.01, 10]");
  if (!(clamping_min_prob > 0.0 && clamping_min_prob < 0.5)) return fail("clamping_min_prob must be in (0, 0.5)");
  if (!(clamping_max_prob > 0.5 && clamping_max_prob < 1.0)) return fail("clamping_max_prob must be in (0.5, 1)");
  if (!(occupancy_threshold_prob > clamping_min_prob && occupancy_threshold_prob < clamping_max_prob))
    return fail("occupancy_threshold_prob must be in (clamping_min_prob, clamping_max_prob)");
  if (!(std::isfinite(max_extent_m) && max_extent_m >= 0.0)) return fail("max_extent_m must be finite and >= 0");
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
}

bool MapAccumulator::integrate(const GridUpdate& update, std::string* why) {
  if (!update.isConsistent(why)) return false;
  if (std::abs(update.resolution_m - config_.resolution_m) > 1e-9 * config_.resolution_m) {
    if (why)
      *why = "update resolution " + std::to_string(update.resolution_m) + " m differs from the map's " +
             std::to_string(config_.resolution_m) + " m";
    return false;
  }
  const int offset = static_cast<int>(tree_->coordToKey(0.0));  // key of global index 0
  // Sibling leaves one after another (an octree node's eight cells): the
  // updater descends from the previous key's common ancestor, mostly the
  // same parent, and a new node's children are created together, so they
  // lie together in memory for the next update too. Over a flight this walk
  // is about a third faster than the storage order (docs/performance.md).
  AccumulatingOcTree::LeafUpdater updater(tree_.get());
  update.forEachSiblingBlock([&](const Eigen::Vector3i& g, const float(&values)[8]) {
    // The block's first key; with it even and at most 65534 the block lies within OcTree's extent.
    const uint64_t kx = static_cast<uint64_t>(int64_t{g.x()} + offset);  // a negative key wraps to above 65535
    const uint64_t ky = static_cast<uint64_t>(int64_t{g.y()} + offset);
    const uint64_t kz = static_cast<uint64_t>(int64_t{g.z()} + offset);
    if ((kx | ky | kz) > 65535u) return;  // outside OcTree's extent (cells on its far side start at 65536)
    updater.addSiblings(octomap::OcTreeKey(static_cast<octomap::key_type>(kx), static_cast<octomap::key_type>(ky),
                                           static_cast<octomap::key_type>(kz)),
                        values);  // = updateNode(key, log_odds, lazy) per cell
  });
  inner_stale_ = true;
  W_last_origin_ = update.W_sensor_origin;
  ++updates_;
  return true;
}

size_t MapAccumulator::prune() {
  if (config_.max_extent_m <= 0.0) return 0;
  tree();  // inner nodes up to date before the leaves are copied
  const Eigen::Array3d lo = W_last_origin_.array() - config_.max_extent_m;
  const Eigen::Array3d hi = W_last_origin_.array() + config_.max_extent_m;
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
