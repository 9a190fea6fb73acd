#pragma once
/// @file
/// Whether the core uses its AVX2 code paths (the encoding's masks, the
/// pyramids' first pass). They give the same results as the SSE2, NEON and
/// scalar ones; the switch lets the tests run both on one machine.

namespace stereo_occupancy {

/// True if the CPU runs AVX2 (x86-64 with GCC, asked once) and allowAvx2(false)
/// has not been called: the core's AVX2 paths are taken.
bool avx2Enabled();

/// Allows (the default) or forbids the core's AVX2 paths for the whole
/// process, for tests and benchmarks. Safe to call from any thread; calls
/// that are drawing or encoding at the time may take either path.
void allowAvx2(bool allowed);

}  // namespace stereo_occupancy
