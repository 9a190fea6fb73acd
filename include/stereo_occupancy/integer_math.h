#pragma once
/// @file
/// Rounding and exponents without libm calls, for the drawing loops (without
/// SSE4.1 or an FPU rounding instruction, std::floor, std::ceil, std::llround,
/// std::ldexp and std::ilogb are function calls). Exact: each returns what
/// its std:: counterpart returns within the stated domain.

#include <cstdint>
#include <cstring>

namespace stereo_occupancy {

/// std::floor(x) as an int, for |x| < 2^31.
inline int floorToInt(double x) {
  const int i = static_cast<int>(x);  // truncates towards zero
  return i - (x < static_cast<double>(i));
}

/// std::ceil(x) as an int, for |x| < 2^31.
inline int ceilToInt(double x) {
  const int i = static_cast<int>(x);
  return i + (x > static_cast<double>(i));
}

/// std::llround(x) (halves away from zero), for |x| < 2^52.
inline int64_t roundToInt64(double x) {
  const int64_t i = static_cast<int64_t>(x);           // truncates towards zero
  const double fraction = x - static_cast<double>(i);  // exact for |x| < 2^52
  return i + (fraction >= 0.5) - (fraction <= -0.5);
}

/// std::ilogb(x) = floor(log2(x)) for a positive, normal, finite x: its exponent.
inline int floorLog2(float x) {
  uint32_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  return static_cast<int>((bits >> 23) & 0xffu) - 127;
}

/// std::ilogb(x) = floor(log2(x)) for a positive, normal, finite x: its exponent.
inline int floorLog2(double x) {
  uint64_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  return static_cast<int>((bits >> 52) & 0x7ffu) - 1023;
}

/// 2^i for |i| < 63, exactly: the double whose exponent is i (no division).
inline double powerOfTwo(int i) {
  const uint64_t bits = static_cast<uint64_t>(i + 1023) << 52;
  double x;
  std::memcpy(&x, &bits, sizeof x);
  return x;
}

}  // namespace stereo_occupancy
