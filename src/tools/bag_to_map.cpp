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

/// What the command line asks for.
struct Options {
  std::string bag_path, prefix, disparity_topic = "/stereo/disparity", depth_topic, info_topic;
  std::map<std::string, std::string> values;  ///< --param and --threads, by parameter name
  bool help = false;
};

/// The command line into @p options; throws std::invalid_argument on a bad one.
void parseArguments(int argc, char** argv, Options* options) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    if (a == "--bag")
      options->bag_path = next();
    else if (a == "--output")
      options->prefix = next();
    else if (a == "--disparity-topic")
      options->disparity_topic = next();
    else if (a == "--depth-topic")
      options->depth_topic = next();
    else if (a == "--camera-info-topic")
      options->info_topic = next();
    else if (a == "--threads")
      options->values["threads"] = next();
    else if (a == "--param") {
      const std::string kv = next();
      const auto eq = kv.find('=');
      if (eq == std::string::npos) throw std::invalid_argument("--param expects NAME=VALUE, got '" + kv + "'");
      options->values[kv.substr(0, eq)] = kv.substr(eq + 1);
    } else if (a == "--help") {
      options->help = true;
      return;
    } else {
      throw std::invalid_argument("unknown option '" + a + "'");
    }
  }
}

/// Throws unless the bag holds messages of the expected type on @p image_topic; returns how many.
size_t countImages(const rosbag::Bag& bag, const std::string& image_topic, bool depth) {
  rosbag::View images(bag, rosbag::TopicQuery(image_topic));
  if (images.size() == 0) throw std::runtime_error("no messages on '" + image_topic + "' in the bag");
  const std::string image_type = depth ? ros::message_traits::datatype<sensor_msgs::Image>()
                                       : ros::message_traits::datatype<stereo_msgs::DisparityImage>();
  for (const rosbag::ConnectionInfo* c : images.getConnections())
    if (c->datatype != image_type)
      throw std::runtime_error("the bag's '" + image_topic + "' carries " + c->datatype + ", not " + image_type +
                               (depth ? "" : " (for depth images give --depth-topic)"));
  return images.size();
}

/// The bag's messages through the nodelets' pipeline: poses into a
/// tf2::BufferCore, images into FrameMapping when their pose has come, the
/// updates into MapFusion.
class BagReplay {
 public:
  BagReplay(const so::DisparityMapperParameters& mapper, const so::OctomapAccumulatorParameters& accumulator,
            const std::string& database)
      : mapper_(mapper), tf_(ros::Duration(3600.0)), mapping_(mapper), fusion_(accumulator) {
    // The whole flight, as the accumulator keeps it: tiles beyond
    // max_extent_m go to the database, a new one for each run (never one
    // that an accumulator holds, nor another program's file).
    so::TileStore::removeDatabase(database);
    fusion_.openDatabase(database);
  }

  /// A message on /tf or /tf_static; a broken one, or a transform tf2 refuses, is skipped.
  void addTransforms(const rosbag::MessageInstance& m) {
    try {
      const auto msg = m.instantiate<tf2_msgs::TFMessage>();
      if (!msg) return;
      for (const auto& t : msg->transforms) {
        if (!tf_.setTransform(t, "bag", m.getTopic() == "/tf_static")) continue;
        if (t.header.stamp > latest_tf_) latest_tf_ = t.header.stamp;
      }
    } catch (const std::exception& e) {
      skipped(m, e);
    }
    mapPending(m.getTime(), false);
  }

  /// A camera_info message: the one the depth images that follow use.
  void setCameraInfo(const rosbag::MessageInstance& m) {
    try {
      info_ = m.instantiate<sensor_msgs::CameraInfo>();
    } catch (const std::exception& e) {
      skipped(m, e);
    }
  }

  /// An image message: queued until its pose comes, the oldest dropped beyond queue_size.
  void addImage(const rosbag::MessageInstance& m, bool depth) {
    ++read_;
    PendingImage image;
    try {
      if (depth)
        image.depth = m.instantiate<sensor_msgs::Image>();
      else
        image.disparity = m.instantiate<stereo_msgs::DisparityImage>();
    } catch (const std::exception& e) {
      skipped(m, e);
    }
    if (!image.disparity && !image.depth) {
      ++unread_;
    } else {
      pending_.push_back(std::move(image));
      while (pending_.size() > static_cast<size_t>(mapper_.queue_size)) {  // the oldest waits no longer
        pending_.pop_front();
        ++queue_dropped_;
      }
    }
    mapPending(m.getTime(), false);
  }

  /// The bag's end: the images still waiting for a pose are mapped if it came, else dropped.
  void finish() { mapPending(latest_tf_, true); }

  size_t imagesRead() const { return read_; }
  so::MapFusion& fusion() { return fusion_; }

  /// The summary line: counts and times per mapped image.
  void report(const std::vector<std::string>& paths, double total_s) const {
    const so::FrameCounters& n = mapping_.counters();
    const double mapped = static_cast<double>(std::max<uint64_t>(n.mapped, 1));
    std::cout << "{\"images\": " << read_ << ", \"mapped\": " << n.mapped
              << ", \"dropped_no_pose\": " << queue_dropped_ + n.no_transform
              << ", \"refused\": " << unread_ + n.refused + fusion_refused_ << ", \"algorithm\": \""
              << so::toString(mapper_.drawing.algorithm) << "\", \"resolution_m\": " << mapper_.drawing.resolution_m
              << ", \"draw_ms_per_image\": " << mapping_ms_ / mapped
              << ", \"fusion_ms_per_image\": " << fusion_ms_ / mapped << ", \"total_s\": " << total_s
              << ", \"map\": [\"" << paths[0] << "\", \"" << paths[1] << "\"]}" << std::endl;
  }

 private:
  static void skipped(const rosbag::MessageInstance& m, const std::exception& e) {
    std::cerr << "\nbag_to_map: skipped a message on " << m.getTopic() << ": " << e.what() << std::endl;
  }

  /// Maps the images whose pose has come, in order, at bag time @p now;
  /// @p flush (the bag's end): those still waiting are dropped.
  void mapPending(const ros::Time& now, bool flush) {
    while (!pending_.empty()) {
      const PendingImage& image = pending_.front();
      const std_msgs::Header& header = image.header();
      if (!tf_.canTransform(mapper_.world_frame, header.frame_id, header.stamp)) {
        // Waits while a pose in time may still come (FrameMapping drops later ones as too old).
        if (!flush && (latest_tf_.isZero() || latest_tf_ < header.stamp + ros::Duration(mapper_.tf_timeout_s))) return;
        ++queue_dropped_;
        pending_.pop_front();
        continue;
      }
      mapImage(image, now);
      pending_.pop_front();
    }
  }

  /// One image with its pose: drawn, then fused.
  void mapImage(const PendingImage& image, const ros::Time& now) {
    const auto t0 = Clock::now();
    so::FrameResult result;
    const so::OccupancyUpdatePtr update = image.disparity ? mapping_.map(image.disparity, info_, tf_, now, &result)
                                                          : mapping_.mapDepth(image.depth, info_, tf_, now, &result);
    const auto t1 = Clock::now();
    std::string why;
    if (update && !fusion_.fuse(*update, &why)) {
      ++fusion_refused_;
      std::cerr << "\nbag_to_map: the map refused an update: " << why << std::endl;
    }
    if (fusion_.mission().takeFreedMemory()) so::MissionMap::trimHeap();
    if (!update && result.outcome == so::FrameOutcome::kRefused)
      std::cerr << "\nbag_to_map: refused an image: " << result.why << std::endl;
    mapping_ms_ += std::chrono::duration<double, std::milli>(t1 - t0).count();
    fusion_ms_ += std::chrono::duration<double, std::milli>(Clock::now() - t1).count();
  }

  const so::DisparityMapperParameters& mapper_;
  tf2::BufferCore tf_;
  so::FrameMapping mapping_;
  so::MapFusion fusion_;
  sensor_msgs::CameraInfoConstPtr info_;
  std::deque<PendingImage> pending_;
  ros::Time latest_tf_;
  size_t read_ = 0, unread_ = 0, queue_dropped_ = 0, fusion_refused_ = 0;
  double mapping_ms_ = 0.0, fusion_ms_ = 0.0;
};

/// Replays the bag of @p options into a map and writes it; the summary line to stdout.
void run(const Options& options, const so::DisparityMapperParameters& mapper,
         const so::OctomapAccumulatorParameters& accumulator) {
  rosbag::Bag bag;
  openBag(options.bag_path, &bag);
  const bool depth = !options.depth_topic.empty();
  const std::string image_topic = depth ? options.depth_topic : options.disparity_topic;
  const size_t total = countImages(bag, image_topic, depth);
  rosbag::View view(bag, rosbag::TopicQuery({"/tf", "/tf_static", image_topic, options.info_topic}));
  const auto start = Clock::now();
  BagReplay replay(mapper, accumulator, options.prefix + ".db");
  so::tools::ProgressBar progress(total, "frames");
  for (const rosbag::MessageInstance& m : view) {
    if (m.getTopic() == "/tf" || m.getTopic() == "/tf_static") {
      replay.addTransforms(m);
    } else if (m.getTopic() == options.info_topic) {
      replay.setCameraInfo(m);
    } else if (m.getTopic() == image_topic) {
      replay.addImage(m, depth);
      progress.update(replay.imagesRead());
    }
  }
  replay.finish();
  progress.finish();

  const auto slash = options.prefix.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "." : options.prefix.substr(0, slash);
  const std::string name = slash == std::string::npos ? options.prefix : options.prefix.substr(slash + 1);
  const auto paths = replay.fusion().mission().saveWhole(dir, name);
  replay.report(paths, std::chrono::duration<double>(Clock::now() - start).count());
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  try {
    parseArguments(argc, argv, &options);
  } catch (const std::exception& e) {
    std::cerr << "bag_to_map: error: " << e.what() << "\n" << kUsage;
    return 2;
  }
  if (options.help) {
    std::cout << kUsage;
    return 0;
  }
  if (options.bag_path.empty() || options.prefix.empty()) {
    std::cerr << "bag_to_map: error: --bag and --output are required\n" << kUsage;
    return 2;
  }
  if (options.info_topic.empty())
    options.info_topic = options.depth_topic.empty() ? "/stereo/left/camera_info" : "/camera_info";

  so::DisparityMapperParameters mapper;
  so::OctomapAccumulatorParameters accumulator;
  std::string why;
  if (!so::loadParameters(options.values, &mapper, &accumulator, &why)) {
    std::cerr << "bag_to_map: error: invalid parameter: " << why << std::endl;
    return 2;
  }
  if (!options.values.count("resolution_m")) accumulator.map.resolution_m = mapper.drawing.resolution_m;

  try {
    run(options, mapper, accumulator);
  } catch (const std::exception& e) {
    std::cerr << "\nbag_to_map: error: " << e.what() << std::endl;
    return 1;
  }
  return 0;
}
