// libFuzzer target over the core's entry point: random image bytes, camera,
// pose and grid parameters through DisparityDrawer::draw, encodeGridUpdate and
// MapAccumulator::integrate. Invalid configurations must be refused with
// std::invalid_argument; everything else must run without a crash, a
// sanitizer report, or a non-finite value in the output.

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/map_accumulator.h"

namespace so = stereo_occupancy;

namespace {

/// Reads the input front to back; past its end, zeros.
class Reader {
 public:
  Reader(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  uint8_t byte() { return pos_ < size_ ? data_[pos_++] : 0; }
  float rawFloat() {
    float f = 0.0f;
    uint8_t b[4] = {byte(), byte(), byte(), byte()};
    std::memcpy(&f, b, 4);
    return f;
  }
  /// A value in [lo, hi], or (1 in 16) a raw float, which may be anything.
  double ranged(double lo, double hi) {
    const uint8_t mode = byte();
    if ((mode & 15) == 0) return rawFloat();
    return lo + (hi - lo) * (byte() | (byte() << 8)) / 65535.0;
  }
  size_t left() const { return pos_ < size_ ? size_ - pos_ : 0; }
  const uint8_t* rest() const { return data_ + pos_; }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Reader in(data, size);
  so::StereoCameraConfig camera;
  camera.width_px = 1 + in.byte() % 80;
  camera.height_px = 1 + in.byte() % 60;
  camera.focal_length_px = in.ranged(1.0, 200.0);
  camera.cx_px = in.ranged(-20.0, 100.0);
  camera.cy_px = in.ranged(-20.0, 80.0);
  camera.baseline_m = in.ranged(0.01, 1.0);
  camera.delta_d_px = in.ranged(0.01, 2.0);
  camera.min_range_m = in.ranged(0.1, 2.0);
  camera.max_range_m = in.ranged(1.0, 8.0);
  camera.min_disparity_px = in.ranged(0.0, 5.0);
  camera.max_disparity_px = in.ranged(5.0, 300.0);

  so::DrawingConfig drawing;
  drawing.algorithm = so::allDrawingAlgorithms()[in.byte() % so::allDrawingAlgorithms().size()];
  drawing.resolution_m = in.ranged(0.2, 2.0);
  drawing.sensor_model.k_m = in.ranged(0.01, 1.0);
  drawing.sensor_model.p_min = in.ranged(0.05, 0.49);
  drawing.sensor_model.p_max = in.ranged(0.51, 0.99);
  if (in.byte() & 1) {  // the mapper's surface profile
    drawing.sensor_model.profile = so::SensorProfile::kSurface;
    drawing.sensor_model.p_free = in.ranged(0.05, 0.45);
    drawing.sensor_model.p_sky = in.ranged(drawing.sensor_model.p_free, 0.5);
    drawing.sensor_model.free_gap_sigmas = in.ranged(0.0, 4.0);
    // From a value already read, so that the corpus keeps its meaning (that
    // value may be NaN: no conversion of it to int).
    const double gap = drawing.sensor_model.free_gap_sigmas;
    drawing.sensor_model.sky_guard_cells =
        std::isfinite(gap) ? static_cast<int>(std::fmod(std::fabs(gap) * 7.0, 3.0)) : 1;
  } else {
    drawing.sensor_model.tail_sigmas = in.ranged(0.0, 3.0);
  }
  if (in.byte() & 1) {
    drawing.blur.sigma_trans_m = in.ranged(0.0, 0.5);
    drawing.blur.sigma_angle_rad = in.ranged(0.0, 0.05);
  }
  drawing.max_grid_cells = 150000;  // keep each run fast

  Eigen::Quaterniond q(in.ranged(-1, 1), in.ranged(-1, 1), in.ranged(-1, 1), in.ranged(-1, 1));
  if (in.byte() & 1) q.normalize();  // sometimes a valid rotation, sometimes not
  Eigen::Isometry3d T_W_C = Eigen::Isometry3d::Identity();
  T_W_C.linear() = q.toRotationMatrix();
  T_W_C.translation() = Eigen::Vector3d(in.ranged(-1e3, 1e3), in.ranged(-1e3, 1e3), in.ranged(-1e3, 1e3));

  cv::Mat disparity(camera.height_px, camera.width_px, CV_32FC1, cv::Scalar(0.0f));
  const size_t n = std::min(disparity.total(), in.left() / 4);
  std::memcpy(disparity.data, in.rest(), n * 4);  // raw bytes: NaN, inf, negative, huge, tiny, ...

  std::unique_ptr<so::DisparityDrawer> drawer;
  try {
    drawer = std::make_unique<so::DisparityDrawer>(camera, drawing);
  } catch (const std::invalid_argument&) {
    return 0;  // refused configuration
  }
  so::LocalGrid grid;
  try {
    drawer->draw(disparity, T_W_C, &grid);
  } catch (const std::invalid_argument&) {
    return 0;  // refused pose, image or grid size
  }
  for (size_t i = 0; i < grid.numCells(); ++i) {
    const float v = grid.data()[i];
    if (v != so::LocalGrid::kUnknown && !std::isfinite(v)) std::abort();  // a NaN or inf reached the grid
  }
  so::GridUpdate update;
  so::encodeGridUpdate(grid, T_W_C.translation(), &update);
  if (!update.isConsistent()) std::abort();
  if (update.numCells() > 20000) return 0;  // OctoMap's updateNode is the slow part; enough is covered below
  so::MapAccumulatorConfig map_config;
  map_config.resolution_m = drawing.resolution_m;
  so::MapAccumulator map(map_config);
  // Every drawn update is fused, but one whose box leaves the OcTree's key
  // range (a camera thousands of kilometres out), which is refused whole.
  std::string why;
  if (!map.integrate(update, &why) && why.find("key range") == std::string::npos) std::abort();
  return 0;
}
