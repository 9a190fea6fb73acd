// Draws the Table I frame N times (grid preparation and drawing, no blur)
// with one algorithm and one free-run instruction set, for counting the
// guest instructions a frame takes under qemu-user
// (bench/scripts/aarch64_instructions.sh): the difference between N and 0 frames
// is N frames' drawing, without the scene's set-up.
//   draw_frames line_pyramid|default scalar|neon|sse2 N
#include <cstdio>
#include <cstdlib>
#include <string>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/sim/synthetic_scene.h"

namespace so = stereo_occupancy;

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: draw_frames line_pyramid|default scalar|neon|sse2 FRAMES\n");
    return 2;
  }
  const std::string algorithm = argv[1], simd = argv[2];
  so::DrawingConfig config;
  if (algorithm == "default") {
    config = so::DrawingConfig::mapperDefaults();
  } else if (!so::parseDrawingAlgorithm(algorithm, &config.algorithm)) {
    std::fprintf(stderr, "unknown algorithm %s\n", argv[1]);
    return 2;
  }
  if (simd == "scalar")
    config.simd = so::SimdLevel::kScalar;
  else if (simd == "neon")
    config.simd = so::SimdLevel::kNeon;
  else if (simd == "sse2")
    config.simd = so::SimdLevel::kSse2;
  else {
    std::fprintf(stderr, "unknown instruction set %s\n", argv[2]);
    return 2;
  }
  if (!so::isAvailable(config.simd)) {
    std::fprintf(stderr, "%s is not available on this target\n", argv[2]);
    return 2;
  }
  config.threads = 1;
  const int frames = std::atoi(argv[3]);
  so::DisparityDrawer drawer(so::StereoCameraConfig(), config);
  Eigen::Isometry3d T_W_C;
  const cv::Mat image = so::table1Image(drawer.camera(), &T_W_C);
  so::LocalGrid grid;
  uint64_t cells = 0;
  for (int i = 0; i < frames; ++i) {  // the drawing alone, as performance's stages: no blur
    drawer.prepareGrid(T_W_C, &grid);
    cells += drawer.drawInto(image, T_W_C, &grid).grid_cells_drawn;
  }
  std::printf("%s %s: %d frames, %llu cells drawn\n", argv[1], argv[2], frames, static_cast<unsigned long long>(cells));
  return 0;
}
