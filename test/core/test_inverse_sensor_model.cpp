#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "stereo_occupancy/inverse_sensor_model.h"
#include "stereo_occupancy/stereo_camera_model.h"

using namespace stereo_occupancy;

namespace {
// Fig. 1: k = 0.1, p_min = 0.35, b = 0.3 m, f = 700 px, Δd = 0.5 px.
InverseSensorModel fig1Model() { return InverseSensorModel(InverseSensorModelConfig()); }
double deltaL(double z) { return StereoCameraModel(StereoCameraConfig()).depthUncertainty(z); }
double logit(double p) { return std::log(p / (1.0 - p)); }
}  // namespace

TEST(InverseSensorModel, Fig1PeakProbabilities) {
  const InverseSensorModel m = fig1Model();
  EXPECT_NEAR(deltaL(10.0), 0.238, 5e-4);
  // On the optical axis l_p = z; the peak is 0.5 + k / (Δl √(2π)).
  EXPECT_NEAR(m.probability(10.0, 10.0, deltaL(10.0)), 0.668, 1e-3);
  EXPECT_NEAR(m.probability(20.0, 20.0, deltaL(20.0)), 0.542, 1e-3);
  EXPECT_NEAR(m.probability(40.0, 40.0, deltaL(40.0)), 0.510, 1e-3);
  EXPECT_NEAR(m.probability(10.0, 10.0, deltaL(10.0)), 0.5 + 0.1 / (deltaL(10.0) * std::sqrt(2 * M_PI)), 1e-12);
}

TEST(InverseSensorModel, FreeInFrontUnknownFarBehind) {
  const InverseSensorModel m = fig1Model();
  for (double lp : {10.0, 20.0, 40.0}) {
    const double dl = deltaL(lp);
    EXPECT_NEAR(m.probability(lp - 8.0 * dl, lp, dl), 0.35, 1e-9) << lp;     // free space is p_min
    EXPECT_NEAR(m.probability(lp + 8.0 * dl, lp, dl), 0.5, 1e-9) << lp;      // unknown behind
    EXPECT_GT(m.probability(lp + 0.5 * dl, lp, dl), 0.5) << lp;              // still occupied just behind
    EXPECT_NEAR(m.logOdds(lp - 8.0 * dl, lp, dl), logit(0.35), 1e-9) << lp;  // eq. 8
  }
  EXPECT_NEAR(m.freeLogOdds(), logit(0.35), 1e-12);
}

TEST(InverseSensorModel, UnimodalAroundTheMeasurement) {
  const InverseSensorModel m = fig1Model();
  const double lp = 15.0, dl = deltaL(15.0);
  double prev = m.probability(0.0, lp, dl);
  for (double l = 0.01; l <= lp; l += 0.01) {
    const double p = m.probability(l, lp, dl);
    EXPECT_GE(p, prev - 1e-15);
    prev = p;
  }
  for (double l = lp; l <= lp + 10.0; l += 0.01) {
    const double p = m.probability(l, lp, dl);
    EXPECT_LE(p, prev + 1e-15);
    prev = p;
  }
}

TEST(InverseSensorModel, PaperConstraintFailsBelow5_8mAndPMaxKeepsProbabilitiesValid) {
  // Uncapped eq. 9 peak 0.5 + k/(Δl√2π) reaches 1 at about 5.8 m.
  auto uncapped = [](double z) { return 0.5 + 0.1 / (deltaL(z) * std::sqrt(2 * M_PI)); };
  EXPECT_GT(uncapped(5.7), 1.0);
  EXPECT_LT(uncapped(5.9), 1.0);

  const InverseSensorModel m = fig1Model();  // p_max = 0.9
  for (double z = 0.5; z <= 60.0; z += 0.25) {
    const double dl = deltaL(z);
    for (double l = 0.0; l <= z + 10.0; l += 0.05) {
      const double p = m.probability(l, z, dl);
      ASSERT_GE(p, 0.35 - 1e-12) << "z=" << z << " l=" << l;
      ASSERT_LE(p, 0.9 + 1e-12) << "z=" << z << " l=" << l;
      ASSERT_TRUE(std::isfinite(m.logOdds(l, z, dl)));
    }
  }
  EXPECT_DOUBLE_EQ(m.peakProbability(deltaL(3.0)), 0.9);
  EXPECT_DOUBLE_EQ(m.probability(3.0, 3.0, deltaL(3.0)), 0.9);
  EXPECT_NEAR(m.logOdds(3.0, 3.0, deltaL(3.0)), logit(0.9), 1e-12);
  // Above the cap the model is the paper's, untouched.
  EXPECT_NEAR(m.peakProbability(deltaL(10.0)), 0.5 + 0.1 / (deltaL(10.0) * std::sqrt(2 * M_PI)), 1e-15);
}

TEST(InverseSensorModel, Eq11ClosedFormEqualsDenseSampling) {
  const InverseSensorModel m = fig1Model();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> range(1.0, 40.0), offset(-3.0, 3.0), cell(0.05, 1.0);
  for (int i = 0; i < 300; ++i) {
    const double lp = range(rng), c = cell(rng), dl = deltaL(lp);
    const double l = lp + offset(rng) * (dl + c);
    EXPECT_NEAR(m.logOddsHat(l, lp, dl, c), m.logOddsHatSampled(l, lp, dl, c), 2e-3)
        << "l=" << l << " lp=" << lp << " c=" << c;
  }
  // Inside the window the peak itself counts.
  const double dl = deltaL(10.0);
  EXPECT_NEAR(m.logOddsHat(10.1, 10.0, dl, 0.25), m.logOdds(10.0, 10.0, dl), 1e-12);
  EXPECT_GT(m.logOddsHat(9.8, 10.0, dl, 0.25), m.logOdds(9.8, 10.0, dl));
}

TEST(LogOddsTable, MatchesTheExactModel) {
  const InverseSensorModel m = fig1Model();
  const StereoCameraModel cam{StereoCameraConfig()};
  std::mt19937 rng(11);
  for (double c : {0.1, 0.25, 0.5, 1.0}) {
    const LogOddsTable table(m, c);
    double worst = 0.0;
    std::uniform_real_distribution<double> z_dist(0.6, 45.0), n_dist(1.0, 1.15), t_dist(0.0, 1.0);
    for (int i = 0; i < 3000; ++i) {
      const double z = z_dist(rng), n = n_dist(rng);
      const double lp = z * n, dl = cam.rangeUncertainty(z, lp);
      const RangeProfile profile = table.profile(static_cast<float>(lp), static_cast<float>(dl));
      const double l = t_dist(rng) * profile.endRange();
      const double exact = m.logOddsHat(l, lp, dl, c);
      worst = std::max(worst, std::abs(profile.at(static_cast<float>(l)) - exact));
    }
    EXPECT_LT(worst, 0.005) << "cell " << c;
    EXPECT_NEAR(table.freeProfile().at(3.0f), logit(0.35), 1e-6);
  }
}

TEST(LogOddsTable, ProfileEndsAtTheTail) {
  const InverseSensorModel m = fig1Model();
  const LogOddsTable table(m, 0.25);
  const double dl = deltaL(10.0);
  const RangeProfile p = table.profile(10.0f, static_cast<float>(dl));
  EXPECT_NEAR(p.endRange(), 10.0 + 0.125 + 3.0 * dl, 1e-5);
  // At the tail the probability is within 1.2 % of the peak height of 0.5.
  EXPECT_GT(p.at(static_cast<float>(p.endRange())), 0.0f);
  EXPECT_LT(m.probability(p.endRange() - 0.125, 10.0, dl) - 0.5, 0.012 * (m.peakProbability(dl) - 0.5));
}

// A camera of tiny focal length gives rays of huge range and Δl = inf (found
// by the drawer fuzzer): the profile stays finite, and the cells before such
// a measurement are free.
TEST(LogOddsTable, HugeOrUndefinedRangeUncertaintyStaysFinite) {
  const LogOddsTable table(fig1Model(), 0.25);
  for (float dl : {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::quiet_NaN(), 1e30f}) {
    const RangeProfile p = table.profile(2.9e38f, dl);
    EXPECT_TRUE(std::isfinite(p.samples_per_m) && p.samples_per_m > 0.0f) << dl;
    EXPECT_TRUE(std::isfinite(p.front_m) && std::isfinite(p.row_origin_m) && std::isfinite(p.tail_m)) << dl;
    for (float l : {0.0f, 10.0f, 200.0f}) EXPECT_EQ(p.at(l), p.free_log_odds) << dl << " at " << l;
  }
}

// A window position far outside the table (float cancellation in l - l_p at
// a Δl of 1e-6 m and a range of 300 m, as a hostile camera can give, put it
// at 1495) reads the table's nearest end, not memory beyond it (the
// sanitizer runs check the reads); inside the table nothing changes.
TEST(LogOddsTable, SamplesFarOutsideTheTableReadItsEnds) {
  const LogOddsTable table(fig1Model(), 0.25);
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  const RangeProfile p = table.profile(300.0f, 0.6f);
  const float low = p.sample(RangeProfile::kMinSampleX), high = p.sample(RangeProfile::kMaxSampleX);
  ASSERT_TRUE(std::isfinite(low) && std::isfinite(high));
  for (float x : {-1.0f, -5.0f, -1e9f, -inf, nan}) EXPECT_EQ(p.sample(x), low) << x;
  for (float x : {225.0f, 1495.0f, 1e9f, 3e9f, inf}) EXPECT_EQ(p.sample(x), high) << x;
  for (float x : {0.0f, 0.5f, 100.25f, 224.0f, 224.5f}) {
    const int j = static_cast<int>(x);
    const float frac = x - static_cast<float>(j);
    const float v0 = p.row[j] + frac * (p.row[j + 1] - p.row[j]);
    const float v1 = p.row[j + p.row_length] + frac * (p.row[j + 1 + p.row_length] - p.row[j + p.row_length]);
    EXPECT_EQ(p.sample(x), v0 + p.row_weight * (v1 - v0)) << x;
  }
  InverseSensorModelConfig surface;
  surface.profile = SensorProfile::kSurface;
  const LogOddsTable surface_table(InverseSensorModel(surface), 0.25);  // outlives the profile's view
  const RangeProfile step = surface_table.profile(300.0f, 0.6f);
  ASSERT_GE(step.step_sample, 0);
  for (float x : {225.0f, 1495.0f, 3e9f, inf}) EXPECT_EQ(step.stepSample(x), 0.0f) << x;
  for (float x : {-1.0f, -3e9f, -inf}) EXPECT_EQ(step.stepSample(x), step.row[0]) << x;
}

// The bounded descent asks only where a measurement's free space ends:
// frontRange() is the whole profile's l_p_m + front_m, bit for bit, for
// ordinary, tiny, huge and undefined Δl.
TEST(LogOddsTable, FrontRangeIsTheProfilesFront) {
  const LogOddsTable table(fig1Model(), 0.25);
  const float inf = std::numeric_limits<float>::infinity();
  for (float l_p : {0.6f, 10.0f, 24.9f, 2.9e38f, inf})
    for (float dl : {0.0f, 1e-7f, 0.01f, static_cast<float>(deltaL(10.0)), 3.0f, 1e30f, inf,
                     std::numeric_limits<float>::quiet_NaN()}) {
      const RangeProfile p = table.profile(l_p, dl);
      const float expected = p.l_p_m + p.front_m, front = table.frontRange(l_p, dl);
      EXPECT_EQ(std::memcmp(&front, &expected, sizeof front), 0) << l_p << " " << dl << ": " << front;
    }
}

TEST(InverseSensorModelConfig, Validation) {
  InverseSensorModelConfig c;
  EXPECT_TRUE(c.isValid());
  c.p_min = 0.6;
  EXPECT_FALSE(c.isValid());
  c = InverseSensorModelConfig();
  c.p_max = 1.0;
  EXPECT_FALSE(c.isValid());
  c = InverseSensorModelConfig();
  c.k_m = -0.1;
  EXPECT_FALSE(c.isValid());
}
