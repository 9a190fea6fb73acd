#include "stereo_occupancy/ros/distance_field_server.h"

#include <ros/console.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <map>
#include <sstream>
#include <vector>

#include "stereo_occupancy/ros/mapping_pipeline.h"

namespace stereo_occupancy {

namespace {

/// At most one warning of a kind in this time [s].
constexpr double kWarnThrottleS = 5.0;
/// The distance query answers this many points per batch sample(): many
/// times its prefetch distance, few enough that the points and answers
/// (52 KiB) stay in L2.
constexpr size_t kDistanceBatchPoints = 1024;

Eigen::Vector3d toEigen(const geometry_msgs::Point& p) { return Eigen::Vector3d(p.x, p.y, p.z); }
Eigen::Vector3d toEigen(const geometry_msgs::Vector3& v) { return Eigen::Vector3d(v.x, v.y, v.z); }

geometry_msgs::Point toPoint(const Eigen::Vector3d& p) {
  geometry_msgs::Point out;
  out.x = p.x();
  out.y = p.y();
  out.z = p.z();
  return out;
}

std::string text(const Eigen::Vector3d& p) {
  std::ostringstream s;
  s << "(" << p.x() << ", " << p.y() << ", " << p.z() << ")";
  return s.str();
}

/// The header every answer carries, refused or not.
template <class Response>
void stamp(const DistanceFieldInfo& info, Response* response) {
  response->header.frame_id = info.frame_id;
  response->header.stamp = info.stamp;
}

/// Index of the first point of @p points that is not finite, or -1.
template <class Points>
long firstNotFinite(const Points& points) {
  for (size_t i = 0; i < points.size(); ++i)
    if (!toEigen(points[i]).allFinite()) return static_cast<long>(i);
  return -1;
}

}  // namespace

// --- The registry --------------------------------------------------------------

namespace {
std::mutex& registryMutex() {
  static std::mutex mutex;
  return mutex;
}
std::map<std::string, std::shared_ptr<SharedDistanceField>>& registry() {
  static std::map<std::string, std::shared_ptr<SharedDistanceField>> fields;
  return fields;
}
}  // namespace

std::shared_ptr<SharedDistanceField> DistanceFieldRegistry::find(const std::string& name) {
  std::lock_guard<std::mutex> lock(registryMutex());
  const auto it = registry().find(name);
  return it == registry().end() ? nullptr : it->second;
}

void DistanceFieldRegistry::add(const std::string& name, std::shared_ptr<SharedDistanceField> field) {
  std::lock_guard<std::mutex> lock(registryMutex());
  registry()[name] = std::move(field);
}

void DistanceFieldRegistry::remove(const std::string& name, const SharedDistanceField* field) {
  std::lock_guard<std::mutex> lock(registryMutex());
  const auto it = registry().find(name);
  if (it != registry().end() && it->second.get() == field) {
    it->second->markGone();
    registry().erase(it);
  }
}

// --- The answers -----------------------------------------------------------------

void answerDistances(const DistanceField& field, const DistanceFieldInfo& info, const GetDistances::Request& request,
                     GetDistances::Response* response) {
  stamp(info, response);
  const size_t n = request.points.size();
  if (n > kMaxDistanceQueryPoints) {
    response->message = "too many points: " + std::to_string(n) + " (at most " +
                        std::to_string(kMaxDistanceQueryPoints) + " per request)";
    return;
  }
  const long bad = firstNotFinite(request.points);
  if (bad >= 0) {
    response->message = "point " + std::to_string(bad) + " " + text(toEigen(request.points[bad])) + " is not finite";
    return;
  }
  try {
    response->in_window.resize(n);
    response->cell_class.resize(n);
    response->distance_m.resize(n);
    response->gradient.resize(n);
    std::vector<Eigen::Vector3d> W_points;
    std::vector<DistanceSample> samples;
    for (size_t first = 0; first < n; first += kDistanceBatchPoints) {
      const size_t count = std::min(kDistanceBatchPoints, n - first);
      W_points.resize(count);
      for (size_t k = 0; k < count; ++k) W_points[k] = toEigen(request.points[first + k]);
      field.sample(W_points, &samples);
      for (size_t k = 0; k < count; ++k) {
        const DistanceSample& s = samples[k];
        const size_t i = first + k;
        response->in_window[i] = s.in_window;
        response->cell_class[i] = static_cast<uint8_t>(s.cell_class);
        response->distance_m[i] = s.distance_m;
        response->gradient[i].x = s.gradient.x();
        response->gradient[i].y = s.gradient.y();
        response->gradient[i].z = s.gradient.z();
      }
    }
  } catch (const std::exception& e) {  // nothing may leave a service callback
    *response = GetDistances::Response();
    stamp(info, response);
    response->message = std::string("distance query failed: ") + e.what();
    return;
  }
  response->success = true;
  response->message = std::to_string(n) + " points";
}

void answerCheckPath(const DistanceField& field, const DistanceFieldInfo& info, const CheckPath::Request& request,
                     CheckPath::Response* response) {
  stamp(info, response);
  response->verdict = CheckPath::Response::UNKNOWN;
  response->first_segment = -1;
  const size_t n = request.waypoints.size();
  const double max_radius_m = field.config().max_distance_m;
  if (n == 0) {
    response->message = "no waypoints";
    return;
  }
  if (n > DistanceField::kMaxWaypoints) {
    response->message =
        "too many waypoints: " + std::to_string(n) + " (at most " + std::to_string(DistanceField::kMaxWaypoints) + ")";
    return;
  }
  const long bad = firstNotFinite(request.waypoints);
  if (bad >= 0) {
    response->message =
        "waypoint " + std::to_string(bad) + " " + text(toEigen(request.waypoints[bad])) + " is not finite";
    return;
  }
  if (!(request.radius_m >= 0.0 && request.radius_m <= max_radius_m)) {
    std::ostringstream s;
    s << "radius_m " << request.radius_m << " is outside [0, " << max_radius_m
      << "] (the field's max_distance_m: distances saturate there)";
    response->message = s.str();
    return;
  }
  std::vector<Eigen::Vector3d> W_waypoints;
  W_waypoints.reserve(n);
  for (const auto& p : request.waypoints) W_waypoints.push_back(toEigen(p));
  try {
    const PathCheckResult r = field.checkPath(W_waypoints, request.radius_m, request.unknown_as_occupied);
    response->verdict = static_cast<uint8_t>(r.verdict);
    response->first_segment = r.first_segment;
    response->point = toPoint(r.W_point);
    response->min_clearance_m = r.min_clearance_m;
  } catch (const std::exception& e) {  // std::invalid_argument: what the checks above missed
    response->message = std::string("path check refused: ") + e.what();
    return;
  }
  response->success = true;
  static const char* const kVerdicts[] = {"clear", "blocked", "unknown"};
  response->message = response->verdict <= 2 ? kVerdicts[response->verdict] : "?";
}

void answerCastRay(const DistanceField& field, const DistanceFieldInfo& info, const CastRay::Request& request,
                   CastRay::Response* response) {
  stamp(info, response);
  response->verdict = CastRay::Response::UNKNOWN;
  const Eigen::Vector3d origin = toEigen(request.origin), direction = toEigen(request.direction);
  if (!origin.allFinite()) {
    response->message = "origin " + text(origin) + " is not finite";
    return;
  }
  if (!direction.allFinite() || direction.squaredNorm() == 0.0) {
    response->message = "direction " + text(direction) + " must be finite and not zero";
    return;
  }
  if (!(request.max_range_m >= 0.0) || !std::isfinite(request.max_range_m)) {
    response->message = "max_range_m " + std::to_string(request.max_range_m) + " must be finite and >= 0";
    return;
  }
  try {
    const RayCastResult r = field.castRay(origin, direction, request.max_range_m);
    response->verdict = static_cast<uint8_t>(r.verdict);
    response->point = toPoint(r.W_point);
    response->range_m = r.range_m;
  } catch (const std::exception& e) {
    response->message = std::string("ray cast refused: ") + e.what();
    return;
  }
  response->success = true;
  static const char* const kVerdicts[] = {"hit", "free", "unknown"};
  response->message = response->verdict <= 2 ? kVerdicts[response->verdict] : "?";
}

// --- The server ------------------------------------------------------------------

DistanceFieldServer::DistanceFieldServer(const DistanceFieldServerConfig& config, double resolution_m,
                                         MapFusion* fusion, std::mutex* fusion_mutex, const std::string& name)
    : config_(config),
      fusion_(fusion),
      fusion_mutex_(fusion_mutex),
      name_(name),
      field_(std::make_shared<SharedDistanceField>(config.field, resolution_m)) {
  std::string why;
  if (!config_.isValid(&why)) throw std::invalid_argument(why);
  std::lock_guard<std::mutex> lock(*fusion_mutex_);
  fusion_->recordClassChanges();
  // Answers carry the map's frame from the start (world_frame; "" until the first update without one).
  field_->write([&](DistanceField&, DistanceFieldInfo& info) { info.frame_id = fusion_->frameId(); });
  DistanceFieldRegistry::add(name_, field_);
}

DistanceFieldServer::~DistanceFieldServer() {
  slice_timer_.stop();
  DistanceFieldRegistry::remove(name_, field_.get());
}

void DistanceFieldServer::advertise(ros::NodeHandle& nh, ros::NodeHandle& private_nh, double publish_rate_hz) {
  distance_srv_ = private_nh.advertiseService("distance", &DistanceFieldServer::distances, this);
  check_path_srv_ = private_nh.advertiseService("check_path", &DistanceFieldServer::checkPath, this);
  cast_ray_srv_ = private_nh.advertiseService("cast_ray", &DistanceFieldServer::castRay, this);
  // A new subscriber gets the slice at the next tick even when the field did not change.
  slice_pub_ = nh.advertise<sensor_msgs::PointCloud2>(
      "distance_slice", 1,
      [this](const ros::SingleSubscriberPublisher&) {
        std::lock_guard<std::mutex> lock(slice_mutex_);
        sliced_updates_ = std::numeric_limits<uint64_t>::max();
      },
      ros::SubscriberStatusCallback());
  slice_timer_ =
      nh.createTimer(ros::Duration(1.0 / publish_rate_hz), [this](const ros::TimerEvent&) { publishSlice(false); });
}

void DistanceFieldServer::update() {
  if (fusion_->lastStamp().isZero()) return;  // no update fused yet: no vehicle position
  const ProcessingTimes::Start start = times_.start();
  bool all = false;
  std::vector<CellBox> regions;
  const std::vector<CellClassChange> changes = fusion_->takeClassChanges(&all, &regions);
  all = all || read_whole_window_;
  read_whole_window_ = true;  // until this update has gone through
  const MapAccumulator& map = fusion_->map();
  field_->write([&](DistanceField& field, DistanceFieldInfo& info) {
    // The leaves only: the inner nodes' pass over the whole tree waits for
    // the outputs that read them; and only the cells the field reads, as
    // the fusion's cache is written back for them (a move: the entering slabs).
    field.update([&map](const CellBox& cells) -> const octomap::OcTree& { return map.leafTree(cells); }, changes,
                 regions, all, fusion_->lastSensorOrigin());
    info.frame_id = fusion_->frameId();
    info.stamp = fusion_->lastStamp();
    ++info.updates;
    last_updated_cells_ = field.lastUpdatedCells();
  });
  read_whole_window_ = false;
  times_.stop(start);
}

bool DistanceFieldServer::distances(GetDistances::Request& request, GetDistances::Response& response) {
  field_->read([&](const DistanceField& field, const DistanceFieldInfo& info) {
    answerDistances(field, info, request, &response);
  });
  if (!response.success)
    ROS_WARN_THROTTLE(kWarnThrottleS, "%s/distance refused: %s", name_.c_str(), response.message.c_str());
  return true;  // the answer carries success and the reason
}

bool DistanceFieldServer::checkPath(CheckPath::Request& request, CheckPath::Response& response) {
  field_->read([&](const DistanceField& field, const DistanceFieldInfo& info) {
    answerCheckPath(field, info, request, &response);
  });
  if (!response.success)
    ROS_WARN_THROTTLE(kWarnThrottleS, "%s/check_path refused: %s", name_.c_str(), response.message.c_str());
  return true;
}

bool DistanceFieldServer::castRay(CastRay::Request& request, CastRay::Response& response) {
  field_->read([&](const DistanceField& field, const DistanceFieldInfo& info) {
    answerCastRay(field, info, request, &response);
  });
  if (!response.success)
    ROS_WARN_THROTTLE(kWarnThrottleS, "%s/cast_ray refused: %s", name_.c_str(), response.message.c_str());
  return true;
}

void DistanceFieldServer::sliceCloud(const DistanceField& field, const DistanceFieldInfo& info, double z_m,
                                     sensor_msgs::PointCloud2* cloud) {
  std::vector<Eigen::Vector3f> W_centres;
  std::vector<float> distances_m;
  field.slice(z_m, &W_centres, &distances_m);
  cloud->header.frame_id = info.frame_id;
  cloud->header.stamp = info.stamp;
  sensor_msgs::PointCloud2Modifier modifier(*cloud);
  modifier.setPointCloud2Fields(4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32,
                                "z", 1, sensor_msgs::PointField::FLOAT32, "intensity", 1,
                                sensor_msgs::PointField::FLOAT32);
  modifier.resize(W_centres.size());
  sensor_msgs::PointCloud2Iterator<float> x(*cloud, "x"), y(*cloud, "y"), z(*cloud, "z"), v(*cloud, "intensity");
  for (size_t i = 0; i < W_centres.size(); ++i, ++x, ++y, ++z, ++v) {
    *x = W_centres[i].x();
    *y = W_centres[i].y();
    *z = W_centres[i].z();
    *v = distances_m[i];
  }
}

void DistanceFieldServer::publishSlice(bool force) {
  if (slice_pub_.getNumSubscribers() == 0) return;  // lazy: built only while someone looks
  std::lock_guard<std::mutex> lock(slice_mutex_);
  auto cloud = boost::make_shared<sensor_msgs::PointCloud2>();
  bool changed = false;
  try {
    field_->read([&](const DistanceField& field, const DistanceFieldInfo& info) {
      changed = force || info.updates != sliced_updates_;
      if (!changed || info.updates == 0) return;
      sliceCloud(field, info, config_.slice_z_m, cloud.get());
      sliced_updates_ = info.updates;
    });
  } catch (const std::exception& e) {  // bad_alloc: nothing may leave a timer callback
    ROS_ERROR_THROTTLE(kWarnThrottleS, "%s: distance_slice failed: %s", name_.c_str(), e.what());
    return;
  }
  if (changed && !cloud->header.frame_id.empty()) slice_pub_.publish(cloud);
}

}  // namespace stereo_occupancy
