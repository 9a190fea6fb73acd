// stereo_occupancy/OctomapAccumulator: occupancy updates -> one OctoMap,
// published for visualisation and saved on request.
//
// ROS glue only: the fusion is the core's MapAccumulator.

#include <diagnostic_updater/diagnostic_updater.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <std_srvs/Empty.h>
#include <std_srvs/Trigger.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <stdexcept>
#include <cstdio>
#include <memory>
#include <mutex>
#include <vector>

#include "stereo_occupancy/BoundingBoxQuery.h"
#include "stereo_occupancy/GetOctomap.h"
#include "stereo_occupancy/projected_map.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/ros/mapping_pipeline.h"
#include "stereo_occupancy/ros/parameters.h"
#include "stereo_occupancy/ros/processing_times.h"

namespace stereo_occupancy {

namespace {
/// At most one warning of a kind in this time [s].
constexpr double kWarnThrottleS = 5.0;
/// Without the mission's database, saves write the live map under
/// <map_name> + this, never over the mission's own files.
constexpr const char* kLiveOnlySuffix = "_live_only";
/// A failing periodic save repeats its error at most this often [s].
constexpr double kSaveErrorThrottleS = 60.0;
}  // namespace

class OctomapAccumulator : public nodelet::Nodelet {
 public:
  ~OctomapAccumulator() override;

 private:
  void onInit() override;
  void updateCallback(const ros::MessageEvent<const OccupancyUpdate>& event);
  void publish(const ros::TimerEvent&);
  void publishOutputs();  ///< publish()'s work; may throw
  /// The whole-map outputs (octree, cloud, projection), built from snapshot_ outside mutex_.
  void publishWholeMap();
  /// Brings snapshot_ up to date (the changed tiles' leaves copied under
  /// mutex_, encoded outside it) and returns the map's header. Requires
  /// snapshot_mutex_, not mutex_.
  std_msgs::Header refreshSnapshot();
  /// The marker arrays of the blocks changed since the last publish (null:
  /// nobody listens or nothing changed).
  struct ChangedBlockMarkers {
    visualization_msgs::MarkerArrayPtr occupied, free;
  };
  /// Builds them from the live tree; requires mutex_ (publish them after it is let go).
  ChangedBlockMarkers changedBlockMarkers(const octomap::OcTree& tree, const std_msgs::Header& header);
  bool saveMap(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response);
  bool clearBox(BoundingBoxQuery::Request& request, BoundingBoxQuery::Response&);
  /// The map on request: binary (octomap_binary) or with log-odds (octomap_full).
  bool getMap(bool binary, GetOctomap::Request&, GetOctomap::Response& response);
  std_msgs::Header mapHeader() const;  ///< requires mutex_
  bool reset(std_srvs::Empty::Request&, std_srvs::Empty::Response&);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  /// Writes the whole map's files; @p lock (on mutex_) is let go while the database's tiles are written.
  std::vector<std::string> save(std::unique_lock<std::mutex>& lock);
  /// Opens <save_dir>/<map_name>.db; on failure logs why and maps without it.
  void openDatabase();

  OctomapAccumulatorParameters params_;

  // Everything below is guarded by mutex_ (callbacks may run on several threads).
  std::mutex mutex_;
  std::unique_ptr<MapFusion> fusion_;  ///< the pipeline: checks, fusion, pruning
  uint64_t saves_failed_ = 0;
  bool last_save_failed_ = false;  ///< diagnostics ERROR until a save succeeds again
  ProcessingTimes fusion_times_;  ///< per update fused
  std::string last_problem_;
  std::string database_problem_;  ///< why the database could not be opened; empty if it was
  bool changed_since_publish_ = true;  ///< the map changed since the markers went out
  bool full_changed_ = true;           ///< ... since the whole-map outputs went out
  ros::WallTime last_full_publish_;    ///< when they went out; zero: never

  /// Taken first by each publish, so that two never interleave their
  /// messages once the fusion lock is let go.
  std::mutex publish_mutex_;
  /// Guards snapshot_; taken before mutex_ when both are: the whole-map
  /// outputs are built from it while the fusion goes on.
  std::mutex snapshot_mutex_;
  std::unique_ptr<MapSnapshot> snapshot_;

  ros::Subscriber update_sub_;
  ros::Publisher octomap_pub_, octomap_full_pub_, markers_pub_, free_markers_pub_, cloud_pub_, projected_pub_;
  ros::ServiceServer save_srv_, reset_srv_, clear_bbx_srv_, octomap_binary_srv_, octomap_full_srv_;
  ros::Timer publish_timer_, diagnostics_timer_;
  ros::WallTimer save_timer_;
  size_t updates_at_last_save_ = 0;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;
};

void OctomapAccumulator::onInit() {
  ros::NodeHandle& nh = getNodeHandle();
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  std::string why;
  if (!loadParameters(pnh, &params_, &why)) {
    NODELET_FATAL("%s: invalid parameter: %s; OctomapAccumulator does not start", getName().c_str(), why.c_str());
    return;
  }
  fusion_ = std::make_unique<MapFusion>(params_);
  if (!params_.map_file.empty()) {
    try {
      fusion_->load(params_.map_file);
    } catch (const std::exception& e) {
      // The map asked for is not there: starting empty would look like success.
      NODELET_FATAL("%s: cannot start from map_file: %s; OctomapAccumulator does not start", getName().c_str(),
                    e.what());
      fusion_.reset();
      return;
    }
    NODELET_INFO("started from %s: %lu leaves", params_.map_file.c_str(),
                 static_cast<unsigned long>(fusion_->map().tree().getNumLeafNodes()));
  }

  if (!params_.save_dir.empty()) openDatabase();
  MapSnapshotConfig snapshot;
  snapshot.resolution_m = params_.map.resolution_m;
  snapshot.occupancy_threshold_prob = params_.map.occupancy_threshold_prob;
  snapshot.projection_min_z_m = params_.projection_min_z_m;
  snapshot.projection_max_z_m = params_.projection_max_z_m;
  snapshot_ = std::make_unique<MapSnapshot>(snapshot);

  // octomap_server's names and types, latched as there. An output that had
  // no subscriber when the whole map went out holds nothing to latch: a new
  // subscriber makes the whole map due again (within full_map_period_s),
  // whatever the other outputs' subscribers got before.
  const auto whole_map_due = [this](const ros::SingleSubscriberPublisher&) {
    std::lock_guard<std::mutex> lock(mutex_);
    full_changed_ = true;
  };
  const auto latched = [&](const std::string& topic, auto message) {
    using Message = decltype(message);
    return nh.advertise<Message>(topic, 1, whole_map_due, ros::SubscriberStatusCallback(), ros::VoidConstPtr(),
                                 /*latch=*/true);
  };
  octomap_pub_ = latched("octomap_binary", Octomap());
  octomap_full_pub_ = latched("octomap_full", Octomap());
  // Occupied and free cells a block at a time, only the blocks changed since
  // the last publish; a new subscriber gets the whole map first.
  const auto whole_map_for_new_subscriber = [this](const ros::SingleSubscriberPublisher&) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!fusion_) return;
    fusion_->markAllChanged();
    changed_since_publish_ = full_changed_ = true;
  };
  markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>("occupied_cells_vis_array", 10,
                                                               whole_map_for_new_subscriber);
  free_markers_pub_ =
      nh.advertise<visualization_msgs::MarkerArray>("free_cells_vis_array", 10, whole_map_for_new_subscriber);
  cloud_pub_ = latched("octomap_point_cloud_centers", sensor_msgs::PointCloud2());
  projected_pub_ = latched("projected_map", nav_msgs::OccupancyGrid());
  octomap_binary_srv_ = nh.advertiseService<GetOctomap::Request, GetOctomap::Response>(
      "octomap_binary", [this](GetOctomap::Request& q, GetOctomap::Response& r) { return getMap(true, q, r); });
  octomap_full_srv_ = nh.advertiseService<GetOctomap::Request, GetOctomap::Response>(
      "octomap_full", [this](GetOctomap::Request& q, GetOctomap::Response& r) { return getMap(false, q, r); });
  clear_bbx_srv_ = pnh.advertiseService("clear_bbx", &OctomapAccumulator::clearBox, this);
  // A queue deep enough to hold the updates that arrive while a large map is
  // published; what still overflows shows as a gap in the mappers' sequence
  // numbers, counted and warned about.
  update_sub_ = nh.subscribe("occupancy_update", static_cast<uint32_t>(params_.update_queue_size),
                             &OctomapAccumulator::updateCallback, this);
  save_srv_ = pnh.advertiseService("save_map", &OctomapAccumulator::saveMap, this);
  reset_srv_ = pnh.advertiseService("reset", &OctomapAccumulator::reset, this);
  publish_timer_ = nh.createTimer(ros::Duration(1.0 / params_.publish_rate_hz), &OctomapAccumulator::publish, this);
  if (params_.save_period_s > 0.0 && !params_.save_dir.empty()) {
    // Periodic checkpoints, so that a crash loses at most save_period_s of
    // mapping: the changed tiles to the database (its thread writes them),
    // or without one the whole map to its files.
    save_timer_ = nh.createWallTimer(ros::WallDuration(params_.save_period_s), [this](const ros::WallTimerEvent&) {
      std::unique_lock<std::mutex> lock(mutex_);
      if (fusion_->mission().store()) {
        fusion_->mission().checkpoint();
        return;
      }
      if (fusion_->map().updates() == updates_at_last_save_) return;
      try {
        save(lock);
      } catch (const std::exception& e) {
        ++saves_failed_;
        last_save_failed_ = true;
        last_problem_ = std::string("periodic save failed: ") + e.what();
        NODELET_ERROR_THROTTLE(kSaveErrorThrottleS, "periodic save failed (the previous map file stays): %s", e.what());
      }
    });
  }

  diagnostics_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
  diagnostics_->setHardwareID("stereo_occupancy");
  diagnostics_->add("accumulator", this, &OctomapAccumulator::diagnose);
  diagnostics_timer_ = nh.createTimer(ros::Duration(1.0), [this](const ros::TimerEvent&) { diagnostics_->update(); });

  const auto& store = fusion_->mission().store();
  const std::string beyond = store ? "kept in " + store->path() : "dropped";
  NODELET_INFO("OctomapAccumulator: %.3g m cells in frame '%s', live map within %.0f m of the vehicle, beyond it %s, "
               "saving to '%s'",
               params_.map.resolution_m, params_.world_frame.empty() ? "(the first update's)" : params_.world_frame.c_str(),
               params_.map.max_extent_m, beyond.c_str(),
               params_.save_dir.empty() ? "(nowhere)" : params_.save_dir.c_str());
}

OctomapAccumulator::~OctomapAccumulator() {
  std::unique_lock<std::mutex> lock(mutex_);
  if (!fusion_times_.empty()) {
    // One line for scripts, on stderr (rosconsole may be gone at shutdown).
    const TimeStatistics fusion = fusion_times_.statistics();
    std::fprintf(stderr,
                 "OctomapAccumulator summary: updates_received=%lu updates_refused=%lu updates_lost=%lu "
                 "fusion_ms_median=%.3f fusion_ms_p99=%.3f fusion_ms_max=%.3f\n",
                 static_cast<unsigned long>(fusion_->counters().received),
                 static_cast<unsigned long>(fusion_->counters().refused),
                 static_cast<unsigned long>(fusion_->counters().lost),
                 fusion.median_ms, fusion.p99_ms, fusion.max_ms);
  }
  if (!fusion_ || params_.save_dir.empty()) return;
  if (fusion_->map().updates() == 0) return;
  try {
    // On stderr: rosconsole may be gone at shutdown. The time tells how much
    // of roslaunch's wait before SIGTERM (--sigint-timeout, 15 s) it took.
    const auto start = std::chrono::steady_clock::now();
    const std::vector<std::string> paths = save(lock);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    for (const auto& path : paths)
      std::fprintf(stderr, "OctomapAccumulator: saved the map of %lu updates to %s on shutdown (%.1f s)\n",
                   static_cast<unsigned long>(fusion_->map().updates()), path.c_str(), seconds);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "OctomapAccumulator: could not save the map on shutdown (the previous map file stays): %s\n", e.what());
  }
}

void OctomapAccumulator::updateCallback(const ros::MessageEvent<const OccupancyUpdate>& event) {
  // Any node may publish on this topic: MapFusion checks everything before
  // the map is touched, and nothing may leave the callback (it would end the manager).
  const OccupancyUpdateConstPtr& msg = event.getConstMessage();
  std::unique_lock<std::mutex> lock(mutex_);
  const bool frame_chosen = !fusion_->frameId().empty();
  const uint64_t lost_before = fusion_->counters().lost;
  std::string why;
  const ProcessingTimes::Start start = fusion_times_.start();
  bool fused = false;
  try {
    fused = fusion_->fuse(*msg, &why, event.getPublisherName());  // reads the message in place
  } catch (const std::exception& e) {
    // admits() bounds what an update may allocate; what is left is the map's
    // own growth running out of memory, which keeps the cells fused so far.
    why = std::string("fusion failed: ") + e.what();
  }
  if (fusion_->counters().lost > lost_before) {
    last_problem_ = "updates lost before they reached the map";
    NODELET_WARN_THROTTLE(kWarnThrottleS, "%lu updates from %s never arrived (%lu lost so far): the accumulator "
                          "fell behind (a large map published under the lock?) or the link drops them; "
                          "update_queue_size is %d", static_cast<unsigned long>(fusion_->counters().lost - lost_before),
                          event.getPublisherName().c_str(), static_cast<unsigned long>(fusion_->counters().lost),
                          params_.update_queue_size);
  }
  if (!fused) {
    last_problem_ = "refused an update: " + why;
    NODELET_WARN_THROTTLE(kWarnThrottleS, "refused an occupancy update (%lu so far): %s",
                          static_cast<unsigned long>(fusion_->counters().refused), why.c_str());
    return;
  }
  fusion_times_.stop(start);
  if (!frame_chosen) NODELET_INFO("the map is in frame '%s' (the first update's)", fusion_->frameId().c_str());
  changed_since_publish_ = full_changed_ = true;
  const bool trim = fusion_->mission().takeFreedMemory();
  lock.unlock();
  if (trim) MissionMap::trimHeap();  // the tiles that went to the database: outside the lock, the fusion goes on
}

std_msgs::Header OctomapAccumulator::mapHeader() const {
  std_msgs::Header header;
  header.frame_id = fusion_->frameId();
  header.stamp = fusion_->lastStamp();
  return header;
}

void OctomapAccumulator::publish(const ros::TimerEvent&) {
  try {
    publishOutputs();
  } catch (const std::exception& e) {  // bad_alloc for a huge map: nothing may leave a callback
    NODELET_ERROR_THROTTLE(kWarnThrottleS, "could not publish the map outputs: %s", e.what());
  }
}

void OctomapAccumulator::publishOutputs() {
  // Each output is built only while someone listens: a marker array of a
  // large map costs more than many updates.
  const auto wanted = [](const ros::Publisher& pub) { return pub.getNumSubscribers() > 0; };
  const bool anyone = wanted(octomap_pub_) || wanted(octomap_full_pub_) || wanted(markers_pub_) ||
                      wanted(free_markers_pub_) || wanted(cloud_pub_) || wanted(projected_pub_);
  std::lock_guard<std::mutex> publishing(publish_mutex_);
  ChangedBlockMarkers markers;
  bool full_due = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!anyone) {
      fusion_->markAllChanged();  // no changes kept for nobody: the next subscriber gets the whole map
      return;
    }
    if (fusion_->frameId().empty()) return;
    // The whole map at most every full_map_period_s, the changed blocks at
    // each publish: a large map's octree and cloud would cost more than its changes.
    const ros::WallTime now = ros::WallTime::now();
    full_due = full_changed_ && (last_full_publish_.isZero() || now < last_full_publish_ ||
                                 (now - last_full_publish_).toSec() >= params_.full_map_period_s);
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
    NODELET_ERROR_THROTTLE(kWarnThrottleS, "could not publish the changed blocks' markers: %s", e.what());
  }
  if (!full_due) return;
  publishWholeMap();
  // The whole map's messages and the snapshot's encoding freed tens of MB
  // of small blocks: back to the system now, not at the next eviction.
  MissionMap::trimHeap();
}

void OctomapAccumulator::publishWholeMap() {
  const auto wanted = [](const ros::Publisher& pub) { return pub.getNumSubscribers() > 0; };
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

std_msgs::Header OctomapAccumulator::refreshSnapshot() {
  std::vector<TileContent> changes;
  bool whole_map = false;
  std_msgs::Header header;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    changes = fusion_->mission().takeChangedTiles(snapshot_->needsWholeMap(), &whole_map);
    header = mapHeader();
  }
  snapshot_->apply(changes, whole_map);
  return header;
}

OctomapAccumulator::ChangedBlockMarkers OctomapAccumulator::changedBlockMarkers(const octomap::OcTree& tree,
                                                                                const std_msgs::Header& header) {
  const auto wanted = [](const ros::Publisher& pub) { return pub.getNumSubscribers() > 0; };
  const bool free_wanted = params_.publish_free_space && wanted(free_markers_pub_);
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

bool OctomapAccumulator::getMap(bool binary, GetOctomap::Request&, GetOctomap::Response& response) {
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  try {
    if (!binary) snapshot_->setKeepFull(true);  // until a publish finds octomap_full without subscribers
    const std_msgs::Header header = refreshSnapshot();
    toMsg(*snapshot_, binary, header, &response.map);
  } catch (const std::exception& e) {  // nothing may leave a callback
    NODELET_ERROR("could not serialise the map for %s: %s", binary ? "octomap_binary" : "octomap_full", e.what());
    return false;
  }
  return true;
}

bool OctomapAccumulator::clearBox(BoundingBoxQuery::Request& request, BoundingBoxQuery::Response&) {
  const Eigen::Vector3d lo(request.min.x, request.min.y, request.min.z);
  const Eigen::Vector3d hi(request.max.x, request.max.y, request.max.z);
  if (!lo.allFinite() || !hi.allFinite() || (lo.array() > hi.array()).any()) {
    NODELET_WARN("clear_bbx: the box must be finite with min <= max; nothing cleared");
    return false;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  size_t cleared = 0;
  try {
    cleared = fusion_->clearBox(lo, hi);
  } catch (const std::exception& e) {  // bad_alloc for a huge box: nothing may leave a callback
    NODELET_ERROR("clear_bbx failed: %s", e.what());
    changed_since_publish_ = full_changed_ = true;
    return false;
  }
  changed_since_publish_ = full_changed_ = true;
  NODELET_INFO("clear_bbx: cleared %lu occupied cells in [%.2f, %.2f, %.2f] .. [%.2f, %.2f, %.2f]",
               static_cast<unsigned long>(cleared), lo.x(), lo.y(), lo.z(), hi.x(), hi.y(), hi.z());
  return true;
}

void OctomapAccumulator::openDatabase() {
  const std::string path = params_.save_dir + "/" + params_.map_name + ".db";
  ::mkdir(params_.save_dir.c_str(), 0755);  // one level, if missing; any other problem shows in the open
  try {
    fusion_->openDatabase(path);
  } catch (const std::exception& e) {
    // The live map works without it; what leaves max_extent_m is then lost.
    database_problem_ = e.what();
    NODELET_ERROR("%s; mapping goes on without it: cells beyond max_extent_m are dropped, and ~save_map answers "
                  "false and writes only the live map, to %s%s.bt and .ot", e.what(), params_.map_name.c_str(),
                  kLiveOnlySuffix);
    return;
  }
  const size_t tiles = fusion_->mission().store()->tiles().size();
  const TileStoreStatus status = fusion_->mission().store()->status();
  if (status.damaged_rows > 0)
    NODELET_ERROR("%s: %zu damaged tile rows moved to its table damaged_tiles; those tiles start empty (the first: %s)",
                  path.c_str(), status.damaged_rows, status.first_damage.c_str());
  NODELET_INFO("the mission's tiles are kept in %s (%s, %zu tiles)", path.c_str(), tiles ? "continued" : "new", tiles);
}

std::vector<std::string> OctomapAccumulator::save(std::unique_lock<std::mutex>& lock) {
  std::shared_ptr<TileStore> store = fusion_->mission().store();
  std::vector<std::string> paths;
  if (store) {
    // The whole mission: the changed tiles to the database, then all its
    // tiles to the files, outside the lock (the fusion goes on meanwhile).
    fusion_->mission().checkpoint();
    const size_t updates = fusion_->map().updates();
    lock.unlock();
    std::string error;
    try {
      paths = MissionMap::saveStore(*store, params_.save_dir, params_.map_name, params_.map.occupancy_threshold_prob);
    } catch (const std::exception& e) {
      error = e.what();
    }
    lock.lock();
    if (!error.empty()) throw std::runtime_error(error);
    updates_at_last_save_ = updates;
  } else if (!database_problem_.empty()) {
    // The mission's files may hold more than this live map (the database
    // that could not be opened has the rest): never replaced by it.
    paths = fusion_->map().save(params_.save_dir, params_.map_name + kLiveOnlySuffix);
    throw std::runtime_error("the mission's database is not open (" + database_problem_ +
                             "): wrote only the live map, to " + paths[0] + " and " + paths[1] + "; " +
                             params_.map_name + ".bt and .ot stay as they were");
  } else {
    paths = fusion_->map().save(params_.save_dir, params_.map_name);
    updates_at_last_save_ = fusion_->map().updates();
  }
  last_save_failed_ = false;
  return paths;
}

bool OctomapAccumulator::saveMap(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
  if (params_.save_dir.empty()) {
    response.success = false;
    response.message = "save_dir is not set";
    return true;
  }
  std::unique_lock<std::mutex> lock(mutex_);
  try {
    const auto paths = save(lock);
    response.success = true;
    response.message = paths[0] + " " + paths[1];
    NODELET_INFO("saved the map: %s", response.message.c_str());
  } catch (const std::exception& e) {
    ++saves_failed_;
    last_save_failed_ = true;
    last_problem_ = std::string("save failed: ") + e.what();
    response.success = false;
    response.message = e.what();
    NODELET_ERROR("could not save the map (the previous map file stays): %s", e.what());
  }
  return true;
}

bool OctomapAccumulator::reset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
  std::lock_guard<std::mutex> lock(mutex_);
  fusion_->reset();
  changed_since_publish_ = full_changed_ = true;
  NODELET_INFO("map reset");
  return true;
}

void OctomapAccumulator::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  std::lock_guard<std::mutex> lock(mutex_);
  const FusionCounters& n = fusion_->counters();
  if (last_save_failed_)
    status.summary(diagnostic_msgs::DiagnosticStatus::ERROR, last_problem_);
  else
    status.summary(n.refused + n.lost > 0 ? diagnostic_msgs::DiagnosticStatus::WARN
                                          : diagnostic_msgs::DiagnosticStatus::OK,
                   n.refused + n.lost > 0 ? last_problem_ : "accumulating");
  status.add("frame", fusion_->frameId());
  status.add("updates received", n.received);
  status.add("updates refused", n.refused);
  status.add("updates lost", n.lost);
  status.add("saves failed", saves_failed_);
  status.add("leaves", fusion_->map().tree().getNumLeafNodes());
  status.add("leaves pruned (max_extent_m)", n.leaves_pruned);
  if (const auto& store = fusion_->mission().store()) {
    const TileStoreStatus db = store->status();
    status.add("database", store->path());
    status.add("tiles moved to the database", n.tiles_stored);
    status.add("tiles written", db.tiles_written);
    status.add("tiles waiting to be written", db.queued);
    status.add("database writes failed", db.writes_failed);
    if (db.queued > 0 && !db.last_error.empty())
      status.mergeSummary(diagnostic_msgs::DiagnosticStatus::ERROR, "database: " + db.last_error);
  } else if (!database_problem_.empty()) {
    status.mergeSummary(diagnostic_msgs::DiagnosticStatus::ERROR, "no database: " + database_problem_);
  }
  status.add("last fusion time [ms]", fusion_times_.lastMs());
  status.add("max fusion time [ms]", fusion_times_.maxMs());
  // Since the last report (1 s): what a soak plots over time.
  const TimeStatistics window = fusion_times_.takeWindow();
  status.add("updates fused since last report", window.count);
  status.add("fusion time p50 since last report [ms]", window.median_ms);
  status.add("fusion time p99 since last report [ms]", window.p99_ms);
}

}  // namespace stereo_occupancy

PLUGINLIB_EXPORT_CLASS(stereo_occupancy::OctomapAccumulator, nodelet::Nodelet)
