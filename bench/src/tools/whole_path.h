#pragma once
// The nodelets' whole path offline, image in to map fused, for the
// benchmarks that time it (performance --stages, compare_wavemap), and the
// same frames as the peers take them (OctoMap's point cloud, a depth image).

#include <octomap/octomap.h>
#include <ros/time.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2/buffer_core.h>

#include <boost/make_shared.hpp>

#include <limits>
#include <string>

#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/ros/mapping_pipeline.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "stereo_occupancy/stage_times.h"

namespace stereo_occupancy {
namespace tools {

/// FrameMapping and MapFusion with the nodelets' defaults on @p threads
/// threads, fed as the nodelets are: a DisparityImage and its pose on tf.
class WholePath {
 public:
  explicit WholePath(int threads) : mapping_(mapperParameters(threads)), fusion_(accumulatorParameters(threads)) {}

  /// Frame @p frame of @p scenario, whose image is @p disparity
  /// (renderStereoFrame()), as a camera driver publishes it, its pose on tf
  /// at the k-th stamp (untimed: the driver's and tf's work).
  stereo_msgs::DisparityImageConstPtr prepare(const FlightScenario& scenario, size_t frame, const cv::Mat& disparity,
                                              size_t k) {
    const ros::Time stamp = ros::Time(1000.0) + ros::Duration(0.1 * static_cast<double>(k));
    tf_.setTransform(toTransformMsg(scenario.T_W_B[frame], stamp, "map", "base_link"), "bench");
    tf_.setTransform(toTransformMsg(scenario.T_B_C, stamp, "base_link", "camera_optical"), "bench");
    std_msgs::Header header;
    header.stamp = stamp;
    header.frame_id = "camera_optical";
    auto msg = boost::make_shared<stereo_msgs::DisparityImage>();
    toDisparityImageMsg(disparity, header, scenario.camera, scenario.effects.max_search_disparity_px,
                        scenario.effects.subpixel_step_px, msg.get());
    return msg;
  }

  /// Maps @p image and fuses its update; each stage's time is added to
  /// @p times (may be null). False if the image or the update was refused.
  bool run(const stereo_msgs::DisparityImageConstPtr& image, StageTimes* times) {
    mapping_.setStageTimes(times);
    fusion_.setStageTimes(times);
    FrameResult result;
    std::string why;
    const OccupancyUpdatePtr update = mapping_.map(image, nullptr, tf_, image->header.stamp, &result);
    return update && fusion_.fuse(*update, &why);
  }

  const DisparityMapperParameters& mapper() const { return mapping_.parameters(); }
  const MapFusion& fusion() const { return fusion_; }

 private:
  static DisparityMapperParameters mapperParameters(int threads) {
    DisparityMapperParameters p;
    p.drawing.threads = threads;
    return p;
  }
  static OctomapAccumulatorParameters accumulatorParameters(int threads) {
    OctomapAccumulatorParameters p;
    p.map.threads = threads;
    p.map.resolution_m = mapperParameters(threads).drawing.resolution_m;
    return p;
  }

  tf2::BufferCore tf_{ros::Duration(1e6)};  // every pose of the run
  FrameMapping mapping_;
  MapFusion fusion_;
};

/// OctoMap's input for @p disparity: every matched pixel's point in the
/// world; the sky (zero disparity) as a point at twice the range, whose ray
/// OctoMap draws free up to the range.
inline octomap::Pointcloud disparityCloud(const cv::Mat& disparity, const StereoCameraConfig& camera,
                                          const Eigen::Isometry3d& T_W_C) {
  const StereoCameraModel model(camera);
  octomap::Pointcloud cloud;
  for (int y = 0; y < disparity.rows; ++y)
    for (int x = 0; x < disparity.cols; ++x) {
      const float d = disparity.at<float>(y, x);
      if (!(d >= 0.0f)) continue;
      const Eigen::Vector3d C_p = d > 0.0f ? model.pointFromDisparity(x, y, d)
                                           : Eigen::Vector3d(model.rayThroughPixel(x, y) * 2.0 * camera.max_range_m);
      const Eigen::Vector3d W_p = T_W_C * C_p;
      cloud.push_back(static_cast<float>(W_p.x()), static_cast<float>(W_p.y()), static_cast<float>(W_p.z()));
    }
  return cloud;
}

/// A depth image [m] (CV_32FC1) for @p disparity: z = b·f / d (eq. 1);
/// infinity for zero disparity (the sky), 0 for no match.
inline cv::Mat depthFromDisparity(const cv::Mat& disparity, const StereoCameraConfig& camera) {
  const double bf = camera.baseline_m * camera.focal_length_px;
  cv::Mat depth(disparity.size(), CV_32FC1);
  for (int y = 0; y < disparity.rows; ++y)
    for (int x = 0; x < disparity.cols; ++x) {
      const float d = disparity.at<float>(y, x);
      depth.at<float>(y, x) = d > 0.0f    ? static_cast<float>(bf / d)
                              : d == 0.0f ? std::numeric_limits<float>::infinity()
                                          : 0.0f;
    }
  return depth;
}

}  // namespace tools
}  // namespace stereo_occupancy
