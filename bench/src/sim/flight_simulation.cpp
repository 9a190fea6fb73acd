#include "stereo_occupancy/sim/flight_simulation.h"

#include <cmath>
#include <limits>
#include <random>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace stereo_occupancy {

namespace {

/// Optical frame in a body frame (x forward, y left, z up), pitched down.
Eigen::Isometry3d forwardCamera(double pitch_down_rad) {
  return lookingAlongX(Eigen::Vector3d(0.3, 0.0, -0.2), 0.0, pitch_down_rad);
}

Eigen::Isometry3d bodyPose(const Eigen::Vector3d& position, double yaw_rad) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = position;
  return T;
}

/// n body poses of a flight along +x at speed_mps, weaving sideways as
/// amplitude_m·sin(omega·t) and heading along its path, at altitude(t).
template <typename Altitude>
std::vector<Eigen::Isometry3d> weavingFlight(int n, double rate_hz, double speed_mps, double amplitude_m,
                                             double omega_rad_s, Altitude&& altitude) {
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < n; ++i) {
    const double t = i / rate_hz;
    const double yaw = std::atan2(amplitude_m * omega_rad_s * std::cos(omega_rad_s * t), speed_mps);
    poses.push_back(bodyPose({speed_mps * t, amplitude_m * std::sin(omega_rad_s * t), altitude(t)}, yaw));
  }
  return poses;
}

FlightScenario postsScenario() {
  FlightScenario s;
  s.name = "posts";
  s.scene.ground_height_m = 0.0;
  // Pairs of 0.4 m posts, 8 m tall, forming gates every 12 m along +x; the
  // flight passes between them. Every second gate has a 2 cm wire across at 6 m.
  for (int g = 0; g < 6; ++g) {
    const double x = 15.0 + 12.0 * g;
    const double offset = (g % 2 == 0) ? 0.0 : 1.5;
    const double y_left = 3.5 + offset, y_right = -3.5 + offset;
    s.scene.addBox({x - 0.2, y_left - 0.2, 0.0}, {x + 0.2, y_left + 0.2, 8.0});
    s.scene.addBox({x - 0.2, y_right - 0.2, 0.0}, {x + 0.2, y_right + 0.2, 8.0});
    if (g % 2 == 1) s.scene.addBox({x - 0.01, y_right, 5.99}, {x + 0.01, y_left, 6.01});
  }
  // Single posts off the path and a shed.
  s.scene.addBox({30.0, 10.0, 0.0}, {30.5, 10.5, 6.0});
  s.scene.addBox({50.0, -11.0, 0.0}, {50.5, -10.5, 7.0});
  s.scene.addBox({70.0, 9.0, 0.0}, {76.0, 15.0, 3.5}, /*textureless=*/true);  // a white shed
  s.camera = StereoCameraConfig();
  s.effects.sky_unmatched_above_row = 120;
  s.T_B_C = forwardCamera(0.15);
  s.frame_rate_hz = 10.0;
  // 4 m/s at 4 m altitude with a gentle weave, 20 s.
  s.T_W_B =
      weavingFlight(200, s.frame_rate_hz, 4.0, 0.75, 0.4, [](double t) { return 4.0 + 0.3 * std::sin(0.25 * t); });
  return s;
}

FlightScenario housesScenario() {
  FlightScenario s;
  s.name = "houses";
  s.scene.ground_height_m = 0.0;
  // Houses on both sides of a street along +x: walls and a roof block each.
  for (int k = 0; k < 6; ++k) {
    const double x = 12.0 + 16.0 * k;
    const double h = 5.0 + 2.0 * (k % 3);
    s.scene.addBox({x, 9.0, 0.0}, {x + 10.0, 17.0, h});                 // left house
    s.scene.addBox({x + 1.0, 10.0, h}, {x + 9.0, 16.0, h + 2.0});       // its roof
    s.scene.addBox({x + 4.0, -18.0, 0.0}, {x + 12.0, -10.0, h - 1.0});  // right house
  }
  // Trees as trunks with crowns, a lamp post every 20 m.
  for (int k = 0; k < 5; ++k) {
    const double x = 20.0 + 20.0 * k;
    s.scene.addBox({x - 0.15, 6.0, 0.0}, {x + 0.15, 6.3, 6.0});
    s.scene.addBox({x + 8.0, -7.3, 0.0}, {x + 8.4, -6.9, 3.0});
    s.scene.addBox({x + 6.8, -8.3, 3.0}, {x + 9.6, -5.9, 5.5});
  }
  s.camera = StereoCameraConfig();
  s.effects.sky_unmatched_above_row = 100;
  s.T_B_C = forwardCamera(0.25);
  s.frame_rate_hz = 10.0;
  // 5 m/s at 8 m altitude down the street, turning slightly left then right, 20 s.
  for (int i = 0; i < 200; ++i) {
    const double t = i / s.frame_rate_hz;
    const double yaw = 0.15 * std::sin(0.3 * t);
    s.T_W_B.push_back(bodyPose({5.0 * t, 1.0 * std::sin(0.3 * t), 8.0}, yaw));
  }
  return s;
}

FlightScenario forestScenario() {
  FlightScenario s;
  s.name = "forest";
  s.scene.ground_height_m = 0.0;
  // Thin trunks (0.08-0.3 m, 6-14 m tall) at random, none within 2.5 m of
  // the flight's lane y = 0; a few are texture-less (birch bark in shade).
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> along(8.0, 110.0), across(-25.0, 25.0), width(0.08, 0.3), height(6.0, 14.0),
      unit(0.0, 1.0);
  for (int k = 0; k < 260; ++k) {
    const double x = along(rng), y = across(rng), w = width(rng), h = height(rng);
    const bool textureless = unit(rng) < 0.05;
    if (std::abs(y) < 2.5 + w) continue;
    s.scene.addBox({x - 0.5 * w, y - 0.5 * w, 0.0}, {x + 0.5 * w, y + 0.5 * w, h}, textureless);
  }
  s.camera = StereoCameraConfig();
  s.effects.sky_unmatched_above_row = 60;
  s.T_B_C = forwardCamera(0.1);
  s.frame_rate_hz = 10.0;
  // 3 m/s at 3 m altitude down the lane with a slow weave, 20 s.
  s.T_W_B = weavingFlight(200, s.frame_rate_hz, 3.0, 0.8, 0.5, [](double) { return 3.0; });
  return s;
}

FlightScenario wiresScenario() {
  FlightScenario s;
  s.name = "wires";
  s.scene.ground_height_m = 0.0;
  // Three power lines across the flight path, each three 2 cm wires between
  // 0.3 m masts at y = +-20 m; the wires hang at 7.5-10 m, above the
  // helicopter, so that they are seen against the sky.
  for (int k = 0; k < 3; ++k) {
    const double x = 25.0 + 22.0 * k;
    for (double y : {-20.0, 20.0}) s.scene.addBox({x - 0.15, y - 0.15, 0.0}, {x + 0.15, y + 0.15, 10.5});
    for (int w = 0; w < 3; ++w) {
      const double z = 7.5 + 1.0 * w + 0.5 * (k % 2);
      s.scene.addBox({x - 0.01, -20.0, z - 0.01}, {x + 0.01, 20.0, z + 0.01});
    }
  }
  s.camera = StereoCameraConfig();
  s.effects.sky_unmatched_above_row = -1;  // all sky matched at zero disparity
  s.T_B_C = forwardCamera(-0.08);          // pitched slightly up
  s.frame_rate_hz = 10.0;
  // 4 m/s at 4.5 m altitude, drifting sideways, 20 s.
  for (int i = 0; i < 200; ++i) {
    const double t = i / s.frame_rate_hz;
    s.T_W_B.push_back(bodyPose({4.0 * t, 2.0 * std::sin(0.2 * t), 4.5 + 0.3 * std::sin(0.3 * t)}, 0.0));
  }
  return s;
}

/// A flight toward the scene of @p near from 40 m before its first obstacle
/// to 12 m before it, slowly: the obstacles are seen from 10-40 m away, as a
/// helicopter sees what it plans around, not only in close passes.
FlightScenario farView(FlightScenario near, const std::string& name, double first_obstacle_x_m) {
  near.name = name;
  const double start = first_obstacle_x_m - 40.0, speed_mps = 28.0 / 20.0;  // 28 m in 20 s
  const double altitude = near.T_W_B.front().translation().z();
  near.T_W_B = weavingFlight(200, near.frame_rate_hz, speed_mps, 1.5, 0.3, [&](double) { return altitude; });
  for (auto& T : near.T_W_B) T.translation().x() += start;
  return near;
}

}  // namespace

std::vector<std::string> scenarioNames() { return {"posts", "houses", "forest", "wires", "posts_far", "forest_far"}; }

/// Half a mission's path: 4 m/s for 30 min, weaving 30 m sideways over
/// 800 m, 4-6 m up; scenery generated along it every 50 m, each stretch one of
/// a gate of posts (with a wire), houses, trees or power lines, never on the path.
FlightScenario missionScenario() {
  FlightScenario s;
  s.name = "mission";
  s.scene.ground_height_m = 0.0;
  constexpr double kSpeedMps = 4.0, kMinutes = 30.0, kWeaveM = 30.0, kWeaveLengthM = 800.0, kStretchM = 50.0;
  const double length_m = kSpeedMps * kMinutes * 60.0;
  auto pathY = [&](double x) { return kWeaveM * std::sin(2.0 * M_PI * x / kWeaveLengthM); };
  std::mt19937 rng(2026);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (double x0 = 20.0; x0 + kStretchM < length_m; x0 += kStretchM) {
    const int kind = static_cast<int>(unit(rng) * 4.0);
    const double x = x0 + 10.0 + 30.0 * unit(rng), y = pathY(x);
    if (kind == 0) {  // a gate of two 0.4 m posts, 8 m tall, a 2 cm wire across at 7.5 m
      for (double side : {-3.5, 3.5}) s.scene.addBox({x - 0.2, y + side - 0.2, 0.0}, {x + 0.2, y + side + 0.2, 8.0});
      s.scene.addBox({x - 0.01, y - 3.5, 7.49}, {x + 0.01, y + 3.5, 7.51});
    } else if (kind == 1) {  // houses on both sides, one white (texture-less) now and then
      for (double side : {-1.0, 1.0}) {
        const double near = 9.0 + 4.0 * unit(rng), w = 6.0 + 4.0 * unit(rng), h = 5.0 + 4.0 * unit(rng);
        const double y_near = y + side * near, y_far = y + side * (near + w);
        s.scene.addBox({x, std::min(y_near, y_far), 0.0}, {x + w, std::max(y_near, y_far), h}, unit(rng) < 0.15);
      }
    } else if (kind == 2) {  // thin trunks, none within 3 m of the path
      for (int k = 0; k < 12; ++k) {
        const double tx = x0 + kStretchM * unit(rng),
                     ty = pathY(tx) + (unit(rng) < 0.5 ? -1.0 : 1.0) * (3.0 + 20.0 * unit(rng));
        const double w = 0.1 + 0.2 * unit(rng), h = 6.0 + 8.0 * unit(rng);
        s.scene.addBox({tx - 0.5 * w, ty - 0.5 * w, 0.0}, {tx + 0.5 * w, ty + 0.5 * w, h});
      }
    } else {  // a power line across the path: masts 20 m to each side, two 2 cm wires above the flight
      for (double side : {-20.0, 20.0})
        s.scene.addBox({x - 0.15, y + side - 0.15, 0.0}, {x + 0.15, y + side + 0.15, 10.0});
      for (double z : {8.0, 9.0}) s.scene.addBox({x - 0.01, y - 20.0, z - 0.01}, {x + 0.01, y + 20.0, z + 0.01});
    }
  }
  s.camera = StereoCameraConfig();
  s.effects.sky_unmatched_above_row = 120;
  s.T_B_C = forwardCamera(0.15);
  s.frame_rate_hz = 10.0;
  const int n = static_cast<int>(kMinutes * 60.0 * s.frame_rate_hz);
  for (int i = 0; i < n; ++i) {
    const double t = i / s.frame_rate_hz, x = kSpeedMps * t;
    const double dy_dx = kWeaveM * 2.0 * M_PI / kWeaveLengthM * std::cos(2.0 * M_PI * x / kWeaveLengthM);
    s.T_W_B.push_back(bodyPose({x, pathY(x), 5.0 + 1.0 * std::sin(0.05 * t)}, std::atan(dy_dx)));
  }
  return s;
}

FlightScenario makeScenario(const std::string& name) {
  if (name == "posts") return postsScenario();
  if (name == "houses") return housesScenario();
  if (name == "forest") return forestScenario();
  if (name == "wires") return wiresScenario();
  if (name == "posts_far") return farView(postsScenario(), name, 14.8);
  if (name == "forest_far") return farView(forestScenario(), name, 8.0);
  if (name == "mission") return missionScenario();
  throw std::invalid_argument("unknown scenario '" + name +
                              "' (posts, houses, forest, wires, posts_far, forest_far, mission)");
}

namespace {
/// Scenes larger than this are cut to the boxes near the camera first.
constexpr size_t kCullAboveBoxes = 500;
/// ... those within this of the camera [m]: far beyond the sensor's range.
constexpr double kCullDistanceM = 100.0;

/// @p scene's boxes within kCullDistanceM of @p W_camera (a mission's
/// thousands of boxes would cost each ray a test of every one).
/// @p original[i]: the index in @p scene of the near scene's box i.
SyntheticScene nearScene(const SyntheticScene& scene, const Eigen::Vector3d& W_camera, std::vector<int>* original) {
  SyntheticScene near;
  near.ground_height_m = scene.ground_height_m;
  for (size_t k = 0; k < scene.boxes.size(); ++k)
    if (scene.boxes[k].exteriorDistance(W_camera) < kCullDistanceM) {
      near.boxes.push_back(scene.boxes[k]);
      near.textureless.push_back(scene.textureless[k]);
      original->push_back(static_cast<int>(k));
    }
  return near;
}

cv::Mat render(const FlightScenario& full, size_t frame, cv::Mat* true_depth, cv::Mat* hit_index) {
  const Eigen::Isometry3d T_W_C = full.cameraPose(frame);
  FlightScenario culled;
  std::vector<int> original;  // culled box index -> full.scene's
  const bool cull = full.scene.boxes.size() > kCullAboveBoxes;
  if (cull) {
    culled.scene = nearScene(full.scene, T_W_C.translation(), &original);
    culled.camera = full.camera;
  }
  const FlightScenario& s = cull ? culled : full;
  const StereoCameraModel camera(s.camera);
  const Eigen::Matrix3d R_W_C = T_W_C.linear();
  cv::Mat disparity(s.camera.height_px, s.camera.width_px, CV_32FC1);
  if (true_depth) true_depth->create(disparity.size(), CV_32FC1);
  if (hit_index) hit_index->create(disparity.size(), CV_32SC1);
  for (int y = 0; y < disparity.rows; ++y) {
    for (int x = 0; x < disparity.cols; ++x) {
      const Eigen::Vector3d ray = camera.rayThroughPixel(x, y);
      const double norm = ray.norm();
      int hit = SyntheticScene::kHitNothing;
      const double range = s.scene.castRay(T_W_C.translation(), R_W_C * (ray / norm), &hit);
      const double z = range / norm;
      disparity.at<float>(y, x) = std::isfinite(z) ? static_cast<float>(camera.disparityFromDepth(z)) : 0.0f;
      if (true_depth) true_depth->at<float>(y, x) = static_cast<float>(z);
      if (hit_index) hit_index->at<int>(y, x) = (cull && hit >= 0) ? original[static_cast<size_t>(hit)] : hit;
    }
  }
  return disparity;
}
}  // namespace

cv::Mat renderTrueDisparity(const FlightScenario& scenario, size_t frame, cv::Mat* true_depth) {
  return render(scenario, frame, true_depth, nullptr);
}

namespace {
/// The exact disparities with the effects of StereoEffects.
cv::Mat gaussianFrame(const FlightScenario& s, size_t frame, uint32_t seed) {
  cv::Mat hit;
  cv::Mat d = render(s, frame, nullptr, &hit);
  std::mt19937 rng(seed * 2654435761u + static_cast<uint32_t>(frame));
  std::normal_distribution<float> noise(0.0f, static_cast<float>(s.effects.noise_sigma_px));
  std::uniform_real_distribution<float> uniform(0.0f, 1.0f);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float step = static_cast<float>(s.effects.subpixel_step_px);
  for (int y = 0; y < d.rows; ++y) {
    for (int x = 0; x < d.cols; ++x) {
      float& v = d.at<float>(y, x);
      const int h = hit.at<int>(y, x);
      if (h == SyntheticScene::kHitNothing) {  // sky
        v = (s.effects.sky_unmatched_above_row >= 0 && y < s.effects.sky_unmatched_above_row) ? nan : 0.0f;
        continue;
      }
      if (h >= 0 && s.scene.textureless[h]) {
        v = nan;
        continue;
      }
      if (uniform(rng) < s.effects.unmatched_fraction) {
        v = nan;
        continue;
      }
      v += noise(rng);
      if (step > 0.0f) v = std::round(v / step) * step;
      if (v < s.effects.min_search_disparity_px)
        v = 0.0f;  // too far for the search range
      else if (v > s.effects.max_search_disparity_px)
        v = nan;  // too near for the search range
    }
  }
  return d;
}

/// The seed of one camera's sensor noise in frame i (0: left, 1: right).
uint32_t noiseSeed(uint32_t seed, size_t frame, uint32_t camera) {
  return (seed * 2654435761u) ^ (static_cast<uint32_t>(frame) * 40503u + camera * 0x9e3779b9u);
}
}  // namespace

bool parseStereoMatcher(const std::string& name, StereoMatcher* matcher) {
  if (name == "gaussian")
    *matcher = StereoMatcher::kGaussian;
  else if (name == "sgbm")
    *matcher = StereoMatcher::kSgbm;
  else
    return false;
  return true;
}

const char* toString(StereoMatcher matcher) { return matcher == StereoMatcher::kSgbm ? "sgbm" : "gaussian"; }

void useMatcher(FlightScenario* scenario, StereoMatcher matcher) {
  scenario->matcher = matcher;
  if (matcher != StereoMatcher::kSgbm) return;
  scenario->effects.min_search_disparity_px = scenario->sgbm.min_disparity_px;
  scenario->effects.max_search_disparity_px = scenario->sgbm.maxDisparityPx();
  scenario->effects.subpixel_step_px = 1.0 / 16.0;  // SGBM's fixed point
}

StereoImages renderStereoImages(const FlightScenario& s, size_t frame, uint32_t seed) {
  const StereoCameraModel camera(s.camera);
  const Eigen::Isometry3d T_W_L = s.cameraPose(frame);
  StereoImages images;
  // The two cameras at once: rendering costs about 0.2 s an image, the matching a quarter of that.
  std::thread left(
      [&] { images.left = renderGreyImage(s.scene, camera, T_W_L, noiseSeed(seed, frame, 0), s.appearance); });
  images.right = renderGreyImage(s.scene, camera, rightCameraPose(T_W_L, s.camera.baseline_m),
                                 noiseSeed(seed, frame, 1), s.appearance);
  left.join();
  return images;
}

cv::Mat renderStereoFrame(const FlightScenario& s, size_t frame, uint32_t seed) {
  if (s.matcher == StereoMatcher::kGaussian) return gaussianFrame(s, frame, seed);
  const StereoImages images = renderStereoImages(s, frame, seed);
  return matchSgbm(images.left, images.right, s.sgbm);
}

std::string describeScene(const SyntheticScene& scene) {
  std::ostringstream out;
  if (scene.ground_height_m) out << "ground z=" << *scene.ground_height_m << "\n";
  for (size_t i = 0; i < scene.boxes.size(); ++i) {
    const auto& b = scene.boxes[i];
    out << "box " << b.min().x() << " " << b.min().y() << " " << b.min().z() << " " << b.max().x() << " " << b.max().y()
        << " " << b.max().z() << (scene.textureless[i] ? " textureless" : "") << "\n";
  }
  return out.str();
}

}  // namespace stereo_occupancy
