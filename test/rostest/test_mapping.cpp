// The two nodelets in a real manager, driven as a vehicle drives them:
// rendered disparity images of a known scene with their poses on /tf.

#include <diagnostic_msgs/DiagnosticArray.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <gtest/gtest.h>
#include <nodelet/NodeletLoad.h>
#include <nodelet/NodeletUnload.h>
#include <ros/ros.h>
#include <rosgraph_msgs/Log.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <std_srvs/Empty.h>
#include <std_srvs/Trigger.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2_ros/transform_broadcaster.h>

#include <sys/stat.h>

#include <array>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "stereo_occupancy/OccupancyUpdate.h"
#include "stereo_occupancy/Octomap.h"
#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "wait_for.h"

using namespace stereo_occupancy;

namespace {

/// A 6 m wide, 4 m high wall 12 m in front of a camera 2 m above the ground, looking along +x.
SyntheticScene wallScene() {
  SyntheticScene scene;
  scene.addBox(Eigen::Vector3d(12.0, -3.0, 0.0), Eigen::Vector3d(13.0, 3.0, 4.0));
  return scene;
}

class MappingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    update_sub_ = nh_.subscribe("/occupancy_update", 20, &MappingTest::onUpdate, this);
    map_sub_ = nh_.subscribe("/octomap_binary", 2, &MappingTest::onMap, this);
    disparity_pub_ = nh_.advertise<stereo_msgs::DisparityImage>("/stereo/disparity", 20);
    T_W_C_ = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0));
    const StereoCameraModel camera{StereoCameraConfig()};
    image_ = renderDisparity(wallScene(), camera, T_W_C_);
    // Wait for the mapper's subscription and the accumulator's publisher.
    const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(20.0);
    while ((disparity_pub_.getNumSubscribers() == 0 || update_sub_.getNumPublishers() == 0) &&
           ros::WallTime::now() < until)
      ros::WallDuration(0.05).sleep();
    ASSERT_GT(disparity_pub_.getNumSubscribers(), 0u) << "DisparityMapper did not subscribe";
    // Each case starts from an empty map, so that it passes or fails on its own.
    ASSERT_TRUE(ros::service::waitForService("/octomap_accumulator/reset", ros::Duration(10.0)));
    std_srvs::Empty reset;
    ASSERT_TRUE(ros::service::call("/octomap_accumulator/reset", reset));
  }

  /// The diagnostic values of the status @p name ("disparity_mapper: mapper",
  /// "octomap_accumulator: accumulator") and its summary ("message"), from
  /// the next /diagnostics message that has them.
  std::map<std::string, std::string> diagnostics(const std::string& name) {
    std::map<std::string, std::string> values;
    bool got = false;
    ros::Subscriber sub = nh_.subscribe<diagnostic_msgs::DiagnosticArray>(
        "/diagnostics", 10, [&](const diagnostic_msgs::DiagnosticArrayConstPtr& msg) {
          std::lock_guard<std::mutex> lock(mutex_);
          for (const auto& status : msg->status)
            if (status.name == name) {
              for (const auto& kv : status.values) values[kv.key] = kv.value;
              values["message"] = status.message;
              got = true;
            }
        });
    EXPECT_TRUE(waitFor([&] { return got; }, 10.0)) << "no diagnostics of " << name;
    sub.shutdown();
    std::lock_guard<std::mutex> lock(mutex_);
    return values;
  }
  std::map<std::string, std::string> mapperDiagnostics() { return diagnostics("disparity_mapper: mapper"); }
  std::map<std::string, std::string> accumulatorDiagnostics() {
    return diagnostics("octomap_accumulator: accumulator");
  }

  void onUpdate(const OccupancyUpdateConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    updates_.push_back(msg);
  }
  void onMap(const OctomapConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    map_ = msg;
  }

  /// Sends the camera pose on /tf (unless frame is unknown) and one disparity image at @p stamp.
  void sendFrame(const ros::Time& stamp, const std::string& frame = "camera_optical", bool with_tf = true,
                 const cv::Mat* disparity = nullptr) {
    const cv::Mat image = disparity ? *disparity : cv::Mat();
    if (with_tf) tf_.sendTransform(toTransformMsg(T_W_C_, stamp, "map", frame));
    disparity_pub_.publish(makeFrame(stamp, frame, image));
  }

  /// A well-formed disparity message of @p image (default: the wall) at @p stamp.
  boost::shared_ptr<stereo_msgs::DisparityImage> makeFrame(const ros::Time& stamp,
                                                           const std::string& frame = "camera_optical",
                                                           const cv::Mat& image = cv::Mat()) {
    const cv::Mat& img = image.empty() ? image_ : image;
    auto msg = boost::make_shared<stereo_msgs::DisparityImage>();
    std_msgs::Header header;
    header.stamp = stamp;
    header.frame_id = frame;
    toDisparityImageMsg(img, header, StereoCameraConfig(), 128.0, 1.0 / 16.0, msg.get());
    return msg;
  }

  bool waitFor(const std::function<bool()>& condition, double seconds) {
    return stereo_occupancy::waitFor(mutex_, condition, seconds);
  }

  ros::NodeHandle nh_;
  ros::Publisher disparity_pub_;
  tf2_ros::TransformBroadcaster tf_;
  Eigen::Isometry3d T_W_C_;
  cv::Mat image_;
  std::mutex mutex_;
  std::vector<OccupancyUpdateConstPtr> updates_;
  std::vector<OccupancyUpdateConstPtr> depth_updates_;
  OctomapConstPtr map_;
  // Last, so destroyed first: the spinner's threads run their callbacks until
  // they are shut down, and the callbacks write the members above.
  ros::Subscriber update_sub_, map_sub_;
};

TEST_F(MappingTest, UpdatesMapSaveAndDroppedImages) {
  // 1. One frame: its update has the wall occupied and free space in front.
  ros::Time t0 = ros::Time::now();
  sendFrame(t0);
  ASSERT_TRUE(waitFor([&] { return !updates_.empty(); }, 20.0)) << "no occupancy_update";
  OccupancyUpdateConstPtr first;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    first = updates_.front();
  }
  EXPECT_EQ(first->header.frame_id, "map");
  EXPECT_EQ(first->header.stamp, t0);
  EXPECT_DOUBLE_EQ(first->resolution, 0.25);
  EXPECT_NEAR(first->sensor_origin.z, 2.0, 1e-6);
  GridUpdateView update;
  std::string why;
  ASSERT_TRUE(viewOf(*first, &update, &why) && update.isConsistent(&why)) << why;
  size_t wall = 0, wall_occupied = 0, front = 0, front_free = 0, behind = 0, other_occupied = 0;
  const double c = update.resolution_m;
  update.forEachCell([&](const Eigen::Vector3i& g, float v) {
    const Eigen::Vector3d p = (g.cast<double>().array() + 0.5).matrix() * c;
    const bool in_wall_span = std::abs(p.y()) < 2.5 && p.z() > 0.5 && p.z() < 3.5;
    if (in_wall_span && p.x() > 12.0 && p.x() < 12.25) {
      ++wall;
      wall_occupied += v > 0.0f;
    } else if (in_wall_span && p.x() > 1.0 && p.x() < 10.5) {
      ++front;
      front_free += v < 0.0f;
    } else if (in_wall_span && p.x() > 14.5) {
      ++behind;  // the wall hides everything beyond its measurement's tail
    } else if (v > 0.0f && !(p.x() > 11.5 && p.x() < 14.5)) {
      ++other_occupied;
    }
  });
  EXPECT_GT(wall, 100u);
  EXPECT_GT(static_cast<double>(wall_occupied) / wall, 0.8) << wall_occupied << " of " << wall;
  EXPECT_GT(front, 1000u);
  EXPECT_EQ(front_free, front);
  EXPECT_EQ(behind, 0u);
  EXPECT_EQ(other_occupied, 0u);

  // 2. An image whose frame has no transform is dropped; the next ones still work.
  sendFrame(t0 + ros::Duration(0.1), "frame_without_tf", /*with_tf=*/false);
  for (int i = 2; i <= 6; ++i) {
    ros::WallDuration(0.15).sleep();
    sendFrame(t0 + ros::Duration(0.1 * i));
  }
  ASSERT_TRUE(waitFor([&] { return updates_.size() >= 6; }, 20.0)) << updates_.size() << " updates";
  ros::WallDuration(0.5).sleep();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    EXPECT_EQ(updates_.size(), 6u);
    for (const auto& u : updates_) EXPECT_NE(u->header.stamp, t0 + ros::Duration(0.1)) << "the image without tf";
    EXPECT_EQ(updates_.back()->header.stamp, t0 + ros::Duration(0.6));
  }

  // 3. The accumulated map holds the wall as occupied and the space in front as free.
  ASSERT_TRUE(waitFor([&] { return map_ && map_->header.stamp == t0 + ros::Duration(0.6); }, 20.0));
  OctomapConstPtr map;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    map = map_;
  }
  EXPECT_TRUE(map->binary);
  EXPECT_EQ(map->id, "OcTree");
  const std::unique_ptr<octomap::OcTree> read = treeFromMsg(*map);
  ASSERT_TRUE(read);
  const octomap::OcTree& tree = *read;
  const octomap::OcTreeNode* at_wall = tree.search(12.1, 0.1, 2.1);
  const octomap::OcTreeNode* in_front = tree.search(6.1, 0.1, 2.1);
  ASSERT_NE(at_wall, nullptr);
  ASSERT_NE(in_front, nullptr);
  EXPECT_TRUE(tree.isNodeOccupied(at_wall));
  EXPECT_FALSE(tree.isNodeOccupied(in_front));
  EXPECT_EQ(tree.search(16.1, 0.1, 2.1), nullptr);  // behind the wall: unknown

  // 4. ~save_map writes a .bt that octomap::OcTree reads back.
  ::mkdir("/tmp/stereo_occupancy_rostest", 0755);
  std::remove("/tmp/stereo_occupancy_rostest/stereo_occupancy_map.bt");
  std_srvs::Trigger save;
  ASSERT_TRUE(ros::service::waitForService("/octomap_accumulator/save_map", ros::Duration(10.0)));
  ASSERT_TRUE(ros::service::call("/octomap_accumulator/save_map", save));
  EXPECT_TRUE(save.response.success) << save.response.message;
  EXPECT_NE(save.response.message.find("/tmp/stereo_occupancy_rostest/stereo_occupancy_map.bt"), std::string::npos);
  octomap::OcTree saved("/tmp/stereo_occupancy_rostest/stereo_occupancy_map.bt");
  ASSERT_NE(saved.search(12.1, 0.1, 2.1), nullptr);
  EXPECT_TRUE(saved.isNodeOccupied(saved.search(12.1, 0.1, 2.1)));
  EXPECT_EQ(saved.getNumLeafNodes(), tree.getNumLeafNodes());
}

/// The largest log-odds of an update (the wall's peak).
float maxLogOdds(const OccupancyUpdate& msg) {
  float m = -1e9f;
  for (float v : msg.log_odds) m = std::max(m, v);
  return m;
}

// A depth camera's image gives the same update as the disparity image of the
// same frame; dynamic_reconfigure changes the model; an invalid parameter
// keeps a nodelet from starting without harming the manager.
TEST_F(MappingTest, DepthInputReconfigureAndInvalidParameters) {
  ros::Subscriber depth_updates =
      nh_.subscribe<OccupancyUpdate>("/depth_update", 5, [this](const OccupancyUpdateConstPtr& msg) {
        std::lock_guard<std::mutex> lock(mutex_);
        depth_updates_.push_back(msg);
      });
  ros::Publisher depth_pub = nh_.advertise<sensor_msgs::Image>("/depth/image", 2);
  ros::Publisher info_pub = nh_.advertise<sensor_msgs::CameraInfo>("/depth/camera_info", 2, /*latch=*/true);
  const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(20.0);
  while ((depth_pub.getNumSubscribers() == 0 || depth_updates.getNumPublishers() == 0) && ros::WallTime::now() < until)
    ros::WallDuration(0.05).sleep();
  ASSERT_GT(depth_pub.getNumSubscribers(), 0u);

  // A mapper loaded with resolution_m = -1 refuses to start: it says so,
  // naming the parameter, and subscribes to nothing (its onInit returns, so
  // the load itself answers success); the manager lives on, and the same
  // nodelet with a valid value starts.
  std::vector<std::string> fatal;
  ros::Subscriber log_sub =
      nh_.subscribe<rosgraph_msgs::Log>("/rosout", 100, [&](const rosgraph_msgs::LogConstPtr& log) {
        std::lock_guard<std::mutex> lock(mutex_);
        if (log->level == rosgraph_msgs::Log::FATAL) fatal.push_back(log->msg);
      });
  const ros::WallTime log_until = ros::WallTime::now() + ros::WallDuration(10.0);
  while (log_sub.getNumPublishers() < 2 && ros::WallTime::now() < log_until) ros::WallDuration(0.05).sleep();
  ASSERT_GE(log_sub.getNumPublishers(), 2u) << "the nodelet manager's /rosout is not connected";
  ros::WallDuration(0.5).sleep();  // the connections' handshakes
  ros::Publisher bad_pub = nh_.advertise<stereo_msgs::DisparityImage>("/bad/disparity", 1);
  nodelet::NodeletLoad load;
  load.request.name = "/bad_mapper";
  load.request.type = "stereo_occupancy/DisparityMapper";
  for (const auto& [from, to] :
       std::vector<std::pair<std::string, std::string>>{{"disparity", "/bad/disparity"},
                                                        {"occupancy_update", "/bad/occupancy_update"},
                                                        {"local_grid_cloud", "/bad/local_grid_cloud"},
                                                        {"disparity_image", "/bad/disparity_image"}}) {
    load.request.remap_source_args.push_back("/" + from);
    load.request.remap_target_args.push_back(to);
  }
  nodelet::NodeletUnload unload;
  unload.request.name = "/bad_mapper";
  nh_.setParam("/bad_mapper/resolution_m", -1.0);
  ASSERT_TRUE(ros::service::call("/stereo_occupancy_manager/load_nodelet", load));
  auto refusedToStart = [&] {
    for (const auto& m : fatal)
      if (m.find("/bad_mapper: invalid parameter: resolution_m") != std::string::npos &&
          m.find("does not start") != std::string::npos)
        return true;
    return false;
  };
  ASSERT_TRUE(waitFor(refusedToStart, 10.0)) << fatal.size() << " FATAL messages, none from /bad_mapper";
  // The message is onInit's last act: from here on no subscription can come.
  ros::WallDuration(0.5).sleep();
  EXPECT_EQ(bad_pub.getNumSubscribers(), 0u);
  EXPECT_FALSE(ros::service::exists("/bad_mapper/set_parameters", false));
  ASSERT_TRUE(ros::service::call("/stereo_occupancy_manager/unload_nodelet", unload));
  nh_.setParam("/bad_mapper/resolution_m", 0.25);
  ASSERT_TRUE(ros::service::call("/stereo_occupancy_manager/load_nodelet", load));
  ASSERT_TRUE(load.response.success);
  const ros::WallTime start_until = ros::WallTime::now() + ros::WallDuration(20.0);
  while (bad_pub.getNumSubscribers() == 0 && ros::WallTime::now() < start_until) ros::WallDuration(0.05).sleep();
  EXPECT_GT(bad_pub.getNumSubscribers(), 0u) << "the same mapper with resolution_m = 0.25 did not start";
  EXPECT_TRUE(ros::service::call("/stereo_occupancy_manager/unload_nodelet", unload));
  nh_.deleteParam("/bad_mapper");

  sensor_msgs::CameraInfo info;
  info.header.frame_id = "camera_optical";
  info.width = 640;
  info.height = 480;
  info.K = {700, 0, 319.5, 0, 700, 239.5, 0, 0, 1};
  info.P = {700, 0, 319.5, 0, 0, 700, 239.5, 0, 0, 0, 1, 0};
  info_pub.publish(info);
  ros::WallDuration(0.5).sleep();

  // A wall filling the whole view: a depth camera reports no "infinitely far"
  // (depth 0 means no measurement), so both inputs carry the same information.
  SyntheticScene big_wall;
  // Its face off the cells' faces (12.0 m is one): a hit goes into the cell
  // that holds its point, and a point on a face falls in either cell by the
  // last bit of z = bf / d.
  big_wall.addBox(Eigen::Vector3d(12.1, -30.0, -30.0), Eigen::Vector3d(13.0, 30.0, 30.0));
  const cv::Mat wall_image = renderDisparity(big_wall, StereoCameraModel(StereoCameraConfig()), T_W_C_);
  const ros::Time stamp = ros::Time::now();
  sendFrame(stamp, "camera_optical", true, &wall_image);
  auto depth = boost::make_shared<sensor_msgs::Image>();
  depth->header.stamp = stamp;
  depth->header.frame_id = "camera_optical";
  depth->width = 640;
  depth->height = 480;
  depth->encoding = "32FC1";
  depth->step = 640 * 4;
  depth->data.resize(640 * 480 * 4);
  float* z = reinterpret_cast<float*>(depth->data.data());
  for (int i = 0; i < 640 * 480; ++i) {
    const float d = reinterpret_cast<const float*>(wall_image.data)[i];
    ASSERT_GT(d, 0.0f);
    z[i] = 210.0f / d;  // z = bf / d
  }
  depth_pub.publish(depth);
  ASSERT_TRUE(waitFor([&] { return !depth_updates_.empty() && !updates_.empty(); }, 20.0));
  OccupancyUpdateConstPtr from_depth, from_disparity;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    from_depth = depth_updates_.back();
    from_disparity = updates_.back();
  }
  ASSERT_EQ(from_depth->header.stamp, stamp);
  ASSERT_EQ(from_disparity->header.stamp, stamp);
  EXPECT_EQ(from_depth->origin_index, from_disparity->origin_index);
  EXPECT_EQ(from_depth->size, from_disparity->size);
  // The same cells with the same values, but for the few at the edge of the
  // surface profile's gap, where z = bf/d rounded in float moves a cell
  // between "free" and "no information" (not sent).
  auto cellsOf = [](const OccupancyUpdate& msg) {
    GridUpdateView u;
    std::string why;
    EXPECT_TRUE(viewOf(msg, &u, &why) && u.isConsistent(&why)) << why;
    std::map<std::array<int, 3>, float> cells;
    u.forEachCell([&](const Eigen::Vector3i& g, float v) { cells[{g.x(), g.y(), g.z()}] = v; });
    return cells;
  };
  const auto depth_cells = cellsOf(*from_depth), disparity_cells = cellsOf(*from_disparity);
  size_t same = 0, differ = 0;
  for (const auto& [cell, v] : disparity_cells) {
    const auto it = depth_cells.find(cell);
    if (it != depth_cells.end() && std::abs(it->second - v) <= 1e-3f)
      ++same;
    else
      ++differ;
  }
  differ += depth_cells.size() - same;  // cells only the depth update has, or with other values
  ASSERT_GT(disparity_cells.size(), 10000u);
  EXPECT_LT(static_cast<double>(differ) / disparity_cells.size(), 0.002) << differ << " cells differ";

  // The default surface profile: the wall's cells take p_hit. Raise it at
  // run time, then switch to the paper's Gaussian profile, whose peak at 12 m
  // is 0.5 + k / (Δl √(2π)) (eq. 9), with k halved.
  const double dl = 144.0 * 0.5 / 210.0;
  auto logit = [](double p) { return std::log(p / (1.0 - p)); };
  EXPECT_NEAR(maxLogOdds(*from_disparity), logit(0.68), 0.01);
  auto drawWith = [&](dynamic_reconfigure::Reconfigure srv, const ros::Time& stamp) {
    EXPECT_TRUE(ros::service::call("/disparity_mapper/set_parameters", srv));
    sendFrame(stamp);
    EXPECT_TRUE(waitFor([&] { return updates_.back()->header.stamp == stamp; }, 20.0));
    std::lock_guard<std::mutex> lock(mutex_);
    return maxLogOdds(*updates_.back());
  };
  dynamic_reconfigure::Reconfigure hit;
  dynamic_reconfigure::DoubleParameter p_hit;
  p_hit.name = "p_hit";
  p_hit.value = 0.8;
  hit.request.config.doubles.push_back(p_hit);
  const ros::Time with_hit = stamp + ros::Duration(0.05);
  EXPECT_NEAR(drawWith(hit, with_hit), logit(0.8), 0.01);
  dynamic_reconfigure::Reconfigure reconfigure;
  dynamic_reconfigure::StrParameter gaussian;
  gaussian.name = "sensor_profile";
  gaussian.value = "gaussian";
  reconfigure.request.config.strs.push_back(gaussian);
  dynamic_reconfigure::DoubleParameter k;
  k.name = "k_m";
  k.value = 0.05;
  reconfigure.request.config.doubles.push_back(k);
  const ros::Time later = with_hit + ros::Duration(0.1);
  EXPECT_NEAR(drawWith(reconfigure, later), logit(0.5 + 0.05 / (dl * std::sqrt(2 * M_PI))), 0.01);

  // Out of range: the server clamps k_m = 50 to its maximum, 10.
  auto reconfigureDouble = [&](const std::vector<std::pair<std::string, double>>& values) {
    dynamic_reconfigure::Reconfigure srv;
    for (const auto& [name, value] : values) {
      dynamic_reconfigure::DoubleParameter p;
      p.name = name;
      p.value = value;
      srv.request.config.doubles.push_back(p);
    }
    EXPECT_TRUE(ros::service::call("/disparity_mapper/set_parameters", srv));
    std::map<std::string, double> shown;
    for (const auto& d : srv.response.config.doubles) shown[d.name] = d.value;
    return shown;
  };
  EXPECT_DOUBLE_EQ(reconfigureDouble({{"k_m", 50.0}})["k_m"], 10.0);  // clamped to the table's maximum
  // Each in range, together invalid (min_range_m >= max_range_m): refused,
  // and the server shows the values still in use.
  std::map<std::string, double> shown = reconfigureDouble({{"k_m", 0.05}, {"min_range_m", 9.0}, {"max_range_m", 5.0}});
  EXPECT_DOUBLE_EQ(shown["k_m"], 10.0);
  EXPECT_DOUBLE_EQ(shown["min_range_m"], 0.5);
  EXPECT_DOUBLE_EQ(shown["max_range_m"], 25.0);
  // An unknown algorithm: refused likewise.
  dynamic_reconfigure::Reconfigure bad_algorithm;
  dynamic_reconfigure::StrParameter algorithm;
  algorithm.name = "algorithm";
  algorithm.value = "bresenham";
  bad_algorithm.request.config.strs.push_back(algorithm);
  ASSERT_TRUE(ros::service::call("/disparity_mapper/set_parameters", bad_algorithm));
  std::map<std::string, std::string> shown_strs;
  for (const auto& p : bad_algorithm.response.config.strs) shown_strs[p.name] = p.value;
  EXPECT_EQ(shown_strs["algorithm"], "line_pyramid_bounded");
  EXPECT_EQ(shown_strs["sensor_profile"], "gaussian");  // as set above
  // The next image is drawn with k = 10 (the clamped value) and the old
  // range (0.5 to 25 m). At 12 m any k above 0.34 m reaches the cap p_max;
  // a wall at 20 m with delta_d_px = 5 has Δl = 20² · 5 / 210 = 9.5 m, so
  // with p_max = 0.99 its peak 0.5 + k / (Δl √(2π)) is 0.92 for k = 10 and
  // 0.54 for k = 1: below the cap, it tells the two apart.
  std::map<std::string, double> wide = reconfigureDouble({{"delta_d_px", 5.0}, {"p_max", 0.99}});
  EXPECT_DOUBLE_EQ(wide["k_m"], 10.0);
  EXPECT_DOUBLE_EQ(wide["p_max"], 0.99);
  SyntheticScene far_wall;
  far_wall.addBox(Eigen::Vector3d(20.0, -30.0, -30.0), Eigen::Vector3d(21.0, 30.0, 30.0));
  const cv::Mat far_image = renderDisparity(far_wall, StereoCameraModel(StereoCameraConfig()), T_W_C_);
  const ros::Time last = later + ros::Duration(0.1);
  sendFrame(last, "camera_optical", true, &far_image);
  ASSERT_TRUE(waitFor([&] { return updates_.back()->header.stamp == last; }, 20.0));
  OccupancyUpdateConstPtr clamped;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    clamped = updates_.back();
  }
  const double dl_far = 400.0 * 5.0 / 210.0;
  EXPECT_NEAR(maxLogOdds(*clamped), logit(0.5 + 10.0 / (dl_far * std::sqrt(2 * M_PI))), 0.01);
  reconfigureDouble({{"delta_d_px", 0.5}, {"p_max", 0.9}});  // as before, for the cases after this one
}

// Hostile input: each bad message is refused without an update, the next
// good image is mapped, and nothing non-finite reaches an update or the map.
TEST_F(MappingTest, BadInputIsRefusedAndTheNextImageWorks) {
  // The mapper's counters before this case: it counts what this case adds.
  const std::map<std::string, std::string> before = mapperDiagnostics();
  auto added = [&](const std::map<std::string, std::string>& now, const std::string& key) {
    return std::stol(now.at(key)) - std::stol(before.at(key));
  };
  ros::Publisher update_pub = nh_.advertise<OccupancyUpdate>("/occupancy_update", 5);
  // Stamped a little ahead, so that a later jump back lands at "now" (with
  // wall time an image far in the past is rightly too old for tf_timeout_s).
  ros::Time t = ros::Time::now() + ros::Duration(3.0);
  auto next = [&]() { return t += ros::Duration(0.05); };
  auto nan = std::numeric_limits<float>::quiet_NaN();
  auto inf = std::numeric_limits<float>::infinity();
  std::vector<std::pair<std::string, std::function<void(stereo_msgs::DisparityImage&)>>> cases = {
      {"16UC1 encoding", [](stereo_msgs::DisparityImage& m) { m.image.encoding = "16UC1"; }},
      {"step too small", [](stereo_msgs::DisparityImage& m) { m.image.step = 100; }},
      {"data too short", [](stereo_msgs::DisparityImage& m) { m.image.data.resize(1000); }},
      {"empty image",
       [](stereo_msgs::DisparityImage& m) {
         m.image.width = m.image.height = 0;
         m.image.data.clear();
       }},
      {"zero height", [](stereo_msgs::DisparityImage& m) { m.image.height = 0; }},
      {"f = 0", [](stereo_msgs::DisparityImage& m) { m.f = 0.0f; }},
      {"f < 0", [](stereo_msgs::DisparityImage& m) { m.f = -700.0f; }},
      {"T = 0", [](stereo_msgs::DisparityImage& m) { m.T = 0.0f; }},
      {"T < 0", [](stereo_msgs::DisparityImage& m) { m.T = -0.3f; }},
      {"f NaN", [=](stereo_msgs::DisparityImage& m) { m.f = nan; }},
      {"T inf", [=](stereo_msgs::DisparityImage& m) { m.T = inf; }},
      {"delta_d NaN", [=](stereo_msgs::DisparityImage& m) { m.delta_d = nan; }},
      {"oversized image",
       [](stereo_msgs::DisparityImage& m) {
         m.image.width = 5000;
         m.image.height = 5000;
         m.image.step = 20000;
       }},
      // A well-formed camera for which 0.25 m cells are too fine (f = 1 px
      // would need 2^-10 px lines): refused, and reported once for both.
      {"f = 1 px", [](stereo_msgs::DisparityImage& m) { m.f = 1.0f; }},
      {"f = 1 px again", [](stereo_msgs::DisparityImage& m) { m.f = 1.0f; }},
  };
  int too_fine_errors = 0;
  // Straight from the nodes' /rosout publishers (the rosout node, which
  // would aggregate them to /rosout_agg, is not part of every installation).
  ros::Subscriber log_sub =
      nh_.subscribe<rosgraph_msgs::Log>("/rosout", 100, [&](const rosgraph_msgs::LogConstPtr& log) {
        std::lock_guard<std::mutex> lock(mutex_);
        if (log->level == rosgraph_msgs::Log::ERROR &&
            log->msg.find("cannot map with this camera") != std::string::npos)
          ++too_fine_errors;
      });
  const ros::WallTime log_until = ros::WallTime::now() + ros::WallDuration(10.0);
  while (log_sub.getNumPublishers() < 2 && ros::WallTime::now() < log_until) ros::WallDuration(0.05).sleep();
  ASSERT_GE(log_sub.getNumPublishers(), 2u) << "the nodelet manager's /rosout is not connected";
  ros::WallDuration(0.5).sleep();  // the connections' handshakes done before the first case
  for (const auto& c : cases) {
    const ros::Time stamp = next();
    tf_.sendTransform(toTransformMsg(T_W_C_, stamp, "map", "camera_optical"));
    auto msg = makeFrame(stamp);
    c.second(*msg);
    disparity_pub_.publish(msg);
    ros::WallDuration(0.05).sleep();  // paced: queues drop messages of a burst
  }
  // Hostile pixel values are skipped, not mapped: the image still gives an update without NaN.
  cv::Mat wild = image_.clone();
  for (int i = 0; i < static_cast<int>(wild.total()); i += 7) {
    const float values[] = {nan, inf, -inf, -5.0f, 1e30f, 1e-30f, 200.0f};
    reinterpret_cast<float*>(wild.data)[i] = values[(i / 7) % 7];
  }
  const ros::Time wild_stamp = next();
  sendFrame(wild_stamp, "camera_optical", true, &wild);
  // A pose with NaN and one with a non-unit quaternion: never mapped.
  for (int k = 0; k < 2; ++k) {
    const ros::Time stamp = next();
    auto pose = toTransformMsg(T_W_C_, stamp, "map", "bad_pose_" + std::to_string(k));
    if (k == 0)
      pose.transform.translation.x = nan;
    else
      pose.transform.rotation.w = 3.0;
    tf_.sendTransform(pose);
    disparity_pub_.publish(makeFrame(stamp, "bad_pose_" + std::to_string(k)));
  }
  const ros::Time good = next();
  sendFrame(good);
  ASSERT_TRUE(waitFor([&] { return !updates_.empty() && updates_.back()->header.stamp == good; }, 20.0))
      << updates_.size() << " updates";
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ASSERT_EQ(updates_.size(), 2u) << "only the wild image and the good one are mapped";
    EXPECT_EQ(updates_[0]->header.stamp, wild_stamp);
    for (const auto& u : updates_)
      for (float v : u->log_odds) ASSERT_TRUE(std::isfinite(v));
  }

  // An image whose disparities all lie outside the message's range maps
  // nothing: published empty, counted and warned about (checked below).
  const ros::Time narrow_stamp = next();
  tf_.sendTransform(toTransformMsg(T_W_C_, narrow_stamp, "map", "camera_optical"));
  auto narrow = makeFrame(narrow_stamp, "camera_optical", cv::Mat(480, 640, CV_32FC1, cv::Scalar(17.5f)));
  narrow->max_disparity = 5.0f;
  disparity_pub_.publish(narrow);
  ASSERT_TRUE(waitFor([&] { return updates_.back()->header.stamp == narrow_stamp; }, 20.0));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    EXPECT_TRUE(updates_.back()->log_odds.empty());
  }

  // Stamps going back by 3 s (a looping bag): warned, the old poses cleared,
  // then mapping goes on.
  const ros::Time back = ros::Time::now();
  sendFrame(back);
  ros::WallDuration(0.3).sleep();
  const ros::Time after = back + ros::Duration(0.1);
  sendFrame(after);
  ASSERT_TRUE(waitFor([&] { return updates_.back()->header.stamp == after; }, 20.0));
  // The mapper's diagnostics count what it refused and the jump back.
  ros::WallDuration(1.5).sleep();  // the diagnostics (1 Hz) published after the last image
  const std::map<std::string, std::string> diag = mapperDiagnostics();
  EXPECT_EQ(added(diag, "time jumps back"), 1);
  EXPECT_EQ(added(diag, "dropped: invalid input"), 15);  // the 13 malformed messages and the 2 too-fine cameras
  EXPECT_EQ(added(diag, "mapped nothing"), 1);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    EXPECT_EQ(too_fine_errors, 1);
    // tf2 itself refuses a NaN pose and a non-unit quaternion, so those two
    // images wait for a pose that never comes (dropped when the queue pushes
    // them out); no update carries their stamps (checked above).
  }

  // Updates the accumulator must refuse: sizes that do not fit, another
  // resolution, NaN. Each is counted in its diagnostics, with the reason.
  // (After the images: waiting for the diagnostics would age their stamps.)
  OccupancyUpdate good_update;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    good_update = *updates_.back();
  }
  std::vector<std::tuple<std::string, std::function<void(OccupancyUpdate&)>, std::string>> bad_updates = {
      {"one value more than the runs cover", [](OccupancyUpdate& u) { u.log_odds.push_back(1.0f); }, "the runs cover"},
      {"resolution 0.5 m", [](OccupancyUpdate& u) { u.resolution = 0.5; }, "update resolution 0.5"},
      {"a NaN value", [=](OccupancyUpdate& u) { u.log_odds[0] = nan; }, "a log-odds value is not finite"},
      {"a run past the grid", [](OccupancyUpdate& u) { u.run_start[0] = 4000000000u; }, "a run ends outside the grid"},
  };
  long refused_before = std::stol(accumulatorDiagnostics()["updates refused"]);
  for (const auto& [what, spoil, reason] : bad_updates) {
    OccupancyUpdate bad = good_update;
    spoil(bad);
    update_pub.publish(bad);
    std::map<std::string, std::string> accumulator;
    const std::string refused = std::to_string(refused_before + 1);
    const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(10.0);
    while ((accumulator = accumulatorDiagnostics())["updates refused"] != refused && ros::WallTime::now() < until) {
    }
    EXPECT_EQ(accumulator["updates refused"], refused) << what << " was not refused";
    EXPECT_NE(accumulator["message"].find("refused an update: " + reason), std::string::npos)
        << what << ": " << accumulator["message"];
    refused_before = std::stol(accumulator["updates refused"]);  // the next case counts from here
  }

  // The manager is alive and the map holds the wall, with nothing non-finite.
  std_srvs::Trigger save;
  ::mkdir("/tmp/stereo_occupancy_rostest", 0755);
  ASSERT_TRUE(ros::service::call("/octomap_accumulator/save_map", save));
  ASSERT_TRUE(save.response.success) << save.response.message;
  octomap::OcTree saved("/tmp/stereo_occupancy_rostest/stereo_occupancy_map.bt");
  ASSERT_NE(saved.search(12.1, 0.1, 2.1), nullptr);
  EXPECT_TRUE(saved.isNodeOccupied(saved.search(12.1, 0.1, 2.1)));
  std::unique_ptr<octomap::AbstractOcTree> full(
      octomap::AbstractOcTree::read("/tmp/stereo_occupancy_rostest/stereo_occupancy_map.ot"));
  auto* tree = dynamic_cast<octomap::OcTree*>(full.get());
  ASSERT_NE(tree, nullptr);
  for (auto it = tree->begin_leafs(), end = tree->end_leafs(); it != end; ++it)
    ASSERT_TRUE(std::isfinite(it->getLogOdds()));
}

}  // namespace
