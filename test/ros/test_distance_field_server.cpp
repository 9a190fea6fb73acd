// The distance field's glue without a roscore (ros/distance_field_server.h):
// the services' answers refuse bad input with a reason before any work and
// carry the map's frame; the registry hands out the live field; the
// PathWatcher's waypoints parse.

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "stereo_occupancy/ros/distance_field_server.h"
#include "stereo_occupancy/ros/parameters.h"

using namespace stereo_occupancy;

namespace {

constexpr double kCellM = 0.25;
const double kNan = std::numeric_limits<double>::quiet_NaN();
const double kInf = std::numeric_limits<double>::infinity();

geometry_msgs::Point point(double x, double y, double z) {
  geometry_msgs::Point p;
  p.x = x;
  p.y = y;
  p.z = z;
  return p;
}

/// A field over a map that is free in the box [-5, 5]² x [0, 4] m but for a
/// wall of occupied cells at x in [2, 2.25); the vehicle at the origin, 1 m up.
class DistanceFieldServerTest : public ::testing::Test {
 protected:
  DistanceFieldServerTest() : tree_(kCellM) {
    for (double x = -5.0 + kCellM / 2; x < 5.0; x += kCellM)
      for (double y = -5.0 + kCellM / 2; y < 5.0; y += kCellM)
        for (double z = kCellM / 2; z < 4.0; z += kCellM) tree_.updateNode(x, y, z, x > 2.0 && x < 2.25);
    DistanceFieldConfig config;
    config.window_xy_m = 20.0;
    config.window_z_m = 10.0;
    config.max_distance_m = 2.0;
    field_ = std::make_unique<DistanceField>(config, kCellM);
    field_->update(tree_, {}, true, Eigen::Vector3d(0.0, 0.0, 1.0));
    info_.frame_id = "map";
    info_.stamp = ros::Time(12.5);
    info_.updates = 1;
  }

  octomap::OcTree tree_;
  std::unique_ptr<DistanceField> field_;
  DistanceFieldInfo info_;
};

}  // namespace

TEST_F(DistanceFieldServerTest, DistancesCarryTheFrameAndTheField) {
  GetDistances::Request request;
  request.points = {point(0.125, 0.125, 1.125), point(1.625, 0.125, 1.125), point(100.0, 0.0, 1.0)};
  GetDistances::Response response;
  answerDistances(*field_, info_, request, &response);
  ASSERT_TRUE(response.success) << response.message;
  EXPECT_EQ(response.header.frame_id, "map");
  EXPECT_EQ(response.header.stamp, ros::Time(12.5));
  ASSERT_EQ(response.distance_m.size(), 3u);
  EXPECT_TRUE(response.in_window[0]);
  EXPECT_EQ(response.cell_class[0], GetDistances::Response::CELL_FREE);
  EXPECT_FLOAT_EQ(response.distance_m[0], 2.0f);   // 2 m from the wall: saturated
  EXPECT_NEAR(response.distance_m[1], 0.5, 1e-5);  // the wall's cell centre at 2.125
  EXPECT_LT(response.gradient[1].x, 0.0);          // nearer the wall along +x
  EXPECT_FALSE(response.in_window[2]);
  EXPECT_EQ(response.cell_class[2], GetDistances::Response::CELL_UNKNOWN);
  EXPECT_TRUE(std::isnan(response.distance_m[2]));
}

// A request of several of the service's batches: each point's answer is
// sample()'s at that point, in the request's order (near the wall, in free
// and unknown space, outside the window).
TEST_F(DistanceFieldServerTest, DistancesOfManyPointsAreSampleAtEach) {
  GetDistances::Request request;
  for (int k = 0; k < 3000; ++k)  // a spiral through the wall's box and out of the window
    request.points.push_back(
        point(12.0 * std::sin(0.37 * k) * k / 3000.0, 12.0 * std::cos(0.37 * k) * k / 3000.0, -1.0 + 6.0 * k / 3000.0));
  GetDistances::Response response;
  answerDistances(*field_, info_, request, &response);
  ASSERT_TRUE(response.success) << response.message;
  ASSERT_EQ(response.distance_m.size(), request.points.size());
  size_t near_wall = 0, outside = 0;
  for (size_t i = 0; i < request.points.size(); ++i) {
    const geometry_msgs::Point& p = request.points[i];
    const DistanceSample s = field_->sample(Eigen::Vector3d(p.x, p.y, p.z));
    ASSERT_EQ(bool(response.in_window[i]), s.in_window) << i;
    ASSERT_EQ(response.cell_class[i], static_cast<uint8_t>(s.cell_class)) << i;
    if (std::isnan(s.distance_m))
      ASSERT_TRUE(std::isnan(response.distance_m[i])) << i;
    else
      ASSERT_EQ(response.distance_m[i], s.distance_m) << i;
    ASSERT_EQ(response.gradient[i].x, s.gradient.x()) << i;
    ASSERT_EQ(response.gradient[i].y, s.gradient.y()) << i;
    ASSERT_EQ(response.gradient[i].z, s.gradient.z()) << i;
    near_wall += s.distance_m < 2.0f;
    outside += !s.in_window;
  }
  EXPECT_GT(near_wall, 50u);
  EXPECT_GT(outside, 50u);
}

TEST_F(DistanceFieldServerTest, DistancesRefuseNotFinitePointsAndTooLargeRequests) {
  GetDistances::Request request;
  GetDistances::Response response;
  request.points = {point(0, 0, 1), point(0, kNan, 1)};
  answerDistances(*field_, info_, request, &response);
  EXPECT_FALSE(response.success);
  EXPECT_NE(response.message.find("point 1"), std::string::npos) << response.message;
  EXPECT_TRUE(response.distance_m.empty());
  EXPECT_EQ(response.header.frame_id, "map");  // refused answers carry the frame too
  request.points = {point(kInf, 0, 1)};
  response = GetDistances::Response();
  answerDistances(*field_, info_, request, &response);
  EXPECT_FALSE(response.success);
  EXPECT_NE(response.message.find("not finite"), std::string::npos) << response.message;
  request.points.assign(kMaxDistanceQueryPoints + 1, point(0, 0, 1));
  response = GetDistances::Response();
  answerDistances(*field_, info_, request, &response);
  EXPECT_FALSE(response.success);
  EXPECT_NE(response.message.find("at most 100000"), std::string::npos) << response.message;
  request.points.assign(kMaxDistanceQueryPoints, point(0, 0, 1));  // the limit itself is served
  response = GetDistances::Response();
  answerDistances(*field_, info_, request, &response);
  EXPECT_TRUE(response.success) << response.message;
}

TEST_F(DistanceFieldServerTest, CheckPathAnswersAndRefusesBadInput) {
  CheckPath::Request request;
  CheckPath::Response response;
  request.waypoints = {point(-1, 0, 1), point(3, 0, 1)};  // through the wall
  request.radius_m = 0.3;
  answerCheckPath(*field_, info_, request, &response);
  ASSERT_TRUE(response.success) << response.message;
  EXPECT_EQ(response.verdict, CheckPath::Response::BLOCKED);
  EXPECT_EQ(response.first_segment, 0);
  EXPECT_NEAR(response.point.x, 2.0, 2 * kCellM);
  EXPECT_EQ(response.header.frame_id, "map");

  auto refused = [&](const std::vector<geometry_msgs::Point>& waypoints, double radius_m, const std::string& says) {
    CheckPath::Request bad;
    bad.waypoints = waypoints;
    bad.radius_m = radius_m;
    CheckPath::Response answer;
    answerCheckPath(*field_, info_, bad, &answer);
    EXPECT_FALSE(answer.success) << says;
    EXPECT_NE(answer.message.find(says), std::string::npos) << "'" << answer.message << "' should say '" << says << "'";
    EXPECT_EQ(answer.header.frame_id, "map");
  };
  const std::vector<geometry_msgs::Point> ok = {point(-1, 0, 1), point(1, 0, 1)};
  refused({}, 0.3, "no waypoints");
  refused({point(0, 0, 1), point(kNan, 0, 1)}, 0.3, "waypoint 1");
  refused({point(0, kInf, 1)}, 0.3, "waypoint 0");
  refused(ok, -0.1, "radius_m");
  refused(ok, 2.5, "max_distance_m");
  refused(ok, kNan, "radius_m");
  refused(std::vector<geometry_msgs::Point>(DistanceField::kMaxWaypoints + 1, point(0, 0, 1)), 0.3,
          "at most " + std::to_string(DistanceField::kMaxWaypoints));
}

TEST_F(DistanceFieldServerTest, CastRayAnswersAndRefusesBadInput) {
  CastRay::Request request;
  CastRay::Response response;
  request.origin = point(0.125, 0.125, 1.125);
  request.direction.x = 3.0;  // any length
  request.max_range_m = 10.0;
  answerCastRay(*field_, info_, request, &response);
  ASSERT_TRUE(response.success) << response.message;
  EXPECT_EQ(response.verdict, CastRay::Response::HIT);
  EXPECT_NEAR(response.point.x, 2.125, 1e-6);
  EXPECT_NEAR(response.range_m, 1.875, kCellM);
  request.max_range_m = 1.0;
  answerCastRay(*field_, info_, request, &response);
  ASSERT_TRUE(response.success) << response.message;
  EXPECT_EQ(response.verdict, CastRay::Response::FREE);

  auto refused = [&](const geometry_msgs::Point& origin, double dx, double range_m, const std::string& says) {
    CastRay::Request bad;
    bad.origin = origin;
    bad.direction.x = dx;
    bad.max_range_m = range_m;
    CastRay::Response answer;
    answerCastRay(*field_, info_, bad, &answer);
    EXPECT_FALSE(answer.success) << says;
    EXPECT_NE(answer.message.find(says), std::string::npos) << "'" << answer.message << "' should say '" << says << "'";
  };
  refused(point(0, 0, 1), 0.0, 5.0, "not zero");
  refused(point(0, 0, 1), kNan, 5.0, "direction");
  refused(point(kNan, 0, 1), 1.0, 5.0, "origin");
  refused(point(0, 0, 1), 1.0, -1.0, "max_range_m");
  refused(point(0, 0, 1), 1.0, kInf, "max_range_m");
}

TEST(DistanceFieldRegistry, HandsOutTheLiveFieldUntilItsAccumulatorGoes) {
  EXPECT_EQ(DistanceFieldRegistry::find("/test_accumulator"), nullptr);
  auto field = std::make_shared<SharedDistanceField>(DistanceFieldConfig(), kCellM);
  DistanceFieldRegistry::add("/test_accumulator", field);
  const std::shared_ptr<SharedDistanceField> found = DistanceFieldRegistry::find("/test_accumulator");
  ASSERT_EQ(found, field);
  field->write([](DistanceField&, DistanceFieldInfo& info) {
    info.frame_id = "odom";
    ++info.updates;
  });
  // read() with the field alone, or with what the accumulator says about it.
  EXPECT_EQ(found->read([](const DistanceField& f) { return f.resolution(); }), kCellM);
  EXPECT_EQ(found->read([](const DistanceField&, const DistanceFieldInfo& info) { return info.frame_id; }), "odom");
  EXPECT_TRUE(found->alive());
  DistanceFieldRegistry::remove("/test_accumulator", nullptr);  // not the registered field: nothing happens
  EXPECT_NE(DistanceFieldRegistry::find("/test_accumulator"), nullptr);
  DistanceFieldRegistry::remove("/test_accumulator", field.get());
  EXPECT_EQ(DistanceFieldRegistry::find("/test_accumulator"), nullptr);
  EXPECT_FALSE(found->alive());  // the reader's handle stays valid, and says the field no longer changes
  EXPECT_EQ(found->read([](const DistanceField&, const DistanceFieldInfo& info) { return info.updates; }), 1u);
}

TEST(PathWatcherParameters, WaypointsParseOrSayWhy) {
  std::vector<Eigen::Vector3d> waypoints;
  std::string why;
  ASSERT_TRUE(parseWaypoints("57 0 3; 59, 3.5, 3;67 3.5 3;", &waypoints, &why)) << why;
  ASSERT_EQ(waypoints.size(), 3u);
  EXPECT_EQ(waypoints[1], Eigen::Vector3d(59.0, 3.5, 3.0));
  EXPECT_FALSE(parseWaypoints("", &waypoints, &why));
  EXPECT_NE(why.find("none given"), std::string::npos) << why;
  EXPECT_FALSE(parseWaypoints("1 2", &waypoints, &why));
  EXPECT_NE(why.find("'1 2' is not three numbers"), std::string::npos) << why;
  EXPECT_FALSE(parseWaypoints("1 2 3 4", &waypoints, &why));
  EXPECT_FALSE(parseWaypoints("1 2 nan", &waypoints, &why));
  EXPECT_FALSE(parseWaypoints("1 2 inf", &waypoints, &why));
  PathWatcherParameters params;
  EXPECT_TRUE(params.isValid(&why)) << why;
  params.waypoints = "a b c";
  EXPECT_FALSE(params.isValid(&why));
  params = PathWatcherParameters();
  params.radius_m = -1.0;
  EXPECT_FALSE(params.isValid(&why));
  EXPECT_NE(why.find("radius_m"), std::string::npos) << why;
}
