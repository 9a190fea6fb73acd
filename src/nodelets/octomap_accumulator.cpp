// stereo_occupancy/OctomapAccumulator: occupancy updates -> one OctoMap,
// published for visualisation and saved on request.
//
// ROS glue only: the fusion is the mapping pipeline's MapFusion (the core's
// MapAccumulator), the outputs are MapPublisher's, the files MapSaver's, the
// distance field's services and slice DistanceFieldServer's; the nodelet
// subscribes, serves reset and clear_bbx, and reports.

#include <diagnostic_updater/diagnostic_updater.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <std_srvs/Empty.h>
#include <pluginlib/class_list_macros.hpp>

#include <cstdio>
#include <memory>
#include <mutex>
#include <string>

#include "stereo_occupancy/BoundingBoxQuery.h"
#include "stereo_occupancy/ros/distance_field_server.h"
#include "stereo_occupancy/ros/map_publisher.h"
#include "stereo_occupancy/ros/map_saver.h"
#include "stereo_occupancy/ros/mapping_pipeline.h"
#include "stereo_occupancy/ros/parameters.h"
#include "stereo_occupancy/ros/processing_times.h"

namespace stereo_occupancy {

namespace {
/// At most one warning of a kind in this time [s].
constexpr double kWarnThrottleS = 5.0;
}  // namespace

class OctomapAccumulator : public nodelet::Nodelet {
 public:
  ~OctomapAccumulator() override;

 private:
  void onInit() override;
  /// Builds the map (from map_file if given); false, logged, if it cannot start.
  bool startMap();
  /// Brings the distance field (if any) up to date, under mutex_; false, logged, if that failed.
  void updateField();
  void updateCallback(const ros::MessageEvent<const OccupancyUpdate>& event);
  bool clearBox(BoundingBoxQuery::Request& request, BoundingBoxQuery::Response&);
  bool reset(std_srvs::Empty::Request&, std_srvs::Empty::Response&);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  OctomapAccumulatorParameters params_;

  // Everything below is guarded by mutex_ (callbacks may run on several
  // threads); the publisher and the saver take it for the map too.
  std::mutex mutex_;
  std::unique_ptr<MapFusion> fusion_;  ///< the pipeline: checks, fusion, pruning
  ProcessingTimes fusion_times_;       ///< per update fused
  std::string last_problem_;
  std::string field_problem_;  ///< why the distance field's last update failed; empty when it went through

  // Declared after the map: destroyed (their callbacks ended) before it.
  std::unique_ptr<DistanceFieldServer> field_;  ///< the planners' distance field; null with distance_field off
  std::unique_ptr<MapSaver> saver_;             ///< files, database, checkpoints
  std::unique_ptr<MapPublisher> publisher_;     ///< the map's topics and GetOctomap services
  ros::Subscriber update_sub_;
  ros::ServiceServer reset_srv_, clear_bbx_srv_;
  ros::Timer diagnostics_timer_;
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
  if (!startMap()) return;
  saver_ = std::make_unique<MapSaver>(
      params_.saving, params_.map, fusion_.get(), &mutex_,
      [this](const std::string& problem) { last_problem_ = problem; }, getName());
  if (!params_.saving.save_dir.empty()) saver_->openDatabase();
  publisher_ = std::make_unique<MapPublisher>(params_.publisher, params_.map, fusion_.get(), &mutex_, getName());
  publisher_->advertise(nh);
  if (params_.distance.field.enabled) {
    try {
      field_ = std::make_unique<DistanceFieldServer>(params_.distance, params_.map.resolution_m, fusion_.get(), &mutex_,
                                                     getName());
    } catch (const std::exception& e) {  // the config was validated: bad_alloc for a huge window
      NODELET_FATAL("%s: cannot build the distance field: %s; OctomapAccumulator does not start", getName().c_str(),
                    e.what());
      return;
    }
    field_->advertise(nh, pnh, params_.publisher.publish_rate_hz);
  }
  clear_bbx_srv_ = pnh.advertiseService("clear_bbx", &OctomapAccumulator::clearBox, this);
  // A queue deep enough to hold the updates that arrive while a large map is
  // published; what still overflows shows as a gap in the mappers' sequence
  // numbers, counted and warned about.
  update_sub_ = nh.subscribe("occupancy_update", static_cast<uint32_t>(params_.update_queue_size),
                             &OctomapAccumulator::updateCallback, this);
  reset_srv_ = pnh.advertiseService("reset", &OctomapAccumulator::reset, this);
  saver_->advertise(nh, pnh);

  diagnostics_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
  diagnostics_->setHardwareID("stereo_occupancy");
  diagnostics_->add("accumulator", this, &OctomapAccumulator::diagnose);
  diagnostics_timer_ = nh.createTimer(ros::Duration(1.0), [this](const ros::TimerEvent&) { diagnostics_->update(); });

  const auto& store = fusion_->mission().store();
  const std::string beyond = store ? "kept in " + store->path() : "dropped";
  const std::string& save_dir = params_.saving.save_dir;
  NODELET_INFO(
      "OctomapAccumulator: %.3g m cells in frame '%s', live map within %.0f m of the vehicle, beyond it %s, "
      "saving to '%s'",
      params_.map.resolution_m, params_.world_frame.empty() ? "(the first update's)" : params_.world_frame.c_str(),
      params_.map.max_extent_m, beyond.c_str(), save_dir.empty() ? "(nowhere)" : save_dir.c_str());
  if (field_) {
    const DistanceFieldConfig& field = params_.distance.field;
    NODELET_INFO(
        "distance field: %.0f x %.0f x %.0f m around the vehicle, distances up to %.2f m; services %s/distance, "
        "check_path, cast_ray; planners in this manager: DistanceFieldRegistry::find(\"%s\")",
        field.window_xy_m, field.window_xy_m, field.window_z_m, field.max_distance_m, pnh.getNamespace().c_str(),
        getName().c_str());
  }
}

void OctomapAccumulator::updateField() {
  if (!field_) return;
  try {
    field_->update();
    field_problem_.clear();
  } catch (const std::exception& e) {  // bad_alloc: the map goes on; the next update reads the window again
    field_problem_ = std::string("distance field update failed: ") + e.what();
    NODELET_ERROR_THROTTLE(kWarnThrottleS, "%s", field_problem_.c_str());
  }
}

bool OctomapAccumulator::startMap() {
  fusion_ = std::make_unique<MapFusion>(params_);
  if (params_.map_file.empty()) return true;
  try {
    fusion_->load(params_.map_file);
  } catch (const std::exception& e) {
    // The map asked for is not there: starting empty would look like success.
    NODELET_FATAL("%s: cannot start from map_file: %s; OctomapAccumulator does not start", getName().c_str(), e.what());
    fusion_.reset();
    return false;
  }
  NODELET_INFO("started from %s: %lu leaves", params_.map_file.c_str(),
               static_cast<unsigned long>(fusion_->map().tree().getNumLeafNodes()));
  return true;
}

OctomapAccumulator::~OctomapAccumulator() {
  std::unique_lock<std::mutex> lock(mutex_);
  if (!fusion_times_.empty()) {
    // One line for scripts, on stderr (rosconsole may be gone at shutdown).
    const TimeStatistics fusion = fusion_times_.statistics();
    // The field's update is timed apart from the fusion: its own columns (0 without the field).
    const TimeStatistics field = field_ ? field_->times().statistics() : TimeStatistics();
    std::fprintf(stderr,
                 "OctomapAccumulator summary: updates_received=%lu updates_refused=%lu updates_lost=%lu "
                 "fusion_ms_median=%.3f fusion_ms_p99=%.3f fusion_ms_max=%.3f distance_field_ms_median=%.3f "
                 "distance_field_ms_p99=%.3f distance_field_ms_max=%.3f\n",
                 static_cast<unsigned long>(fusion_->counters().received),
                 static_cast<unsigned long>(fusion_->counters().refused),
                 static_cast<unsigned long>(fusion_->counters().lost), fusion.median_ms, fusion.p99_ms, fusion.max_ms,
                 field.median_ms, field.p99_ms, field.max_ms);
  }
  if (saver_) saver_->saveOnShutdown(lock);
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
    NODELET_WARN_THROTTLE(kWarnThrottleS,
                          "%lu updates from %s never arrived (%lu lost so far): the accumulator "
                          "fell behind (a large map published under the lock?) or the link drops them; "
                          "update_queue_size is %d",
                          static_cast<unsigned long>(fusion_->counters().lost - lost_before),
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
  updateField();  // timed on its own (DistanceFieldServer::times())
  if (!frame_chosen) NODELET_INFO("the map is in frame '%s' (the first update's)", fusion_->frameId().c_str());
  publisher_->mapChanged();
  const bool trim = fusion_->mission().takeFreedMemory();
  lock.unlock();
  if (trim) MissionMap::trimHeap();  // the tiles that went to the database: outside the lock, the fusion goes on
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
    publisher_->mapChanged();
    updateField();
    return false;
  }
  publisher_->mapChanged();
  updateField();
  NODELET_INFO("clear_bbx: cleared %lu occupied cells in [%.2f, %.2f, %.2f] .. [%.2f, %.2f, %.2f]",
               static_cast<unsigned long>(cleared), lo.x(), lo.y(), lo.z(), hi.x(), hi.y(), hi.z());
  return true;
}

bool OctomapAccumulator::reset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
  std::lock_guard<std::mutex> lock(mutex_);
  fusion_->reset();
  publisher_->mapChanged();
  updateField();
  NODELET_INFO("map reset");
  return true;
}

void OctomapAccumulator::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  std::lock_guard<std::mutex> lock(mutex_);
  const FusionCounters& n = fusion_->counters();
  if (saver_->lastSaveFailed())
    status.summary(diagnostic_msgs::DiagnosticStatus::ERROR, last_problem_);
  else
    status.summary(
        n.refused + n.lost > 0 ? diagnostic_msgs::DiagnosticStatus::WARN : diagnostic_msgs::DiagnosticStatus::OK,
        n.refused + n.lost > 0 ? last_problem_ : "accumulating");
  status.add("frame", fusion_->frameId());
  status.add("updates received", n.received);
  status.add("updates refused", n.refused);
  status.add("updates lost", n.lost);
  status.add("saves failed", saver_->savesFailed());
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
  } else if (!saver_->databaseProblem().empty()) {
    status.mergeSummary(diagnostic_msgs::DiagnosticStatus::ERROR, "no database: " + saver_->databaseProblem());
  }
  status.add("last fusion time [ms]", fusion_times_.lastMs());
  status.add("max fusion time [ms]", fusion_times_.maxMs());
  // Since the last report (1 s): what a soak plots over time.
  const TimeStatistics window = fusion_times_.takeWindow();
  status.add("updates fused since last report", window.count);
  status.add("fusion time p50 since last report [ms]", window.median_ms);
  status.add("fusion time p99 since last report [ms]", window.p99_ms);
  if (field_) {
    if (!field_problem_.empty()) status.mergeSummary(diagnostic_msgs::DiagnosticStatus::ERROR, field_problem_);
    const TimeStatistics field = field_->times().takeWindow();
    status.add("distance field updates since last report", field.count);
    status.add("distance field update p50 since last report [ms]", field.median_ms);
    status.add("distance field update p99 since last report [ms]", field.p99_ms);
    status.add("distance field last update [ms]", field_->times().lastMs());
    status.add("distance field max update [ms]", field_->times().maxMs());
    status.add("distance field cells recomputed (last update)", field_->lastUpdatedCells());
  }
}

}  // namespace stereo_occupancy

PLUGINLIB_EXPORT_CLASS(stereo_occupancy::OctomapAccumulator, nodelet::Nodelet)
