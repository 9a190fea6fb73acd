#include "stereo_occupancy/ros/processing_times.h"

#include <time.h>

#include <algorithm>

namespace stereo_occupancy {

namespace {

/// CPU time of the calling thread [ms].
double threadCpuMs() {
  timespec t{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return 1e3 * static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_nsec);
}

}  // namespace

ProcessingTimes::Start ProcessingTimes::start() const {
  Start start;
  start.wall = std::chrono::steady_clock::now();
  if (cpu_time_) start.cpu_ms = threadCpuMs();
  return start;
}

void ProcessingTimes::stop(const Start& start) {
  last_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start.wall).count();
  max_ms_ = std::max(max_ms_, last_ms_);
  if (wall_ms_.size() < kMaxTimings) {
    wall_ms_.push_back(last_ms_);
    if (cpu_time_) cpu_ms_.push_back(threadCpuMs() - start.cpu_ms);
  }
  if (window_ms_.size() < kMaxTimings) window_ms_.push_back(last_ms_);
}

TimeStatistics ProcessingTimes::takeWindow() {
  const TimeStatistics window = TimeStatistics::of(window_ms_);
  window_ms_.clear();
  return window;
}

}  // namespace stereo_occupancy
