// simulate_flight: writes a simulated helicopter flight to a rosbag, as a
// stereo camera with stereo_image_proc and a navigation system would record
// it: stereo_msgs/DisparityImage on /stereo/disparity, the rectified left
// camera_info, and /tf with map -> base_link -> camera_optical (REP-103/105).
// The ground truth goes beside it: the scene on /ground_truth/scene and in
// <bag>.scene.txt, and with --true-depth each frame's exact depth on
// /ground_truth/depth. With --matcher sgbm the disparities come from
// StereoSGBM on rendered left and right images (a real matcher's errors)
// instead of exact disparities with Gaussian noise. No roscore needed.

#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <std_msgs/String.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2_msgs/TFMessage.h>

#include <cstring>
#include <fstream>
#include <iostream>
#include <string>

#include "progress.h"
#include "scenario_support.h"
#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "tool_support.h"

namespace so = stereo_occupancy;
namespace tools = stereo_occupancy::tools;

namespace {

int usage(int code) {
  std::cerr << "usage: simulate_flight --scenario posts|houses|forest|wires|posts_far|forest_far|mission\n"
               "                       --output FILE.bag [--seed N] [--frames N | --duration-s S] [--true-depth]\n"
               "                       [--matcher gaussian|sgbm]\n"
               "  mission        a 30-minute, 7 km flight with scenery generated along its path\n"
               "  --matcher      gaussian (default): exact disparities with Gaussian noise (the paper's figures);\n"
               "                 sgbm: textured left and right images matched by StereoSGBM with stereo_image_proc's\n"
               "                 defaults (64 disparities, 15 px block)\n"
               "  --duration-s   the first S seconds of the flight (as --frames S x its frame rate)\n"
               "  --true-depth   also write each frame's exact depth (32FC1, m; inf: sky) on /ground_truth/depth\n";
  return code;
}

int run(int argc, char** argv) {
  std::string scenario_name, output;
  uint32_t seed = 1;
  long frames = -1;
  double duration_s = -1.0;
  bool true_depth = false;
  so::StereoMatcher matcher = so::StereoMatcher::kGaussian;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--scenario")
      scenario_name = tools::nextValue(argc, argv, &i);
    else if (a == "--output")
      output = tools::nextValue(argc, argv, &i);
    else if (a == "--seed")
      seed = static_cast<uint32_t>(tools::parseWhole(a, tools::nextValue(argc, argv, &i), 0, 4294967295L));
    else if (a == "--frames")
      frames = tools::parseWhole(a, tools::nextValue(argc, argv, &i), 1, 1000000);
    else if (a == "--duration-s") {
      duration_s = tools::parseNumber(a, tools::nextValue(argc, argv, &i));
      if (!(duration_s > 0.0)) throw tools::UsageError("--duration-s expects a positive number of seconds");
    } else if (a == "--true-depth")
      true_depth = true;
    else if (a == "--matcher") {
      if (!so::parseStereoMatcher(tools::nextValue(argc, argv, &i), &matcher))
        throw tools::UsageError("--matcher must be gaussian or sgbm");
    } else if (a == "--help")
      return usage(0);
    else
      throw tools::UsageError("unknown option '" + a + "'");
  }
  if (scenario_name.empty() || output.empty()) throw tools::UsageError("--scenario and --output are required");
  if (frames > 0 && duration_s > 0.0) throw tools::UsageError("--frames and --duration-s exclude each other");
  so::FlightScenario s = tools::scenarioNamed(scenario_name);
  so::useMatcher(&s, matcher);
  if (duration_s > 0.0) frames = std::max(1L, std::lround(duration_s * s.frame_rate_hz));
  const size_t n = frames > 0 ? std::min<size_t>(frames, s.T_W_B.size()) : s.T_W_B.size();
  rosbag::Bag bag(output, rosbag::bagmode::Write);
  bag.setCompression(rosbag::compression::LZ4);
  const ros::Time start(1700000000.0);
  so::tools::ProgressBar progress(n, "frames");
  std_msgs::String scene;
  scene.data = "scenario " + s.name + " seed " + std::to_string(seed) + " matcher " + so::toString(s.matcher) +
               (s.matcher == so::StereoMatcher::kSgbm ? " (" + s.sgbm.describe() + ")" : std::string()) + "\n" +
               so::describeScene(s.scene);
  bag.write("/ground_truth/scene", start, scene);
  std::ofstream scene_file(output + ".scene.txt");
  scene_file << scene.data;
  if (!scene_file) throw std::runtime_error("cannot write '" + output + ".scene.txt'");

  sensor_msgs::CameraInfo info;
  info.header.frame_id = "camera_optical";
  info.width = s.camera.width_px;
  info.height = s.camera.height_px;
  info.distortion_model = "plumb_bob";
  info.D.assign(5, 0.0);
  info.K = {s.camera.focal_length_px, 0, s.camera.cx_px, 0, s.camera.focal_length_px, s.camera.cy_px, 0, 0, 1};
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  info.P = {s.camera.focal_length_px, 0, s.camera.cx_px, 0, 0, s.camera.focal_length_px, s.camera.cy_px, 0, 0, 0, 1, 0};

  for (size_t i = 0; i < n; ++i) {
    const ros::Time stamp = start + ros::Duration(i / s.frame_rate_hz);
    tf2_msgs::TFMessage tf;
    tf.transforms.push_back(so::toTransformMsg(s.T_W_B[i], stamp, "map", "base_link"));
    tf.transforms.push_back(so::toTransformMsg(s.T_B_C, stamp, "base_link", "camera_optical"));
    bag.write("/tf", stamp, tf);

    const cv::Mat d = so::renderStereoFrame(s, i, seed);
    std_msgs::Header header;
    header.stamp = stamp;
    header.frame_id = "camera_optical";
    stereo_msgs::DisparityImage msg;
    so::toDisparityImageMsg(d, header, s.camera, s.effects.max_search_disparity_px, s.effects.subpixel_step_px, &msg);
    bag.write("/stereo/disparity", stamp + ros::Duration(0.001), msg);
    if (true_depth) {
      cv::Mat depth;
      so::renderTrueDisparity(s, i, &depth);
      sensor_msgs::Image truth;
      truth.header = msg.header;
      truth.width = depth.cols;
      truth.height = depth.rows;
      truth.encoding = "32FC1";
      truth.step = depth.cols * 4;
      truth.data.resize(depth.total() * 4);
      std::memcpy(truth.data.data(), depth.data, truth.data.size());
      bag.write("/ground_truth/depth", stamp + ros::Duration(0.001), truth);
    }
    info.header.stamp = stamp;
    bag.write("/stereo/left/camera_info", stamp + ros::Duration(0.001), info);
    progress.update(static_cast<size_t>(i) + 1);
  }
  bag.close();
  progress.finish();
  std::cerr << "simulate_flight: " << s.name << " (" << so::toString(s.matcher) << "), " << n << " frames at "
            << s.frame_rate_hz << " Hz -> " << output << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return so::tools::runTool("simulate_flight", [&] { return run(argc, argv); });
}
