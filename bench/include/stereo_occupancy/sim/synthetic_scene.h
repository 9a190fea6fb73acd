#pragma once
/// @file
/// Analytic scenes ray-cast into ideal disparity images: test and benchmark
/// input with a known ground truth.

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <cstdint>
#include <optional>
#include <vector>

#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

/// A scene in the world frame W: axis-aligned boxes and an optional ground
/// plane z = ground_height_m (REP-103: z up).
struct SyntheticScene {
  static constexpr int kHitNothing = -2;
  static constexpr int kHitGround = -1;

  std::vector<Eigen::AlignedBox3d> boxes;
  /// Boxes a stereo matcher finds no texture on (their pixels come out unmatched).
  std::vector<bool> textureless;
  std::optional<double> ground_height_m;

  /// Adds a box spanning [min, max] [m].
  void addBox(const Eigen::Vector3d& min, const Eigen::Vector3d& max, bool is_textureless = false);

  /// Range along the unit ray W_dir from W_origin to the first surface, +inf
  /// if none; @p hit (optional) is the box index, kHitGround or kHitNothing.
  double castRay(const Eigen::Vector3d& W_origin, const Eigen::Vector3d& W_dir, int* hit = nullptr) const;
  /// True if W_point lies inside a box or below the ground.
  bool isInside(const Eigen::Vector3d& W_point) const;
  /// Euclidean distance from W_point to the nearest solid (0 inside) [m].
  double distance(const Eigen::Vector3d& W_point) const;
};

/// Renders the exact disparity of @p scene seen from T_W_C: bf/z of the first
/// surface hit through each pixel centre, 0 where no surface is hit (sky).
cv::Mat renderDisparity(const SyntheticScene& scene, const StereoCameraModel& camera, const Eigen::Isometry3d& T_W_C);

/// Marks pixels invalid (NaN), like an unmatched stereo pixel: each pixel with
/// probability @p fraction, drawn from a fixed-seed generator.
void addInvalidSpeckle(cv::Mat* disparity, double fraction, uint32_t seed);

/// Pose of an optical frame at W_position looking along W +x, horizon level
/// (optical x = -W y, optical y = -W z), turned by yaw about W z [rad] and
/// pitched down by pitch [rad].
Eigen::Isometry3d lookingAlongX(const Eigen::Vector3d& W_position, double yaw_rad = 0.0, double pitch_down_rad = 0.0);

/// The Table I test scene, after the paper's Fig. 6: a camera 2 m above a
/// ground plane looking level along +x at posts and boxes between 5 and
/// 25 m; sky above. Pose in @p T_W_C.
SyntheticScene table1Scene(Eigen::Isometry3d* T_W_C);

/// The Table I test image: table1Scene() rendered by the paper's camera
/// (640x480, f = 700 px, b = 0.3 m). Like Fig. 6, about a third of the pixels
/// are invalid: the texture-less sky more than 60 px above the horizon (the
/// sky below it is matched at zero disparity), 3 % speckle and a texture-less
/// patch on the ground.
cv::Mat table1Image(const StereoCameraModel& camera, Eigen::Isometry3d* T_W_C);

}  // namespace stereo_occupancy
