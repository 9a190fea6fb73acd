#pragma once
/// @file
/// The nodelets' timing bookkeeping: how long each unit of work (an image, an
/// update) took, for the diagnostics and the summary line at shutdown.

#include <chrono>
#include <cstddef>
#include <vector>

#include "stereo_occupancy/time_statistics.h"

namespace stereo_occupancy {

/// Times of a nodelet's units of work [ms]: the last and the longest, each
/// one for the summary at shutdown (the first kMaxTimings), and those since
/// the diagnostics' last report. Wall time on the steady clock; with
/// @p cpu_time also the CPU time of the thread that did the work: the work
/// without the waits for a core that other threads and processes hold.
/// Not thread-safe: the nodelet's lock guards it with the rest of its state.
class ProcessingTimes {
 public:
  /// Times kept for the summary at shutdown (at 30 Hz, nine hours); as many
  /// again for one diagnostics window.
  static constexpr size_t kMaxTimings = 1000000;

  /// When one unit of work started, on the thread that does it.
  struct Start {
    std::chrono::steady_clock::time_point wall;
    double cpu_ms = 0.0;  ///< the thread's CPU time then (with cpu_time) [ms]
  };

  /// @param cpu_time also time each unit in its thread's CPU time (cpuStatistics()).
  explicit ProcessingTimes(bool cpu_time = false) : cpu_time_(cpu_time) {}

  /// Now, for stop() on the same thread when the work is done.
  Start start() const;
  /// Records the unit of work begun at @p start as done now.
  void stop(const Start& start);

  /// No unit recorded yet.
  bool empty() const { return wall_ms_.empty(); }
  /// The last unit's wall time [ms]; 0 before the first.
  double lastMs() const { return last_ms_; }
  /// The longest wall time so far [ms].
  double maxMs() const { return max_ms_; }
  /// Of every wall time kept (the first kMaxTimings).
  TimeStatistics statistics() const { return TimeStatistics::of(wall_ms_); }
  /// Of the same units' CPU times (all 0 without cpu_time).
  TimeStatistics cpuStatistics() const { return TimeStatistics::of(cpu_ms_); }
  /// Of the wall times since the last call (the last diagnostics report); starts the next window.
  TimeStatistics takeWindow();

 private:
  bool cpu_time_;
  double last_ms_ = 0.0, max_ms_ = 0.0;
  std::vector<double> wall_ms_, cpu_ms_;  ///< per unit, for the summary at shutdown (bounded)
  std::vector<double> window_ms_;         ///< per unit since the last report (bounded)
};

}  // namespace stereo_occupancy
