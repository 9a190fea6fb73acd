#pragma once
/// @file
/// An incremental Euclidean distance field over a window around the vehicle,
/// for planners: distance to the nearest occupied cell (up to a maximum)
/// with its gradient, a flag for unknown space, path checks and ray casts.
/// Not in the paper. Fed by the accumulator's fusion (the cells whose class
/// each fused update changed, MapAccumulator::takeClassChanges()), never by a
/// second fusion of the same updates.

#include <octomap/OcTree.h>

#include <Eigen/Core>
#include <Eigen/Geometry>  // AlignedBox3d

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "stereo_occupancy/cell_class.h"  // CellClass, CellClassChange
#include "stereo_occupancy/parameter_table.h"

namespace stereo_occupancy {

/// Parameters of the distance field.
struct DistanceFieldConfig {
  bool enabled = true;               ///< maintain the field at all
  double window_xy_m = 50.0;         ///< window edge along x and y, centred on the vehicle [m]
  double window_z_m = 10.0;          ///< window edge along z [m]
  double max_distance_m = 2.0;       ///< distances saturate here; path checks take radii up to it [m]
  bool unknown_is_occupied = false;  ///< unknown cells are obstacles of the field (distances to them)

  /// The parameters (parameter_table.h): f(spec, member) for each.
  template <typename Self, typename F>
  static void forEachParameter(Self& c, F&& f) {
    f(textParameter("distance_field", "maintain the distance field around the vehicle (services, slice)"), c.enabled);
    f(numberParameter("distance_window_xy_m", "m", 1.0, 1000.0, "the field's window edge along x and y"),
      c.window_xy_m);
    f(numberParameter("distance_window_z_m", "m", 1.0, 1000.0, "the field's window edge along z"), c.window_z_m);
    f(numberParameter("max_distance_m", "m", 0.1, 20.0, "distances saturate here; the largest path-check radius"),
      c.max_distance_m);
    f(textParameter("unknown_is_occupied", "unknown cells count as obstacles of the field"), c.unknown_is_occupied);
  }
  /// The ranges of forEachParameter().
  bool isValid(std::string* why = nullptr) const { return parametersInRange(*this, why); }
};

/// One point's answer.
struct DistanceSample {
  bool in_window = false;  ///< false: outside the window; the rest says unknown
  CellClass cell_class = CellClass::kUnknown;
  /// Distance from the centre of the point's cell to the centre of the
  /// nearest obstacle cell, exact; max_distance_m if none is nearer [m].
  /// NaN outside the window.
  float distance_m = 0.0f;
  /// Central differences of distance_m over the neighbouring cells [m/m];
  /// zero where the distance saturates or outside the window.
  Eigen::Vector3f gradient = Eigen::Vector3f::Zero();
};

/// A path check's verdict.
enum class PathVerdict : uint8_t {
  kClear = 0,    ///< every cell along the path is known and at least the radius from any obstacle
  kBlocked = 1,  ///< a cell along it lies nearer than the radius to an obstacle (or is unknown, if asked)
  kUnknown = 2,  ///< not blocked, but it crosses unknown space or leaves the window
};

/// A path check's answer.
struct PathCheckResult {
  PathVerdict verdict = PathVerdict::kUnknown;
  /// Index of the first segment (waypoints i and i + 1) that is blocked, or
  /// that is unknown if none is blocked; -1 when clear.
  long first_segment = -1;
  Eigen::Vector3d W_point = Eigen::Vector3d::Zero();  ///< where that segment first is blocked / unknown [m]
  double min_clearance_m = 0.0;                       ///< smallest distance along the known part of the path [m]
};

/// A ray cast's verdict.
enum class RayVerdict : uint8_t {
  kHit = 0,      ///< an occupied cell within the range
  kFree = 1,     ///< known free up to the range
  kUnknown = 2,  ///< unknown space (or the window's edge) before any occupied cell
};

/// A ray cast's answer.
struct RayCastResult {
  RayVerdict verdict = RayVerdict::kUnknown;
  Eigen::Vector3d W_point = Eigen::Vector3d::Zero();  ///< centre of the occupied / first unknown cell [m]
  double range_m = 0.0;                               ///< distance along the ray to where it entered that cell [m]
};

/// The field. Not thread-safe: callers serialise updates and queries
/// (ros/distance_field_server.h shares one between the accumulator and
/// planners in the same process).
class DistanceField {
 public:
  /// Largest number of waypoints checkPath() takes.
  static constexpr size_t kMaxWaypoints = 100000;

  /// @throws std::invalid_argument if @p config is not valid or
  /// @p resolution_m is not positive.
  DistanceField(const DistanceFieldConfig& config, double resolution_m);

  const DistanceFieldConfig& config() const { return config_; }
  double resolution() const { return resolution_m_; }

  /// Brings the field up to date after a fused update: re-centres the window
  /// on @p W_vehicle (in whole blocks; the cells that enter are read from
  /// @p map), applies @p changes and recomputes the distances they can
  /// change. @p all: the map changed everywhere (load, reset, clear, prune):
  /// the window is read from @p map again. Work follows the changes.
  void update(const octomap::OcTree& map, const std::vector<CellClassChange>& changes, bool all,
              const Eigen::Vector3d& W_vehicle);

  /// The window's box in the map's frame [m].
  Eigen::AlignedBox3d window() const;

  /// The answer at @p W_point (metres, map frame); outside the window or at
  /// a NaN point, in_window is false and the point is unknown.
  DistanceSample sample(const Eigen::Vector3d& W_point) const;

  /// Checks the straight segments between @p W_waypoints for a body of
  /// radius @p radius_m: each cell the segments pass through must be known
  /// and at least radius_m from the nearest obstacle (cell centres).
  /// @throws std::invalid_argument for fewer than 1 or more than
  /// kMaxWaypoints waypoints, a NaN / infinite waypoint, a negative radius or
  /// one above max_distance_m.
  PathCheckResult checkPath(const std::vector<Eigen::Vector3d>& W_waypoints, double radius_m,
                            bool unknown_as_occupied) const;

  /// Walks from @p W_origin along @p W_direction (any length) up to
  /// @p max_range_m through the cells.
  /// @throws std::invalid_argument for a NaN / infinite input, a zero
  /// direction, or a negative range.
  RayCastResult castRay(const Eigen::Vector3d& W_origin, const Eigen::Vector3d& W_direction, double max_range_m) const;

  /// Cell centres and distances of the window's cells in the horizontal
  /// layer that holds height @p z_m (known cells only), for a slice.
  void slice(double z_m, std::vector<Eigen::Vector3f>* W_centres, std::vector<float>* distances_m) const;

  /// Cells whose distance the last update() recomputed (for the summary lines).
  size_t lastUpdatedCells() const { return last_updated_cells_; }

 private:
  DistanceFieldConfig config_;
  double resolution_m_;
  size_t last_updated_cells_ = 0;
};

}  // namespace stereo_occupancy
