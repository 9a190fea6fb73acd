// bag_to_map: builds a map from a recorded bag without a roscore, as fast as
// it can, through the nodelets' own pipeline (FrameMapping, MapFusion) with
// the same parameters; only the transport differs: the bag and a
// tf2::BufferCore instead of subscriptions and a tf listener. Reads
// DisparityImage (or depth image + CameraInfo) and /tf, /tf_static; writes
// PREFIX.bt and PREFIX.ot.

#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <tf2/buffer_core.h>
#include <tf2_msgs/TFMessage.h>

#include <chrono>
#include <cstdio>
#include <deque>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include "progress.h"
#include "stereo_occupancy/ros/mapping_pipeline.h"
#include "stereo_occupancy/ros/parameters.h"

namespace so = stereo_occupancy;
using Clock = std::chrono::steady_clock;

namespace {

const char* kUsage =
    "usage: bag_to_map --bag FILE.bag --output PREFIX [--disparity-topic T] [--depth-topic T]\n"
    "                  [--camera-info-topic T] [--threads N] [--param NAME=VALUE ...]\n"
    "Maps the bag's DisparityImage messages (or, with --depth-topic, depth images with their\n"
    "camera_info) at the poses on /tf and /tf_static, and writes PREFIX.bt and PREFIX.ot.\n"
    "Topics default to launch/mapping.launch's: /stereo/disparity and /stereo/left/camera_info.\n"
    "--param takes the nodelets' parameter names (config/mapping.yaml), e.g. algorithm=raytrace.\n"
    "--threads N: draw, blur and fuse on N threads (the threads parameters; default 0: the cores, at most 4).\n";

/// Opens @p path for reading. A bag whose recording did not end cleanly
/// (a crash, a full disk) has no index, and rosbag cannot read it until
/// `rosbag reindex` rebuilt it: said so instead of rosbag's "wanted 4 bytes".
void openBag(const std::string& path, rosbag::Bag* bag) {
  try {
    bag->open(path, rosbag::bagmode::Read);
  } catch (const rosbag::BagException& e) {
    throw std::runtime_error("cannot read the bag '" + path + "' (" + e.what() +
                             "); if its recording was cut short it has no index: repair it with "
                             "'rosbag reindex " +
                             path + "' and run again");
  }
}

/// An image waiting for its pose, as in the nodelet's tf2_ros::MessageFilter.
struct PendingImage {
  stereo_msgs::DisparityImageConstPtr disparity;  ///< or
  sensor_msgs::ImageConstPtr depth;
  const std_msgs::Header& header() const { return disparity ? disparity->header : depth->header; }
};

}  // namespace

int main(int argc, char** argv) {
  std::string bag_path, prefix, disparity_topic = "/stereo/disparity", depth_topic, info_topic;
  std::map<std::string, std::string> values;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    try {
      if (a == "--bag")
        bag_path = next();
      else if (a == "--output")
        prefix = next();
      else if (a == "--disparity-topic")
        disparity_topic = next();
      else if (a == "--depth-topic")
        depth_topic = next();
      else if (a == "--camera-info-topic")
        info_topic = next();
      else if (a == "--threads")
        values["threads"] = next();
      else if (a == "--param") {
        const std::string kv = next();
        const auto eq = kv.find('=');
        if (eq == std::string::npos) throw std::invalid_argument("--param expects NAME=VALUE, got '" + kv + "'");
        values[kv.substr(0, eq)] = kv.substr(eq + 1);
      } else if (a == "--help") {
        std::cout << kUsage;
        return 0;
      } else {
        throw std::invalid_argument("unknown option '" + a + "'");
      }
    } catch (const std::exception& e) {
      std::cerr << "bag_to_map: error: " << e.what() << "\n" << kUsage;
      return 2;
    }
  }
  if (bag_path.empty() || prefix.empty()) {
    std::cerr << "bag_to_map: error: --bag and --output are required\n" << kUsage;
    return 2;
  }
  if (info_topic.empty()) info_topic = depth_topic.empty() ? "/stereo/left/camera_info" : "/camera_info";

  so::DisparityMapperParameters mapper;
  so::OctomapAccumulatorParameters accumulator;
  std::string why;
  if (!so::loadParameters(values, &mapper, &accumulator, &why)) {
    std::cerr << "bag_to_map: error: invalid parameter: " << why << std::endl;
    return 2;
  }
  if (!values.count("resolution_m")) accumulator.map.resolution_m = mapper.drawing.resolution_m;

  try {
    rosbag::Bag bag;
    openBag(bag_path, &bag);
    const std::string image_topic = depth_topic.empty() ? disparity_topic : depth_topic;
    const std::vector<std::string> topics = {"/tf", "/tf_static", image_topic, info_topic};
    rosbag::View view(bag, rosbag::TopicQuery(topics));
    const size_t total = rosbag::View(bag, rosbag::TopicQuery(image_topic)).size();
    if (total == 0) throw std::runtime_error("no messages on '" + image_topic + "' in the bag");
    const std::string image_type = depth_topic.empty() ? ros::message_traits::datatype<stereo_msgs::DisparityImage>()
                                                       : ros::message_traits::datatype<sensor_msgs::Image>();
    for (const rosbag::ConnectionInfo* c : rosbag::View(bag, rosbag::TopicQuery(image_topic)).getConnections())
      if (c->datatype != image_type)
        throw std::runtime_error("the bag's '" + image_topic + "' carries " + c->datatype + ", not " + image_type +
                                 (depth_topic.empty() ? " (for depth images give --depth-topic)" : ""));

    tf2::BufferCore tf(ros::Duration(3600.0));
    so::FrameMapping mapping(mapper);
    so::MapFusion fusion(accumulator);
    // The whole flight, as the accumulator keeps it: tiles beyond
    // max_extent_m go to PREFIX.db, a new one for each run (never one that
    // an accumulator holds, nor another program's file).
    so::TileStore::removeDatabase(prefix + ".db");
    fusion.openDatabase(prefix + ".db");
    sensor_msgs::CameraInfoConstPtr info;
    std::deque<PendingImage> pending;
    size_t read = 0, unread = 0, queue_dropped = 0, fusion_refused = 0;
    double mapping_ms = 0.0, fusion_ms = 0.0;
    ros::Time latest_tf;
    const auto start = Clock::now();
    so::tools::ProgressBar progress(total, "frames");

    // Maps the images whose pose has come, in order, at bag time `now`;
    // `flush` (the bag's end): those still waiting are dropped.
    auto mapPending = [&](const ros::Time& now, bool flush) {
      while (!pending.empty()) {
        const PendingImage& image = pending.front();
        const std_msgs::Header& header = image.header();
        if (!tf.canTransform(mapper.world_frame, header.frame_id, header.stamp)) {
          // Waits while a pose in time may still come (FrameMapping drops later ones as too old).
          if (!flush && (latest_tf.isZero() || latest_tf < header.stamp + ros::Duration(mapper.tf_timeout_s))) return;
          ++queue_dropped;
          pending.pop_front();
          continue;
        }
        const auto t0 = Clock::now();
        so::FrameResult result;
        const so::OccupancyUpdatePtr update = image.disparity ? mapping.map(image.disparity, info, tf, now, &result)
                                                              : mapping.mapDepth(image.depth, info, tf, now, &result);
        const auto t1 = Clock::now();
        if (update && !fusion.fuse(*update, &why)) {
          ++fusion_refused;
          std::cerr << "\nbag_to_map: the map refused an update: " << why << std::endl;
        }
        if (fusion.mission().takeFreedMemory()) so::MissionMap::trimHeap();
        if (!update && result.outcome == so::FrameOutcome::kRefused)
          std::cerr << "\nbag_to_map: refused an image: " << result.why << std::endl;
        mapping_ms += std::chrono::duration<double, std::milli>(t1 - t0).count();
        fusion_ms += std::chrono::duration<double, std::milli>(Clock::now() - t1).count();
        pending.pop_front();
      }
    };

    for (const rosbag::MessageInstance& m : view) {
      if (m.getTopic() == "/tf" || m.getTopic() == "/tf_static") {
        try {  // a broken message, or a transform tf2 refuses, is skipped
          const auto msg = m.instantiate<tf2_msgs::TFMessage>();
          if (!msg) continue;
          for (const auto& t : msg->transforms) {
            if (!tf.setTransform(t, "bag", m.getTopic() == "/tf_static")) continue;
            if (t.header.stamp > latest_tf) latest_tf = t.header.stamp;
          }
        } catch (const std::exception& e) {
          std::cerr << "\nbag_to_map: skipped a message on " << m.getTopic() << ": " << e.what() << std::endl;
        }
        mapPending(m.getTime(), false);
      } else if (m.getTopic() == info_topic) {
        try {
          info = m.instantiate<sensor_msgs::CameraInfo>();
        } catch (const std::exception& e) {
          std::cerr << "\nbag_to_map: skipped a message on " << m.getTopic() << ": " << e.what() << std::endl;
        }
      } else if (m.getTopic() == image_topic) {
        ++read;
        PendingImage image;
        try {
          if (depth_topic.empty())
            image.disparity = m.instantiate<stereo_msgs::DisparityImage>();
          else
            image.depth = m.instantiate<sensor_msgs::Image>();
        } catch (const std::exception& e) {
          std::cerr << "\nbag_to_map: skipped a message on " << m.getTopic() << ": " << e.what() << std::endl;
        }
        if (!image.disparity && !image.depth) {
          ++unread;
        } else {
          pending.push_back(std::move(image));
          while (pending.size() > static_cast<size_t>(mapper.queue_size)) {  // the oldest waits no longer
            pending.pop_front();
            ++queue_dropped;
          }
        }
        mapPending(m.getTime(), false);
        progress.update(read);
      }
    }
    mapPending(latest_tf, true);
    progress.finish();

    const auto slash = prefix.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "." : prefix.substr(0, slash);
    const std::string name = slash == std::string::npos ? prefix : prefix.substr(slash + 1);
    const auto paths = fusion.mission().saveWhole(dir, name);
    const double total_s = std::chrono::duration<double>(Clock::now() - start).count();
    const so::FrameCounters& n = mapping.counters();
    const double mapped = static_cast<double>(std::max<uint64_t>(n.mapped, 1));
    std::cout << "{\"images\": " << read << ", \"mapped\": " << n.mapped
              << ", \"dropped_no_pose\": " << queue_dropped + n.no_transform
              << ", \"refused\": " << unread + n.refused + fusion_refused << ", \"algorithm\": \""
              << so::toString(mapper.drawing.algorithm) << "\", \"resolution_m\": " << mapper.drawing.resolution_m
              << ", \"draw_ms_per_image\": " << mapping_ms / mapped
              << ", \"fusion_ms_per_image\": " << fusion_ms / mapped << ", \"total_s\": " << total_s << ", \"map\": [\""
              << paths[0] << "\", \"" << paths[1] << "\"]}" << std::endl;
  } catch (const std::exception& e) {
    std::cerr << "\nbag_to_map: error: " << e.what() << std::endl;
    return 1;
  }
  return 0;
}
