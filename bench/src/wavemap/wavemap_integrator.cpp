#include "stereo_occupancy/sim/wavemap_integrator.h"

#include <wavemap/core/map/map_factory.h>
#include <wavemap/core/utils/thread_pool.h>
#include <wavemap/pipeline/pipeline.h>

#include <stdexcept>
#include <string>
#include <utility>

namespace stereo_occupancy {

namespace {
constexpr char kIntegrator[] = "camera";

wavemap::param::Value number(double v) { return wavemap::param::Value(static_cast<wavemap::FloatingPoint>(v)); }
wavemap::param::Value meters(double v) { return wavemap::param::Value(wavemap::param::Map{{"meters", number(v)}}); }
wavemap::param::Value text(const char* v) { return wavemap::param::Value(std::string(v)); }

/// The projective integrator's parameters: wavemap's own example for a
/// 640x480 depth camera (examples/python/mapping/full_pipeline.py), with the
/// camera's intrinsics and our range limits.
wavemap::param::Value integratorParams(const StereoCameraConfig& camera) {
  using wavemap::param::Map;
  using wavemap::param::Value;
  Map projection{{"type", text("pinhole_camera_projector")},
                 {"width", Value(camera.width_px)},
                 {"height", Value(camera.height_px)},
                 {"fx", number(camera.focal_length_px)},
                 {"fy", number(camera.focal_length_px)},
                 {"cx", number(camera.cx_px)},
                 {"cy", number(camera.cy_px)}};
  Map measurement{{"type", text("continuous_ray")},
                  {"range_sigma", meters(0.01)},
                  {"scaling_free", number(0.2)},
                  {"scaling_occupied", number(0.4)}};
  Map method{{"type", text("hashed_chunked_wavelet_integrator")},
             {"min_range", meters(camera.min_range_m)},
             {"max_range", meters(camera.max_range_m)}};
  return Value(Map{{"projection_model", Value(projection)},
                   {"measurement_model", Value(measurement)},
                   {"integration_method", Value(method)}});
}
}  // namespace

struct WavemapIntegrator::Impl {
  StereoCameraConfig camera;
  std::shared_ptr<wavemap::MapBase> map;
  std::unique_ptr<wavemap::Pipeline> pipeline;
  wavemap::PosedImage<> image;
  explicit Impl(const StereoCameraConfig& c) : camera(c), image(wavemap::Transformation3D(), c.width_px, c.height_px) {}
};

WavemapIntegrator::WavemapIntegrator(const StereoCameraConfig& camera, double cell_m, int threads)
    : impl_(std::make_unique<Impl>(camera)) {
  using wavemap::param::Map;
  using wavemap::param::Value;
  impl_->map = wavemap::MapFactory::create(
      Value(Map{{"type", text("hashed_chunked_wavelet_octree")}, {"min_cell_width", meters(cell_m)}}));
  if (!impl_->map) throw std::runtime_error("wavemap: the map could not be made");
  impl_->pipeline = std::make_unique<wavemap::Pipeline>(
      impl_->map, std::make_shared<wavemap::ThreadPool>(static_cast<size_t>(threads)));
  if (!impl_->pipeline->addIntegrator(kIntegrator, integratorParams(camera)))
    throw std::runtime_error("wavemap: the integrator could not be made");
}

WavemapIntegrator::~WavemapIntegrator() = default;

void WavemapIntegrator::integrate(const cv::Mat& depth_m, const Eigen::Isometry3d& T_W_C) {
  // wavemap's images are indexed (column, row): the camera's (u, v).
  for (int v = 0; v < depth_m.rows; ++v)
    for (int u = 0; u < depth_m.cols; ++u) impl_->image.at({u, v}) = depth_m.at<float>(v, u);
  const Eigen::Matrix<wavemap::FloatingPoint, 4, 4> T = T_W_C.matrix().cast<wavemap::FloatingPoint>();
  impl_->image.setPose(wavemap::Transformation3D(T));
  impl_->pipeline->runIntegrators({kIntegrator}, impl_->image);
}

size_t WavemapIntegrator::memoryBytes() const { return impl_->map->getMemoryUsage(); }

}  // namespace stereo_occupancy
