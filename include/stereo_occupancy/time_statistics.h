#pragma once
/// @file
/// Order statistics of processing times, as the nodelets' shutdown summaries
/// and the benchmarks print them.

#include <algorithm>
#include <cstddef>
#include <numeric>
#include <vector>

namespace stereo_occupancy {

/// Mean, median, 99th percentile and extremes of a set of times [ms].
struct TimeStatistics {
  size_t count = 0;
  double mean_ms = 0.0;
  double median_ms = 0.0;  ///< element n/2 of the sorted times (the upper median)
  double p99_ms = 0.0;     ///< element min(n-1, floor(0.99·n)) of the sorted times (nearest rank)
  double min_ms = 0.0;
  double max_ms = 0.0;

  /// Of @p ms in any order; every field 0 when it is empty.
  static TimeStatistics of(std::vector<double> ms) {
    TimeStatistics t;
    if (ms.empty()) return t;
    std::sort(ms.begin(), ms.end());
    const size_t n = ms.size();
    t.count = n;
    t.mean_ms = std::accumulate(ms.begin(), ms.end(), 0.0) / static_cast<double>(n);
    t.median_ms = ms[n / 2];
    t.p99_ms = ms[std::min(n - 1, n * 99 / 100)];
    t.min_ms = ms.front();
    t.max_ms = ms.back();
    return t;
  }
};

}  // namespace stereo_occupancy
