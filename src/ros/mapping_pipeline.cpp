#include "stereo_occupancy/ros/mapping_pipeline.h"

#include <sensor_msgs/image_encodings.h>
#include <tf2/exceptions.h>

#include <boost/make_shared.hpp>

#include <sstream>
#include <utility>

#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/ros/map_conversions.h"

namespace stereo_occupancy {

namespace {

/// Why an image gave an empty update: what its pixels hold, against the camera's limits.
std::string mappedNothingWhy(const StereoCameraModel& camera, const cv::Mat& disparity) {
  const DisparityCensus c = camera.census(disparity);
  const StereoCameraConfig& cfg = camera.config();
  std::ostringstream why;
  why << "the image mapped nothing: of its " << c.total() << " pixels " << c.no_match << " have no match, "
      << c.out_of_range << " lie outside the valid disparities [" << cfg.min_disparity_px << ", "
      << camera.nearDisparity() << "] px (the message's min_disparity / max_disparity and min_range_m), "
      << c.beyond_range + c.sky << " are beyond max_range_m = " << cfg.max_range_m << " m or sky, " << c.measured
      << " measure a range";
  if (c.out_of_range > c.measured)
    why << "; are the cameras' principal points or the matcher's disparity range set as the images need?";
  return why.str();
}

}  // namespace

FrameMapping::FrameMapping(const DisparityMapperParameters& params) : params_(params) {}

void FrameMapping::setParameters(const DisparityMapperParameters& params) {
  params_ = params;
  drawer_.reset();  // rebuilt with the new tables on the next image
  refused_setup_.clear();
}

OccupancyUpdatePtr FrameMapping::finish(FrameOutcome outcome, std::string why, FrameResult* result) {
  result->outcome = outcome;
  result->why = std::move(why);
  if (outcome == FrameOutcome::kNoTransform) ++counters_.no_transform;
  if (outcome == FrameOutcome::kRefused) ++counters_.refused;
  return nullptr;
}

OccupancyUpdatePtr FrameMapping::map(const stereo_msgs::DisparityImageConstPtr& msg,
                                     const sensor_msgs::CameraInfoConstPtr& info, const tf2::BufferCore& tf,
                                     const ros::Time& now, FrameResult* result) {
  StageTimer input(stage_times_, PathStage::kInput);
  *result = FrameResult();
  ++counters_.images;
  if (msg->image.encoding != sensor_msgs::image_encodings::TYPE_32FC1)
    return finish(FrameOutcome::kRefused, "encoding '" + msg->image.encoding + "', expected 32FC1", result);
  std::string why;
  if (!checkImageLayout(msg->image, static_cast<uint64_t>(params_.max_image_pixels), &why))
    return finish(FrameOutcome::kRefused, why, result);
  StereoCameraConfig camera;
  if (!cameraFromDisparityImage(*msg, info.get(), params_, &camera, &why))
    return finish(FrameOutcome::kRefused, why, result);
  if (info && !cameraInfoFits(*msg, *info, &result->info_mismatch)) {
    ++counters_.info_mismatch;
    result->info_mismatch += ": its principal point is not used, (" + std::to_string(camera.cx_px) + ", " +
                             std::to_string(camera.cy_px) + ") px is (cx_px, cy_px or the image's centre)";
  }
  try {
    const cv_bridge::CvImageConstPtr image = cv_bridge::toCvShare(msg->image, msg);  // a view, no copy
    return mapDisparity(image->image, msg->header, camera, tf, now, result, &input);
  } catch (const std::exception& e) {  // cv_bridge, bad_alloc: one image fails, the pipeline goes on
    return finish(FrameOutcome::kRefused, std::string("mapping failed: ") + e.what(), result);
  }
}

OccupancyUpdatePtr FrameMapping::mapDepth(const sensor_msgs::ImageConstPtr& msg,
                                          const sensor_msgs::CameraInfoConstPtr& info, const tf2::BufferCore& tf,
                                          const ros::Time& now, FrameResult* result) {
  StageTimer input(stage_times_, PathStage::kInput);
  *result = FrameResult();
  ++counters_.images;
  if (!info) return finish(FrameOutcome::kRefused, "no camera_info received yet", result);
  if (info->width != msg->width || info->height != msg->height)
    return finish(FrameOutcome::kRefused, "camera_info size differs from the depth image's", result);
  std::string why;
  if (!checkImageLayout(*msg, static_cast<uint64_t>(params_.max_image_pixels), &why))
    return finish(FrameOutcome::kRefused, why, result);
  StereoCameraConfig camera;
  if (!cameraFromDepthInfo(*info, params_, &camera, &why)) return finish(FrameOutcome::kRefused, why, result);
  try {
    const cv_bridge::CvImageConstPtr depth = cv_bridge::toCvShare(msg);
    depthToDisparity(depth->image, camera.baseline_m * camera.focal_length_px, &depth_disparity_);
    return mapDisparity(depth_disparity_, msg->header, camera, tf, now, result, &input);
  } catch (const std::exception& e) {
    return finish(FrameOutcome::kRefused, std::string("mapping failed: ") + e.what(), result);
  }
}

OccupancyUpdatePtr FrameMapping::mapDisparity(const cv::Mat& disparity, const std_msgs::Header& header,
                                              const StereoCameraConfig& camera, const tf2::BufferCore& tf,
                                              const ros::Time& now, FrameResult* result, StageTimer* input) {
  // tf2 reads time 0 as "the latest pose": the image would be drawn where
  // the camera is now, not where it was.
  if (header.stamp.isZero()) return finish(FrameOutcome::kRefused, "image stamped 0 (no time, no pose)", result);
  const double age_s = (now - header.stamp).toSec();
  if (params_.tf_timeout_s > 0.0 && age_s > params_.tf_timeout_s)
    return finish(FrameOutcome::kNoTransform,
                  "transform came " + std::to_string(age_s) + " s after the image (tf_timeout_s)", result);
  geometry_msgs::TransformStamped transform;
  try {
    transform = tf.lookupTransform(params_.world_frame, header.frame_id, header.stamp);
  } catch (const tf2::TransformException& e) {
    return finish(FrameOutcome::kNoTransform, e.what(), result);
  }
  Eigen::Isometry3d T_W_C;
  if (!poseFromTransform(transform, &T_W_C))
    return finish(FrameOutcome::kRefused, "camera pose is not finite or its quaternion not of unit norm", result);
  DisparityDrawer* drawer = drawerFor(camera, result);
  if (!drawer) return finish(FrameOutcome::kRefused, refused_setup_, result);
  input->stop();
  try {
    drawer->draw(disparity, T_W_C, &grid_);
  } catch (const std::invalid_argument& e) {
    return finish(FrameOutcome::kRefused, e.what(), result);
  }
  GridUpdate update;
  {
    const StageTimer timer(stage_times_, PathStage::kEncoding);
    update.log_odds.reserve(last_cells_);
    update.run_start.reserve(last_runs_);
    update.run_length.reserve(last_runs_);
    drawer->encode(grid_, T_W_C.translation(), &update);
    last_cells_ = update.log_odds.size();
    last_runs_ = update.run_start.size();
  }
  StageTimer message(stage_times_, PathStage::kMessage);
  auto msg = boost::make_shared<OccupancyUpdate>();
  std_msgs::Header out_header = header;
  out_header.frame_id = params_.world_frame;
  toMsg(std::move(update), out_header, msg.get());
  ++counters_.mapped;
  msg->sequence = counters_.mapped;  // the accumulator counts the gaps
  result->outcome = FrameOutcome::kMapped;
  if (msg->log_odds.empty()) {
    ++counters_.mapped_nothing;
    result->mapped_nothing = true;
    result->why = mappedNothingWhy(drawer->camera(), disparity);
  }
  return msg;
}

DisparityDrawer* FrameMapping::drawerFor(const StereoCameraConfig& camera, FrameResult* result) {
  if (drawer_ && drawer_->camera().config() == camera) return drawer_.get();
  // A set-up the drawer refuses (e.g. a grid too fine for this camera's focal
  // length) is tried once; its images are refused until the camera or the
  // parameters change.
  if (!refused_setup_.empty() && refused_camera_ == camera) return nullptr;
  try {
    drawer_ = std::make_unique<DisparityDrawer>(camera, params_.drawing);  // builds the lookup tables
    drawer_->setStageTimes(stage_times_);
    refused_setup_.clear();
    return drawer_.get();
  } catch (const std::invalid_argument& e) {
    drawer_.reset();
    refused_setup_ = e.what();
    refused_camera_ = camera;
    result->setup_refused_now = true;
    return nullptr;
  }
}

void FrameMapping::setStageTimes(StageTimes* times) {
  stage_times_ = times;
  if (drawer_) drawer_->setStageTimes(times);
}

MapFusion::MapFusion(const OctomapAccumulatorParameters& params)
    : params_(params), mission_(params.map), frame_id_(params.world_frame) {}

void MapFusion::openDatabase(const std::string& path) {
  mission_.attachStore(std::make_shared<TileStore>(path, params_.map.resolution_m));
}

bool MapFusion::refuse(const std::string& text, std::string* why) {
  ++counters_.refused;
  if (why) *why = text;
  return false;
}

bool MapFusion::fuse(const OccupancyUpdate& msg, std::string* why, const std::string& publisher) {
  ++counters_.received;
  countLost(msg, publisher);
  if (!frame_id_.empty() && msg.header.frame_id != frame_id_)
    return refuse("frame '" + msg.header.frame_id + "', the map is in '" + frame_id_ + "'", why);
  GridUpdateView update;
  std::string reason;
  StageTimer fusion(stage_times_, PathStage::kFusion);
  if (!viewOf(msg, &update, &reason) || !mission_.integrate(update, &reason)) return refuse(reason, why);
  fusion.stop();
  if (frame_id_.empty()) frame_id_ = msg.header.frame_id;  // world_frame "": the first update's, from then on
  last_stamp_ = msg.header.stamp;
  last_sensor_origin_ = Eigen::Vector3d(msg.sensor_origin.x, msg.sensor_origin.y, msg.sensor_origin.z);
  // Pruning follows the updates' time, so that a replay prunes where the flight did.
  if (last_prune_.isZero() || last_stamp_ < last_prune_) last_prune_ = last_stamp_;
  // The merges of equal leaves (compress_map) are spread over the next
  // updates: all at once, they and their frees held one update for ~10 ms.
  if ((last_stamp_ - last_prune_).toSec() > params_.prune_period_s) {
    const StageTimer timer(stage_times_, PathStage::kMaintenance);
    const MaintainResult kept = mission_.maintain(MergeTiming::kSpread);
    counters_.leaves_pruned += kept.leaves_dropped;
    counters_.tiles_stored += kept.tiles_stored;
    last_prune_ = last_stamp_;
  } else if (mission_.mergesQueued()) {
    const StageTimer timer(stage_times_, PathStage::kMaintenance);
    mission_.mergeStep();
  }
  return true;
}

void MapFusion::countLost(const OccupancyUpdate& msg, const std::string& publisher) {
  if (msg.sequence == 0) return;  // not counted by its source
  // Nodelets in one manager share its node name: the source tells them apart.
  uint64_t& last = last_sequence_[publisher + " " + msg.source];
  const uint64_t sequence = msg.sequence;
  // A sequence that goes back is a restarted mapper, not a loss.
  if (last > 0 && sequence > last + 1) counters_.lost += sequence - last - 1;
  last = sequence;
}

void MapFusion::reset() {
  mission_.reset();
  if (record_class_changes_) mission_.live().recordClassChanges(true);
}

void MapFusion::load(const std::string& path) {
  mission_.load(path);
  if (record_class_changes_) mission_.live().recordClassChanges(true);
}

}  // namespace stereo_occupancy
