#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <random>

#include "avx2_paths.h"
#include "stereo_occupancy/disparity_pyramid.h"

using namespace stereo_occupancy;

namespace {

/// Random disparities with zeros (sky), NaN, negative and too-large values.
cv::Mat randomDisparity(int w, int h, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> d(0.5f, 60.0f), kind(0.0f, 1.0f);
  cv::Mat img(h, w, CV_32FC1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float k = kind(rng);
      img.at<float>(y, x) = k < 0.1f ? 0.0f : k < 0.15f ? std::nanf("") : k < 0.2f ? -3.0f : k < 0.22f ? 1e6f : d(rng);
    }
  return img;
}

/// The bits of a float: tells -0 from +0 (the reductions keep the first of equal values).
uint32_t bitsOf(float v) {
  uint32_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  return bits;
}

void expectReductionExact(const DisparityPyramid& pyr, bool is_min) {
  for (int i = 1; i <= pyr.topLevel(); ++i) {
    const cv::Mat& lo = pyr.level(i - 1);
    const cv::Mat& hi = pyr.level(i);
    ASSERT_EQ(hi.cols, (lo.cols + 1) / 2);
    ASSERT_EQ(hi.rows, (lo.rows + 1) / 2);
    for (int y = 0; y < hi.rows; ++y)
      for (int x = 0; x < hi.cols; ++x) {
        float expected = is_min ? INFINITY : -INFINITY;
        for (int cy = 2 * y; cy <= 2 * y + 1 && cy < lo.rows; ++cy)
          for (int cx = 2 * x; cx <= 2 * x + 1 && cx < lo.cols; ++cx)
            expected = is_min ? std::min(expected, lo.at<float>(cy, cx)) : std::max(expected, lo.at<float>(cy, cx));
        // The first of equal values in block order, as std::min/max keep it: bit for bit.
        ASSERT_EQ(bitsOf(hi.at<float>(y, x)), bitsOf(expected)) << "level " << i << " (" << x << ", " << y << ")";
      }
  }
}

}  // namespace

// On a pool's workers (the pass over the image in bands of rows) the same
// pyramid, bit for bit, for sizes with odd rows and bands of unequal height.
TEST(DisparityPyramid, WorkersBuildTheSamePyramid) {
  const StereoCameraModel cam{StereoCameraConfig()};
  for (auto size : {cv::Size(640, 480), cv::Size(641, 479), cv::Size(37, 97), cv::Size(9, 31)}) {
    const cv::Mat img = randomDisparity(size.width, size.height, 5);
    for (PyramidType type : {PyramidType::kMinDisparity, PyramidType::kMaxDisparity})
      for (int top : {0, 1, 5}) {
        DisparityPyramid alone;
        alone.build(img, cam, type, top);
        for (unsigned threads : {2u, 3u, 5u}) {
          WorkerPool pool(threads);
          DisparityPyramid shared;
          shared.build(img, cam, type, top, &pool);
          ASSERT_EQ(shared.topLevel(), alone.topLevel());
          for (int i = 0; i <= alone.topLevel(); ++i) {
            const cv::Mat& a = alone.level(i);
            const cv::Mat& b = shared.level(i);
            ASSERT_EQ(a.size(), b.size());
            for (int y = 0; y < a.rows; ++y)
              ASSERT_EQ(std::memcmp(a.ptr<float>(y), b.ptr<float>(y), a.cols * sizeof(float)), 0)
                  << size << " top " << top << " threads " << threads << " level " << i << " row " << y;
          }
        }
      }
  }
}

// Both pyramids of one image in one pass: the same levels, bit for bit, as
// two builds, alone and on a pool's workers; the two builds without the
// AVX2 pass, the one pass with it where the CPU has it.
TEST(DisparityPyramid, BothPyramidsInOnePassAreTheTwoBuilds) {
  const AllowAvx2AtEnd restore;
  const StereoCameraModel cam{StereoCameraConfig()};
  for (auto size : {cv::Size(640, 480), cv::Size(641, 479), cv::Size(37, 97), cv::Size(9, 31)}) {
    const cv::Mat img = randomDisparity(size.width, size.height, 7);
    for (int top : {0, 1, 5}) {
      DisparityPyramid min_alone, max_alone;
      allowAvx2(false);  // the SSE2 (or NEON, scalar) pass, against the AVX2 one below where the CPU has it
      min_alone.build(img, cam, PyramidType::kMinDisparity, top);
      max_alone.build(img, cam, PyramidType::kMaxDisparity, top);
      allowAvx2(true);
      for (unsigned threads : {1u, 2u, 3u}) {
        WorkerPool pool(threads);
        DisparityPyramid min_both, max_both;
        DisparityPyramid::buildPyramids(img, cam, top, &min_both, &max_both, threads > 1 ? &pool : nullptr);
        ASSERT_EQ(min_both.type(), PyramidType::kMinDisparity);
        ASSERT_EQ(max_both.type(), PyramidType::kMaxDisparity);
        for (auto pair : {std::make_pair(&min_alone, &min_both), std::make_pair(&max_alone, &max_both)}) {
          ASSERT_EQ(pair.second->topLevel(), pair.first->topLevel());
          for (int i = 0; i <= pair.first->topLevel(); ++i) {
            const cv::Mat& a = pair.first->level(i);
            const cv::Mat& b = pair.second->level(i);
            ASSERT_EQ(a.size(), b.size());
            for (int y = 0; y < a.rows; ++y)
              ASSERT_EQ(std::memcmp(a.ptr<float>(y), b.ptr<float>(y), a.cols * sizeof(float)), 0)
                  << size << " top " << top << " threads " << threads << " level " << i << " row " << y;
          }
        }
      }
    }
  }
}

namespace {
void expectLevel0Sanitised() {
  const StereoCameraModel cam{StereoCameraConfig()};  // near disparity 420 px
  // Sizes that end in the vectorised part of a row and in its scalar rest
  // (25: eight blocks in AVX2 lanes where the CPU has them, four in SSE2's,
  // then the rest), odd rows and columns; a top level of 0 sanitises
  // without reducing.
  for (auto size :
       {cv::Size(64, 48), cv::Size(641, 479), cv::Size(37, 5), cv::Size(25, 3), cv::Size(7, 3), cv::Size(1, 1)}) {
    for (int top : {3, 0}) {
      cv::Mat img = randomDisparity(size.width, size.height, 1);
      for (int y = 0; y < img.rows; ++y)       // zero with the sign bit in odd columns: kept as it is, and
        for (int x = 1; x < img.cols; x += 2)  // a block of +0 and -0 reduces to its first
          if (img.at<float>(y, x) == 0.0f) img.at<float>(y, x) = -0.0f;
      DisparityPyramid min_pyr, max_pyr;
      min_pyr.build(img, cam, PyramidType::kMinDisparity, top);
      max_pyr.build(img, cam, PyramidType::kMaxDisparity, top);
      for (int y = 0; y < img.rows; ++y)
        for (int x = 0; x < img.cols; ++x) {
          const float d = img.at<float>(y, x);
          const bool valid = cam.isValidDisparity(d);
          ASSERT_EQ(bitsOf(min_pyr.at(0, x, y)), bitsOf(valid ? d : DisparityPyramid::kInvalidMin))
              << size << " top " << top << " (" << x << ", " << y << ")";
          ASSERT_EQ(bitsOf(max_pyr.at(0, x, y)), bitsOf(valid ? d : DisparityPyramid::kInvalidMax))
              << size << " top " << top << " (" << x << ", " << y << ")";
        }
      expectReductionExact(min_pyr, true);
      expectReductionExact(max_pyr, false);
    }
  }
}

}  // namespace

TEST(DisparityPyramid, Level0IsSanitised) {
  const AllowAvx2AtEnd restore;
  for (const bool avx2 : {true, false}) {
    SCOPED_TRACE(avx2 ? "AVX2 where the CPU has it" : "without AVX2");
    allowAvx2(avx2);
    expectLevel0Sanitised();
  }
}

TEST(DisparityPyramid, MinPyramidObeysEq14) {
  const StereoCameraModel cam{StereoCameraConfig()};
  for (auto size : {cv::Size(640, 480), cv::Size(641, 479), cv::Size(37, 5)}) {
    DisparityPyramid pyr;
    pyr.build(randomDisparity(size.width, size.height, 2), cam, PyramidType::kMinDisparity, 6);
    EXPECT_EQ(pyr.topLevel(), 6);
    expectReductionExact(pyr, true);
  }
}

TEST(DisparityPyramid, MaxPyramidObeysEq16) {
  const StereoCameraModel cam{StereoCameraConfig()};
  for (auto size : {cv::Size(640, 480), cv::Size(641, 479), cv::Size(37, 5)}) {
    DisparityPyramid pyr;
    pyr.build(randomDisparity(size.width, size.height, 3), cam, PyramidType::kMaxDisparity, 6);
    expectReductionExact(pyr, false);
  }
}

TEST(DisparityPyramid, EnlargedLevelsObeyEq15) {
  const StereoCameraModel cam{StereoCameraConfig()};
  DisparityPyramid pyr;
  pyr.build(randomDisparity(40, 30, 4), cam, PyramidType::kMinDisparity, 2);
  for (int i = -1; i >= -3; --i) {
    EXPECT_EQ(pyr.width(i), 40 << -i);
    EXPECT_EQ(pyr.height(i), 30 << -i);
    for (int y = 0; y < pyr.height(i); ++y)
      for (int x = 0; x < pyr.width(i); ++x)
        ASSERT_EQ(pyr.at(i, x, y), pyr.at(i + 1, x / 2, y / 2)) << "level " << i;  // d_{i-1}(x,y) = d_i(x/2, y/2)
  }
  // Pixel centres: a level-1 pixel is the centre of its 2x2 block; level -1 halves pixels.
  EXPECT_DOUBLE_EQ(DisparityPyramid::centreOf(1, 0, 640), 0.5);
  EXPECT_DOUBLE_EQ(DisparityPyramid::centreOf(2, 1, 640), 5.5);
  EXPECT_DOUBLE_EQ(DisparityPyramid::centreOf(-1, 0, 640), -0.25);
  EXPECT_DOUBLE_EQ(DisparityPyramid::centreOf(-1, 1, 640), 0.25);
  // Blocks cut by the image's edge: the centre of the pixels they hold.
  EXPECT_DOUBLE_EQ(DisparityPyramid::centreOf(6, 7, 480), 463.5);  // rows 448..479
  EXPECT_DOUBLE_EQ(DisparityPyramid::centreOf(8, 2, 640), 575.5);  // columns 512..639
  EXPECT_DOUBLE_EQ(DisparityPyramid::centreOf(9, 1, 640), 575.5);  // columns 512..639
  EXPECT_DOUBLE_EQ(DisparityPyramid::centreOf(1, 320, 641), 640.0);
}

// Eq. 13 for random disparities between the far and the near end; those at
// a clamped level are skipped, and the test counts the rest against the share
// of [far, near] that eq. 13 leaves unclamped.
TEST(PyramidLevelTable, LevelChoiceObeysEq13) {
  const StereoCameraConfig cfg;
  const StereoCameraModel cam{cfg};
  std::mt19937 rng(5);
  constexpr int kSamples = 5000;
  for (double c : {0.1, 0.25, 0.5, 1.0}) {
    const PyramidLevelTable table(cam, c);
    std::uniform_real_distribution<double> d_dist(cam.farDisparity(), cam.nearDisparity());
    int tested = 0;
    for (int n = 0; n < kSamples; ++n) {
      const float d = static_cast<float>(d_dist(rng));
      const int i = table.levelForDisparity(d);
      if (i == table.topLevel() || i == table.minLevel()) continue;  // clamped
      const double z = cam.depthFromDisparity(d);
      const double dp = z * std::ldexp(1.0, i) / 700.0;       // eq. 12
      ASSERT_GT(dp, 0.5 * c) << "d=" << d << " level " << i;  // eq. 13
      ASSERT_LE(dp, c) << "d=" << d << " level " << i;
      ASSERT_EQ(table.levelForDepth(z), i);
      ++tested;
    }
    // Unclamped: floor(log2(c·d/b)) above the lowest level (that of the far
    // end, at most 0) and below the top (that of the nearest range, at most
    // the image's log2 size), i.e. c·d/b in [2^(lowest + 1), 2^top).
    const double b = cfg.baseline_m;
    const int top = std::min(static_cast<int>(std::floor(std::log2(c * cam.bf() / cfg.min_range_m / b))),
                             static_cast<int>(std::floor(std::log2(std::max(cfg.width_px, cfg.height_px)))));
    const int lowest = std::min(0, static_cast<int>(std::floor(std::log2(c * cam.farDisparity() / b))));
    const double lo = std::max(cam.farDisparity(), b * std::ldexp(1.0, lowest + 1) / c);
    const double hi = std::min(cam.nearDisparity(), b * std::ldexp(1.0, top) / c);
    const double share = std::max(0.0, hi - lo) / (cam.nearDisparity() - cam.farDisparity());
    // Within 5 standard deviations of the binomial count (the seed is fixed: no flakiness).
    EXPECT_NEAR(tested, kSamples * share, 5.0 * std::sqrt(kSamples * share * (1.0 - share)) + 1.0) << "cell " << c;
    EXPECT_GT(tested, 1000) << "cell " << c;
    std::printf("[          ] cell %.2f m: %d of %d disparities at an unclamped level (expected %.0f)\n", c, tested,
                kSamples, kSamples * share);
  }
}

TEST(PyramidLevelTable, Fig3LevelsAndFarRange) {
  const StereoCameraModel cam{StereoCameraConfig()};
  const PyramidLevelTable t05(cam, 0.5);
  // Fig. 3 (0.5 m grid): 6..25 m need only reduced resolutions, levels 3..5.
  EXPECT_EQ(t05.levelForDepth(25.0), 3);
  EXPECT_EQ(t05.levelForDepth(6.0), 5);
  // Zero disparity (sky) and beyond-range disparities use the level of the maximum range.
  EXPECT_EQ(t05.levelForDisparity(0.0f), 3);
  EXPECT_EQ(t05.levelForDisparity(1.0f), 3);
  EXPECT_EQ(t05.minLevel(), 0);
  // Top level: the near disparity (0.5 m: 420 px) -> floor(log2(0.5 * 420 / 0.3)) = 9, capped by the image.
  EXPECT_EQ(t05.topLevel(), 9);

  // A range beyond c·f needs enlarged levels (eq. 15).
  StereoCameraConfig far = StereoCameraConfig();
  far.max_range_m = 100.0;
  const PyramidLevelTable t01(StereoCameraModel(far), 0.1);
  EXPECT_EQ(t01.minLevel(), -1);  // c·f/R = 0.7 px
  EXPECT_EQ(t01.levelForDisparity(0.0f), -1);

  // c·f/R = 2^-20 -> -20, capped at -16; one that underflows a float to 0
  // (ilogb(0) = INT_MIN, found by the fuzzer) likewise.
  StereoCameraConfig tiny = StereoCameraConfig();
  tiny.focal_length_px = std::ldexp(1.0, -20) * 25.0 / 0.1;
  EXPECT_EQ(PyramidLevelTable(StereoCameraModel(tiny), 0.1).minLevel(), -16);
  tiny.focal_length_px = 1e-40;
  const PyramidLevelTable underflow(StereoCameraModel(tiny), 0.1);
  EXPECT_EQ(underflow.minLevel(), -16);
  EXPECT_EQ(underflow.levelForDisparity(0.0f), -16);
  EXPECT_EQ(underflow.levelForDepth(25.0), -16);
}
