#include "stereo_occupancy/sim/synthetic_scene.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace stereo_occupancy {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();

/// Slab test: entry range of the unit ray into the box, +inf if it misses.
double rayBox(const Eigen::AlignedBox3d& box, const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
  double t0 = 0.0, t1 = kInf;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-15) {
      if (o[a] < box.min()[a] || o[a] > box.max()[a]) return kInf;
      continue;
    }
    double ta = (box.min()[a] - o[a]) / d[a];
    double tb = (box.max()[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return kInf;
  }
  return t0;
}
}  // namespace

void SyntheticScene::addBox(const Eigen::Vector3d& min, const Eigen::Vector3d& max, bool is_textureless) {
  boxes.emplace_back(min, max);
  textureless.resize(boxes.size(), false);
  textureless.back() = is_textureless;
}

double SyntheticScene::castRay(const Eigen::Vector3d& W_origin, const Eigen::Vector3d& W_dir, int* hit) const {
  double best = kInf;
  int what = kHitNothing;
  for (size_t i = 0; i < boxes.size(); ++i) {
    const double t = rayBox(boxes[i], W_origin, W_dir);
    if (t < best) {
      best = t;
      what = static_cast<int>(i);
    }
  }
  if (ground_height_m && W_dir.z() < 0.0 && W_origin.z() > *ground_height_m) {
    const double t = (*ground_height_m - W_origin.z()) / W_dir.z();
    if (t < best) {
      best = t;
      what = kHitGround;
    }
  }
  if (hit) *hit = what;
  return best;
}

double SyntheticScene::distance(const Eigen::Vector3d& W_point) const {
  double best = kInf;
  if (ground_height_m) best = std::max(0.0, W_point.z() - *ground_height_m);
  for (const auto& box : boxes) best = std::min(best, box.exteriorDistance(W_point));
  return best;
}

bool SyntheticScene::isInside(const Eigen::Vector3d& W_point) const {
  if (ground_height_m && W_point.z() < *ground_height_m) return true;
  for (const auto& box : boxes)
    if (box.contains(W_point)) return true;
  return false;
}

cv::Mat renderDisparity(const SyntheticScene& scene, const StereoCameraModel& camera, const Eigen::Isometry3d& T_W_C) {
  const auto& cfg = camera.config();
  cv::Mat disparity(cfg.height_px, cfg.width_px, CV_32FC1);
  const Eigen::Matrix3d R_W_C = T_W_C.linear();
  for (int y = 0; y < cfg.height_px; ++y) {
    float* row = disparity.ptr<float>(y);
    for (int x = 0; x < cfg.width_px; ++x) {
      const Eigen::Vector3d C_ray = camera.rayThroughPixel(x, y);  // z component 1
      const double norm = C_ray.norm();
      const double range = scene.castRay(T_W_C.translation(), R_W_C * (C_ray / norm));
      // depth z = range / |ray|; disparity = bf / z
      row[x] = std::isfinite(range) ? static_cast<float>(camera.disparityFromDepth(range / norm)) : 0.0f;
    }
  }
  return disparity;
}

void addInvalidSpeckle(cv::Mat* disparity, double fraction, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (int y = 0; y < disparity->rows; ++y) {
    float* row = disparity->ptr<float>(y);
    for (int x = 0; x < disparity->cols; ++x)
      if (uniform(rng) < fraction) row[x] = std::numeric_limits<float>::quiet_NaN();
  }
}

Eigen::Isometry3d lookingAlongX(const Eigen::Vector3d& W_position, double yaw_rad, double pitch_down_rad) {
  Eigen::Matrix3d R_level;  // columns: optical x, y, z expressed in W
  R_level.col(0) = Eigen::Vector3d(0, -1, 0);
  R_level.col(1) = Eigen::Vector3d(0, 0, -1);
  R_level.col(2) = Eigen::Vector3d(1, 0, 0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()) *
               Eigen::AngleAxisd(pitch_down_rad, Eigen::Vector3d::UnitY()) * R_level;
  T.translation() = W_position;
  return T;
}

SyntheticScene table1Scene(Eigen::Isometry3d* T_W_C) {
  SyntheticScene scene;
  scene.ground_height_m = 0.0;
  auto box = [&](double x0, double y0, double z0, double x1, double y1, double z1) {
    scene.addBox(Eigen::Vector3d(x0, y0, z0), Eigen::Vector3d(x1, y1, z1));
  };
  box(5.5, 1.0, 0.0, 6.5, 2.0, 3.5);      // post at 6 m, left
  box(9.5, -3.5, 0.0, 10.5, -2.5, 6.0);   // post at 10 m, right
  box(14.0, -1.0, 0.0, 16.0, 1.5, 2.5);   // low box at 15 m, centre
  box(19.5, 4.0, 0.0, 20.5, 5.0, 8.0);    // tall post at 20 m, left
  box(23.0, -9.0, 0.0, 26.0, -5.0, 5.0);  // house at 24 m, right
  box(12.0, 6.0, 0.0, 13.0, 7.0, 4.0);    // post at 12.5 m, far left
  if (T_W_C) *T_W_C = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0));
  return scene;
}

cv::Mat table1Image(const StereoCameraModel& camera, Eigen::Isometry3d* T_W_C) {
  Eigen::Isometry3d pose;
  const SyntheticScene scene = table1Scene(&pose);
  cv::Mat image = renderDisparity(scene, camera, pose);
  // Texture-less sky: unmatched (invalid) more than 60 px above the horizon,
  // matched at zero disparity (infinitely far) below that.
  const int sky_matched_from = static_cast<int>(camera.config().cy_px) - 60;
  for (int y = 0; y < std::min(sky_matched_from, image.rows); ++y) {
    float* row = image.ptr<float>(y);
    for (int x = 0; x < image.cols; ++x)
      if (row[x] == 0.0f) row[x] = std::numeric_limits<float>::quiet_NaN();
  }
  addInvalidSpeckle(&image, 0.03, 42);
  // A texture-less patch on the ground where the matcher finds nothing.
  image(cv::Rect(380, 400, 120, 50)).setTo(std::numeric_limits<float>::quiet_NaN());
  if (T_W_C) *T_W_C = pose;
  return image;
}

}  // namespace stereo_occupancy
