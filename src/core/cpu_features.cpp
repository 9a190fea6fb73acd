#include "stereo_occupancy/cpu_features.h"

#include <atomic>

namespace stereo_occupancy {

namespace {

/// The CPU's answer, asked once (__builtin_cpu_init: also safe before main).
bool cpuRunsAvx2() {
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
  static const bool runs = [] {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") != 0;
  }();
  return runs;
#else
  return false;
#endif
}

std::atomic<bool> g_avx2_allowed{true};

}  // namespace

bool avx2Enabled() { return g_avx2_allowed.load(std::memory_order_relaxed) && cpuRunsAvx2(); }

void allowAvx2(bool allowed) { g_avx2_allowed.store(allowed, std::memory_order_relaxed); }

}  // namespace stereo_occupancy
