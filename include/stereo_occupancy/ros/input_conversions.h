#pragma once
/// @file
/// The input messages and the core's types: a disparity image, a depth
/// camera's camera_info and a tf transform to the camera, its pose and its
/// image (and back, for the tools and tests that synthesise the inputs).

#include <geometry_msgs/TransformStamped.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <stereo_msgs/DisparityImage.h>

#include <Eigen/Geometry>
#include <cstdint>
#include <string>

#include "stereo_occupancy/ros/parameters.h"
#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

/// True if the image message can be read safely: a known encoding, width and
/// height > 0, at most @p max_pixels pixels, a step that holds a row and data
/// that hold step·height bytes. Otherwise false and the reason in @p why.
bool checkImageLayout(const sensor_msgs::Image& image, uint64_t max_pixels, std::string* why);

/// True if @p info can give @p msg's principal point (cameraFromDisparityImage()):
/// the same size and a rectified projection (P[0] > 0); else what differs in @p why.
bool cameraInfoFits(const stereo_msgs::DisparityImage& msg, const sensor_msgs::CameraInfo& info, std::string* why);

/// The camera of a DisparityImage: f and T (baseline) and the valid disparity
/// interval from the message, the size from its image, Δd = max(delta_d_px,
/// the message's delta_d), the principal point from @p info when given, else
/// from the parameters (or the image centre), range limits from the
/// parameters. False, with the reason, if the message's numbers are unusable.
bool cameraFromDisparityImage(const stereo_msgs::DisparityImage& msg, const sensor_msgs::CameraInfo* info,
                              const DisparityMapperParameters& params, StereoCameraConfig* camera, std::string* why);

/// The camera of a depth image: f, cx, cy from @p info, b from the parameters.
bool cameraFromDepthInfo(const sensor_msgs::CameraInfo& info, const DisparityMapperParameters& params,
                         StereoCameraConfig* camera, std::string* why);

/// T_W_C from a tf2 transform of the camera frame into the world frame; false
/// if it is not finite or its quaternion is not of unit norm (±1e-3).
bool poseFromTransform(const geometry_msgs::TransformStamped& transform, Eigen::Isometry3d* T_W_C);

/// A tf2 transform message of the pose T (child frame in the parent frame).
geometry_msgs::TransformStamped toTransformMsg(const Eigen::Isometry3d& T, const ros::Time& stamp,
                                               const std::string& parent, const std::string& child);

/// A stereo_msgs/DisparityImage holding a copy of a CV_32FC1 disparity image
/// [px], with the camera's f and b, a matcher's search range [0, max] and its
/// disparity step delta_d (as stereo_image_proc fills them).
void toDisparityImageMsg(const cv::Mat& disparity, const std_msgs::Header& header, const StereoCameraConfig& camera,
                         double max_disparity_px, double delta_d_px, stereo_msgs::DisparityImage* msg);

}  // namespace stereo_occupancy
