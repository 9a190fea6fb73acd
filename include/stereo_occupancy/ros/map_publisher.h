#pragma once
/// @file
/// The accumulated map's outputs, octomap_server's names and types: the
/// occupied and free cells' markers, the octree binary and full, the occupied
/// cells' cloud, projected_map, and the map on request (OctomapAccumulator's).

#include <ros/node_handle.h>
#include <ros/publisher.h>
#include <ros/service_server.h>
#include <ros/single_subscriber_publisher.h>
#include <ros/time.h>
#include <ros/timer.h>
#include <std_msgs/Header.h>
#include <visualization_msgs/MarkerArray.h>

#include <memory>
#include <mutex>
#include <string>

#include "stereo_occupancy/GetOctomap.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/parameter_table.h"
#include "stereo_occupancy/store/map_snapshot.h"

namespace stereo_occupancy {

class MapFusion;

/// How often the outputs go out and what projected_map sees.
struct MapPublisherConfig {
  double publish_rate_hz = 1.0;  ///< rate of the map outputs, while subscribed [Hz]
  /// The outputs that carry the whole live map (octomap_binary, octomap_full,
  /// the point cloud, projected_map) go out at most this often; the markers
  /// carry the changes at publish_rate_hz. 0: at publish_rate_hz too [s].
  double full_map_period_s = 10.0;
  /// Publish free_cells_vis_array (octomap_server's publish_free_space): the
  /// free cells' markers cost more than all other outputs together.
  bool publish_free_space = false;
  /// The height band of projected_map (octomap_server's occupancy_min_z / occupancy_max_z) [m].
  double projection_min_z_m = -10000.0;
  double projection_max_z_m = 10000.0;

  /// The parameters (stereo_occupancy/parameter_table.h): f(spec, member) for each.
  template <typename Self, typename F>
  static void forEachParameter(Self& c, F&& f) {
    f(numberParameter("publish_rate_hz", "Hz", 0.01, 100.0, "rate of the map outputs, while subscribed"),
      c.publish_rate_hz);
    f(numberParameter("full_map_period_s", "s", 0.0, 3600.0,
                      "the whole-map outputs go out at most this often; 0: at publish_rate_hz"),
      c.full_map_period_s);
    f(textParameter("publish_free_space", "publish free_cells_vis_array (octomap_server's publish_free_space)"),
      c.publish_free_space);
    f(numberParameter("projection_min_z_m", "m", -10000.0, 10000.0, "lowest height projected_map sees"),
      c.projection_min_z_m);
    f(numberParameter("projection_max_z_m", "m", -10000.0, 10000.0, "highest height projected_map sees"),
      c.projection_max_z_m);
  }

  /// The ranges of forEachParameter(), a projection band of positive height.
  bool isValid(std::string* why) const;
};

/// Publishes a MapFusion's map on a timer, each output only while someone
/// listens and only when the map changed (mapChanged()). The markers carry
/// the blocks changed since the last publish (a new subscriber first gets the
/// whole map); the outputs that carry the whole live map go out at most every
/// full_map_period_s, built from a MapSnapshot kept per tile: under the fusion
/// lock only the changed tiles' leaves are copied, the messages are encoded
/// outside it. The latched whole-map outputs and the GetOctomap services are
/// octomap_server's names and types.
///
/// Threading: the map is the owner's, guarded by the owner's fusion mutex,
/// which also guards what changed since the last publish. The snapshot has a
/// mutex of its own, taken before the fusion mutex when both are; one publish
/// at a time.
class MapPublisher {
 public:
  /// @param config valid (MapPublisherConfig::isValid()).
  /// @param map the map's config (its resolution and occupancy threshold).
  /// @param fusion the map, guarded by @p fusion_mutex; both outlive the publisher.
  /// @param log_name the logger's name (the nodelet's, as NODELET_* log).
  MapPublisher(const MapPublisherConfig& config, const MapAccumulatorConfig& map, MapFusion* fusion,
               std::mutex* fusion_mutex, const std::string& log_name);

  /// Advertises the topics and the services octomap_binary and octomap_full
  /// on @p nh, and starts the publish timer (publish_rate_hz, ROS time).
  void advertise(ros::NodeHandle& nh);
  /// The map changed: every output is due again. Requires the fusion lock.
  void mapChanged();
  /// What the timer does: publishes the changed blocks' markers, and the
  /// whole-map outputs when due, to those who listen. Never throws.
  void publish();

 private:
  void publishOutputs();  ///< publish()'s work; may throw
  /// The whole-map outputs (octree, cloud, projection), built from snapshot_ outside the fusion lock.
  void publishWholeMap();
  /// Brings snapshot_ up to date (the changed tiles' leaves copied under the
  /// fusion lock, encoded outside it) and returns the map's header. Requires
  /// snapshot_mutex_, not the fusion lock.
  std_msgs::Header refreshSnapshot();
  /// The marker arrays of the blocks changed since the last publish (null:
  /// nobody listens or nothing changed).
  struct ChangedBlockMarkers {
    visualization_msgs::MarkerArrayPtr occupied, free;
  };
  /// Builds them from the live tree; requires the fusion lock (publish them after it is let go).
  ChangedBlockMarkers changedBlockMarkers(const octomap::OcTree& tree, const std_msgs::Header& header);
  /// The map on request: binary (octomap_binary) or with log-odds (octomap_full).
  bool getMap(bool binary, GetOctomap::Request&, GetOctomap::Response& response);
  std_msgs::Header mapHeader() const;  ///< requires the fusion lock
  /// A new subscriber of a latched output: the whole map is due (within full_map_period_s).
  void wholeMapDue(const ros::SingleSubscriberPublisher&);
  /// A new subscriber of the markers: every block is due, and the whole map.
  void everythingDue(const ros::SingleSubscriberPublisher&);

  MapPublisherConfig config_;
  MapFusion* fusion_;
  std::mutex* fusion_mutex_;
  std::string log_name_;

  // Guarded by *fusion_mutex_.
  bool changed_since_publish_ = true;  ///< the map changed since the markers went out
  bool full_changed_ = true;           ///< ... since the whole-map outputs went out
  ros::WallTime last_full_publish_;    ///< when they went out; zero: never

  /// Taken first by each publish, so that two never interleave their
  /// messages once the fusion lock is let go.
  std::mutex publish_mutex_;
  /// Guards snapshot_; taken before the fusion mutex when both are: the
  /// whole-map outputs are built from it while the fusion goes on.
  std::mutex snapshot_mutex_;
  std::unique_ptr<MapSnapshot> snapshot_;

  ros::Publisher octomap_pub_, octomap_full_pub_, markers_pub_, free_markers_pub_, cloud_pub_, projected_pub_;
  ros::ServiceServer octomap_binary_srv_, octomap_full_srv_;
  ros::Timer publish_timer_;
};

}  // namespace stereo_occupancy
