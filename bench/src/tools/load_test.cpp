// load_test: drives the running mapping nodelets (launch/mapping.launch) at a
// given image size and rate, with tf, and reports what a vehicle integrator
// needs to know: latency from image stamp to the occupancy update, images
// mapped and dropped, and the nodelet manager's resident memory over the run.
// A benchmark: it prints figures (Markdown) and asserts nothing.
//
//   roslaunch stereo_occupancy mapping.launch &
//   rosrun stereo_occupancy load_test --width 640 --height 480 --rate 60 --duration 60

#include <ros/ros.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2_ros/transform_broadcaster.h>

#include <dirent.h>

#include <algorithm>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "stereo_occupancy/OccupancyUpdate.h"
#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "tool_support.h"

namespace so = stereo_occupancy;
namespace tools = stereo_occupancy::tools;

namespace {

const char* kUsage =
    "usage: load_test [--width W --height H] [--rate HZ] [--duration S] [--frames N] [--manager NAME]\n"
    "                 [--disparity TOPIC] [--update TOPIC] [--world-frame F] [--blank]\n"
    "Publishes the 'posts' flight's disparity images (rendered at W x H, f scaled with W) and their\n"
    "poses on /tf at HZ for S seconds to the running nodelets, and prints latency (image stamp ->\n"
    "occupancy update received), images mapped and dropped, and the manager's resident memory.\n"
    "--blank: images of the same size without a match (every disparity invalid): the mapper draws\n"
    "nothing, so the latency is the path's floor (transport, tf, input checks, grid preparation,\n"
    "pyramids, encoding an empty grid, the census behind its warning, messages).\n"
    "Defaults: 640 x 480, 30 Hz, 60 s, 40 distinct frames, manager stereo_occupancy_manager.\n";

/// Resident memory of process @p pid [MiB], or -1.
double residentMiB(int pid) {
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;  // kB
  return -1.0;
}

/// The PID of the process with the argument "__name:=<name>" (a roslaunch'ed node), or -1.
int findProcess(const std::string& name) {
  DIR* proc = opendir("/proc");
  if (!proc) return -1;
  int found = -1;
  while (dirent* entry = readdir(proc)) {
    const int pid = std::atoi(entry->d_name);
    if (pid <= 0) continue;
    std::ifstream cmdline("/proc/" + std::to_string(pid) + "/cmdline");
    std::string arg;
    while (found < 0 && std::getline(cmdline, arg, '\0'))
      if (arg == "__name:=" + name) found = pid;
    if (found >= 0) break;
  }
  closedir(proc);
  return found;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5))];
}

int run(int argc, char** argv) {
  int width = 640, height = 480, frames = 40;
  bool blank = false;
  double rate_hz = 30.0, duration_s = 60.0;
  std::string manager = "stereo_occupancy_manager", disparity_topic = "/stereo/disparity",
              update_topic = "/occupancy_update", world_frame = "map";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--width") {
      width = static_cast<int>(tools::parseWhole(a, tools::nextValue(argc, argv, &i), 64, 8192));
    } else if (a == "--height") {
      height = static_cast<int>(tools::parseWhole(a, tools::nextValue(argc, argv, &i), 48, 8192));
    } else if (a == "--rate") {
      rate_hz = tools::parseNumber(a, tools::nextValue(argc, argv, &i));
      if (!(rate_hz > 0.0 && rate_hz <= 1000.0)) throw tools::UsageError("--rate must be in (0, 1000] Hz");
    } else if (a == "--duration") {
      duration_s = tools::parseNumber(a, tools::nextValue(argc, argv, &i));
      if (!(duration_s > 0.0)) throw tools::UsageError("--duration must be > 0");
    } else if (a == "--frames") {
      frames = static_cast<int>(tools::parseWhole(a, tools::nextValue(argc, argv, &i), 1, 200));
    } else if (a == "--manager") {
      manager = tools::nextValue(argc, argv, &i);
    } else if (a == "--disparity") {
      disparity_topic = tools::nextValue(argc, argv, &i);
    } else if (a == "--update") {
      update_topic = tools::nextValue(argc, argv, &i);
    } else if (a == "--world-frame") {
      world_frame = tools::nextValue(argc, argv, &i);
    } else if (a == "--blank") {
      blank = true;
    } else {
      throw tools::UsageError("unknown option '" + a + "'");
    }
  }

  // The posts flight, with the camera scaled to the requested size.
  so::FlightScenario flight = so::makeScenario("posts");
  const double scale = width / 640.0;
  flight.camera.width_px = width;
  flight.camera.height_px = height;
  flight.camera.focal_length_px *= scale;
  flight.camera.cx_px = 0.5 * (width - 1);
  flight.camera.cy_px = 0.5 * (height - 1);
  flight.effects.sky_unmatched_above_row = static_cast<int>(flight.effects.sky_unmatched_above_row * scale);
  std::vector<stereo_msgs::DisparityImage> images;
  std::vector<Eigen::Isometry3d> poses;
  const size_t step = std::max<size_t>(1, flight.T_W_B.size() / frames);
  std::cerr << "load_test: rendering " << frames << " frames of " << width << "x" << height << "..." << std::flush;
  for (size_t k = 0; k < static_cast<size_t>(frames); ++k) {
    const size_t i = (k * step) % flight.T_W_B.size();
    cv::Mat d = so::renderStereoFrame(flight, i, 1);
    if (blank) d.setTo(-1.0f);  // no match anywhere (stereo_image_proc's invalid value)
    std_msgs::Header header;
    header.frame_id = "camera_optical";
    stereo_msgs::DisparityImage m;
    so::toDisparityImageMsg(d, header, flight.camera, flight.effects.max_search_disparity_px * scale,
                            flight.effects.subpixel_step_px, &m);
    images.push_back(m);
    poses.push_back(flight.cameraPose(i));
  }
  std::cerr << " done" << std::endl;

  ros::NodeHandle nh;
  ros::Publisher pub = nh.advertise<stereo_msgs::DisparityImage>(disparity_topic, 2);
  tf2_ros::TransformBroadcaster tf;
  std::mutex mutex;
  std::vector<double> latency_ms;
  size_t received = 0;
  ros::Subscriber sub = nh.subscribe<so::OccupancyUpdate>(update_topic, 10, [&](const so::OccupancyUpdateConstPtr& u) {
    const double ms = (ros::Time::now() - u->header.stamp).toSec() * 1e3;
    std::lock_guard<std::mutex> lock(mutex);
    latency_ms.push_back(ms);
    ++received;
  });
  ros::AsyncSpinner spinner(1);
  spinner.start();

  const int manager_pid = findProcess(manager);
  if (manager_pid < 0) std::cerr << "load_test: no process named '" << manager << "'; memory not measured" << std::endl;
  const ros::WallTime wait_until = ros::WallTime::now() + ros::WallDuration(20.0);
  while ((pub.getNumSubscribers() == 0 || sub.getNumPublishers() == 0) && ros::WallTime::now() < wait_until &&
         ros::ok())
    ros::WallDuration(0.05).sleep();
  if (pub.getNumSubscribers() == 0) throw std::runtime_error("nobody subscribes to " + disparity_topic);

  // The measured run (the first second includes the nodelets' first allocations).
  std::vector<double> rss_mib;
  const double rss_start = residentMiB(manager_pid);
  ros::WallRate rate(rate_hz);
  const ros::WallTime start = ros::WallTime::now();
  ros::WallTime next_sample = start;
  size_t published = 0;
  while (ros::ok() && (ros::WallTime::now() - start).toSec() < duration_s) {
    const ros::Time stamp = ros::Time::now();
    const size_t k = published % images.size();
    tf.sendTransform(so::toTransformMsg(poses[k], stamp, world_frame, "camera_optical"));
    auto msg = boost::make_shared<stereo_msgs::DisparityImage>(images[k]);
    msg->header.stamp = stamp;
    msg->image.header = msg->header;
    pub.publish(msg);
    ++published;
    if (ros::WallTime::now() >= next_sample) {
      rss_mib.push_back(residentMiB(manager_pid));
      next_sample += ros::WallDuration(1.0);
    }
    rate.sleep();
  }
  ros::WallDuration(2.0).sleep();  // the last updates
  const double rss_end = residentMiB(manager_pid);
  spinner.stop();

  std::lock_guard<std::mutex> lock(mutex);
  const double elapsed = (ros::WallTime::now() - start).toSec() - 2.0;
  std::ostringstream out;
  out << std::fixed << std::setprecision(1);
  out << "| " << width << "x" << height << " | " << rate_hz << " | " << duration_s << " | " << published << " ("
      << published / elapsed << " Hz) | " << received << " | " << (published > received ? published - received : 0)
      << " | " << percentile(latency_ms, 0.5) << " | " << percentile(latency_ms, 0.9) << " | "
      << percentile(latency_ms, 0.99) << " | " << percentile(latency_ms, 1.0) << " | " << rss_start << " | "
      << (rss_mib.empty() ? -1.0 : *std::max_element(rss_mib.begin(), rss_mib.end())) << " | " << rss_end << " |";
  std::cout
      << "| image | rate Hz | s | published | updates | dropped | latency p50 ms | p90 | p99 | max | "
         "manager RSS start MiB | max | end |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n"
      << out.str() << std::endl;
  std::cerr << "load_test: RSS every second [MiB]:";
  for (double r : rss_mib) std::cerr << " " << std::setprecision(0) << std::fixed << r;
  std::cerr << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return tools::runTool("load_test", [&] {
    ros::init(argc, argv, "load_test", ros::init_options::AnonymousName);
    return run(argc, argv);
  });
}
