// The nodelets in a real manager under hostile input: another node's
// occupancy updates (any node may publish on the topic), a full disk under
// save_dir, images stamped 0 or far ahead, tf that comes late, loops, never
// comes or floods. The manager must live, the map stay as it was, the
// counters move.

#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <ros/master.h>
#include <ros/network.h>
#include <ros/ros.h>
#include <rosgraph_msgs/Log.h>
#include <std_srvs/Trigger.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2_ros/transform_broadcaster.h>
#include <xmlrpcpp/XmlRpcClient.h>

#include <signal.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>
#include <vector>

#include "stereo_occupancy/OccupancyUpdate.h"
#include "stereo_occupancy/Octomap.h"
#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "wait_for.h"

using namespace stereo_occupancy;

namespace {

const char* kSaveDir = "/tmp/stereo_occupancy_hostile";
constexpr uint32_t kIntMax = static_cast<uint32_t>(std::numeric_limits<int>::max());

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

/// The process id of this test's nodelet manager, asked through its ROS API
/// (another test's manager of the same name may run beside it); 0 if it is gone.
pid_t managerPid() {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  args[1] = "/stereo_occupancy_manager";
  if (!ros::master::execute("lookupNode", args, result, payload, false)) return 0;
  std::string host;
  uint32_t port = 0;
  if (!ros::network::splitURI(static_cast<std::string>(payload), host, port)) return 0;
  XmlRpc::XmlRpcClient client(host.c_str(), static_cast<int>(port), "/");
  XmlRpc::XmlRpcValue request, response;
  request[0] = ros::this_node::getName();
  if (!client.execute("getPid", request, response) || response.size() < 3) return 0;
  const pid_t pid = static_cast<int>(response[2]);
  return ::kill(pid, 0) == 0 ? pid : 0;
}

/// A /proc/PID/status field in kB (VmHWM: peak resident memory).
long statusKb(pid_t pid, const std::string& field) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line))
    if (line.compare(0, field.size() + 1, field + ":") == 0) return std::atol(line.c_str() + field.size() + 1);
  return -1;
}

class HostileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    update_pub_ = nh_.advertise<OccupancyUpdate>("/occupancy_update", 50);
    map_sub_ = nh_.subscribe<Octomap>("/octomap_binary", 2, [this](const OctomapConstPtr& m) {
      std::lock_guard<std::mutex> lock(mutex_);
      map_ = m;
    });
    diag_sub_ = nh_.subscribe<diagnostic_msgs::DiagnosticArray>(
        "/diagnostics", 20, [this](const diagnostic_msgs::DiagnosticArrayConstPtr& msg) {
          std::lock_guard<std::mutex> lock(mutex_);
          for (const auto& status : msg->status) {
            auto& values = diag_[status.name];
            for (const auto& kv : status.values) values[kv.key] = kv.value;
            values["message"] = status.message;
          }
        });
    log_sub_ = nh_.subscribe<rosgraph_msgs::Log>("/rosout", 200, [this](const rosgraph_msgs::LogConstPtr& log) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (log->level >= rosgraph_msgs::Log::WARN) warnings_.push_back(log->msg);
    });
    updates_sub_ = nh_.subscribe<OccupancyUpdate>("/occupancy_update", 50, [this](const OccupancyUpdateConstPtr& u) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (u->header.frame_id == "map" && u->run_start.size() > 1) mapped_stamps_.push_back(u->header.stamp);
    });
    disparity_pub_ = nh_.advertise<stereo_msgs::DisparityImage>("/stereo/disparity", 20);
    lost_pub_ = nh_.advertise<stereo_msgs::DisparityImage>("/lost/disparity", 5);
    SyntheticScene scene;
    scene.addBox(Eigen::Vector3d(12.0, -3.0, 0.0), Eigen::Vector3d(13.0, 3.0, 4.0));
    T_W_C_ = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0));
    image_ = renderDisparity(scene, StereoCameraModel(StereoCameraConfig()), T_W_C_);
    const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(20.0);
    while ((update_pub_.getNumSubscribers() < 2 || disparity_pub_.getNumSubscribers() == 0 ||
            lost_pub_.getNumSubscribers() == 0 || log_sub_.getNumPublishers() < 2) &&
           ros::WallTime::now() < until)
      ros::WallDuration(0.05).sleep();
    ASSERT_GE(update_pub_.getNumSubscribers(), 2u) << "the accumulator did not subscribe";
    ASSERT_GT(disparity_pub_.getNumSubscribers(), 0u) << "the mapper did not subscribe";
    ros::WallDuration(0.5).sleep();
  }

  bool waitFor(const std::function<bool()>& condition, double seconds) {
    return stereo_occupancy::waitFor(mutex_, condition, seconds);
  }
  std::string diag(const std::string& status, const std::string& key) {
    std::lock_guard<std::mutex> lock(mutex_);
    return diag_[status][key];
  }
  /// Requires mutex_ (inside waitFor's condition), or use mappedNow().
  bool mapped(const ros::Time& stamp) {
    for (const auto& s : mapped_stamps_)
      if (s == stamp) return true;
    return false;
  }
  bool mappedNow(const ros::Time& stamp) {
    std::lock_guard<std::mutex> lock(mutex_);
    return mapped(stamp);
  }

  /// A well-formed update: a 4 x 4 x 4 box at global index @p origin, its cells @p value, seen from inside.
  static OccupancyUpdate goodUpdate(const Eigen::Vector3i& origin, float value = 1.5f) {
    LocalGrid grid;
    grid.reset(origin, Eigen::Vector3i(4, 4, 4), 0.25);
    for (size_t i = 0; i < grid.numCells(); ++i) grid.data()[i] = value;
    GridUpdate u;
    encodeGridUpdate(grid, grid.cellCentre(2, 2, 2), &u);
    OccupancyUpdate msg;
    std_msgs::Header header;
    header.frame_id = "map";
    header.stamp = ros::Time::now();
    toMsg(std::move(u), header, &msg);
    return msg;
  }
  /// An update that claims a box of @p size at @p origin and carries one cell of 1 at each linear index.
  static OccupancyUpdate claimedBox(const Eigen::Vector3i& origin, const std::array<uint32_t, 3>& size,
                                    const std::vector<uint32_t>& cells) {
    OccupancyUpdate msg;
    msg.header.frame_id = "map";
    msg.header.stamp = ros::Time::now();
    msg.resolution = 0.25;
    for (int a = 0; a < 3; ++a) {
      msg.origin_index[a] = origin[a];
      msg.size[a] = size[a];
    }
    msg.sensor_origin.x = origin.x() * 0.25;
    msg.sensor_origin.y = origin.y() * 0.25;
    msg.sensor_origin.z = origin.z() * 0.25;
    for (uint32_t i : cells) {
      msg.run_start.push_back(i);
      msg.run_length.push_back(1);
      msg.log_odds.push_back(1.0f);
    }
    return msg;
  }

  std_srvs::Trigger save() {
    std_srvs::Trigger srv;
    EXPECT_TRUE(ros::service::call("/octomap_accumulator/save_map", srv));
    return srv;
  }

  void sendFrame(const ros::Time& stamp, bool with_tf = true, const std::string& frame = "camera_optical") {
    if (with_tf) tf_.sendTransform(toTransformMsg(T_W_C_, stamp, "map", frame));
    auto msg = boost::make_shared<stereo_msgs::DisparityImage>();
    std_msgs::Header header;
    header.stamp = stamp;
    header.frame_id = frame;
    toDisparityImageMsg(image_, header, StereoCameraConfig(), 128.0, 1.0 / 16.0, msg.get());
    disparity_pub_.publish(msg);
  }

  ros::NodeHandle nh_;
  ros::Publisher update_pub_, disparity_pub_, lost_pub_;
  tf2_ros::TransformBroadcaster tf_;
  Eigen::Isometry3d T_W_C_;
  cv::Mat image_;
  std::mutex mutex_;
  OctomapConstPtr map_;
  std::map<std::string, std::map<std::string, std::string>> diag_;
  std::vector<std::string> warnings_;
  std::vector<ros::Time> mapped_stamps_;
  // Last, so destroyed first: the spinner's threads run their callbacks until
  // they are shut down, and the callbacks write the members above.
  ros::Subscriber map_sub_, diag_sub_, log_sub_, updates_sub_;
};

const char* kAccumulator = "octomap_accumulator: accumulator";

TEST_F(HostileTest, HostileUpdatesLeaveTheMapAndTheManagerAndAFullDiskKeepsTheFile) {
  ::mkdir(kSaveDir, 0755);
  const bool root = ::geteuid() == 0;
  // The full-disk part needs root for its tmpfs; CI runs as root (CI=true),
  // where a skip would count as a pass.
  const char* ci = std::getenv("CI");
  ASSERT_TRUE(root || !(ci && std::string(ci) == "true")) << "CI=true but not root: the full-disk part cannot run";
  bool mounted = false;
  if (root) {
    mounted = ::mount("tmpfs", kSaveDir, "tmpfs", 0, "size=4m") == 0;
    ASSERT_TRUE(mounted) << "mount tmpfs at " << kSaveDir << ": " << std::strerror(errno);
  }
  const pid_t manager = managerPid();
  ASSERT_GT(manager, 0) << "no nodelet manager process";

  // The map before: two good updates.
  update_pub_.publish(goodUpdate(Eigen::Vector3i(0, 0, 8)));
  update_pub_.publish(goodUpdate(Eigen::Vector3i(8, 0, 8), -1.0f));
  ASSERT_TRUE(waitFor([&] { return diag_[kAccumulator]["updates received"] == "2"; }, 20.0));
  std_srvs::Trigger saved = save();
  ASSERT_TRUE(saved.response.success) << saved.response.message;
  const std::string ot_path = std::string(kSaveDir) + "/stereo_occupancy_map.ot";
  const std::string before = readFile(ot_path);
  ASSERT_FALSE(before.empty());
  const long peak_before_kb = statusKb(manager, "VmHWM");

  // The attacks of issue 21, each refused.
  std::vector<OccupancyUpdate> hostile = {
      claimedBox({0, 0, 0}, {1, 16384, 16384}, {12345}),              // 99 bytes claiming 268 M cells
      claimedBox({-32768, -32768, -32768}, {1, 65535, 65535}, {0}),   // 4.3 G cells
      claimedBox({0, 0, 0}, {kIntMax, 1, 1}, {0, kIntMax - 1}),       // width + 1 overflowed
      claimedBox({static_cast<int>(kIntMax), 0, 0}, {kIntMax, 1, 1},  // origin + local wrapped
                 {kIntMax - 4, kIntMax - 3, kIntMax - 2, kIntMax - 1}),
      claimedBox({static_cast<int>(kIntMax) - 100, 0, 0}, {100, 1, 1}, {96, 97, 98, 99}),  // beyond the key range
  };
  OccupancyUpdate evil = goodUpdate(Eigen::Vector3i(0, 0, 8));
  evil.header.frame_id = "evil_frame";
  hostile.push_back(evil);
  OccupancyUpdate empty_far = claimedBox({0, 0, 0}, {0, 0, 0}, {});
  empty_far.sensor_origin.x = 1e6;
  hostile.push_back(empty_far);
  OccupancyUpdate nan_value = goodUpdate(Eigen::Vector3i(0, 0, 8));
  nan_value.log_odds[7] = std::numeric_limits<float>::quiet_NaN();
  hostile.push_back(nan_value);
  for (const auto& msg : hostile) {
    update_pub_.publish(msg);
    ros::WallDuration(0.3).sleep();  // past the prune period each time
  }
  const std::string refused = std::to_string(hostile.size());
  ASSERT_TRUE(waitFor([&] { return diag_[kAccumulator]["updates refused"] == refused; }, 20.0))
      << "refused: " << diag(kAccumulator, "updates refused");
  EXPECT_EQ(managerPid(), manager) << "the manager died";
  EXPECT_LT(statusKb(manager, "VmHWM") - peak_before_kb, 200 * 1024) << "the manager's peak memory jumped";
  EXPECT_EQ(diag(kAccumulator, "frame"), "map");
  saved = save();
  ASSERT_TRUE(saved.response.success) << saved.response.message;
  EXPECT_EQ(readFile(ot_path), before) << "a refused update changed the map";
  ASSERT_TRUE(waitFor([&] { return map_ != nullptr; }, 10.0));
  {
    std::lock_guard<std::mutex> lock(mutex_);  // the callback may replace map_ meanwhile
    EXPECT_EQ(map_->header.frame_id, "map");
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    size_t named = 0;
    for (const auto& w : warnings_) named += w.find("refused an occupancy update") != std::string::npos;
    EXPECT_GE(named, 1u) << "no warning for the refused updates";
  }

  // A well-formed update 5 km away is taken, but pruning keeps the vehicle's map.
  update_pub_.publish(goodUpdate(Eigen::Vector3i(20000, 0, 8)));
  ros::WallDuration(0.5).sleep();
  update_pub_.publish(goodUpdate(Eigen::Vector3i(0, 0, 8)));  // a callback after the prune period: prunes
  ASSERT_TRUE(
      waitFor([&] { return diag_[kAccumulator]["updates received"] == std::to_string(2 + hostile.size() + 2); }, 20.0));
  saved = save();
  ASSERT_TRUE(saved.response.success) << saved.response.message;
  const std::string after_far = readFile(ot_path);
  {
    std::istringstream in(after_far);
    std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(in));
    auto* tree = dynamic_cast<octomap::OcTree*>(read.get());
    ASSERT_NE(tree, nullptr);
    ASSERT_NE(tree->search(0.6, 0.6, 2.6), nullptr) << "the vehicle's map was pruned";
    ASSERT_NE(tree->search(2.6, 0.6, 2.6), nullptr);
  }

  if (!mounted) GTEST_SKIP() << "not root: the full-disk part needs a tmpfs (a failure with CI=true)";
  // The disk full: the save fails with the reason, the previous file stays.
  {
    std::FILE* f = std::fopen((std::string(kSaveDir) + "/filler").c_str(), "wb");
    ASSERT_NE(f, nullptr);
    const std::vector<char> block(4096, 'x');
    while (std::fwrite(block.data(), 1, block.size(), f) == block.size()) {
    }
    std::fclose(f);
  }
  for (int i = 0; i < 40; ++i) update_pub_.publish(goodUpdate(Eigen::Vector3i(4 * i, 40, 8), 0.8f));
  ros::WallDuration(1.0).sleep();
  saved = save();
  EXPECT_FALSE(saved.response.success) << "a save on a full disk reported success";
  EXPECT_NE(saved.response.message.find(std::strerror(ENOSPC)), std::string::npos) << saved.response.message;
  EXPECT_EQ(readFile(ot_path), after_far) << "the failed save changed the previous file";
  ASSERT_TRUE(waitFor([&] { return diag_[kAccumulator]["saves failed"] == "1"; }, 10.0));
  EXPECT_EQ(managerPid(), manager);
  // Room again: saves work, and the shutdown save has room.
  std::remove((std::string(kSaveDir) + "/filler").c_str());
  saved = save();
  EXPECT_TRUE(saved.response.success) << saved.response.message;
  ::umount2(kSaveDir, MNT_DETACH);
}

const char* kMapper = "disparity_mapper: mapper";

// An update queue that overflowed, or a link that drops updates, shows as a
// gap in a mapper's sequence numbers: counted in the diagnostics, not silent.
TEST_F(HostileTest, UpdatesThatNeverArriveAreCountedAsLost) {
  ASSERT_TRUE(waitFor([&] { return diag_[kAccumulator].count("updates lost") > 0; }, 10.0)) << "no diagnostics";
  const long before = std::stol(diag(kAccumulator, "updates lost"));
  for (uint64_t sequence : {1u, 2u, 6u}) {  // 3, 4 and 5 never arrive
    OccupancyUpdate msg = goodUpdate(Eigen::Vector3i(0, 0, 8));
    msg.source = "/test_mapper";
    msg.sequence = sequence;
    update_pub_.publish(msg);
    ros::WallDuration(0.1).sleep();
  }
  const std::string expected = std::to_string(before + 3);
  EXPECT_TRUE(waitFor([&] { return diag_[kAccumulator]["updates lost"] == expected; }, 20.0))
      << "updates lost: " << diag(kAccumulator, "updates lost");
}

TEST_F(HostileTest, BadStampsAndTfNeitherStopNorMisplaceTheMapping) {
  // tf at 100 Hz on another frame all along; stopped however the test ends
  // (a failed ASSERT returns early: a thread left joinable would abort the test).
  struct Spam {
    std::atomic<bool> on{true};
    std::thread thread;
    void stop() {
      on = false;
      if (thread.joinable()) thread.join();
    }
    ~Spam() { stop(); }
  } spam;
  spam.thread = std::thread([&spam] {
    tf2_ros::TransformBroadcaster broadcaster;
    ros::WallRate rate(100.0);
    while (spam.on) {
      broadcaster.sendTransform(toTransformMsg(Eigen::Isometry3d::Identity(), ros::Time::now(), "map", "spam_link"));
      rate.sleep();
    }
  });
  auto stopSpam = [&] { spam.stop(); };

  ros::Time t = ros::Time::now();
  sendFrame(t);
  ASSERT_TRUE(waitFor([&] { return mapped(t); }, 20.0)) << "the first image was not mapped";

  // An image stamped 0 (tf2 reads 0 as "the latest pose"): refused, and the
  // tf buffer keeps the pose sent for the next image.
  const ros::Time t2 = t + ros::Duration(0.2);
  tf_.sendTransform(toTransformMsg(T_W_C_, t2, "map", "camera_optical"));
  ros::WallDuration(0.3).sleep();
  sendFrame(ros::Time(0), /*with_tf=*/false);
  ros::WallDuration(0.3).sleep();
  sendFrame(t2, /*with_tf=*/false);
  EXPECT_TRUE(waitFor([&] { return mapped(t2); }, 10.0)) << "the image after the one stamped 0 lost its pose";
  // One stamped a year ahead: not mapped, and not taken for the time line.
  sendFrame(t2 + ros::Duration(3.2e7), /*with_tf=*/false);  // a pose a year ahead would empty tf's cache
  ros::WallDuration(0.3).sleep();
  const ros::Time t3 = ros::Time::now();
  sendFrame(t3);
  EXPECT_TRUE(waitFor([&] { return mapped(t3); }, 10.0));
  EXPECT_FALSE(mappedNow(ros::Time(0)));
  EXPECT_FALSE(mappedNow(t2 + ros::Duration(3.2e7)));

  // tf 10 s late: the image is too old by then (tf_timeout_s), dropped and counted.
  const ros::Time late = ros::Time::now();
  sendFrame(late, /*with_tf=*/false);
  ros::WallDuration(10.0).sleep();
  tf_.sendTransform(toTransformMsg(T_W_C_, late, "map", "camera_optical"));
  // A tf loop: the image's frame never reaches map.
  const ros::Time loop = ros::Time::now();
  tf_.sendTransform(toTransformMsg(Eigen::Isometry3d::Identity(), loop, "loop_b", "loop_a"));
  tf_.sendTransform(toTransformMsg(Eigen::Isometry3d::Identity(), loop, "loop_a", "loop_b"));
  ros::WallDuration(0.2).sleep();
  sendFrame(loop, /*with_tf=*/false, "loop_a");
  // Mapping goes on beside the images that wait for a pose that cannot come.
  ros::Time last;
  for (int i = 0; i < 6; ++i) {
    ros::WallDuration(0.2).sleep();
    last = ros::Time::now();
    sendFrame(last);
  }
  EXPECT_TRUE(waitFor([&] { return mapped(last); }, 10.0));
  EXPECT_FALSE(mappedNow(late));
  EXPECT_FALSE(mappedNow(loop));

  // A mapper whose world frame never appears says so.
  for (int i = 0; i < 14; ++i) {
    auto msg = boost::make_shared<stereo_msgs::DisparityImage>();
    std_msgs::Header header;
    header.stamp = ros::Time::now();
    header.frame_id = "camera_optical";
    toDisparityImageMsg(image_, header, StereoCameraConfig(), 128.0, 1.0 / 16.0, msg.get());
    lost_pub_.publish(msg);
    ros::WallDuration(0.5).sleep();
  }
  stopSpam();
  EXPECT_TRUE(waitFor(
      [&] {
        for (const auto& w : warnings_)
          if (w.find("world_frame 'never_published_world' does not exist in tf") != std::string::npos) return true;
        return false;
      },
      5.0))
      << "no warning that the world frame is missing";

  ASSERT_TRUE(waitFor([&] { return !diag_[kMapper]["dropped: no transform"].empty(); }, 5.0));
  EXPECT_EQ(diag(kMapper, "time jumps back"), "0");
  EXPECT_GE(std::stoi(diag(kMapper, "dropped: invalid input")), 1) << "the image stamped 0";
  EXPECT_GE(std::stoi(diag(kMapper, "dropped: no transform")), 1) << "the image whose pose came 10 s late";
  EXPECT_NE(diag("lost_mapper: mapper", "message").find("never_published_world"), std::string::npos)
      << diag("lost_mapper: mapper", "message");
}

}  // namespace
