#pragma once
/// @file
/// The distance field (distance_field.h) in the accumulator: kept up to date
/// after each fused update, answered on services (~distance, ~check_path,
/// ~cast_ray), drawn as a horizontal slice (distance_slice), and shared
/// without messages with planner nodelets in the same manager
/// (DistanceFieldRegistry).
///
/// Threads: the accumulator updates the field under the fusion's lock (it
/// reads the map) and the field's own exclusive lock; services and planners
/// read it under the field's shared lock only, so a query never waits for a
/// fusion, only for the field's update, and never sees half of one.

#include <ros/node_handle.h>
#include <ros/publisher.h>
#include <ros/service_server.h>
#include <ros/time.h>
#include <ros/timer.h>
#include <sensor_msgs/PointCloud2.h>

#include <Eigen/Core>

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <type_traits>
#include <utility>

#include "stereo_occupancy/CastRay.h"
#include "stereo_occupancy/CheckPath.h"
#include "stereo_occupancy/GetDistances.h"
#include "stereo_occupancy/distance_field.h"
#include "stereo_occupancy/parameter_table.h"
#include "stereo_occupancy/ros/processing_times.h"

namespace stereo_occupancy {

class MapFusion;

/// Parameters of the accumulator's distance field: the field's own and the slice's height.
struct DistanceFieldServerConfig {
  DistanceFieldConfig field;
  double slice_z_m = 2.0;  ///< height of the distance_slice cloud, map frame [m]

  /// The parameters (parameter_table.h): f(spec, member) for each.
  template <typename Self, typename F>
  static void forEachParameter(Self& c, F&& f) {
    DistanceFieldConfig::forEachParameter(c.field, f);
    f(numberParameter("distance_slice_z_m", "m", -10000.0, 10000.0,
                      "height of the distance_slice cloud (the field's layer that holds it)"),
      c.slice_z_m);
  }
  bool isValid(std::string* why = nullptr) const { return parametersInRange(*this, why) && field.isValid(why); }
};

/// Most points one ~distance request may ask for; a larger request is refused before any work.
constexpr size_t kMaxDistanceQueryPoints = 100000;

/// What a reader of the field learns besides the field: the map's frame and
/// how recent the field is.
struct DistanceFieldInfo {
  std::string frame_id;  ///< the map's frame ("" before the first update)
  ros::Time stamp;       ///< stamp of the last fused update the field holds (0: none yet)
  uint64_t updates = 0;  ///< how many times the field was brought up to date
};

/// The live field and its lock: what the accumulator hands to readers in
/// the same process (DistanceFieldRegistry). Readers hold it by shared_ptr;
/// it outlives the accumulator that made it (then it no longer changes, and
/// alive() is false).
class SharedDistanceField {
 public:
  /// @throws std::invalid_argument as DistanceField does.
  SharedDistanceField(const DistanceFieldConfig& config, double resolution_m) : field_(config, resolution_m) {}

  /// Runs @p f(const DistanceField&) or @p f(const DistanceField&, const
  /// DistanceFieldInfo&) under the shared lock and returns what it returns.
  /// Readers run at the same time; the accumulator's update waits for them,
  /// so keep @p f short (a path check, some samples), and do not keep
  /// references to the field beyond it.
  template <typename F>
  decltype(auto) read(F&& f) const {
    std::shared_lock<std::shared_mutex> lock(mutex_);
    if constexpr (std::is_invocable_v<F, const DistanceField&, const DistanceFieldInfo&>)
      return std::forward<F>(f)(static_cast<const DistanceField&>(field_),
                                static_cast<const DistanceFieldInfo&>(info_));
    else
      return std::forward<F>(f)(static_cast<const DistanceField&>(field_));
  }

  /// Runs @p f(DistanceField&, DistanceFieldInfo&) under the exclusive lock
  /// (the accumulator's update).
  template <typename F>
  void write(F&& f) {
    std::unique_lock<std::shared_mutex> lock(mutex_);
    std::forward<F>(f)(field_, info_);
  }

  /// False once the accumulator that updates it has gone (unloaded, shut down).
  bool alive() const { return alive_.load(); }
  void markGone() { alive_.store(false); }

 private:
  mutable std::shared_mutex mutex_;
  DistanceField field_;
  DistanceFieldInfo info_;
  std::atomic<bool> alive_{true};
};

/// The process's live distance fields, by the name of the accumulator nodelet
/// that keeps each (its nodelet name, e.g. "/octomap_accumulator"): how a
/// planner nodelet in the same manager reads the field without messages.
///
///     auto field = DistanceFieldRegistry::find("/octomap_accumulator");
///     if (field) {
///       PathCheckResult r = field->read([&](const DistanceField& f) { return f.checkPath(path, 0.5, true); });
///     }
///
/// Thread-safe.
class DistanceFieldRegistry {
 public:
  /// The field kept by accumulator @p name; null if there is none (not
  /// loaded yet, distance_field off, or unloaded).
  static std::shared_ptr<SharedDistanceField> find(const std::string& name);
  /// Makes @p field findable as @p name (the accumulator, at start).
  static void add(const std::string& name, std::shared_ptr<SharedDistanceField> field);
  /// Withdraws @p field (the accumulator, when it goes), if @p name still names it; marks it gone.
  static void remove(const std::string& name, const SharedDistanceField* field);
};

/// The services' answers, from a field and what the reader learns with it
/// (the nodelet's service callbacks under the shared lock; testable without a
/// roscore). Bad input gives success false and a message, never an exception.
void answerDistances(const DistanceField& field, const DistanceFieldInfo& info, const GetDistances::Request& request,
                     GetDistances::Response* response);
void answerCheckPath(const DistanceField& field, const DistanceFieldInfo& info, const CheckPath::Request& request,
                     CheckPath::Response* response);
void answerCastRay(const DistanceField& field, const DistanceFieldInfo& info, const CastRay::Request& request,
                   CastRay::Response* response);

/// The accumulator's distance field: owns it (shared with the registry),
/// brings it up to date after each fused update, serves it and publishes its slice.
class DistanceFieldServer {
 public:
  /// Turns on @p fusion's class-change recording (MapAccumulator::recordClassChanges)
  /// and builds the field; the first update() reads the window from the map.
  /// @p fusion_mutex guards @p fusion (the accumulator's lock); @p name is the
  /// accumulator's nodelet name, under which the registry finds the field.
  /// @throws std::invalid_argument for an invalid config.
  DistanceFieldServer(const DistanceFieldServerConfig& config, double resolution_m, MapFusion* fusion,
                      std::mutex* fusion_mutex, const std::string& name);
  /// Withdraws the field from the registry; readers that hold it keep a field that no longer changes.
  ~DistanceFieldServer();

  /// Advertises the services (on @p private_nh) and distance_slice (on @p nh),
  /// published at @p publish_rate_hz while subscribed and changed.
  void advertise(ros::NodeHandle& nh, ros::NodeHandle& private_nh, double publish_rate_hz);

  /// Brings the field up to date with the map: the class changes since the
  /// last call, the window re-centred on the last fused update's sensor
  /// origin. Call under the fusion's lock after each fused update, reset and
  /// clear. Does nothing before the first fused update (no vehicle position yet).
  /// @throws what DistanceField::update throws (bad_alloc); the next call reads the whole window again.
  void update();

  /// The updates' times (under the fusion's lock).
  const ProcessingTimes& times() const { return times_; }
  ProcessingTimes& times() { return times_; }
  /// Cells the last update recomputed.
  size_t lastUpdatedCells() const { return last_updated_cells_; }
  /// The shared field (also the registry's).
  const std::shared_ptr<SharedDistanceField>& shared() const { return field_; }

  /// A sensor_msgs/PointCloud2 of the field's layer at @p z_m (x, y, z,
  /// intensity = distance [m]), as voxblox's ESDF slice; frame and stamp from @p info.
  static void sliceCloud(const DistanceField& field, const DistanceFieldInfo& info, double z_m,
                         sensor_msgs::PointCloud2* cloud);

 private:
  bool distances(GetDistances::Request& request, GetDistances::Response& response);
  bool checkPath(CheckPath::Request& request, CheckPath::Response& response);
  bool castRay(CastRay::Request& request, CastRay::Response& response);
  void publishSlice(bool force);

  DistanceFieldServerConfig config_;
  MapFusion* fusion_;
  std::mutex* fusion_mutex_;
  std::string name_;
  std::shared_ptr<SharedDistanceField> field_;
  // Guarded by *fusion_mutex_:
  bool read_whole_window_ = true;  ///< the next update reads the window from the map (start, after a failure)
  ProcessingTimes times_;
  size_t last_updated_cells_ = 0;
  // The slice's: only the timer's and connect callbacks touch them (slice_mutex_).
  std::mutex slice_mutex_;
  uint64_t sliced_updates_ = 0;  ///< the field's update count at the last slice published
  ros::Publisher slice_pub_;
  ros::Timer slice_timer_;
  ros::ServiceServer distance_srv_, check_path_srv_, cast_ray_srv_;
};

}  // namespace stereo_occupancy
