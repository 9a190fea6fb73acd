#pragma once
/// @file
/// Scoring a map against a simulated flight's ground truth.

#include <octomap/OcTree.h>

#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <unordered_set>
#include <vector>

#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/sim/flight_simulation.h"

namespace stereo_occupancy {

/// The cells a flight really observed, from its exact images.
struct ObservedGroundTruth {
  double resolution_m = 0.0;
  std::unordered_set<uint64_t> surface;     ///< cells holding a surface point seen within range
  std::unordered_set<uint64_t> empty;       ///< cells truly empty on the rays, at least 1.5 cells before the surface
  std::vector<Eigen::Vector3d> viewpoints;  ///< camera centres of the observed frames [m]
};

/// The cells a score counts: those whose distance to the nearest viewpoint
/// (the range at which the flight saw them best) lies in [min_m, max_m).
struct RangeBand {
  double min_m = 0.0;
  double max_m = std::numeric_limits<double>::infinity();
  /// "0-10 m", "20+ m".
  std::string name() const;
};

/// The bands of issue 16: 0-10, 10-20 and 20+ m (the range ends at 25 m).
std::vector<RangeBand> standardRangeBands();

/// Packs a global cell index (each component within ±2^20) into one key.
inline uint64_t packCell(const Eigen::Vector3i& g) {
  constexpr int64_t kOffset = 1 << 20;
  return (static_cast<uint64_t>(g.x() + kOffset) << 42) | (static_cast<uint64_t>(g.y() + kOffset) << 21) |
         static_cast<uint64_t>(g.z() + kOffset);
}
inline Eigen::Vector3i unpackCell(uint64_t k) {
  constexpr int64_t kOffset = 1 << 20;
  constexpr uint64_t kMask = (1u << 21) - 1;
  return Eigen::Vector3i(static_cast<int>(static_cast<int64_t>(k >> 42) - kOffset),
                         static_cast<int>(static_cast<int64_t>((k >> 21) & kMask) - kOffset),
                         static_cast<int>(static_cast<int64_t>(k & kMask) - kOffset));
}

/// Casts the exact rays of every @p frame_step-th frame through every
/// @p pixel_step-th pixel (in x and y) and collects the observed cells; the
/// surface cells through every @p surface_pixel_step-th pixel instead if it
/// is > 0 (1 finds objects thinner than @p pixel_step pixels, such as wires).
ObservedGroundTruth observeGroundTruth(const FlightScenario& scenario, double resolution_m, double max_range_m,
                                       int frame_step = 1, int pixel_step = 4, int surface_pixel_step = 0);

/// Map quality against the truth.
struct MapQuality {
  size_t occupied_cells = 0;       ///< occupied leaves of the map
  size_t occupied_at_surface = 0;  ///< ... within one cell of a solid (inside one counts)
  /// ... farther than one cell from a true surface with the centre in free
  /// air, outside every solid: phantom obstacles, which close a planner's corridors.
  size_t occupied_phantom = 0;
  size_t truth_surface_cells = 0;
  size_t surface_found = 0;        ///< truth surface cells with an occupied cell within one cell
  size_t surface_called_free = 0;  ///< truth surface cells the map calls free
  size_t truth_empty_cells = 0;
  size_t empty_known_free = 0;  ///< truly empty observed cells the map calls free
  double occupiedPrecision() const { return occupied_cells ? double(occupied_at_surface) / occupied_cells : 0.0; }
  double occupiedRecall() const { return truth_surface_cells ? double(surface_found) / truth_surface_cells : 0.0; }
  double surfaceCalledFree() const {
    return truth_surface_cells ? double(surface_called_free) / truth_surface_cells : 0.0;
  }
  double freeCoverage() const { return truth_empty_cells ? double(empty_known_free) / truth_empty_cells : 0.0; }
  /// Share of the occupied cells that are phantom obstacles.
  double phantomShare() const { return occupied_cells ? double(occupied_phantom) / occupied_cells : 0.0; }
  /// Harmonic mean of occupied precision and recall.
  double f1() const {
    const double p = occupiedPrecision(), r = occupiedRecall();
    return p + r > 0.0 ? 2.0 * p * r / (p + r) : 0.0;
  }
  /// One JSON object with the counts and the ratios.
  std::string toJson() const;
};

/// The cells holding the surface points that frame @p frame's exact image
/// sees through every pixel within @p max_range_m, each once.
std::vector<Eigen::Vector3i> frameSurfaceCells(const FlightScenario& scenario, size_t frame, double resolution_m,
                                               double max_range_m);

/// How many of @p cells (global indices) one frame's local grid calls free:
/// known and below zero log-odds.
size_t countCalledFree(const LocalGrid& grid, const std::vector<Eigen::Vector3i>& cells);

/// Scores @p map (occupied: above its occupancy threshold) against the scene
/// and the observed truth, counting the cells within @p band only.
MapQuality evaluateMap(const octomap::OcTree& map, const SyntheticScene& scene, const ObservedGroundTruth& truth,
                       const RangeBand& band = RangeBand());

/// Where each obstacle of a flight (each box of its scene; the ground is
/// none) shows in a map: its zone is the cells holding its surface points
/// that the flight's exact images saw within range, and their 26 neighbours
/// (the recall's one-cell tolerance), less every cell holding a surface
/// point of another box or of the ground (so that the ground at a post's
/// foot or a post at a wire's end does not count for it).
struct ObstacleZones {
  double resolution_m = 0.0;
  std::vector<std::vector<uint64_t>> zones;  ///< per box: packCell keys; empty if the flight never saw it in range
  /// Boxes with a non-empty zone.
  size_t observedCount() const;
};

/// The zones of @p scenario's boxes from every @p pixel_step-th pixel (in x
/// and y) of every @p frame_step-th frame.
ObstacleZones observeObstacles(const FlightScenario& scenario, double resolution_m, double max_range_m,
                               int frame_step = 1, int pixel_step = 1);

/// When an obstacle first showed in a map fused frame by frame.
struct Detection {
  long frame = -1;  ///< the frame after whose fusion it first showed; -1: never
  double distance_m = std::numeric_limits<double>::quiet_NaN();  ///< camera centre to the box then [m]
  bool detected() const { return frame >= 0; }
};

/// Follows a map as frames are fused into it and records, per observed
/// obstacle, the first frame after which an occupied cell lies in its zone
/// (checking only the obstacles not yet detected), and the distance from the
/// camera centre to the obstacle's box at that frame: how far ahead a
/// planner sees it. Keeps references to the zones and the scene.
class DetectionTracker {
 public:
  DetectionTracker(const ObstacleZones& zones, const SyntheticScene& scene);
  /// Call after fusing frame @p frame, taken from W_camera, into @p map.
  void update(const octomap::OcTree& map, long frame, const Eigen::Vector3d& W_camera);
  /// Per box; never detected for a box with an empty zone.
  const std::vector<Detection>& detections() const { return detections_; }

 private:
  const ObstacleZones& zones_;
  const SyntheticScene& scene_;
  std::vector<Detection> detections_;
  std::vector<size_t> pending_;  ///< observed boxes not detected yet
};

/// A method's detections summed up, against a reference's (OctoMap's).
struct DetectionSummary {
  size_t observed = 0;                                                  ///< obstacles with a zone
  size_t detected = 0;                                                  ///< ... that showed in the map
  double median_distance_m = std::numeric_limits<double>::quiet_NaN();  ///< over the detected ones
  double min_distance_m = std::numeric_limits<double>::quiet_NaN();
  /// Obstacles the reference detected and this method more than
  /// frame_tolerance frames later or never; and the other way round.
  size_t later_than_reference = 0;
  size_t earlier_than_reference = 0;
};

/// Sums up @p mine over the boxes with a zone in @p zones, comparing each
/// with @p reference's detection of the same box (none: no comparison).
DetectionSummary summarizeDetections(const ObstacleZones& zones, const std::vector<Detection>& mine,
                                     const std::vector<Detection>* reference, long frame_tolerance = 1);

/// The cells (packCell keys) holding @p W_points at cells of @p resolution_m.
std::unordered_set<uint64_t> surfaceCells(const std::vector<Eigen::Vector3d>& W_points, double resolution_m);

/// octomap_server's input from one disparity image (CV_32FC1) of @p camera
/// at T_W_C: the point of each pixel with a valid disparity above zero, in
/// the world frame (zero, the sky, has no point). What the comparisons with
/// OctoMap's insertPointCloud insert.
octomap::Pointcloud worldPointCloud(const cv::Mat& disparity, const StereoCameraModel& camera,
                                    const Eigen::Isometry3d& T_W_C);

/// Scores @p map against true surface cells alone (a real scene: no solids,
/// so no phantom count): an occupied cell is precise within one cell of a
/// surface cell; only the occupied cells whose centre @p counted accepts
/// (where the truth knows what is there) are scored. Occupied leaves larger
/// than one cell count as the cells they cover.
MapQuality evaluateAgainstSurface(const octomap::OcTree& map, const std::unordered_set<uint64_t>& surface,
                                  const std::function<bool(const Eigen::Vector3d&)>& counted);

}  // namespace stereo_occupancy
