#pragma once
/// @file
/// Simulated helicopter flights like the paper's Fig. 7: analytic scenes, a
/// trajectory, and rectified disparity images with stereo effects.
/// Deterministic for a seed.

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <cstdint>
#include <string>
#include <vector>

#include "stereo_occupancy/sim/scene_images.h"
#include "stereo_occupancy/sim/stereo_matching.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "stereo_occupancy/stereo_camera_model.h"

namespace stereo_occupancy {

/// What a real block matcher does to an ideal disparity image.
struct StereoEffects {
  double noise_sigma_px = 0.15;          ///< Gaussian disparity noise [px]
  double subpixel_step_px = 1.0 / 16.0;  ///< output quantisation (SGBM's 1/16 px) [px]
  double unmatched_fraction = 0.03;      ///< pixels left unmatched at random (NaN)
  /// The matcher's search range [px]: a disparity below min_search comes out
  /// as zero (infinitely far), above max_search as unmatched.
  double min_search_disparity_px = 1.0;
  double max_search_disparity_px = 128.0;
  /// Sky is matched as zero disparity below this image row and unmatched
  /// (texture-less) above it; < 0: all sky is matched.
  int sky_unmatched_above_row = -1;
};

/// How a flight's disparity images come about.
enum class StereoMatcher {
  kGaussian,  ///< the exact disparities with StereoEffects (noise, unmatched pixels): the paper's figures
  kSgbm,      ///< textured left and right images matched by StereoSGBM, as stereo_image_proc matches
};

/// "gaussian" or "sgbm" into @p matcher; false for another name.
bool parseStereoMatcher(const std::string& name, StereoMatcher* matcher);
const char* toString(StereoMatcher matcher);

/// One flight: scene, camera, mount and trajectory.
struct FlightScenario {
  std::string name;
  SyntheticScene scene;
  StereoCameraConfig camera;  ///< 640x480, f = 700 px, b = 0.3 m
  StereoEffects effects;
  Eigen::Isometry3d T_B_C;               ///< camera optical frame in the body frame (REP-103 body: x forward, z up)
  std::vector<Eigen::Isometry3d> T_W_B;  ///< body poses, one per frame
  double frame_rate_hz = 10.0;
  StereoMatcher matcher = StereoMatcher::kGaussian;
  SgbmParameters sgbm;         ///< kSgbm: the matcher
  ImageAppearance appearance;  ///< kSgbm: what its cameras see

  /// Optical frame pose of frame i.
  Eigen::Isometry3d cameraPose(size_t i) const { return T_W_B[i] * T_B_C; }
};

/// Names of the built-in scenarios: "posts" (a flight through obstacle posts
/// with wires between some of them), "houses" (a flight along a street of
/// houses), "forest" (a low flight down a lane between thin trunks) and
/// "wires" (power lines of 2 cm wires above the flight, against the sky);
/// "posts_far" and "forest_far" fly slowly toward the posts' and the forest's
/// scenes from 40 m to 12 m before their first obstacle, so that they are
/// seen from 10-40 m away.
std::vector<std::string> scenarioNames();

/// The named scenario; @throws std::invalid_argument for an unknown name.
FlightScenario makeScenario(const std::string& name);

/// Exact disparity of frame i (0 = sky); optionally the depth z of each pixel
/// (+inf for sky) in @p true_depth.
cv::Mat renderTrueDisparity(const FlightScenario& scenario, size_t frame, cv::Mat* true_depth = nullptr);

/// Frame i as the matcher sees it, deterministic for (seed, frame). kGaussian:
/// the exact disparities with noise, quantisation, unmatched and
/// texture-less pixels and the search range of StereoEffects. kSgbm:
/// renderStereoImages() matched by StereoSGBM with scenario.sgbm (unmatched:
/// NaN; the pixels left of the search range too).
cv::Mat renderStereoFrame(const FlightScenario& scenario, size_t frame, uint32_t seed);

/// Makes @p scenario's frames with @p matcher; kSgbm also sets the effects'
/// search range to the SGBM's, which the DisparityImage messages carry.
void useMatcher(FlightScenario* scenario, StereoMatcher matcher);

/// A rectified pair of 8-bit grey camera images.
struct StereoImages {
  cv::Mat left, right;
};

/// Frame i's textured images: the left camera is the flight's camera, the
/// right one sits a baseline along the left optical frame's +x; each with
/// its own sensor noise from (seed, frame).
StereoImages renderStereoImages(const FlightScenario& scenario, size_t frame, uint32_t seed);

/// A one-line-per-object text description of the scene (for the record).
std::string describeScene(const SyntheticScene& scene);

}  // namespace stereo_occupancy
