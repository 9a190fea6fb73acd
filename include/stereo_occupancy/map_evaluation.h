#pragma once
/// @file
/// Scoring a map against a simulated flight's ground truth.

#include <octomap/OcTree.h>

#include <cstdint>
#include <string>
#include <unordered_set>

#include "stereo_occupancy/flight_simulation.h"
#include "stereo_occupancy/local_grid.h"

namespace stereo_occupancy {

/// The cells a flight really observed, from its exact images.
struct ObservedGroundTruth {
  double resolution_m = 0.0;
  std::unordered_set<uint64_t> surface;  ///< cells holding a surface point seen within range
  std::unordered_set<uint64_t> empty;    ///< cells truly empty on the rays, at least 1.5 cells before the surface
};

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
  size_t occupied_at_surface = 0;        ///< ... within one cell of a true surface
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
  /// One JSON object with the counts and the four ratios.
  std::string toJson() const;
};

/// The cells holding the surface points that frame @p frame's exact image
/// sees through every pixel within @p max_range_m, each once.
std::vector<Eigen::Vector3i> frameSurfaceCells(const FlightScenario& scenario, size_t frame, double resolution_m,
                                               double max_range_m);

/// How many of @p cells (global indices) one frame's local grid calls free:
/// known and below zero log-odds.
size_t countCalledFree(const LocalGrid& grid, const std::vector<Eigen::Vector3i>& cells);

/// Scores @p map (occupied: above its occupancy threshold) against the scene and the observed truth.
MapQuality evaluateMap(const octomap::OcTree& map, const SyntheticScene& scene, const ObservedGroundTruth& truth);

}  // namespace stereo_occupancy
