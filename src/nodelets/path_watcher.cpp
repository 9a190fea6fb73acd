// stereo_occupancy/PathWatcher: the example of a planner nodelet that reads
// the accumulator's distance field in place, without messages: every
// period_s it checks a path from its parameters against the live field
// (DistanceFieldRegistry, SharedDistanceField::read) and publishes the
// verdict on path_verdict, logging it when it changes.
//
// Transport only: the parameters are ros/parameters.h's, the check the
// core's DistanceField::checkPath.

#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <pluginlib/class_list_macros.hpp>

#include <boost/make_shared.hpp>

#include <memory>
#include <string>
#include <vector>

#include "stereo_occupancy/PathCheck.h"
#include "stereo_occupancy/ros/distance_field_server.h"
#include "stereo_occupancy/ros/parameters.h"

namespace stereo_occupancy {

namespace {
/// At most one warning of a kind in this time [s].
constexpr double kWarnThrottleS = 5.0;
const char* const kVerdictNames[] = {"clear", "blocked", "unknown"};
}  // namespace

class PathWatcher : public nodelet::Nodelet {
 private:
  void onInit() override;
  void check();

  PathWatcherParameters params_;
  std::vector<Eigen::Vector3d> W_waypoints_;
  // The timer's callbacks run one at a time (a ros::Timer does not overlap itself).
  std::shared_ptr<SharedDistanceField> field_;
  int last_verdict_ = -1;
  ros::Publisher verdict_pub_;
  ros::Timer timer_;
};

void PathWatcher::onInit() {
  ros::NodeHandle& nh = getNodeHandle();
  std::string why;
  if (!loadParameters(getPrivateNodeHandle(), &params_, &why) ||
      !parseWaypoints(params_.waypoints, &W_waypoints_, &why)) {
    NODELET_FATAL("%s: invalid parameter: %s; PathWatcher does not start", getName().c_str(), why.c_str());
    return;
  }
  verdict_pub_ = nh.advertise<PathCheck>("path_verdict", 1, /*latch=*/true);
  timer_ = nh.createTimer(ros::Duration(params_.period_s), [this](const ros::TimerEvent&) { check(); });
  NODELET_INFO("PathWatcher: %zu waypoints, radius %.2f m, reading the distance field of %s every %.2f s",
               W_waypoints_.size(), params_.radius_m, params_.accumulator.c_str(), params_.period_s);
}

void PathWatcher::check() {
  // The accumulator may load after this nodelet, or be unloaded and loaded again.
  if (!field_ || !field_->alive()) field_ = DistanceFieldRegistry::find(params_.accumulator);
  if (!field_) {
    NODELET_WARN_THROTTLE(kWarnThrottleS,
                          "no distance field of '%s' in this process (not loaded yet, or its "
                          "distance_field is off)",
                          params_.accumulator.c_str());
    return;
  }
  auto msg = boost::make_shared<PathCheck>();
  std::string error;
  // In place, under the field's shared lock: no copy, no message, no service round trip.
  const bool ready = field_->read([&](const DistanceField& field, const DistanceFieldInfo& info) {
    if (info.updates == 0) return false;
    msg->header.frame_id = info.frame_id;
    msg->header.stamp = info.stamp;
    try {
      const PathCheckResult r = field.checkPath(W_waypoints_, params_.radius_m, params_.unknown_as_occupied);
      msg->verdict = static_cast<uint8_t>(r.verdict);
      msg->first_segment = r.first_segment;
      msg->point.x = r.W_point.x();
      msg->point.y = r.W_point.y();
      msg->point.z = r.W_point.z();
      msg->min_clearance_m = r.min_clearance_m;
    } catch (const std::exception& e) {  // a radius above the field's max_distance_m
      error = e.what();
    }
    return true;
  });
  if (!ready) return;  // the field has not seen an update yet
  if (!error.empty()) {
    NODELET_ERROR_THROTTLE(kWarnThrottleS, "path check refused: %s", error.c_str());
    return;
  }
  if (msg->verdict != last_verdict_) {
    NODELET_INFO("path %s (first segment %ld at (%.2f, %.2f, %.2f), clearance %.2f m)",
                 msg->verdict <= 2 ? kVerdictNames[msg->verdict] : "?", static_cast<long>(msg->first_segment),
                 msg->point.x, msg->point.y, msg->point.z, msg->min_clearance_m);
    last_verdict_ = msg->verdict;
  }
  verdict_pub_.publish(msg);
}

}  // namespace stereo_occupancy

PLUGINLIB_EXPORT_CLASS(stereo_occupancy::PathWatcher, nodelet::Nodelet)
