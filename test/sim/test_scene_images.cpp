// Camera images of the synthetic scenes (scene_images.h) and StereoSGBM on
// them (stereo_matching.h): what the flights through a real matcher rest on.

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "stereo_occupancy/sim/flight_simulation.h"
#include "stereo_occupancy/sim/scene_images.h"
#include "stereo_occupancy/sim/stereo_matching.h"

using namespace stereo_occupancy;

namespace {

/// The paper's camera (640x480, f = 700 px, b = 0.3 m): bf = 210 px m.
const StereoCameraConfig kCamera;
constexpr double kWallDepthM = 10.0;  ///< disparity bf / z = 21 px exactly
constexpr int kWallDisparityPx = 21;

/// A textured wall filling the view at kWallDepthM along W +x, no ground.
SyntheticScene wallScene() {
  SyntheticScene scene;
  scene.addBox({kWallDepthM, -30.0, -30.0}, {kWallDepthM + 1.0, 30.0, 30.0});
  return scene;
}

/// The camera at the origin looking along W +x.
Eigen::Isometry3d T_W_C() { return lookingAlongX(Eigen::Vector3d::Zero()); }

/// Pixels the matcher can match: right of its search range and a block's
/// half from the borders.
cv::Rect matchableWindow(const SgbmParameters& sgbm) {
  const int margin = sgbm.block_size_px / 2;
  const int left = sgbm.min_disparity_px + sgbm.num_disparities + margin;
  return cv::Rect(left, margin, kCamera.width_px - left - margin, kCamera.height_px - 2 * margin);
}

/// Mean absolute grey difference of the left image and the right image
/// shifted by @p shift_px (left(x) against right(x - shift)), over the
/// columns both hold.
double meanDifference(const cv::Mat& left, const cv::Mat& right, int shift_px) {
  const int width = left.cols - std::abs(shift_px);
  const cv::Rect in_left(std::max(0, shift_px), 0, width, left.rows);
  const cv::Rect in_right(std::max(0, -shift_px), 0, width, left.rows);
  cv::Mat difference;
  cv::absdiff(left(in_left), right(in_right), difference);
  return cv::mean(difference)[0];
}

}  // namespace

// The per-tile box lists give every pixel the same first hit as casting the
// pixel's ray against the whole scene: on frames of the forest (240 thin
// trunks) and of the posts, and beside a wall that runs past the camera (a
// box reaching behind the camera plane, whose corners bound nothing).
TEST(SceneImages, TiledRaysHitWhatTheWholeSceneHits) {
  std::vector<std::pair<SyntheticScene, Eigen::Isometry3d>> cases;
  for (const char* name : {"forest", "posts"}) {
    const FlightScenario s = makeScenario(name);
    for (size_t frame : {0u, 120u}) cases.emplace_back(s.scene, s.cameraPose(frame));
  }
  SyntheticScene wall;
  wall.ground_height_m = 0.0;
  wall.addBox({-20.0, 3.0, 0.0}, {40.0, 4.0, 5.0});
  wall.addBox({-5.0, -9.0, 0.0}, {-4.0, -8.0, 5.0});  // behind the camera: seen by no pixel
  cases.emplace_back(wall, lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0), 0.3));
  const StereoCameraModel camera(kCamera);
  for (size_t c = 0; c < cases.size(); ++c) {
    const auto& [scene, pose] = cases[c];
    const PixelHits hits = castPixelRays(scene, camera, pose);
    int boxes_seen = 0, differ = 0;
    for (int y = 0; y < kCamera.height_px; ++y)
      for (int x = 0; x < kCamera.width_px; ++x) {
        int hit = SyntheticScene::kHitNothing;
        const double range =
            scene.castRay(pose.translation(), pose.linear() * camera.rayThroughPixel(x, y).normalized(), &hit);
        differ += hit != hits.object.at<int>(y, x) || (std::isfinite(range) && range != hits.range_m.at<double>(y, x));
        boxes_seen += hit >= 0;
      }
    EXPECT_EQ(differ, 0) << "case " << c;
    EXPECT_GT(boxes_seen, 5000) << "case " << c;  // the frame shows obstacles
  }
}

// The right camera sits a baseline along the left optical frame's +x and
// the texture is fixed to the surface: without sensor noise, the right image
// shifted by the wall's true disparity (21 px) is the left image (up to the
// texture's blur, which follows each camera's range), and any other shift
// is not.
TEST(SceneImages, BothCamerasSeeOneTexture) {
  const SyntheticScene scene = wallScene();
  const StereoCameraModel camera(kCamera);
  ImageAppearance look;
  look.sensor_noise_grey = 0.0;
  const cv::Mat left = renderGreyImage(scene, camera, T_W_C(), 1, look);
  const cv::Mat right = renderGreyImage(scene, camera, rightCameraPose(T_W_C(), kCamera.baseline_m), 2, look);
  const double at_truth = meanDifference(left, right, kWallDisparityPx);
  std::printf("[          ] mean grey difference at the true shift %.3f", at_truth);
  EXPECT_LT(at_truth, 0.3);
  for (int wrong :
       {kWallDisparityPx - 4, kWallDisparityPx - 1, kWallDisparityPx + 1, kWallDisparityPx + 4, -kWallDisparityPx, 0}) {
    const double off = meanDifference(left, right, wrong);
    std::printf(", at %d px %.2f", wrong, off);
    EXPECT_GT(off, 1.0) << "shift " << wrong;
  }
  std::printf("\n");
  // The texture carries detail for a matcher: a standard deviation of several grey levels.
  cv::Scalar mean, deviation;
  cv::meanStdDev(left, mean, deviation);
  EXPECT_GT(deviation[0], 8.0);
}

// StereoSGBM with stereo_image_proc's defaults on a textured wall at 10 m:
// nearly every matchable pixel matched, and within 1 px of the true 21 px
// (the median within a sixteenth).
TEST(SceneImages, SgbmFindsTheWallsDisparity) {
  const SyntheticScene scene = wallScene();
  const StereoCameraModel camera(kCamera);
  const SgbmParameters sgbm;
  const cv::Mat left = renderGreyImage(scene, camera, T_W_C(), 1);
  const cv::Mat right = renderGreyImage(scene, camera, rightCameraPose(T_W_C(), kCamera.baseline_m), 2);
  const cv::Mat disparity = matchSgbm(left, right, sgbm);
  ASSERT_EQ(disparity.type(), CV_32FC1);
  std::vector<float> matched;
  int within_1px = 0;
  const cv::Mat window = disparity(matchableWindow(sgbm));
  for (int y = 0; y < window.rows; ++y)
    for (int x = 0; x < window.cols; ++x) {
      const float d = window.at<float>(y, x);
      if (std::isnan(d)) continue;
      matched.push_back(d);
      within_1px += std::abs(d - kWallDisparityPx) <= 1.0f;
    }
  const double pixels = static_cast<double>(window.total());
  std::printf("[          ] wall: %.1f %% matched, %.1f %% within 1 px\n", 100.0 * matched.size() / pixels,
              100.0 * within_1px / pixels);
  EXPECT_GT(matched.size(), 0.95 * pixels);
  EXPECT_GT(within_1px, 0.95 * pixels);
  std::nth_element(matched.begin(), matched.begin() + matched.size() / 2, matched.end());
  EXPECT_NEAR(matched[matched.size() / 2], kWallDisparityPx, 1.0 / 16.0);
  // Left of the search range the matcher has nothing to compare: unmatched.
  EXPECT_EQ(
      cv::countNonZero(disparity.colRange(0, sgbm.num_disparities) == disparity.colRange(0, sgbm.num_disparities)), 0);
}

// The ground seen at a slant: its disparity falls row by row toward the
// horizon, and SGBM follows it within 1 px on most pixels up to 25 m.
TEST(SceneImages, SgbmFollowsTheGround) {
  SyntheticScene scene;
  scene.ground_height_m = 0.0;
  const StereoCameraModel camera(kCamera);
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 3.0), 0.0, 0.15);
  const SgbmParameters sgbm;
  const cv::Mat left = renderGreyImage(scene, camera, pose, 1);
  const cv::Mat right = renderGreyImage(scene, camera, rightCameraPose(pose, kCamera.baseline_m), 2);
  const cv::Mat disparity = matchSgbm(left, right, sgbm);
  PixelHits hits = castPixelRays(scene, camera, pose);
  const cv::Rect window = matchableWindow(sgbm);
  int ground = 0, within_1px = 0;
  for (int y = window.y; y < window.y + window.height; ++y)
    for (int x = window.x; x < window.x + window.width; ++x) {
      const double range = hits.range_m.at<double>(y, x);
      if (!(range <= kCamera.max_range_m)) continue;
      ++ground;
      const double truth = camera.disparityFromDepth(range / camera.rayThroughPixel(x, y).norm());
      within_1px += std::abs(disparity.at<float>(y, x) - truth) <= 1.0;
    }
  std::printf("[          ] ground within 25 m: %d px, %.1f %% within 1 px\n", ground, 100.0 * within_1px / ground);
  EXPECT_GT(ground, 50000);
  EXPECT_GT(within_1px, 0.9 * ground);
}

// A clear sky is uniform: every sky pixel is the sky's grey (without
// sensor noise), and a pair of sky alone is never matched as a surface
// (no disparity of 1 px or more: zero, "infinitely far", or unmatched).
TEST(SceneImages, TheSkyIsUniformAndNeverASurface) {
  SyntheticScene scene;  // nothing: all sky
  const StereoCameraModel camera(kCamera);
  ImageAppearance look;
  look.sensor_noise_grey = 0.0;
  const cv::Mat left = renderGreyImage(scene, camera, T_W_C(), 1, look);
  const cv::Mat right = renderGreyImage(scene, camera, rightCameraPose(T_W_C(), kCamera.baseline_m), 2, look);
  EXPECT_EQ(cv::countNonZero(left != static_cast<uchar>(look.sky_grey)), 0);
  const cv::Mat disparity = matchSgbm(left, right);
  EXPECT_EQ(cv::countNonZero(disparity >= 1.0f), 0);
}

// A flight through the real matcher: StereoSGBM on the rendered images of a
// posts_far frame matches most surface pixels within 1 px of the exact
// disparity, and the frame is reproducible for its seed.
TEST(SceneImages, SgbmFlightFramesFollowTheTruth) {
  FlightScenario s = makeScenario("posts_far");
  useMatcher(&s, StereoMatcher::kSgbm);
  EXPECT_EQ(s.effects.max_search_disparity_px, 63.0);
  constexpr size_t kFrame = 150;
  const cv::Mat d = renderStereoFrame(s, kFrame, 1);
  const cv::Mat truth = renderTrueDisparity(s, kFrame);
  int surface = 0, within_1px = 0;
  for (int y = 0; y < d.rows; ++y)
    for (int x = s.sgbm.num_disparities; x < d.cols; ++x) {
      const float t = truth.at<float>(y, x);
      if (t == 0.0f) continue;  // sky
      ++surface;
      within_1px += std::abs(d.at<float>(y, x) - t) <= 1.0f;
    }
  std::printf("[          ] posts_far frame %zu: %d surface px, %.1f %% within 1 px\n", kFrame, surface,
              100.0 * within_1px / surface);
  EXPECT_GT(surface, 100000);
  EXPECT_GT(within_1px, 0.8 * surface);
  const cv::Mat again = renderStereoFrame(s, kFrame, 1);
  EXPECT_EQ(cv::countNonZero((d != again) & (d == d)), 0);
}
