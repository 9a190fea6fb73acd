// The distance field in a real manager (distance_field.test): the posts
// flight (simulate_flight's "posts" scenario, frame by frame with its tf)
// through the mapper and the accumulator; then a planner's questions on the
// accumulator's ~check_path, ~cast_ray and ~distance, answered against the
// scene's true geometry, bad input refused with a reason while the nodelet
// keeps serving, the PathWatcher nodelet in the same manager, reading the
// field in place, gives the service's verdict, and ~clear_bbx and ~reset
// reach the field at once.

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_srvs/Empty.h>
#include <stereo_msgs/DisparityImage.h>
#include <tf2_ros/transform_broadcaster.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "stereo_occupancy/BoundingBoxQuery.h"
#include "stereo_occupancy/CastRay.h"
#include "stereo_occupancy/CheckPath.h"
#include "stereo_occupancy/GetDistances.h"
#include "stereo_occupancy/GetOctomap.h"
#include "stereo_occupancy/OccupancyUpdate.h"
#include "stereo_occupancy/PathCheck.h"
#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/sim/flight_simulation.h"
#include "wait_for.h"

using namespace stereo_occupancy;

namespace {

constexpr double kCellM = 0.25;  // resolution_m of config/mapping.yaml
const std::string kNode = "/octomap_accumulator/";

geometry_msgs::Point point(double x, double y, double z) {
  geometry_msgs::Point p;
  p.x = x;
  p.y = y;
  p.z = z;
  return p;
}

/// Distance from the centre of @p p's cell to the centre of the nearest
/// occupied cell of @p map, at most @p max_m: what the field says, by brute force.
double nearestOccupiedCell(const octomap::OcTree& map, const Eigen::Vector3d& p, double max_m) {
  const double res = map.getResolution();
  const Eigen::Vector3d centre = ((p / res).array().floor() + 0.5).matrix() * res;
  const double reach = max_m + res;
  double best = max_m;
  for (auto it = map.begin_leafs_bbx(octomap::point3d(centre.x() - reach, centre.y() - reach, centre.z() - reach),
                                     octomap::point3d(centre.x() + reach, centre.y() + reach, centre.z() + reach)),
            end = map.end_leafs_bbx();
       it != end; ++it) {
    if (!map.isNodeOccupied(*it)) continue;
    // A merged leaf is a cube of cells: the nearest of its cell centres.
    const double half = 0.5 * it.getSize() - 0.5 * res;
    const Eigen::Vector3d leaf(it.getX(), it.getY(), it.getZ());
    const Eigen::Vector3d lo = leaf.array() - half, hi = leaf.array() + half;
    const Eigen::Vector3d nearest = centre.cwiseMax(lo).cwiseMin(hi);
    const Eigen::Vector3d cell = ((nearest - lo) / res).array().round().matrix() * res + lo;
    best = std::min(best, (cell - centre).norm());
  }
  return best;
}

/// The scene's box nearest to @p p.
Eigen::AlignedBox3d nearestBox(const SyntheticScene& scene, const Eigen::Vector3d& p) {
  Eigen::AlignedBox3d best = scene.boxes.front();
  for (const Eigen::AlignedBox3d& box : scene.boxes)
    if (box.exteriorDistance(p) < best.exteriorDistance(p)) best = box;
  return best;
}

/// The path straight through gate 4's left post (x = 63, y = 3.5), at 3 m: its segment 1 hits the post.
const std::vector<geometry_msgs::Point> kThroughThePost = {point(57, 0, 3), point(59, 3.5, 3), point(67, 3.5, 3),
                                                           point(69, 0, 3)};
const Eigen::Vector3d kPost(63.0, 3.5, 3.0);
/// Down the flight's lane between the gates (posts 3.5 m to each side).
const std::vector<geometry_msgs::Point> kLane = {point(58, 0, 3), point(68, 0, 3)};
/// 18 m to the side, where the forward camera never looked within its range.
const std::vector<geometry_msgs::Point> kNeverSeen = {point(57, 18, 3), point(65, 18, 3)};
constexpr double kRadiusM = 0.3;

class DistanceFieldTest : public ::testing::Test {
 protected:
  // The flight once for all tests. Nothing in SetUpTestSuite() may fail a
  // check: gtest then skips every test, and rosunit counts skipped tests as
  // passed. Each test's SetUp() fails instead.
  static void SetUpTestSuite() {
    scenario_ = makeScenario("posts");
    flight_error_ = flyThePostsFlight();
  }
  void SetUp() override { ASSERT_TRUE(flight_error_.empty()) << flight_error_; }

  /// Publishes every second frame of the posts flight with its tf, each
  /// after the mapper's update of the one before, then waits for the field
  /// to hold the last. Returns what went wrong, or "".
  static std::string flyThePostsFlight() {
    ros::NodeHandle nh;
    tf2_ros::TransformBroadcaster tf;
    ros::Publisher pub = nh.advertise<stereo_msgs::DisparityImage>("/stereo/disparity", 5);
    std::mutex mutex;
    ros::Time last_update;
    ros::Subscriber updates =
        nh.subscribe<OccupancyUpdate>("/occupancy_update", 10, [&](const OccupancyUpdateConstPtr& msg) {
          std::lock_guard<std::mutex> lock(mutex);
          last_update = msg->header.stamp;
        });
    if (!waitFor(
            mutex, [&] { return pub.getNumSubscribers() > 0 && updates.getNumPublishers() > 0; }, 30.0))
      return "the mapper did not connect";
    if (!ros::service::waitForService(kNode + "distance", ros::Duration(30.0))) return "no ~distance service";
    // A planner asks all through the flight, while the field is updated (queries and updates never race).
    std::atomic<bool> flying{true};
    std::atomic<int> answered{0}, failed{0};
    std::string first_failure;  // the planner thread's, read after join()
    std::thread planner([&] {
      // Persistent connections, a call every 2 ms: thousands of calls each on a
      // new connection leave as many sockets in TIME_WAIT, and one connect may fail.
      ros::ServiceClient check_client = nh.serviceClient<CheckPath>(kNode + "check_path", /*persistent=*/true);
      ros::ServiceClient get_client = nh.serviceClient<GetDistances>(kNode + "distance", /*persistent=*/true);
      while (flying) {
        ros::WallDuration(0.002).sleep();
        CheckPath check;
        check.request.waypoints = kThroughThePost;
        check.request.radius_m = kRadiusM;
        GetDistances get;
        get.request.points = kLane;
        const bool check_called = check_client.call(check);
        const bool get_called = get_client.call(get);
        const bool ok = check_called && check.response.success && get_called && get.response.success;
        if (!ok && failed == 0)
          first_failure = "check_path " + std::string(check_called ? "answered '" : "not answered '") +
                          check.response.message + "', distance " + (get_called ? "answered '" : "not answered '") +
                          get.response.message + "'";
        ++(ok ? answered : failed);
      }
    });
    ros::Time last_stamp;
    for (size_t i = 0; i < scenario_.T_W_B.size(); i += 2) {
      const ros::Time stamp = ros::Time::now();
      tf.sendTransform(toTransformMsg(scenario_.T_W_B[i], stamp, "map", "base_link"));
      tf.sendTransform(toTransformMsg(scenario_.T_B_C, stamp, "base_link", "camera_optical"));
      std_msgs::Header header;
      header.stamp = stamp;
      header.frame_id = "camera_optical";
      auto msg = boost::make_shared<stereo_msgs::DisparityImage>();
      toDisparityImageMsg(renderStereoFrame(scenario_, i, 1), header, scenario_.camera,
                          scenario_.effects.max_search_disparity_px, scenario_.effects.subpixel_step_px, msg.get());
      pub.publish(msg);
      // Paced by the mapper: each frame mapped, none dropped on a loaded machine.
      if (!waitFor(
              mutex, [&] { return last_update == stamp; }, 10.0)) {
        flying = false;
        planner.join();
        return "frame " + std::to_string(i) + " was not mapped within 10 s";
      }
      last_stamp = stamp;
    }
    flying = false;
    planner.join();
    std::printf("queries during the flight: %d answered\n", answered.load());
    if (failed > 0 || answered < 10)
      return "queries during the flight: " + std::to_string(answered) + " answered, " + std::to_string(failed) +
             " failed (the first: " + first_failure + ")";
    // The field holds the last update once ~distance answers with its stamp.
    GetDistances get;
    get.request.points.push_back(point(60, 0, 3));
    const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(20.0);
    while (ros::WallTime::now() < until) {
      if (!ros::service::call(kNode + "distance", get)) return "~distance did not answer";
      if (get.response.header.stamp == last_stamp) break;
      ros::WallDuration(0.1).sleep();
    }
    if (get.response.header.stamp != last_stamp)
      return "the field does not hold the flight's last update (its stamp " +
             std::to_string(get.response.header.stamp.toSec()) + ", the last update's " +
             std::to_string(last_stamp.toSec()) + ")";
    last_stamp_ = last_stamp;
    return "";
  }

  static CheckPath::Response checkPath(const std::vector<geometry_msgs::Point>& waypoints, double radius_m,
                                       bool unknown_as_occupied) {
    CheckPath check;
    check.request.waypoints = waypoints;
    check.request.radius_m = radius_m;
    check.request.unknown_as_occupied = unknown_as_occupied;
    EXPECT_TRUE(ros::service::call(kNode + "check_path", check));
    EXPECT_EQ(check.response.header.frame_id, "map");
    return check.response;
  }

  static CastRay::Response castRay(const geometry_msgs::Point& origin, double dx, double dy, double dz,
                                   double range_m) {
    CastRay cast;
    cast.request.origin = origin;
    cast.request.direction.x = dx;
    cast.request.direction.y = dy;
    cast.request.direction.z = dz;
    cast.request.max_range_m = range_m;
    EXPECT_TRUE(ros::service::call(kNode + "cast_ray", cast));
    EXPECT_EQ(cast.response.header.frame_id, "map");
    return cast.response;
  }

  static FlightScenario scenario_;
  static ros::Time last_stamp_;
  static std::string flight_error_;  ///< "" once the field holds the whole flight
};

FlightScenario DistanceFieldTest::scenario_;
ros::Time DistanceFieldTest::last_stamp_;
std::string DistanceFieldTest::flight_error_ = "not flown";

}  // namespace

TEST_F(DistanceFieldTest, APathThroughAPostIsBlockedAtThatPost) {
  const CheckPath::Response r = checkPath(kThroughThePost, kRadiusM, false);
  ASSERT_TRUE(r.success) << r.message;
  EXPECT_EQ(r.verdict, CheckPath::Response::BLOCKED) << r.message;
  EXPECT_EQ(r.first_segment, 1);
  const Eigen::Vector3d at(r.point.x, r.point.y, r.point.z);
  const Eigen::AlignedBox3d post = nearestBox(scenario_.scene, at);
  EXPECT_TRUE(post.contains(kPost)) << "blocked at (" << at.transpose() << "), nearest the box from ("
                                    << post.min().transpose() << ") to (" << post.max().transpose() << ")";
  // Where the body first comes within its radius of the post: a cell or two before it.
  EXPECT_LE(post.exteriorDistance(at), kRadiusM + 2 * kCellM) << at.transpose();
  EXPECT_LT(r.min_clearance_m, kRadiusM);
  EXPECT_EQ(r.header.stamp, last_stamp_);
}

TEST_F(DistanceFieldTest, TheLaneBetweenThePostsIsClear) {
  const CheckPath::Response r = checkPath(kLane, kRadiusM, false);
  ASSERT_TRUE(r.success) << r.message;
  EXPECT_EQ(r.verdict, CheckPath::Response::CLEAR)
      << "segment " << r.first_segment << " at (" << r.point.x << ", " << r.point.y << ", " << r.point.z << ")";
  EXPECT_EQ(r.first_segment, -1);
  EXPECT_GE(r.min_clearance_m, kRadiusM);
  // Unknown as occupied changes nothing on a lane the camera saw.
  EXPECT_EQ(checkPath(kLane, kRadiusM, true).verdict, CheckPath::Response::CLEAR);
}

TEST_F(DistanceFieldTest, NeverSeenSpaceIsUnknownOrBlockedWhenAskedSo) {
  const CheckPath::Response r = checkPath(kNeverSeen, kRadiusM, false);
  ASSERT_TRUE(r.success) << r.message;
  EXPECT_EQ(r.verdict, CheckPath::Response::UNKNOWN);
  EXPECT_EQ(r.first_segment, 0);
  const CheckPath::Response occupied = checkPath(kNeverSeen, kRadiusM, true);
  ASSERT_TRUE(occupied.success) << occupied.message;
  EXPECT_EQ(occupied.verdict, CheckPath::Response::BLOCKED);
  EXPECT_EQ(occupied.first_segment, 0);
  // The space is in the window, only never seen.
  GetDistances get;
  get.request.points = kNeverSeen;
  ASSERT_TRUE(ros::service::call(kNode + "distance", get));
  ASSERT_TRUE(get.response.success) << get.response.message;
  for (size_t i = 0; i < kNeverSeen.size(); ++i) {
    EXPECT_TRUE(get.response.in_window[i]) << i;
    EXPECT_EQ(get.response.cell_class[i], GetDistances::Response::CELL_UNKNOWN) << i;
  }
}

TEST_F(DistanceFieldTest, RaysHitThePostOrEndInUnknownSpace) {
  const CastRay::Response hit = castRay(point(57, 3.5, 3), 2.0, 0.0, 0.0, 20.0);  // any length of direction
  ASSERT_TRUE(hit.success) << hit.message;
  EXPECT_EQ(hit.verdict, CastRay::Response::HIT);
  // The post's face as the map has it: up to two cells nearer the camera (disparity noise).
  const Eigen::Vector3d at(hit.point.x, hit.point.y, hit.point.z);
  EXPECT_LE(nearestBox(scenario_.scene, at).exteriorDistance(at), 2 * kCellM) << at.transpose();
  EXPECT_TRUE(nearestBox(scenario_.scene, at).contains(kPost)) << at.transpose();
  // Entered at the cell that holds the post's true face (x = 62.8, the cell from 62.75), or two before it.
  EXPECT_NEAR(hit.range_m, 62.75 - 57.0, 2 * kCellM + 1e-6);
  const CastRay::Response unknown = castRay(kNeverSeen[0], 1.0, 0.0, 0.0, 5.0);
  ASSERT_TRUE(unknown.success) << unknown.message;
  EXPECT_EQ(unknown.verdict, CastRay::Response::UNKNOWN);
  const CastRay::Response free = castRay(point(58, 0, 3), 1.0, 0.0, 0.0, 8.0);
  ASSERT_TRUE(free.success) << free.message;
  EXPECT_EQ(free.verdict, CastRay::Response::FREE);
}

TEST_F(DistanceFieldTest, TheBatchDistancesAreTheTrueGeometrys) {
  // Cell centres beside gate 4's posts (no wire at that gate), level with
  // them, and down its lane, 3 m up: their nearest surface is a post's side,
  // which the camera saw edge-on, or nothing within max_distance_m. (In front
  // of a post the map's surface lies up to two cells nearer the camera than
  // the true one: disparity noise of 0.15 px is 0.3 m of depth at 20 m.)
  GetDistances get;
  for (double x : {62.875, 63.125})
    for (double y : {-1.875, -1.125, 0.125, 1.375, 2.125, 2.625}) get.request.points.push_back(point(x, y, 3.125));
  for (double x : {58.125, 60.125, 66.125, 68.125}) get.request.points.push_back(point(x, 0.125, 3.125));
  ASSERT_TRUE(ros::service::call(kNode + "distance", get));
  ASSERT_TRUE(get.response.success) << get.response.message;
  EXPECT_EQ(get.response.header.frame_id, "map");
  EXPECT_EQ(get.response.header.stamp, last_stamp_);
  ASSERT_EQ(get.response.distance_m.size(), get.request.points.size());
  ASSERT_EQ(get.response.gradient.size(), get.request.points.size());
  const double max_distance_m = 2.0;  // config/mapping.yaml
  // The map the field was made from (nothing has changed it since the field's last update).
  GetOctomap full;
  ASSERT_TRUE(ros::service::call("/octomap_full", full));
  const std::unique_ptr<octomap::OcTree> map = treeFromMsg(full.response.map);
  ASSERT_TRUE(map);
  for (size_t i = 0; i < get.request.points.size(); ++i) {
    const auto& p = get.request.points[i];
    const Eigen::Vector3d at(p.x, p.y, p.z);
    const double truth = std::min(scenario_.scene.distance(at), max_distance_m);
    EXPECT_TRUE(get.response.in_window[i]);
    EXPECT_EQ(get.response.cell_class[i], GetDistances::Response::CELL_FREE) << at.transpose();
    EXPECT_NEAR(get.response.distance_m[i], truth, kCellM) << "against the scene at (" << at.transpose() << ")";
    // Against the map it is exact: centre to centre of the nearest occupied cell.
    EXPECT_NEAR(get.response.distance_m[i], nearestOccupiedCell(*map, at, max_distance_m), 1e-4)
        << "against the map at (" << at.transpose() << ")";
    if (get.response.distance_m[i] < max_distance_m - kCellM) {  // below saturation: a slope of about 1
      const Eigen::Vector3d g(get.response.gradient[i].x, get.response.gradient[i].y, get.response.gradient[i].z);
      EXPECT_GT(g.norm(), 0.5) << "gradient at (" << at.transpose() << ")";
    }
  }
  // Inside the post: occupied, distance 0.
  get.request.points = {point(63.125, 3.375, 3.125)};
  ASSERT_TRUE(ros::service::call(kNode + "distance", get));
  ASSERT_TRUE(get.response.success) << get.response.message;
  EXPECT_EQ(get.response.cell_class[0], GetDistances::Response::CELL_OCCUPIED);
  EXPECT_EQ(get.response.distance_m[0], 0.0f);
  // Far outside the window: not in it, unknown, NaN.
  get.request.points = {point(500, 0, 3)};
  ASSERT_TRUE(ros::service::call(kNode + "distance", get));
  ASSERT_TRUE(get.response.success) << get.response.message;
  EXPECT_FALSE(get.response.in_window[0]);
  EXPECT_EQ(get.response.cell_class[0], GetDistances::Response::CELL_UNKNOWN);
  EXPECT_TRUE(std::isnan(get.response.distance_m[0]));
}

TEST_F(DistanceFieldTest, BadInputIsRefusedWithAReasonAndTheNodeletKeepsServing) {
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  auto expectRefused = [](bool success, const std::string& message, const std::string& says) {
    EXPECT_FALSE(success);
    EXPECT_NE(message.find(says), std::string::npos) << "'" << message << "' should say '" << says << "'";
  };
  GetDistances get;
  get.request.points = {point(60, 0, 3), point(nan, 0, 3)};
  ASSERT_TRUE(ros::service::call(kNode + "distance", get));
  expectRefused(get.response.success, get.response.message, "point 1");
  EXPECT_TRUE(get.response.distance_m.empty());
  EXPECT_EQ(get.response.header.frame_id, "map");
  get.request.points = {point(60, inf, 3)};
  ASSERT_TRUE(ros::service::call(kNode + "distance", get));
  expectRefused(get.response.success, get.response.message, "not finite");
  get.request.points.assign(100001, point(60, 0, 3));
  ASSERT_TRUE(ros::service::call(kNode + "distance", get));
  expectRefused(get.response.success, get.response.message, "at most 100000");

  CheckPath::Response r = checkPath(kLane, -0.1, false);
  expectRefused(r.success, r.message, "radius_m");
  r = checkPath(kLane, 3.0, false);  // above max_distance_m (2)
  expectRefused(r.success, r.message, "max_distance_m");
  r = checkPath(kLane, nan, false);
  expectRefused(r.success, r.message, "radius_m");
  r = checkPath({point(58, 0, 3), point(inf, 0, 3)}, kRadiusM, false);
  expectRefused(r.success, r.message, "waypoint 1");
  r = checkPath({}, kRadiusM, false);
  expectRefused(r.success, r.message, "no waypoints");
  r = checkPath(std::vector<geometry_msgs::Point>(100001, point(58, 0, 3)), kRadiusM, false);
  expectRefused(r.success, r.message, "at most 100000");

  CastRay::Response c = castRay(point(58, 0, 3), 0.0, 0.0, 0.0, 5.0);
  expectRefused(c.success, c.message, "not zero");
  c = castRay(point(58, nan, 3), 1.0, 0.0, 0.0, 5.0);
  expectRefused(c.success, c.message, "origin");
  c = castRay(point(58, 0, 3), 1.0, 0.0, 0.0, -1.0);
  expectRefused(c.success, c.message, "max_range_m");
  c = castRay(point(58, 0, 3), 1.0, 0.0, 0.0, inf);
  expectRefused(c.success, c.message, "max_range_m");

  // Still serving, with the same answers.
  EXPECT_EQ(checkPath(kThroughThePost, kRadiusM, false).verdict, CheckPath::Response::BLOCKED);
  EXPECT_EQ(checkPath(kLane, kRadiusM, false).verdict, CheckPath::Response::CLEAR);
}

TEST_F(DistanceFieldTest, ThePathWatcherInTheSameManagerSeesTheSameVerdict) {
  // distance_field.test gives the watcher kThroughThePost and kRadiusM.
  ros::NodeHandle nh;
  std::mutex mutex;
  PathCheckConstPtr last;
  ros::Subscriber sub = nh.subscribe<PathCheck>("/path_verdict", 10, [&](const PathCheckConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex);
    last = msg;
  });
  ASSERT_TRUE(waitFor(
      mutex, [&] { return last && last->header.stamp == last_stamp_; }, 20.0))
      << "the watcher published no verdict on the field's last update";
  const CheckPath::Response r = checkPath(kThroughThePost, kRadiusM, false);
  std::lock_guard<std::mutex> lock(mutex);
  EXPECT_EQ(last->header.frame_id, "map");
  EXPECT_EQ(last->verdict, r.verdict);
  EXPECT_EQ(last->verdict, PathCheck::BLOCKED);
  EXPECT_EQ(last->first_segment, r.first_segment);
  EXPECT_EQ(last->point.x, r.point.x);
  EXPECT_EQ(last->point.y, r.point.y);
  EXPECT_EQ(last->point.z, r.point.z);
  EXPECT_EQ(last->min_clearance_m, r.min_clearance_m);
}

TEST_F(DistanceFieldTest, TheSliceIsTheFieldsLayerAtItsHeight) {
  // The field no longer changes: a new subscriber gets the slice all the same.
  ros::NodeHandle nh;
  std::mutex mutex;
  sensor_msgs::PointCloud2ConstPtr slice;
  ros::Subscriber sub =
      nh.subscribe<sensor_msgs::PointCloud2>("/distance_slice", 1, [&](const sensor_msgs::PointCloud2ConstPtr& msg) {
        std::lock_guard<std::mutex> lock(mutex);
        slice = msg;
      });
  ASSERT_TRUE(waitFor(
      mutex, [&] { return slice != nullptr; }, 10.0))
      << "no distance_slice for a new subscriber";
  std::lock_guard<std::mutex> lock(mutex);
  EXPECT_EQ(slice->header.frame_id, "map");
  EXPECT_EQ(slice->header.stamp, last_stamp_);
  ASSERT_EQ(slice->fields.size(), 4u);
  EXPECT_EQ(slice->fields[3].name, "intensity");
  EXPECT_GT(slice->width * slice->height, 1000u);
  // distance_slice_z_m 2 (config/mapping.yaml): the layer from 2 to 2.25 m.
  bool post_seen = false;
  for (sensor_msgs::PointCloud2ConstIterator<float> x(*slice, "x"), y(*slice, "y"), z(*slice, "z"),
       d(*slice, "intensity");
       x != x.end(); ++x, ++y, ++z, ++d) {
    ASSERT_FLOAT_EQ(*z, 2.125f);
    ASSERT_GE(*d, 0.0f);
    ASSERT_LE(*d, 2.0f);
    if (std::abs(*x - 63.125f) < 0.01f && std::abs(*y - 3.375f) < 0.01f) {
      post_seen = true;
      EXPECT_EQ(*d, 0.0f) << "gate 4's left post";
    }
  }
  EXPECT_TRUE(post_seen) << "the slice lacks gate 4's left post";
}

// Last, since it changes the map: ~clear_bbx and ~reset reach the field at
// once, without waiting for the next update.
TEST_F(DistanceFieldTest, ClearAndResetReachTheFieldAtOnce) {
  BoundingBoxQuery clear;
  clear.request.min = point(62.0, 2.5, -1.0);
  clear.request.max = point(64.0, 4.5, 9.0);
  ASSERT_TRUE(ros::service::call(kNode + "clear_bbx", clear));
  const CastRay::Response through = castRay(point(57, 3.5, 3), 1.0, 0.0, 0.0, 10.0);
  ASSERT_TRUE(through.success) << through.message;
  EXPECT_NE(through.verdict, CastRay::Response::HIT)
      << "hit at (" << through.point.x << ", " << through.point.y << ", " << through.point.z << ") after the clear";
  GetDistances get;
  get.request.points = {point(63.125, 3.375, 3.125)};
  ASSERT_TRUE(ros::service::call(kNode + "distance", get));
  ASSERT_TRUE(get.response.success) << get.response.message;
  EXPECT_NE(get.response.cell_class[0], GetDistances::Response::CELL_OCCUPIED);
  EXPECT_GT(get.response.distance_m[0], 0.0f);

  std_srvs::Empty reset;
  ASSERT_TRUE(ros::service::call(kNode + "reset", reset));
  get.request.points = {point(60, 0, 3)};
  ASSERT_TRUE(ros::service::call(kNode + "distance", get));
  ASSERT_TRUE(get.response.success) << get.response.message;
  EXPECT_EQ(get.response.cell_class[0], GetDistances::Response::CELL_UNKNOWN);
  EXPECT_EQ(checkPath(kLane, kRadiusM, false).verdict, CheckPath::Response::UNKNOWN);
}
