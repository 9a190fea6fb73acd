#pragma once
// A camera's 8-bit grey image as the driver would publish it (image_raw),
// for the rostests that feed stereo_image_proc.

#include <cv_bridge/cv_bridge.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>

#include <opencv2/core.hpp>

namespace stereo_occupancy {

/// @p gray (CV_8UC1) as a mono8 sensor_msgs/Image with @p header.
inline sensor_msgs::ImagePtr monoMsg(const cv::Mat& gray, const std_msgs::Header& header) {
  return cv_bridge::CvImage(header, sensor_msgs::image_encodings::MONO8, gray).toImageMsg();
}

}  // namespace stereo_occupancy
