// The nodelets' timing bookkeeping (no roscore needed).

#include <gtest/gtest.h>

#include <time.h>

#include <chrono>
#include <thread>

#include "stereo_occupancy/ros/processing_times.h"

using namespace stereo_occupancy;

namespace {

/// CPU time of the calling thread [ms].
double threadCpuMs() {
  timespec t{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return 1e3 * static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_nsec);
}

/// Keeps the thread busy for @p ms of its CPU time (however long that takes on a loaded machine).
void spin(double ms) {
  const double end = threadCpuMs() + ms;
  volatile double sink = 0.0;
  while (threadCpuMs() < end) sink = sink + 1.0;
}

}  // namespace

TEST(ProcessingTimes, EmptyBeforeTheFirstUnit) {
  ProcessingTimes times;
  EXPECT_TRUE(times.empty());
  EXPECT_EQ(times.lastMs(), 0.0);
  EXPECT_EQ(times.maxMs(), 0.0);
  EXPECT_EQ(times.statistics().count, 0u);
  EXPECT_EQ(times.takeWindow().count, 0u);
}

TEST(ProcessingTimes, LastMaxAndTheSummary) {
  ProcessingTimes times;
  for (const double ms : {20.0, 5.0}) {
    const ProcessingTimes::Start start = times.start();
    std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(ms));
    times.stop(start);
  }
  EXPECT_FALSE(times.empty());
  EXPECT_GE(times.lastMs(), 5.0);
  EXPECT_LT(times.lastMs(), times.maxMs());  // the first took longer
  EXPECT_GE(times.maxMs(), 20.0);
  const TimeStatistics all = times.statistics();
  EXPECT_EQ(all.count, 2u);
  EXPECT_EQ(all.max_ms, times.maxMs());
  EXPECT_EQ(all.min_ms, times.lastMs());
  EXPECT_EQ(times.cpuStatistics().count, 0u);  // not asked for
}

TEST(ProcessingTimes, TheWindowStartsAgainAtEachReport) {
  ProcessingTimes times;
  for (int i = 0; i < 3; ++i) times.stop(times.start());
  EXPECT_EQ(times.takeWindow().count, 3u);
  EXPECT_EQ(times.takeWindow().count, 0u);  // nothing since
  times.stop(times.start());
  EXPECT_EQ(times.takeWindow().count, 1u);
  EXPECT_EQ(times.statistics().count, 4u);  // the summary keeps them all
}

// A sleep takes wall time but no CPU time; a busy loop takes both.
TEST(ProcessingTimes, CpuTimeLeavesOutTheWaits) {
  ProcessingTimes times(/*cpu_time=*/true);
  ProcessingTimes::Start start = times.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  times.stop(start);
  start = times.start();
  spin(30.0);
  times.stop(start);
  const TimeStatistics cpu = times.cpuStatistics();
  ASSERT_EQ(cpu.count, 2u);
  EXPECT_LT(cpu.min_ms, 10.0);                 // the sleep
  EXPECT_GE(cpu.max_ms, 30.0);                 // the busy loop
  EXPECT_GE(times.statistics().min_ms, 30.0);  // both took at least 30 ms of wall time
}

TEST(ProcessingTimes, KeepsAtMostMaxTimingsForTheSummary) {
  ProcessingTimes times;
  for (size_t i = 0; i < ProcessingTimes::kMaxTimings + 5; ++i) times.stop(times.start());
  EXPECT_EQ(times.statistics().count, ProcessingTimes::kMaxTimings);
  EXPECT_EQ(times.takeWindow().count, ProcessingTimes::kMaxTimings);
}
