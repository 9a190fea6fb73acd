#include "stereo_occupancy/disparity_drawer.h"

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "stereo_occupancy/surface_guards.h"

namespace stereo_occupancy {

namespace {

StereoCameraConfig checked(const StereoCameraConfig& camera, const DrawingConfig& config) {
  std::string why;
  if (!camera.isValid(&why)) throw std::invalid_argument("camera: " + why);
  if (!config.isValid(&why)) throw std::invalid_argument("drawing: " + why);
  return camera;
}

}  // namespace

const char* toString(DrawingAlgorithm algorithm) {
  switch (algorithm) {
    case DrawingAlgorithm::kLine:
      return "line";
    case DrawingAlgorithm::kLinePyramid:
      return "line_pyramid";
    case DrawingAlgorithm::kRayTrace:
      return "raytrace";
    case DrawingAlgorithm::kRayTracePyramid:
      return "raytrace_pyramid";
    case DrawingAlgorithm::kLinePyramidBounded:
      return "line_pyramid_bounded";
    case DrawingAlgorithm::kRayTracePyramidBounded:
      return "raytrace_pyramid_bounded";
  }
  return "?";
}

const std::vector<DrawingAlgorithm>& allDrawingAlgorithms() {
  static const std::vector<DrawingAlgorithm> all = {DrawingAlgorithm::kLine,
                                                    DrawingAlgorithm::kLinePyramid,
                                                    DrawingAlgorithm::kRayTrace,
                                                    DrawingAlgorithm::kRayTracePyramid,
                                                    DrawingAlgorithm::kLinePyramidBounded,
                                                    DrawingAlgorithm::kRayTracePyramidBounded};
  return all;
}

std::string drawingAlgorithmNames() {
  std::string names;
  for (DrawingAlgorithm a : allDrawingAlgorithms()) names += (names.empty() ? "" : ", ") + std::string(toString(a));
  return names;
}

bool parseDrawingAlgorithm(const std::string& name, DrawingAlgorithm* algorithm) {
  for (DrawingAlgorithm a : allDrawingAlgorithms()) {
    if (name == toString(a)) {
      *algorithm = a;
      return true;
    }
  }
  return false;
}

bool DrawingConfig::isValid(std::string* why) const {
  if (!sensor_model.isValid(why) || !blur.isValid(why) || !parametersInRange(*this, why)) return false;
  if (max_grid_cells < 1) {
    if (why) *why = "max_grid_cells must be >= 1";
    return false;
  }
  return true;
}

bool isValidPose(const Eigen::Isometry3d& T_W_C) {
  if (!T_W_C.matrix().allFinite()) return false;
  const Eigen::Matrix3d R = T_W_C.linear();
  return (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-6 && R.determinant() > 0.0;
}

DisparityDrawer::DisparityDrawer(const StereoCameraConfig& camera, const DrawingConfig& config)
    : camera_(checked(camera, config)),
      config_(config),
      model_(config.sensor_model),
      table_(model_, config.resolution_m),
      levels_(camera_, config.resolution_m),
      line_drawer_(camera_, table_, levels_, config.simd),
      ray_tracer_(camera_, table_, levels_),
      blur_(config.blur) {
  const unsigned threads = config_.threads == 0 ? WorkerPool::defaultThreads() : static_cast<unsigned>(config_.threads);
  if (threads > 1) {
    workers_ = std::make_unique<WorkerPool>(threads);
    line_drawer_.setWorkers(workers_.get());
    blur_.setWorkers(workers_.get());
  }
  line_drawer_.setSurfaceSpans(config_.surface_spans);
  const bool draws_pyramid_lines =
      config_.algorithm == DrawingAlgorithm::kLinePyramid || config_.algorithm == DrawingAlgorithm::kLinePyramidBounded;
  if (draws_pyramid_lines && levels_.minLevel() < PyramidLevelTable::kLowestLevel) {
    // Eq. 13 at the maximum range needs c >= 2^i·z/f; at i = kLowestLevel:
    const double finest_m =
        std::ldexp(camera_.config().max_range_m / camera_.config().focal_length_px, PyramidLevelTable::kLowestLevel);
    throw std::invalid_argument(
        "drawing: resolution_m = " + std::to_string(config_.resolution_m) +
        " is too fine for this camera at max_range_m = " + std::to_string(camera_.config().max_range_m) +
        ": it would draw 4^" + std::to_string(-levels_.minLevel()) + " lines per pixel (eq. 15, level " +
        std::to_string(levels_.minLevel()) + "); raise resolution_m to at least " + std::to_string(finest_m) +
        " m or lower max_range_m");
  }
  if (config_.algorithm == DrawingAlgorithm::kLinePyramidBounded ||
      config_.algorithm == DrawingAlgorithm::kRayTracePyramidBounded)
    bound_ = std::make_unique<DisparityBlockBound>(camera_, model_, config_.resolution_m);
}

void DisparityDrawer::checkInput(const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C) const {
  if (disparity.type() != CV_32FC1) throw std::invalid_argument("disparity image must be CV_32FC1");
  if (disparity.cols != camera_.config().width_px || disparity.rows != camera_.config().height_px)
    throw std::invalid_argument("disparity image size differs from the camera's");
  if (!isValidPose(T_W_C)) throw std::invalid_argument("camera pose is not finite or not a rotation");
}

namespace {
/// A cell count for a message: whole below 2^53, else in exponent form (a
/// conversion of 1e22 to an integer would be undefined).
std::string cellCount(double cells) {
  if (cells < 9007199254740992.0) return std::to_string(static_cast<uint64_t>(cells));
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", cells);
  return text;
}
}  // namespace

void DisparityDrawer::prepareGrid(const Eigen::Isometry3d& T_W_C, LocalGrid* grid) const {
  // One cell of padding keeps every line strictly inside the grid (the fast
  // path of LineDrawer::drawRay); the blur needs room for its kernels.
  const StageTimer timer(stage_times_, PathStage::kGridPreparation);
  const int padding = 1 + blur_.paddingCells(camera_.config().max_range_m, config_.resolution_m);
  const Eigen::AlignedBox3d box = frustumBoundingBox(camera_, T_W_C);
  // Global cell indices are ints (and OctoMap keys 16 bits): refuse poses
  // whose cells could not even be numbered.
  constexpr double kMaxCellIndex = 1e9;  // below 2^31, with room for the box and its padding
  if ((box.min().array().abs().max(box.max().array().abs()) / config_.resolution_m > kMaxCellIndex).any())
    throw std::invalid_argument("camera position too far from the world origin for this resolution");
  const Eigen::Array3d cells = (box.sizes() / config_.resolution_m).array() + 2.0 * padding + 2.0;
  if (!(cells.prod() <= static_cast<double>(config_.max_grid_cells)))
    throw std::invalid_argument("the frustum's grid would have " + cellCount(cells.prod()) +
                                " cells, more than max_grid_cells = " + std::to_string(config_.max_grid_cells));
  fitGridToBox(box, config_.resolution_m, padding, grid, workers_.get());
}

DrawStatistics DisparityDrawer::drawInto(const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C, LocalGrid* grid) {
  checkInput(disparity, T_W_C);
  DrawStatistics stats;
  buildPyramids(disparity);
  {
    const StageTimer timer(stage_times_, PathStage::kDrawing);
    switch (config_.algorithm) {
      case DrawingAlgorithm::kLine:
        line_drawer_.drawImage(disparity, T_W_C, grid, &stats);
        break;
      case DrawingAlgorithm::kLinePyramid:
        line_drawer_.drawPyramid(min_pyramid_, T_W_C, grid, &stats);
        break;
      case DrawingAlgorithm::kRayTrace:
        ray_tracer_.drawImage(max_pyramid_, T_W_C, grid, &stats);
        break;
      case DrawingAlgorithm::kRayTracePyramid:
        ray_tracer_.drawPyramid(max_pyramid_, T_W_C, grid, &stats);
        break;
      case DrawingAlgorithm::kLinePyramidBounded:
        line_drawer_.drawPyramidBounded(min_pyramid_, max_pyramid_, *bound_, T_W_C, grid, &stats);
        break;
      case DrawingAlgorithm::kRayTracePyramidBounded:
        ray_tracer_.drawPyramidBounded(min_pyramid_, max_pyramid_, *bound_, T_W_C, grid, &stats);
        break;
    }
  }
  if (config_.sensor_model.profile == SensorProfile::kSurface) {
    const StageTimer timer(stage_times_, PathStage::kGuards);
    // The lines flag where they put their hits, the surface profile's only occupied cells.
    const std::vector<uint8_t>& hit_blocks = line_drawer_.hitBlocks();
    SurfaceGuards guards;
    guards.sky_value = table_.skyLogOdds();
    guards.sky_radius = config_.sensor_model.sky_guard_cells;
    guards.free_value = table_.freeLogOdds();
    guards.gap_radius = config_.sensor_model.gap_guard_cells;
    guards.edge_radius = config_.sensor_model.edge_guard_cells;
    guards.grid_camera = T_W_C.translation() / grid->resolution() - grid->originIndex().cast<double>();
    applySurfaceGuards(grid, guards, workers_.get(),
                       drawsLines() && hit_blocks.size() == grid->numBlocks() ? hit_blocks.data() : nullptr);
  }
  if (config_.count_different_cells) stats.different_grid_cells = grid->countKnown();
  return stats;
}

void DisparityDrawer::buildPyramids(const cv::Mat& disparity) {
  const StageTimer timer(stage_times_, PathStage::kPyramids);
  switch (config_.algorithm) {
    case DrawingAlgorithm::kLine:
      break;  // the image as is
    case DrawingAlgorithm::kLinePyramid:
      min_pyramid_.build(disparity, camera_, PyramidType::kMinDisparity, levels_.topLevel(), workers_.get());
      break;
    case DrawingAlgorithm::kRayTrace:  // level 0: the image as is
      max_pyramid_.build(disparity, camera_, PyramidType::kMaxDisparity, 0, workers_.get());
      break;
    case DrawingAlgorithm::kRayTracePyramid:
      max_pyramid_.build(disparity, camera_, PyramidType::kMaxDisparity, levels_.topLevel(), workers_.get());
      break;
    case DrawingAlgorithm::kLinePyramidBounded:
    case DrawingAlgorithm::kRayTracePyramidBounded:
      DisparityPyramid::buildPyramids(disparity, camera_, levels_.topLevel(), &min_pyramid_, &max_pyramid_,
                                      workers_.get());
      break;
  }
}

void DisparityDrawer::blur(const Eigen::Isometry3d& T_W_C, LocalGrid* grid) {
  const StageTimer timer(stage_times_, PathStage::kBlur);
  blur_.apply(T_W_C.translation(), grid);
}

DrawStatistics DisparityDrawer::draw(const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C, LocalGrid* grid) {
  checkInput(disparity, T_W_C);
  prepareGrid(T_W_C, grid);
  const DrawStatistics stats = drawInto(disparity, T_W_C, grid);
  blur(T_W_C, grid);
  return stats;
}

}  // namespace stereo_occupancy
