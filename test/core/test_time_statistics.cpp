#include <gtest/gtest.h>

#include <vector>

#include "stereo_occupancy/time_statistics.h"

using namespace stereo_occupancy;

TEST(TimeStatistics, EmptyIsAllZero) {
  const TimeStatistics t = TimeStatistics::of({});
  EXPECT_EQ(t.count, 0u);
  EXPECT_EQ(t.mean_ms, 0.0);
  EXPECT_EQ(t.median_ms, 0.0);
  EXPECT_EQ(t.p99_ms, 0.0);
  EXPECT_EQ(t.max_ms, 0.0);
}

TEST(TimeStatistics, NearestRanksOfUnsortedTimes) {
  // 1..200 ms in reverse: the median is element 100 (101 ms), the p99 element 198 (199 ms).
  std::vector<double> ms;
  for (int i = 200; i >= 1; --i) ms.push_back(i);
  const TimeStatistics t = TimeStatistics::of(ms);
  EXPECT_EQ(t.count, 200u);
  EXPECT_DOUBLE_EQ(t.mean_ms, 100.5);
  EXPECT_EQ(t.median_ms, 101.0);
  EXPECT_EQ(t.p99_ms, 199.0);
  EXPECT_EQ(t.min_ms, 1.0);
  EXPECT_EQ(t.max_ms, 200.0);
  // Fewer than 100 times: the p99 is the maximum; one time is every statistic.
  const TimeStatistics few = TimeStatistics::of({3.0, 9.0, 1.0});
  EXPECT_EQ(few.median_ms, 3.0);
  EXPECT_EQ(few.p99_ms, 9.0);
  const TimeStatistics one = TimeStatistics::of({2.5});
  EXPECT_EQ(one.median_ms, 2.5);
  EXPECT_EQ(one.p99_ms, 2.5);
  EXPECT_EQ(one.mean_ms, 2.5);
}
