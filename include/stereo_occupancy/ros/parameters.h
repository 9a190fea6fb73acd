#pragma once
/// @file
/// The one place that reads the parameter server: one struct per nodelet,
/// built from core config structs, validated on load.

#include <ros/node_handle.h>

#include <map>
#include <string>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

/// Parameters of the DisparityMapper nodelet (names as in config/*.yaml).
struct DisparityMapperParameters {
  std::string world_frame = "map";  ///< REP-105 world-fixed frame the grid is aligned with
  /// An image whose pose is known only later than this after its stamp is dropped; 0: never [s].
  double tf_timeout_s = 1.0;
  int queue_size = 5;               ///< images waiting for their transform; the oldest is dropped
  bool use_depth = false;           ///< subscribe depth + camera_info instead of disparity
  double depth_baseline_m = 0.05;   ///< baseline b of a depth camera (eq. 4 with d = bf/z) [m]
  double cx_px = -1.0;              ///< principal point when no camera_info came; < 0: image centre [px]
  double cy_px = -1.0;
  int max_image_pixels = 4096 * 4096;  ///< larger images are refused
  /// Range limits and Δd; size, f, b, cx, cy come with each image.
  StereoCameraConfig camera;
  /// The core's drawing defaults, but for the profile: the mapper draws the
  /// surface profile (docs/quality.md), the paper's Gaussian stays selectable.
  DrawingConfig drawing = surfaceDrawing();

  static DrawingConfig surfaceDrawing() {
    DrawingConfig d;
    d.sensor_model.profile = SensorProfile::kSurface;
    return d;
  }

  bool isValid(std::string* why) const;
};

/// Parameters of the OctomapAccumulator nodelet.
struct OctomapAccumulatorParameters {
  /// The map's frame: updates in any other frame are refused; "": the first update's.
  std::string world_frame = "map";
  MapAccumulatorConfig map;
  double publish_rate_hz = 1.0;  ///< rate of the map outputs, while subscribed [Hz]
  double prune_period_s = 5.0;   ///< how often cells beyond max_extent_m are dropped [s]
  std::string save_dir;          ///< where ~save_map writes (and the map is saved on shutdown); empty: nowhere
  std::string map_name = "stereo_occupancy_map";  ///< file base name in save_dir
  double save_period_s = 0.0;    ///< also save every this many seconds when the map changed; 0: only on request/shutdown

  bool isValid(std::string* why) const;
};

/// Reads private parameters into @p params (defaults for missing ones) and
/// validates them; false with a message naming the parameter and its valid
/// range in @p why.
bool loadParameters(const ros::NodeHandle& private_nh, DisparityMapperParameters* params, std::string* why);
bool loadParameters(const ros::NodeHandle& private_nh, OctomapAccumulatorParameters* params, std::string* why);

/// The same from name=value pairs (the offline tools): the names of both
/// nodelets' parameters (a name both have, such as resolution_m, sets both).
/// Unknown names and unreadable values are errors.
bool loadParameters(const std::map<std::string, std::string>& values, DisparityMapperParameters* mapper,
                    OctomapAccumulatorParameters* accumulator, std::string* why);

}  // namespace stereo_occupancy
