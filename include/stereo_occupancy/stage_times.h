#pragma once
/// @file
/// Where the whole path's time goes, image in to map fused: the time of
/// each stage, summed over the frames timed (docs/performance.md). Filled
/// only when a caller hands a StageTimes to the drawer and the pipeline;
/// without one nothing reads the clock.

#include <array>
#include <chrono>
#include <cstddef>

namespace stereo_occupancy {

/// The stages of the path, in their order.
enum class PathStage : int {
  kInput,            ///< the message's checks, the image's view (cv_bridge) and the pose (tf2)
  kGridPreparation,  ///< shaping the frustum's box and setting it unknown
  kPyramids,         ///< the min / max disparity pyramids
  kDrawing,          ///< lines, pixel hits or ray tracing into the grid
  kGuards,           ///< the surface profile's guards
  kBlur,             ///< eq. 17
  kEncoding,         ///< the grid's known cells into runs (GridUpdate)
  kMessage,          ///< the runs into an OccupancyUpdate message
  kFusion,           ///< the update into the OcTree (checks, view, MapAccumulator::integrate)
  kMaintenance,      ///< pruning and the mission's tiles every prune_period_s; compress_map's merge steps
  kCount,
};

/// Number of stages.
constexpr size_t kPathStages = static_cast<size_t>(PathStage::kCount);

/// The stage's name as tables print it.
inline const char* toString(PathStage stage) {
  static constexpr const char* kNames[kPathStages] = {"input (checks, image view, pose)",
                                                      "grid preparation",
                                                      "pyramids",
                                                      "drawing",
                                                      "guards",
                                                      "blur",
                                                      "encoding",
                                                      "message",
                                                      "fusion",
                                                      "maintenance"};
  const auto i = static_cast<size_t>(stage);
  return i < kPathStages ? kNames[i] : "?";
}

/// Time spent in each stage [ms], summed over what was timed.
struct StageTimes {
  std::array<double, kPathStages> ms{};

  double& operator[](PathStage stage) { return ms[static_cast<size_t>(stage)]; }
  double operator[](PathStage stage) const { return ms[static_cast<size_t>(stage)]; }
  /// The stages' sum [ms].
  double total() const {
    double sum = 0.0;
    for (double t : ms) sum += t;
    return sum;
  }
};

/// Adds the time between its construction and its destruction to one stage
/// of @p times; does nothing (not even read the clock) if @p times is null.
class StageTimer {
 public:
  StageTimer(StageTimes* times, PathStage stage) : times_(times), stage_(stage) {
    if (times_) start_ = std::chrono::steady_clock::now();
  }
  ~StageTimer() { stop(); }
  /// Adds the time so far now; the timer then adds nothing more.
  void stop() {
    if (times_)
      (*times_)[stage_] += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_).count();
    times_ = nullptr;
  }
  StageTimer(const StageTimer&) = delete;
  StageTimer& operator=(const StageTimer&) = delete;

 private:
  StageTimes* times_;
  PathStage stage_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace stereo_occupancy
