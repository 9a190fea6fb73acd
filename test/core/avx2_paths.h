#pragma once
/// @file
/// Tests that run the core's AVX2 paths and the others (allowAvx2()).

#include "stereo_occupancy/cpu_features.h"

namespace stereo_occupancy {

/// Allows the AVX2 paths again when the test's scope ends, also after a
/// failed ASSERT, so that the tests after it run them.
struct AllowAvx2AtEnd {
  AllowAvx2AtEnd() = default;
  AllowAvx2AtEnd(const AllowAvx2AtEnd&) = delete;
  AllowAvx2AtEnd& operator=(const AllowAvx2AtEnd&) = delete;
  ~AllowAvx2AtEnd() { allowAvx2(true); }
};

}  // namespace stereo_occupancy
