// bag_to_map: builds a map from a recorded bag without a roscore, as fast as
// it can, with the nodelets' own code: the same parameters, conversions,
// DisparityDrawer and MapAccumulator. Reads DisparityImage (or depth image +
// CameraInfo) and /tf, /tf_static; writes PREFIX.bt and PREFIX.ot.

#include <cv_bridge/cv_bridge.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2/buffer_core.h>
#include <tf2_msgs/TFMessage.h>

#include <chrono>
#include <deque>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/ros/conversions.h"
#include "stereo_occupancy/ros/parameters.h"

namespace so = stereo_occupancy;
using Clock = std::chrono::steady_clock;

namespace {

const char* kUsage =
    "usage: bag_to_map --bag FILE.bag --output PREFIX [--disparity-topic T] [--depth-topic T]\n"
    "                  [--camera-info-topic T] [--param NAME=VALUE ...]\n"
    "Maps the bag's DisparityImage messages (or, with --depth-topic, depth images with their\n"
    "camera_info) at the poses on /tf and /tf_static, and writes PREFIX.bt and PREFIX.ot.\n"
    "--param takes the nodelets' parameter names (config/mapping.yaml), e.g. algorithm=raytrace.\n";

struct Image {
  ros::Time stamp;
  std::string frame;
  cv::Mat disparity;  // CV_32FC1
  so::StereoCameraConfig camera;
};

void progress(size_t done, size_t total, double elapsed_s) {
  const int width = 30;
  const double f = total ? static_cast<double>(done) / total : 1.0;
  const double rate = elapsed_s > 0.0 ? done / elapsed_s : 0.0;
  const double left = rate > 0.0 ? (total - done) / rate : 0.0;
  std::cerr << "\r[" << std::string(static_cast<size_t>(f * width), '#')
            << std::string(width - static_cast<size_t>(f * width), ' ') << "] " << done << "/" << total
            << " frames, " << static_cast<int>(rate) << " frames/s, " << static_cast<int>(left + 0.5) << " s left   "
            << std::flush;
}

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
      if (a == "--bag") bag_path = next();
      else if (a == "--output") prefix = next();
      else if (a == "--disparity-topic") disparity_topic = next();
      else if (a == "--depth-topic") depth_topic = next();
      else if (a == "--camera-info-topic") info_topic = next();
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
  if (!depth_topic.empty() && info_topic.empty()) info_topic = "/camera_info";

  so::DisparityMapperParameters mapper;
  so::OctomapAccumulatorParameters accumulator;
  std::string why;
  if (!so::loadParameters(values, &mapper, &accumulator, &why)) {
    std::cerr << "bag_to_map: error: invalid parameter: " << why << std::endl;
    return 2;
  }
  if (!values.count("resolution_m")) accumulator.map.resolution_m = mapper.drawing.resolution_m;

  try {
    rosbag::Bag bag(bag_path, rosbag::bagmode::Read);
    std::vector<std::string> topics = {"/tf", "/tf_static"};
    const std::string image_topic = depth_topic.empty() ? disparity_topic : depth_topic;
    topics.push_back(image_topic);
    if (!info_topic.empty()) topics.push_back(info_topic);
    rosbag::View view(bag, rosbag::TopicQuery(topics));
    const size_t total = rosbag::View(bag, rosbag::TopicQuery(image_topic)).size();
    if (total == 0) throw std::runtime_error("no messages on '" + image_topic + "' in the bag");

    tf2::BufferCore tf(ros::Duration(3600.0));
    so::MapAccumulator map(accumulator.map);
    std::unique_ptr<so::DisparityDrawer> drawer;
    so::LocalGrid grid;
    so::GridUpdate update;
    sensor_msgs::CameraInfoConstPtr info;
    std::deque<Image> pending;  // images waiting for their pose
    size_t read = 0, mapped = 0, dropped_pose = 0, refused = 0;
    double draw_ms = 0.0, fusion_ms = 0.0;
    ros::Time latest_tf;
    const auto start = Clock::now();

    auto mapPending = [&](bool flush) {
      while (!pending.empty()) {
        Image& im = pending.front();
        std::string error;
        if (!tf.canTransform(mapper.world_frame, im.frame, im.stamp, &error)) {
          // Wait while newer poses may still come; drop once tf is past it or the bag ends.
          if (!flush && (latest_tf.isZero() || latest_tf < im.stamp + ros::Duration(mapper.tf_timeout_s))) return;
          ++dropped_pose;
          pending.pop_front();
          continue;
        }
        Eigen::Isometry3d T_W_C;
        if (!so::poseFromTransform(tf.lookupTransform(mapper.world_frame, im.frame, im.stamp), &T_W_C)) {
          ++refused;
          pending.pop_front();
          continue;
        }
        const auto t0 = Clock::now();
        try {  // one bad image (a camera or a pose the drawer refuses) does not end the run
          if (!drawer || drawer->camera().config() != im.camera)
            drawer = std::make_unique<so::DisparityDrawer>(im.camera, mapper.drawing);
          drawer->draw(im.disparity, T_W_C, &grid);
        } catch (const std::invalid_argument& e) {
          ++refused;
          std::cerr << "\nbag_to_map: refused an image: " << e.what() << std::endl;
          pending.pop_front();
          continue;
        }
        so::encodeGridUpdate(grid, T_W_C.translation(), &update);
        const auto t1 = Clock::now();
        if (!map.integrate(update, &error)) throw std::runtime_error(error);
        const auto t2 = Clock::now();
        draw_ms += std::chrono::duration<double, std::milli>(t1 - t0).count();
        fusion_ms += std::chrono::duration<double, std::milli>(t2 - t1).count();
        ++mapped;
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
        mapPending(false);
      } else if (m.getTopic() == info_topic) {
        try {
          info = m.instantiate<sensor_msgs::CameraInfo>();
        } catch (const std::exception& e) {
          std::cerr << "\nbag_to_map: skipped a message on " << m.getTopic() << ": " << e.what() << std::endl;
        }
      } else if (m.getTopic() == image_topic) {
        ++read;
        Image im;
        try {
          if (depth_topic.empty()) {
            const auto msg = m.instantiate<stereo_msgs::DisparityImage>();
            if (!msg) throw std::runtime_error("not a stereo_msgs/DisparityImage");
            if (msg->image.encoding != sensor_msgs::image_encodings::TYPE_32FC1)
              throw std::runtime_error("encoding '" + msg->image.encoding + "', expected 32FC1");
            if (!so::checkImageLayout(msg->image, static_cast<uint64_t>(mapper.max_image_pixels), &why))
              throw std::runtime_error(why);
            if (!so::cameraFromDisparityImage(*msg, info.get(), mapper, &im.camera, &why))
              throw std::runtime_error(why);
            im.disparity = cv_bridge::toCvCopy(msg->image)->image;
            im.stamp = msg->header.stamp;
            im.frame = msg->header.frame_id;
          } else {
            const auto msg = m.instantiate<sensor_msgs::Image>();
            if (!msg || !info) throw std::runtime_error("a depth image without camera_info");
            if (!so::checkImageLayout(*msg, static_cast<uint64_t>(mapper.max_image_pixels), &why))
              throw std::runtime_error(why);
            if (info->width != msg->width || info->height != msg->height)
              throw std::runtime_error("camera_info size differs from the depth image's");
            if (!so::cameraFromDepthInfo(*info, mapper, &im.camera, &why)) throw std::runtime_error(why);
            so::depthToDisparity(cv_bridge::toCvShare(msg)->image, im.camera.baseline_m * im.camera.focal_length_px,
                                 &im.disparity);
            im.stamp = msg->header.stamp;
            im.frame = msg->header.frame_id;
          }
          pending.push_back(std::move(im));
          while (pending.size() > static_cast<size_t>(mapper.queue_size)) {  // the oldest waits no longer
            pending.pop_front();
            ++dropped_pose;
          }
        } catch (const std::exception& e) {
          ++refused;
          std::cerr << "\nbag_to_map: refused an image: " << e.what() << std::endl;
        }
        mapPending(false);
        progress(read, total, std::chrono::duration<double>(Clock::now() - start).count());
      }
    }
    mapPending(true);
    progress(read, total, std::chrono::duration<double>(Clock::now() - start).count());
    std::cerr << std::endl;

    const auto slash = prefix.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "." : prefix.substr(0, slash);
    const std::string name = slash == std::string::npos ? prefix : prefix.substr(slash + 1);
    const auto paths = map.save(dir, name);
    const double total_s = std::chrono::duration<double>(Clock::now() - start).count();
    std::cout << "{\"images\": " << read << ", \"mapped\": " << mapped << ", \"dropped_no_pose\": " << dropped_pose
              << ", \"refused\": " << refused << ", \"algorithm\": \"" << so::toString(mapper.drawing.algorithm)
              << "\", \"resolution_m\": " << mapper.drawing.resolution_m
              << ", \"draw_ms_per_image\": " << (mapped ? draw_ms / mapped : 0.0)
              << ", \"fusion_ms_per_image\": " << (mapped ? fusion_ms / mapped : 0.0)
              << ", \"total_s\": " << total_s << ", \"map\": [\"" << paths[0] << "\", \"" << paths[1] << "\"]}"
              << std::endl;
  } catch (const std::exception& e) {
    std::cerr << "\nbag_to_map: error: " << e.what() << std::endl;
    return 1;
  }
  return 0;
}
