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
  std::unordered_set<uint64_t> surface;  ///< cells holding a surface point seen within range
  std::unordered_set<uint64_t> empty;    ///< cells truly empty on the rays, at least 1.5 cells before the surface
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
  size_t occupied_cells = 0;             ///< occupied leaves of the map
  size_t occupied_at_surface = 0;        ///< ... within one cell of a solid (inside one counts)
  /// ... farther than one cell from a true surface with the centre in free
  /// air, outside every solid: phantom obstacles, which close a planner's corridors.
  size_t occupied_phantom = 0;
  size_t truth_surface_cells = 0;
  size_t surface_found = 0;              ///< truth surface cells with an occupied cell within one cell
  size_t surface_called_free = 0;        ///< truth surface cells the map calls free
  size_t truth_empty_cells = 0;
  size_t empty_known_free = 0;           ///< truly empty observed cells the map calls free
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

/// The cells (packCell keys) holding @p W_points at cells of @p resolution_m.
std::unordered_set<uint64_t> surfaceCells(const std::vector<Eigen::Vector3d>& W_points, double resolution_m);

/// Scores @p map against true surface cells alone (a real scene: no solids,
/// so no phantom count): an occupied cell is precise within one cell of a
/// surface cell; only the occupied cells whose centre @p counted accepts
/// (where the truth knows what is there) are scored. Occupied leaves larger
/// than one cell count as the cells they cover.
MapQuality evaluateAgainstSurface(const octomap::OcTree& map, const std::unordered_set<uint64_t>& surface,
                                  const std::function<bool(const Eigen::Vector3d&)>& counted);

}  // namespace stereo_occupancy
