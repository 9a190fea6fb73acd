#pragma once
/// @file
/// The one place that reads the parameter server: one struct per nodelet,
/// built from its components' config structs (the core's, MapPublisherConfig,
/// MapSaverConfig), validated on load.

#include <dynamic_reconfigure/Config.h>
#include <ros/node_handle.h>

#include <map>
#include <set>
#include <string>
#include <vector>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/ros/distance_field_server.h"
#include "stereo_occupancy/ros/map_publisher.h"
#include "stereo_occupancy/ros/map_saver.h"
#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

/// Parameters of the DisparityMapper nodelet (names as in config/*.yaml).
struct DisparityMapperParameters {
  std::string world_frame = "map";  ///< REP-105 world-fixed frame the grid is aligned with
  /// An image whose pose is known only later than this after its stamp is dropped; 0: never [s].
  double tf_timeout_s = 1.0;
  int queue_size = 5;              ///< images waiting for their transform; the oldest is dropped
  bool use_depth = false;          ///< subscribe depth + camera_info instead of disparity
  double depth_baseline_m = 0.05;  ///< baseline b of a depth camera (eq. 4 with d = bf/z) [m]
  double cx_px = -1.0;             ///< principal point when no camera_info came; < 0: image centre [px]
  double cy_px = -1.0;
  int max_image_pixels = 4096 * 4096;  ///< larger images are refused
  /// Range limits and Δd; size, f, b, cx, cy come with each image.
  StereoCameraConfig camera;
  /// The mapper's drawing defaults (the surface profile; the paper's
  /// Gaussian stays selectable).
  DrawingConfig drawing = DrawingConfig::mapperDefaults();

  /// The parameters (stereo_occupancy/parameter_table.h): f(spec, member)
  /// for each, the drawing's included.
  template <typename Self, typename F>
  static void forEachParameter(Self& p, F&& f) {
    f(textParameter("world_frame", "REP-105 world-fixed frame the grid is aligned with"), p.world_frame);
    f(numberParameter("max_range_m", "m", 1.0, 200.0, "sensor range limit along the ray; > min_range_m"),
      p.camera.max_range_m);
    f(numberParameter("min_range_m", "m", 0.05, 10.0, "nearer measurements are invalid"), p.camera.min_range_m);
    f(numberParameter("delta_d_px", "px", 0.01, 5.0, "disparity uncertainty (eq. 4); at least the message's delta_d"),
      p.camera.delta_d_px);
    DrawingConfig::forEachParameter(p.drawing, f);
    f(numberParameter("tf_timeout_s", "s", 0.0, 60.0, "an image whose pose comes later than this is dropped; 0: never"),
      p.tf_timeout_s);
    f(numberParameter("queue_size", "images", 1.0, 100.0, "images waiting for their pose; the oldest is dropped"),
      p.queue_size);
    f(textParameter("use_depth", "subscribe depth + camera_info instead of disparity"), p.use_depth);
    f(numberParameter("depth_baseline_m", "m", 0.001, 10.0, "baseline of a depth camera (eq. 4)"), p.depth_baseline_m);
    f(numberParameter("cx_px", "px", -1.0, 100000.0, "principal point without camera_info; -1: image centre"), p.cx_px);
    f(numberParameter("cy_px", "px", -1.0, 100000.0, "principal point without camera_info; -1: image centre"), p.cy_px);
    f(numberParameter("max_image_pixels", "px", 1.0, 2147483647.0, "larger images are refused"), p.max_image_pixels);
  }

  /// The ranges of forEachParameter(), a world frame, max_range_m > min_range_m, a valid drawing.
  bool isValid(std::string* why) const;
};

/// Parameters of the OctomapAccumulator nodelet: the map's, its outputs' and its saves'.
struct OctomapAccumulatorParameters {
  /// The map's frame: updates in any other frame are refused; "": the first update's.
  std::string world_frame = "map";
  MapAccumulatorConfig map;
  MapPublisherConfig publisher;        ///< the map's outputs
  MapSaverConfig saving;               ///< the map's files and database
  DistanceFieldServerConfig distance;  ///< the planners' distance field (distance_field.h) and its slice
  double prune_period_s = 5.0;         ///< how often cells beyond max_extent_m go to the database (or are dropped) [s]
  std::string map_file;                ///< a .bt or .ot to start from (octomap_server's map_file); empty: an empty map
  int update_queue_size = 100;         ///< updates waiting for the fusion; more are lost (and counted)

  /// The parameters (stereo_occupancy/parameter_table.h): f(spec, member) for each, the components' included.
  template <typename Self, typename F>
  static void forEachParameter(Self& p, F&& f) {
    f(textParameter("world_frame", "the map's frame; updates in another are refused; empty: the first update's"),
      p.world_frame);
    MapAccumulatorConfig::forEachParameter(p.map, f);
    MapPublisherConfig::forEachParameter(p.publisher, f);
    f(numberParameter("prune_period_s", "s", 0.1, 86400.0,
                      "how often cells beyond max_extent_m go to the database, or are dropped without one"),
      p.prune_period_s);
    MapSaverConfig::forEachParameter(p.saving, f);
    f(textParameter("map_file", "a .bt or .ot to start from; empty: an empty map"), p.map_file);
    f(numberParameter("update_queue_size", "updates", 1.0, 10000.0, "updates waiting for the fusion"),
      p.update_queue_size);
    DistanceFieldServerConfig::forEachParameter(p.distance, f);
  }

  /// The ranges of forEachParameter(), a world frame for a map_file, and the
  /// components' checks (a plain map_name, a projection band of positive
  /// height, a valid map config, a valid distance field).
  bool isValid(std::string* why) const;
};

/// Parameters of the PathWatcher nodelet (src/nodelets/path_watcher.cpp):
/// the example planner that reads the accumulator's distance field in place.
struct PathWatcherParameters {
  /// The accumulator's nodelet name: the key of DistanceFieldRegistry.
  std::string accumulator = "/octomap_accumulator";
  /// The path: "x y z; x y z; ..." in the map's frame [m]; at least one waypoint.
  std::string waypoints = "0 0 4; 80 0 4";
  double radius_m = 0.5;             ///< the body's radius [m]; at most the field's max_distance_m
  bool unknown_as_occupied = false;  ///< unknown space blocks the path
  double period_s = 1.0;             ///< how often the path is checked [s]

  template <typename Self, typename F>
  static void forEachParameter(Self& p, F&& f) {
    f(textParameter("accumulator", "the accumulator's nodelet name, whose distance field is read"), p.accumulator);
    f(textParameter("waypoints", "the path: 'x y z; x y z; ...' in the map's frame [m]"), p.waypoints);
    f(numberParameter("radius_m", "m", 0.0, 20.0, "the body's radius; at most the field's max_distance_m"), p.radius_m);
    f(textParameter("unknown_as_occupied", "unknown space blocks the path"), p.unknown_as_occupied);
    f(numberParameter("period_s", "s", 0.01, 3600.0, "how often the path is checked"), p.period_s);
  }
  /// The ranges, an accumulator name, waypoints that parse (parseWaypoints()).
  bool isValid(std::string* why) const;
};

/// Parses "x y z; x y z; ..." (numbers separated by spaces or commas,
/// waypoints by ';') into @p W_waypoints; false with the reason for
/// anything else, no waypoint, a number that is not finite, or more than
/// DistanceField::kMaxWaypoints waypoints.
bool parseWaypoints(const std::string& text, std::vector<Eigen::Vector3d>* W_waypoints, std::string* why);

/// Reads private parameters into @p params (defaults for missing ones) and
/// validates them; false with a message naming the parameter and its valid
/// range in @p why.
bool loadParameters(const ros::NodeHandle& private_nh, DisparityMapperParameters* params, std::string* why);
bool loadParameters(const ros::NodeHandle& private_nh, OctomapAccumulatorParameters* params, std::string* why);
bool loadParameters(const ros::NodeHandle& private_nh, PathWatcherParameters* params, std::string* why);

/// The same from name=value pairs (the offline tools): the names of both
/// nodelets' parameters (a name both have, such as resolution_m, sets both).
/// Unknown names and unreadable values are errors.
bool loadParameters(const std::map<std::string, std::string>& values, DisparityMapperParameters* mapper,
                    OctomapAccumulatorParameters* accumulator, std::string* why);

/// The parameters named in @p names as a dynamic_reconfigure message (what
/// the server shows), by the table: choices as strings.
void toReconfigureMessage(const DisparityMapperParameters& params, const std::set<std::string>& names,
                          dynamic_reconfigure::Config* msg);

/// @p params with the values a dynamic_reconfigure message holds (others
/// keep theirs), validated; false, @p params unchanged, with the reason.
bool fromReconfigureMessage(const dynamic_reconfigure::Config& msg, DisparityMapperParameters* params,
                            std::string* why);

}  // namespace stereo_occupancy
