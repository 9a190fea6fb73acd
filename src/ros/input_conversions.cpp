#include "stereo_occupancy/ros/input_conversions.h"

#include <sensor_msgs/image_encodings.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace stereo_occupancy {

bool checkImageLayout(const sensor_msgs::Image& image, uint64_t max_pixels, std::string* why) {
  auto fail = [why](const std::string& text) {
    if (why) *why = text;
    return false;
  };
  uint64_t bytes_per_pixel = 0;
  try {
    namespace enc = sensor_msgs::image_encodings;
    bytes_per_pixel = static_cast<uint64_t>(enc::numChannels(image.encoding)) * (enc::bitDepth(image.encoding) / 8);
  } catch (const std::exception&) {
    return fail("unknown encoding '" + image.encoding + "'");
  }
  if (bytes_per_pixel == 0) return fail("encoding '" + image.encoding + "' has no whole bytes per pixel");
  if (image.width == 0 || image.height == 0) return fail("empty image");
  const uint64_t pixels = static_cast<uint64_t>(image.width) * image.height;
  if (pixels > max_pixels)
    return fail("image of " + std::to_string(pixels) + " pixels, more than " + std::to_string(max_pixels));
  if (static_cast<uint64_t>(image.step) < image.width * bytes_per_pixel)
    return fail("step " + std::to_string(image.step) + " is shorter than a row");
  if (image.data.size() < static_cast<uint64_t>(image.step) * image.height)
    return fail("image size and data do not fit together (" + std::to_string(image.data.size()) + " bytes for " +
                std::to_string(image.height) + " rows of " + std::to_string(image.step) + ")");
  return true;
}

bool cameraInfoFits(const stereo_msgs::DisparityImage& msg, const sensor_msgs::CameraInfo& info, std::string* why) {
  if (info.width != msg.image.width || info.height != msg.image.height) {
    if (why)
      *why = "camera_info is " + std::to_string(info.width) + " x " + std::to_string(info.height) +
             " px, the disparity image " + std::to_string(msg.image.width) + " x " + std::to_string(msg.image.height);
    return false;
  }
  if (!(info.P[0] > 0.0)) {
    if (why) *why = "camera_info has no rectified projection (P[0] is not > 0)";
    return false;
  }
  return true;
}

bool cameraFromDisparityImage(const stereo_msgs::DisparityImage& msg, const sensor_msgs::CameraInfo* info,
                              const DisparityMapperParameters& params, StereoCameraConfig* camera, std::string* why) {
  StereoCameraConfig c = params.camera;
  c.width_px = static_cast<int>(msg.image.width);
  c.height_px = static_cast<int>(msg.image.height);
  c.focal_length_px = msg.f;
  c.baseline_m = msg.T;
  c.delta_d_px = std::max(params.camera.delta_d_px, static_cast<double>(msg.delta_d));
  c.min_disparity_px = std::max(0.0, static_cast<double>(msg.min_disparity));
  c.max_disparity_px = msg.max_disparity > msg.min_disparity ? static_cast<double>(msg.max_disparity)
                                                             : std::numeric_limits<double>::infinity();
  if (info && cameraInfoFits(msg, *info, nullptr)) {
    c.cx_px = info->P[2];
    c.cy_px = info->P[6];
  } else {
    c.cx_px = params.cx_px >= 0.0 ? params.cx_px : 0.5 * (c.width_px - 1);
    c.cy_px = params.cy_px >= 0.0 ? params.cy_px : 0.5 * (c.height_px - 1);
  }
  if (!std::isfinite(msg.delta_d) || msg.delta_d < 0.0f) {
    if (why) *why = "delta_d is not finite and >= 0";
    return false;
  }
  std::string reason;
  if (!c.isValid(&reason)) {
    if (why)
      *why = "camera from the message: " + reason + " (f = " + std::to_string(msg.f) +
             " px, T = " + std::to_string(msg.T) + " m)";
    return false;
  }
  *camera = c;
  return true;
}

bool cameraFromDepthInfo(const sensor_msgs::CameraInfo& info, const DisparityMapperParameters& params,
                         StereoCameraConfig* camera, std::string* why) {
  StereoCameraConfig c = params.camera;
  c.width_px = static_cast<int>(info.width);
  c.height_px = static_cast<int>(info.height);
  const bool rectified = info.P[0] > 0.0;
  c.focal_length_px = rectified ? info.P[0] : info.K[0];
  c.cx_px = rectified ? info.P[2] : info.K[2];
  c.cy_px = rectified ? info.P[6] : info.K[5];
  c.baseline_m = params.depth_baseline_m;
  std::string reason;
  if (!c.isValid(&reason)) {
    if (why) *why = "camera from camera_info: " + reason;
    return false;
  }
  *camera = c;
  return true;
}

bool poseFromTransform(const geometry_msgs::TransformStamped& transform, Eigen::Isometry3d* T_W_C) {
  const auto& t = transform.transform.translation;
  const auto& q = transform.transform.rotation;
  const Eigen::Quaterniond quat(q.w, q.x, q.y, q.z);
  const Eigen::Vector3d trans(t.x, t.y, t.z);
  if (!trans.allFinite() || !quat.coeffs().allFinite() || std::abs(quat.norm() - 1.0) > 1e-3) return false;
  T_W_C->setIdentity();
  T_W_C->linear() = quat.normalized().toRotationMatrix();
  T_W_C->translation() = trans;
  return true;
}

geometry_msgs::TransformStamped toTransformMsg(const Eigen::Isometry3d& T, const ros::Time& stamp,
                                               const std::string& parent, const std::string& child) {
  geometry_msgs::TransformStamped t;
  t.header.stamp = stamp;
  t.header.frame_id = parent;
  t.child_frame_id = child;
  const Eigen::Quaterniond q(T.linear());
  t.transform.translation.x = T.translation().x();
  t.transform.translation.y = T.translation().y();
  t.transform.translation.z = T.translation().z();
  t.transform.rotation.x = q.x();
  t.transform.rotation.y = q.y();
  t.transform.rotation.z = q.z();
  t.transform.rotation.w = q.w();
  return t;
}

void toDisparityImageMsg(const cv::Mat& disparity, const std_msgs::Header& header, const StereoCameraConfig& camera,
                         double max_disparity_px, double delta_d_px, stereo_msgs::DisparityImage* msg) {
  CV_Assert(disparity.type() == CV_32FC1);
  msg->header = header;
  msg->image.header = header;
  msg->image.width = disparity.cols;
  msg->image.height = disparity.rows;
  msg->image.encoding = sensor_msgs::image_encodings::TYPE_32FC1;
  msg->image.is_bigendian = false;
  msg->image.step = disparity.cols * sizeof(float);
  msg->image.data.resize(static_cast<size_t>(msg->image.step) * disparity.rows);
  for (int y = 0; y < disparity.rows; ++y)
    std::memcpy(&msg->image.data[static_cast<size_t>(y) * msg->image.step], disparity.ptr<float>(y), msg->image.step);
  msg->f = static_cast<float>(camera.focal_length_px);
  msg->T = static_cast<float>(camera.baseline_m);
  msg->min_disparity = 0.0f;
  msg->max_disparity = static_cast<float>(max_disparity_px);
  msg->delta_d = static_cast<float>(delta_d_px);
  msg->valid_window.width = disparity.cols;
  msg->valid_window.height = disparity.rows;
}

}  // namespace stereo_occupancy
