#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "stereo_occupancy/integer_math.h"

using namespace stereo_occupancy;

// Each helper returns what its std:: counterpart returns, on random values
// and on the edges (integers, halves, values next to them).
TEST(IntegerMath, EqualsTheStdFunctions) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> wide(-2.0e9, 2.0e9), narrow(-4.0, 4.0);
  std::vector<double> values = {0.0, -0.0, 0.5, -0.5, 1.5, -1.5, 2.5, -2.5, 1.0, -1.0, 2147483646.5, -2147483647.5};
  for (double v : {1.0, -1.0, 0.5, -0.5, 3.0, -3.0, 1e6, -1e6}) {
    values.push_back(std::nextafter(v, 0.0));
    values.push_back(std::nextafter(v, 1e300));
  }
  for (int i = 0; i < 100000; ++i) values.push_back(i % 2 ? wide(rng) : narrow(rng));
  for (double x : values) {
    ASSERT_EQ(floorToInt(x), static_cast<int>(std::floor(x))) << x;
    ASSERT_EQ(ceilToInt(x), static_cast<int>(std::ceil(x))) << x;
    ASSERT_EQ(roundToInt64(x * 1000.0), std::llround(x * 1000.0)) << x;
    if (x > 0.0) {
      ASSERT_EQ(floorLog2(x), std::ilogb(x)) << x;
      ASSERT_EQ(floorLog2(static_cast<float>(x)), std::ilogb(static_cast<float>(x))) << x;
    }
  }
  for (int i = -62; i <= 62; ++i) ASSERT_EQ(powerOfTwo(i), std::ldexp(1.0, i)) << i;
}
