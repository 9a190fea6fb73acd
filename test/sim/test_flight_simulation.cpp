// The simulated flights (flight_simulation.h).

#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

#include "stereo_occupancy/sim/flight_simulation.h"

using namespace stereo_occupancy;

// The mission: 30 minutes and 7 km with scenery generated along the path
// (not one stretch repeated), nothing on the path itself, and frames that
// render from the boxes near the camera.
TEST(FlightSimulation, TheMissionIsLongAndItsSceneryVaries) {
  const FlightScenario s = makeScenario("mission");
  ASSERT_EQ(s.T_W_B.size(), 18000u);  // 30 min at 10 Hz
  const double length = (s.T_W_B.back().translation() - s.T_W_B.front().translation()).head<2>().norm();
  EXPECT_GT(length, 7000.0);
  EXPECT_GT(s.scene.boxes.size(), 500u);  // beyond the renderer's culling threshold: frames render from the near boxes
  // Every kilometre holds obstacles, and they differ: box counts per km are not all alike.
  std::vector<int> per_km(7, 0);
  for (const auto& b : s.scene.boxes) {
    const int km = static_cast<int>(b.center().x() / 1000.0);
    if (km >= 0 && km < 7) ++per_km[km];
  }
  for (int km = 0; km < 7; ++km) EXPECT_GT(per_km[km], 50) << "km " << km;
  EXPECT_NE(*std::min_element(per_km.begin(), per_km.end()), *std::max_element(per_km.begin(), per_km.end()));
  // No box holds a point of the path.
  for (size_t i = 0; i < s.T_W_B.size(); i += 10)
    for (const auto& b : s.scene.boxes) ASSERT_FALSE(b.contains(s.T_W_B[i].translation())) << "frame " << i;
  // A frame in the middle of the mission sees its own stretch: obstacles and ground.
  const cv::Mat d = renderTrueDisparity(s, 9000);
  const int measured = cv::countNonZero(d > 8.4f);  // nearer than 25 m
  EXPECT_GT(measured, static_cast<int>(d.total() / 4));
}
