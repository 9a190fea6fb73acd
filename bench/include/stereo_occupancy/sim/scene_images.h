#pragma once
/// @file
/// Camera images of a synthetic scene, for a real stereo matcher: every
/// surface wears a procedural texture fixed to the surface (so that both
/// cameras of a pair see the same texture at the same surface point), shaded
/// by a sun; the sky is uniform; the sensor adds noise. And the per-pixel ray
/// casting both these images and the ground truth of a flight's obstacles need.

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <cstdint>

#include "stereo_occupancy/sim/synthetic_scene.h"
#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

/// What the ray through each pixel centre of a camera meets.
struct PixelHits {
  cv::Mat range_m;  ///< CV_64FC1: range along the unit ray to the first surface [m], +inf for none
  cv::Mat object;   ///< CV_32SC1: the box index, SyntheticScene::kHitGround or kHitNothing
};

/// Casts the ray through every pixel centre of @p camera at T_W_C into
/// @p scene: the same first hits as SyntheticScene::castRay(), but each ray
/// tests only the boxes whose image (the bounding rectangle of their
/// projected corners) covers its pixel's tile, so that a scene of hundreds of
/// thin trunks costs a few tests a ray.
PixelHits castPixelRays(const SyntheticScene& scene, const StereoCameraModel& camera, const Eigen::Isometry3d& T_W_C);

/// How the scene looks to the cameras [grey levels of 8 bits].
struct ImageAppearance {
  double sky_grey = 205.0;               ///< the sky: uniform, as a clear sky is to a matcher
  double ground_albedo_grey = 110.0;     ///< the ground's mean before shading
  double ground_contrast = 0.35;         ///< its texture's standard deviation at full detail, relative to its mean
  double min_object_albedo_grey = 70.0;  ///< each box's mean lies in [min, min + span), hashed from its index
  double object_albedo_span_grey = 100.0;
  double min_object_contrast = 0.15;  ///< each box's texture contrast (as the ground's) lies in [min, min + span)
  double object_contrast_span = 0.3;
  double textureless_albedo_grey = 225.0;  ///< boxes marked texture-less: uniform white walls
  double sensor_noise_grey = 1.0;          ///< Gaussian noise of each pixel, independent between the cameras
  Eigen::Vector3d W_sun = Eigen::Vector3d(0.4, 0.3, 0.85);  ///< direction toward the sun (normalised when used)
  double ambient = 0.55;                                    ///< share of the light that reaches every face
};

/// The texture's finest and coarsest wavelengths [m]: bark and gravel to
/// patches of shade; octaves double between them.
constexpr double kFinestTextureWavelengthM = 0.01;
constexpr int kTextureOctaves = 10;

/// Grey value (before sensor noise) of the surface point W_point of
/// @p object (a box index or kHitGround) in @p scene, seen with a pixel
/// footprint of @p footprint_m on the surface: a function of the surface
/// point and the face alone, so both cameras of a pair see one texture. The
/// texture's octaves finer than about two footprints fade out, as a lens
/// and a pixel's area average them, rather than alias differently in the
/// two views. kHitNothing: the sky.
double surfaceGrey(const SyntheticScene& scene, int object, const Eigen::Vector3d& W_point, double footprint_m,
                   const ImageAppearance& look = ImageAppearance());

/// The 8-bit grey image of @p scene seen by @p camera at T_W_C: each pixel
/// the surfaceGrey() of its centre's first hit, plus sensor noise drawn from
/// @p noise_seed. Also returns the pixel hits in @p hits if given.
cv::Mat renderGreyImage(const SyntheticScene& scene, const StereoCameraModel& camera, const Eigen::Isometry3d& T_W_C,
                        uint32_t noise_seed, const ImageAppearance& look = ImageAppearance(),
                        PixelHits* hits = nullptr);

/// The right camera of a rectified pair whose left camera is T_W_L: shifted
/// by the baseline along the left optical frame's +x.
Eigen::Isometry3d rightCameraPose(const Eigen::Isometry3d& T_W_L, double baseline_m);

}  // namespace stereo_occupancy
