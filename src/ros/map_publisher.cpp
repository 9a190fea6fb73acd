#include "stereo_occupancy/ros/map_publisher.h"

#include <nav_msgs/OccupancyGrid.h>
#include <ros/console.h>
#include <sensor_msgs/PointCloud2.h>

#include <boost/make_shared.hpp>

#include <vector>

#include "stereo_occupancy/Octomap.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/ros/mapping_pipeline.h"

namespace stereo_occupancy {

namespace {
/// At most one error of a kind in this time [s].
constexpr double kErrorThrottleS = 5.0;

bool wanted(const ros::Publisher& pub) { return pub.getNumSubscribers() > 0; }
}  // namespace

bool MapPublisherConfig::isValid(std::string* why) const {
  if (!parametersInRange(*this, why)) return false;
  if (!(projection_min_z_m < projection_max_z_m)) {
    if (why) *why = "projection_min_z_m must be < projection_max_z_m";
    return false;
  }
  return true;
}

MapPublisher::MapPublisher(const MapPublisherConfig& config, const MapAccumulatorConfig& map, MapFusion* fusion,
                           std::mutex* fusion_mutex, const std::string& log_name)
    : config_(config), fusion_(fusion), fusion_mutex_(fusion_mutex), log_name_(log_name) {
  MapSnapshotConfig snapshot;
  snapshot.resolution_m = map.resolution_m;
  snapshot.occupancy_threshold_prob = map.occupancy_threshold_prob;
  snapshot.projection_min_z_m = config.projection_min_z_m;
  snapshot.projection_max_z_m = config.projection_max_z_m;
  snapshot_ = std::make_unique<MapSnapshot>(snapshot);
}

void MapPublisher::advertise(ros::NodeHandle& nh) {
  // octomap_server's names and types, latched as there. An output that had
  // no subscriber when the whole map went out holds nothing to latch: a new
  // subscriber makes the whole map due again (within full_map_period_s),
  // whatever the other outputs' subscribers got before.
  const ros::SubscriberStatusCallback whole_map_due = [this](const auto& pub) { wholeMapDue(pub); };
  const auto latched = [&](const std::string& topic, auto message) {
    using Message = decltype(message);
    return nh.advertise<Message>(topic, 1, whole_map_due, ros::SubscriberStatusCallback(), ros::VoidConstPtr(),
                                 /*latch=*/true);
  };
  octomap_pub_ = latched("octomap_binary", Octomap());
  octomap_full_pub_ = latched("octomap_full", Octomap());
  // Occupied and free cells a block at a time, only the blocks changed since
  // the last publish; a new subscriber gets the whole map first.
  const ros::SubscriberStatusCallback everything_due = [this](const auto& pub) { everythingDue(pub); };
  markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>("occupied_cells_vis_array", 10, everything_due);
  free_markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>("free_cells_vis_array", 10, everything_due);
  cloud_pub_ = latched("octomap_point_cloud_centers", sensor_msgs::PointCloud2());
  projected_pub_ = latched("projected_map", nav_msgs::OccupancyGrid());
  octomap_binary_srv_ = nh.advertiseService<GetOctomap::Request, GetOctomap::Response>(
      "octomap_binary", [this](GetOctomap::Request& q, GetOctomap::Response& r) { return getMap(true, q, r); });
  octomap_full_srv_ = nh.advertiseService<GetOctomap::Request, GetOctomap::Response>(
      "octomap_full", [this](GetOctomap::Request& q, GetOctomap::Response& r) { return getMap(false, q, r); });
  publish_timer_ =
      nh.createTimer(ros::Duration(1.0 / config_.publish_rate_hz), [this](const ros::TimerEvent&) { publish(); });
}

void MapPublisher::wholeMapDue(const ros::SingleSubscriberPublisher&) {
  std::lock_guard<std::mutex> lock(*fusion_mutex_);
  full_changed_ = true;
}

void MapPublisher::everythingDue(const ros::SingleSubscriberPublisher&) {
  std::lock_guard<std::mutex> lock(*fusion_mutex_);
  fusion_->markAllChanged();
  changed_since_publish_ = full_changed_ = true;
}

void MapPublisher::mapChanged() { changed_since_publish_ = full_changed_ = true; }

std_msgs::Header MapPublisher::mapHeader() const {
  std_msgs::Header header;
  header.frame_id = fusion_->frameId();
  header.stamp = fusion_->lastStamp();
  return header;
}

void MapPublisher::publish() {
  try {
    publishOutputs();
  } catch (const std::exception& e) {  // bad_alloc for a huge map: nothing may leave a callback
    ROS_ERROR_THROTTLE_NAMED(kErrorThrottleS, log_name_, "could not publish the map outputs: %s", e.what());
  }
}

void MapPublisher::publishOutputs() {
  // Each output is built only while someone listens: a marker array of a
  // large map costs more than many updates.
  const bool anyone = wanted(octomap_pub_) || wanted(octomap_full_pub_) || wanted(markers_pub_) ||
                      wanted(free_markers_pub_) || wanted(cloud_pub_) || wanted(projected_pub_);
  std::lock_guard<std::mutex> publishing(publish_mutex_);
  ChangedBlockMarkers markers;
  bool full_due = false;
  {
    std::lock_guard<std::mutex> lock(*fusion_mutex_);
    if (!anyone) {
      fusion_->markAllChanged();  // no changes kept for nobody: the next subscriber gets the whole map
      return;
    }
    if (fusion_->frameId().empty()) return;
    // The whole map at most every full_map_period_s, the changed blocks at
    // each publish: a large map's octree and cloud would cost more than its changes.
    const ros::WallTime now = ros::WallTime::now();
    full_due = full_changed_ && (last_full_publish_.isZero() || now < last_full_publish_ ||
                                 (now - last_full_publish_).toSec() >= config_.full_map_period_s);
    if (!changed_since_publish_ && !full_due) return;
    changed_since_publish_ = false;
    markers = changedBlockMarkers(fusion_->map().tree(), mapHeader());
    if (full_due) {
      full_changed_ = false;
      last_full_publish_ = now;
    }
  }
  // publish() serialises for subscribers in other processes: outside the
  // fusion lock. A failure here must not cost the whole map its turn.
  try {
    if (markers.occupied) markers_pub_.publish(markers.occupied);
    if (markers.free) free_markers_pub_.publish(markers.free);
  } catch (const std::exception& e) {
    ROS_ERROR_THROTTLE_NAMED(kErrorThrottleS, log_name_, "could not publish the changed blocks' markers: %s", e.what());
  }
  if (!full_due) return;
  publishWholeMap();
  // The whole map's messages and the snapshot's encoding freed tens of MB
  // of small blocks: back to the system now, not at the next eviction.
  MissionMap::trimHeap();
}

void MapPublisher::publishWholeMap() {
  if (!wanted(octomap_pub_) && !wanted(octomap_full_pub_) && !wanted(cloud_pub_) && !wanted(projected_pub_)) return;
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  snapshot_->setKeepFull(wanted(octomap_full_pub_));
  const std_msgs::Header header = refreshSnapshot();
  for (const bool binary : {true, false}) {
    const ros::Publisher& pub = binary ? octomap_pub_ : octomap_full_pub_;
    if (!wanted(pub)) continue;
    auto msg = boost::make_shared<Octomap>();
    toMsg(*snapshot_, binary, header, msg.get());
    pub.publish(msg);
  }
  if (wanted(cloud_pub_)) {
    auto msg = boost::make_shared<sensor_msgs::PointCloud2>();
    occupiedCellCloud(*snapshot_, header, msg.get());
    cloud_pub_.publish(msg);
  }
  if (wanted(projected_pub_)) {
    auto msg = boost::make_shared<nav_msgs::OccupancyGrid>();
    toMsg(snapshot_->projection(), header, msg.get());
    projected_pub_.publish(msg);
  }
}

std_msgs::Header MapPublisher::refreshSnapshot() {
  std::vector<TileContent> changes;
  bool whole_map = false;
  std_msgs::Header header;
  {
    std::lock_guard<std::mutex> lock(*fusion_mutex_);
    changes = fusion_->mission().takeChangedTiles(snapshot_->needsWholeMap(), &whole_map);
    header = mapHeader();
  }
  snapshot_->apply(changes, whole_map);
  return header;
}

MapPublisher::ChangedBlockMarkers MapPublisher::changedBlockMarkers(const octomap::OcTree& tree,
                                                                    const std_msgs::Header& header) {
  const bool free_wanted = config_.publish_free_space && wanted(free_markers_pub_);
  ChangedBlockMarkers markers;
  if (!wanted(markers_pub_) && !free_wanted) {
    fusion_->markAllChanged();  // nobody to send changes to: the next subscriber gets the whole map
    return markers;
  }
  // Both marker arrays from the one set of changed blocks.
  bool all = false;
  const std::vector<MapAccumulator::BlockIndex> blocks = fusion_->takeChangedBlocks(&all);
  if (!all && blocks.empty()) return markers;
  if (wanted(markers_pub_)) {
    markers.occupied = boost::make_shared<visualization_msgs::MarkerArray>();
    blockMarkers(tree, blocks, all, header, markers.occupied.get());
  }
  if (free_wanted) {
    markers.free = boost::make_shared<visualization_msgs::MarkerArray>();
    freeBlockMarkers(tree, blocks, all, header, markers.free.get());
  }
  return markers;
}

bool MapPublisher::getMap(bool binary, GetOctomap::Request&, GetOctomap::Response& response) {
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  try {
    if (!binary) snapshot_->setKeepFull(true);  // until a publish finds octomap_full without subscribers
    const std_msgs::Header header = refreshSnapshot();
    toMsg(*snapshot_, binary, header, &response.map);
  } catch (const std::exception& e) {  // nothing may leave a callback
    ROS_ERROR_NAMED(log_name_, "could not serialise the map for %s: %s", binary ? "octomap_binary" : "octomap_full",
                    e.what());
    return false;
  }
  return true;
}

}  // namespace stereo_occupancy
