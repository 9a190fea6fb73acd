#pragma once
/// @file
/// The core's entry point: draws one disparity image into a local grid with
/// one of the paper's four algorithms, then blurs it.

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <memory>
#include <string>
#include <vector>

#include "stereo_occupancy/disparity_pyramid.h"
#include "stereo_occupancy/draw_statistics.h"
#include "stereo_occupancy/grid_blur.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/inverse_sensor_model.h"
#include "stereo_occupancy/line_drawing.h"
#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/ray_tracing.h"
#include "stereo_occupancy/stage_times.h"
#include "stereo_occupancy/stereo_camera_model.h"
#include "stereo_occupancy/worker_pool.h"

namespace stereo_occupancy {

/// The paper's four ways of drawing a disparity image (sections V and VI)
/// and the two bounded pyramidal variants (beyond the paper).
enum class DrawingAlgorithm {
  kLine,                    ///< "line": V-A, one line per valid pixel
  kLinePyramid,             ///< "line_pyramid": VI-B, min-disparity pyramid
  kRayTrace,                ///< "raytrace": V-B, one projection per cell
  kRayTracePyramid,         ///< "raytrace_pyramid": VI-C, max-disparity pyramid
  kLinePyramidBounded,      ///< "line_pyramid_bounded": VI-B, descending where a block mixes depths
  kRayTracePyramidBounded,  ///< "raytrace_pyramid_bounded": VI-C over the cell's footprint, likewise
};

/// Every algorithm, the paper's four first.
const std::vector<DrawingAlgorithm>& allDrawingAlgorithms();
/// Name of an algorithm as used by parameters and the command line.
const char* toString(DrawingAlgorithm algorithm);
/// The names of all algorithms, comma-separated (for messages).
std::string drawingAlgorithmNames();
/// Parses a name given by toString().
bool parseDrawingAlgorithm(const std::string& name, DrawingAlgorithm* algorithm);

/// Everything about drawing that is not the camera.
struct DrawingConfig {
  /// The bounded pyramid by default: it never loses a near obstacle in a far
  /// block (docs/quality.md); kLinePyramid is the paper's, and faster.
  DrawingAlgorithm algorithm = DrawingAlgorithm::kLinePyramidBounded;
  double resolution_m = 0.25;  ///< c, grid cell size [m]
  InverseSensorModelConfig sensor_model;
  BlurConfig blur;
  /// Largest local grid drawn into (a frustum box of more cells is refused,
  /// so that a fine resolution with a long range cannot exhaust memory).
  size_t max_grid_cells = 64u << 20;  // 256 MiB of log-odds
  /// Fill DrawStatistics::different_grid_cells (Table I's "different grid
  /// cells"): one more pass over the grid per image (docs/performance.md) for the
  /// default frustum. For the benchmarks; the mapper does not read it.
  bool count_different_cells = false;
  /// The line drawing's free-run instruction set: every level draws the same
  /// cells and values (tested); lower ones for tests and benchmarks.
  SimdLevel simd = availableSimdLevel();
  /// The bounded line drawing's spans (LineDrawer::setSurfaceSpans()): one
  /// free line for a block of oblique surface instead of a line per
  /// sub-block (its pixels' hits as always). Off: for tests and benchmarks.
  bool surface_spans = true;
  /// Threads that work on one image: the grid's reset, the pyramids, the
  /// line algorithms' lines and sky guard, and the blur; 0: the machine's
  /// cores, at most WorkerPool::kMaxDefaultThreads. The grid is the same bit
  /// for bit for any number (tested).
  int threads = 0;

  /// The parameters (parameter_table.h): f(spec, member) for each, the
  /// sensor model's and the blur's included.
  template <typename Self, typename F>
  static void forEachParameter(Self& c, F&& f) {
    f(textParameter("algorithm", "drawing algorithm (section V, VI; bounded: beyond the paper)"), c.algorithm);
    f(numberParameter("resolution_m", "m", 0.01, 10.0, "grid cell edge c"), c.resolution_m);
    f(numberParameter("threads", "", 0.0, 64.0,
                      "threads of one image's drawing and blur (0: the machine's cores, at most 4)"),
      c.threads);
    InverseSensorModelConfig::forEachParameter(c.sensor_model, f);
    BlurConfig::forEachParameter(c.blur, f);
  }

  /// The ranges of forEachParameter(), and max_grid_cells >= 1.
  bool isValid(std::string* why = nullptr) const;

  /// What the mapper draws by default: these defaults with the surface
  /// profile (docs/quality.md); the paper's Gaussian stays the sensor
  /// model's own default, for Table I and the reference tests.
  static DrawingConfig mapperDefaults() {
    DrawingConfig d;
    d.sensor_model.profile = SensorProfile::kSurface;
    return d;
  }
};

/// True if T_W_C is finite with an orthonormal, right-handed rotation.
bool isValidPose(const Eigen::Isometry3d& T_W_C);

/// Draws disparity images of one camera set-up. Builds the lookup tables once;
/// reuses its buffers between images. Not thread-safe: one per thread.
class DisparityDrawer {
 public:
  /// @throws std::invalid_argument if a config is not valid.
  DisparityDrawer(const StereoCameraConfig& camera, const DrawingConfig& config);
  /// Neither copied nor moved: its line drawer and ray tracer refer to its
  /// own camera and table (a moved drawer crashed).
  DisparityDrawer(const DisparityDrawer&) = delete;
  DisparityDrawer& operator=(const DisparityDrawer&) = delete;

  const StereoCameraModel& camera() const { return camera_; }
  const DrawingConfig& config() const { return config_; }
  const LogOddsTable& logOddsTable() const { return table_; }
  const PyramidLevelTable& levelTable() const { return levels_; }

  /// prepareGrid() + drawInto() + blur(): the whole path for one image.
  /// @param disparity CV_32FC1, of the camera's size [px]; NaN or negative:
  ///        invalid, 0: infinitely far.
  /// @param T_W_C pose of the optical frame C in the world W.
  /// @throws std::invalid_argument for a wrong image type or size, or a bad pose.
  DrawStatistics draw(const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C, LocalGrid* grid);

  /// Shapes @p grid to the frustum's bounding box (padded for the blur) and
  /// clears it, on the drawer's workers (so, like the drawing, on one
  /// thread at a time).
  /// @throws std::invalid_argument if the box has more than max_grid_cells cells.
  void prepareGrid(const Eigen::Isometry3d& T_W_C, LocalGrid* grid) const;

  /// Draws into a grid that prepareGrid() shaped for the same pose.
  DrawStatistics drawInto(const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C, LocalGrid* grid);

  /// Eq. 17 blur around the camera centre; a no-op when the blur is off.
  void blur(const Eigen::Isometry3d& T_W_C, LocalGrid* grid);

  /// encodeGridUpdate() of a grid this drawer drew, on the drawer's workers
  /// (the same update for any number of them).
  void encode(const LocalGrid& grid, const Eigen::Vector3d& W_sensor_origin, GridUpdate* update) const {
    encodeGridUpdate(grid, W_sensor_origin, update, workers_.get());
  }

  /// The pyramid built for the last pyramidal drawing (for inspection and
  /// tests): the min pyramid for line drawing, the max pyramid for ray tracing.
  const DisparityPyramid& pyramid() const { return drawsLines() ? min_pyramid_ : max_pyramid_; }

  /// From now on adds each stage's time (grid preparation, pyramids,
  /// drawing, guards, blur) to @p times; null: no timing (the default).
  void setStageTimes(StageTimes* times) { stage_times_ = times; }

 private:
  void checkInput(const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C) const;
  /// The pyramids the algorithm draws from (none for kLine).
  void buildPyramids(const cv::Mat& disparity);

  StereoCameraModel camera_;
  DrawingConfig config_;
  InverseSensorModel model_;
  LogOddsTable table_;
  PyramidLevelTable levels_;
  LineDrawer line_drawer_;
  RayTracer ray_tracer_;
  std::unique_ptr<DisparityBlockBound> bound_;  ///< only for the bounded variants
  bool drawsLines() const {
    return config_.algorithm == DrawingAlgorithm::kLine || config_.algorithm == DrawingAlgorithm::kLinePyramid ||
           config_.algorithm == DrawingAlgorithm::kLinePyramidBounded;
  }

  DisparityPyramid min_pyramid_;  ///< for line drawing (eq. 14) and both bounded variants
  DisparityPyramid max_pyramid_;  ///< for ray tracing (section VI-C) and both bounded variants
  DistanceDependentBlur blur_;
  std::unique_ptr<WorkerPool> workers_;  ///< the line drawing's and the blur's; none for one thread
  StageTimes* stage_times_ = nullptr;    ///< setStageTimes()
};

}  // namespace stereo_occupancy
