#pragma once
/// @file
/// The mapping pipeline, one for online and offline: FrameMapping turns an
/// image, its camera and its pose into an occupancy update; MapFusion checks
/// an update and fuses it into the map. The DisparityMapper nodelet runs the
/// first, the OctomapAccumulator nodelet the second, and bag_to_map both;
/// each adds only its transport (subscriptions and a tf listener, or a bag
/// and a tf2::BufferCore). Neither class is thread-safe: callers serialise.

#include <cv_bridge/cv_bridge.h>
#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2/buffer_core.h>

#include <cstdint>
#include <map>
#include <memory>
#include <string>

#include "stereo_occupancy/OccupancyUpdate.h"
#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/distance_field.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/ros/parameters.h"
#include "stereo_occupancy/stage_times.h"
#include "stereo_occupancy/store/mission_map.h"

namespace stereo_occupancy {

/// What became of one image.
enum class FrameOutcome {
  kMapped,       ///< drawn; the update is returned
  kNoTransform,  ///< no usable pose: none in tf, or it came later than tf_timeout_s after the image
  kRefused,      ///< bad input or a camera set-up the drawer refuses
};

/// FrameMapping's account of one image.
struct FrameResult {
  FrameOutcome outcome = FrameOutcome::kRefused;
  std::string why;  ///< for kNoTransform and kRefused: what was wrong
  /// The camera set-up was refused for the first time: worth an error (later
  /// images of the same set-up are refused silently, with the same why).
  bool setup_refused_now = false;
  /// kMapped, but no pixel said anything (the update is empty): why names
  /// the pixels' counts and the message's disparity range.
  bool mapped_nothing = false;
  /// kMapped, but with a camera_info that disagrees with the image (another
  /// size, or not rectified): what it said and what was used instead.
  std::string info_mismatch;
};

/// Images given to FrameMapping and what became of them.
struct FrameCounters {
  uint64_t images = 0;
  uint64_t mapped = 0;
  uint64_t no_transform = 0;
  uint64_t refused = 0;
  uint64_t mapped_nothing = 0;  ///< mapped, but with an empty update (FrameResult::mapped_nothing)
  uint64_t info_mismatch = 0;   ///< mapped, its camera_info not used (FrameResult::info_mismatch)
};

/// Image + camera + pose -> checks -> draw (DisparityDrawer) -> update.
class FrameMapping {
 public:
  /// @param params valid parameters (DisparityMapperParameters::isValid()).
  explicit FrameMapping(const DisparityMapperParameters& params);

  const DisparityMapperParameters& parameters() const { return params_; }
  /// New parameters (dynamic_reconfigure); the drawer is rebuilt for the next image.
  void setParameters(const DisparityMapperParameters& params);

  /// Maps a stereo_msgs/DisparityImage (32FC1) at its pose in @p tf, read at
  /// its stamp. @p info (may be null) gives the principal point. @p now is
  /// the clock (the bag's time offline): a pose known only more than
  /// tf_timeout_s after the stamp is too old. Returns the update (its frame
  /// the world frame, its stamp the image's), or null and why in @p result.
  OccupancyUpdatePtr map(const stereo_msgs::DisparityImageConstPtr& msg, const sensor_msgs::CameraInfoConstPtr& info,
                         const tf2::BufferCore& tf, const ros::Time& now, FrameResult* result);

  /// The same for a depth image (16UC1 mm or 32FC1 m) with its camera_info
  /// (required) and the baseline depth_baseline_m (eq. 1 backwards).
  OccupancyUpdatePtr mapDepth(const sensor_msgs::ImageConstPtr& msg, const sensor_msgs::CameraInfoConstPtr& info,
                              const tf2::BufferCore& tf, const ros::Time& now, FrameResult* result);

  /// The last image's local grid, drawn and blurred (for the local cloud).
  const LocalGrid& grid() const { return grid_; }
  const FrameCounters& counters() const { return counters_; }
  /// Why the current camera set-up cannot be mapped; empty if it can.
  const std::string& refusedSetup() const { return refused_setup_; }
  /// From now on adds each stage's time (input, the drawer's stages,
  /// encoding, message) to @p times; null: no timing (the default).
  void setStageTimes(StageTimes* times);

 private:
  /// The common path once the image is a CV_32FC1 disparity of @p camera;
  /// stops @p input (the input stage's timer) where the drawing begins.
  OccupancyUpdatePtr mapDisparity(const cv::Mat& disparity, const std_msgs::Header& header,
                                  const StereoCameraConfig& camera, const tf2::BufferCore& tf, const ros::Time& now,
                                  FrameResult* result, StageTimer* input);
  /// A drawer for @p camera, built when the camera or the parameters changed;
  /// null, with why in @p result, if the set-up is refused.
  DisparityDrawer* drawerFor(const StereoCameraConfig& camera, FrameResult* result);
  /// Counts the outcome; returns null for the caller to return.
  OccupancyUpdatePtr finish(FrameOutcome outcome, std::string why, FrameResult* result);

  DisparityMapperParameters params_;
  std::unique_ptr<DisparityDrawer> drawer_;
  /// Why no drawer could be built for refused_camera_ (empty: none refused).
  std::string refused_setup_;
  StereoCameraConfig refused_camera_;
  LocalGrid grid_;
  cv::Mat depth_disparity_;                ///< the depth path's disparity image, reused
  size_t last_cells_ = 0, last_runs_ = 0;  ///< the last update's sizes: the next one's arrays reserve as much
  FrameCounters counters_;
  StageTimes* stage_times_ = nullptr;  ///< setStageTimes()
};

/// Updates received by MapFusion and what became of them.
struct FusionCounters {
  uint64_t received = 0;
  uint64_t refused = 0;
  uint64_t leaves_pruned = 0;  ///< dropped for good beyond max_extent_m (no database)
  uint64_t tiles_stored = 0;   ///< moved to the database beyond max_extent_m
  /// Updates that never arrived: gaps in their publishers' sequence numbers
  /// (a queue that overflowed while the accumulator was busy, a lossy link).
  uint64_t lost = 0;
};

/// Update -> checks -> fuse (MapAccumulator), reading the message in place.
class MapFusion {
 public:
  /// @param params valid parameters (OctomapAccumulatorParameters::isValid()).
  explicit MapFusion(const OctomapAccumulatorParameters& params);

  /// Fuses @p msg if it is in the map's frame and MapAccumulator::admits()
  /// it; otherwise false, the map unchanged, and why. Every prune_period_s of
  /// update stamps, moves what lies beyond max_extent_m to the database, or
  /// without one drops it (MissionMap::maintain). Counts the updates of
  /// @p publisher's msg.source lost before this one (the gaps in their
  /// sequence numbers).
  bool fuse(const OccupancyUpdate& msg, std::string* why, const std::string& publisher = "");

  /// Keeps the mission's tiles in the SQLite database at @p path (TileStore):
  /// created if missing, continued if there.
  /// @throws std::runtime_error (locked, unreadable, another resolution); the map then works without one.
  void openDatabase(const std::string& path);
  /// The live map (around the vehicle).
  const MapAccumulator& map() const { return mission_.live(); }
  /// The live map and the database.
  MissionMap& mission() { return mission_; }
  /// Empties the map and the database (the frame stays).
  void reset();
  /// Starts over from the map in @p path (MapAccumulator::load).
  /// @throws std::runtime_error; the map is then unchanged.
  void load(const std::string& path);
  /// MapAccumulator::takeChangedBlocks() and markAllChanged(): what the outputs must send again.
  std::vector<MapAccumulator::BlockIndex> takeChangedBlocks(bool* all) {
    return mission_.live().takeChangedBlocks(all);
  }
  void markAllChanged() { mission_.live().markAllChanged(); }
  /// Leaves no occupied cell in the box, in the store's tiles too (MissionMap::clearBox); returns how many were
  /// cleared.
  size_t clearBox(const Eigen::Vector3d& W_min, const Eigen::Vector3d& W_max) {
    return mission_.clearBox(W_min, W_max);
  }
  /// Turns on the live map's class-change recording (MapAccumulator::recordClassChanges), kept
  /// across reset() and load(): for the distance field (ros/distance_field_server.h).
  void recordClassChanges() {
    record_class_changes_ = true;
    mission_.live().recordClassChanges(true);
  }
  /// MapAccumulator::takeClassChanges(): the cells whose class the fusion changed since the last call, and the
  /// regions where anything else changed the live map (the mission's tiles, prune, clearBox).
  std::vector<CellClassChange> takeClassChanges(bool* all, std::vector<CellBox>* regions) {
    return mission_.live().takeClassChanges(all, regions);
  }
  /// The camera centre of the last fused update, map frame [m] (the vehicle's position).
  const Eigen::Vector3d& lastSensorOrigin() const { return last_sensor_origin_; }
  /// The map's frame: world_frame, or (world_frame "") the first fused update's; "" before it.
  const std::string& frameId() const { return frame_id_; }
  /// The stamp of the last fused update.
  const ros::Time& lastStamp() const { return last_stamp_; }
  const FusionCounters& counters() const { return counters_; }
  /// From now on adds the fusion's and the maintenance's time to @p times; null: no timing (the default).
  void setStageTimes(StageTimes* times) { stage_times_ = times; }

 private:
  bool refuse(const std::string& text, std::string* why);
  void countLost(const OccupancyUpdate& msg, const std::string& publisher);

  OctomapAccumulatorParameters params_;
  MissionMap mission_;
  std::string frame_id_;
  ros::Time last_stamp_;
  Eigen::Vector3d last_sensor_origin_ = Eigen::Vector3d::Zero();
  bool record_class_changes_ = false;
  ros::Time last_prune_;  ///< stamp of the update at the last prune
  FusionCounters counters_;
  StageTimes* stage_times_ = nullptr;              ///< setStageTimes()
  std::map<std::string, uint64_t> last_sequence_;  ///< per publisher and source
};

}  // namespace stereo_occupancy
