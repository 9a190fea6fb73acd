#pragma once
/// @file
/// Fusion of local grids into one global octomap::OcTree (additive log-odds
/// with clamping), bounded in extent, with atomic saving.

#include <octomap/OcTree.h>

#include <memory>
#include <string>
#include <vector>

#include "stereo_occupancy/grid_update.h"

namespace stereo_occupancy {

class AccumulatingOcTree;

/// Parameters of the global map.
struct MapAccumulatorConfig {
  double resolution_m = 0.25;        ///< cell edge; updates at another resolution are refused [m]
  double clamping_min_prob = 0.12;   ///< lower clamping bound of a cell (probability)
  double clamping_max_prob = 0.97;   ///< upper clamping bound of a cell (probability)
  double occupancy_threshold_prob = 0.5;  ///< cells above it are occupied (probability)
  /// Half edge of the cube around the latest sensor origin that the map keeps;
  /// cells outside it are dropped on prune(). 0 keeps everything [m].
  double max_extent_m = 500.0;

  bool isValid(std::string* why = nullptr) const;
};

/// The global map. Not thread-safe: callers serialise access.
class MapAccumulator {
 public:
  /// @throws std::invalid_argument if the config is not valid.
  explicit MapAccumulator(const MapAccumulatorConfig& config);
  ~MapAccumulator();

  const MapAccumulatorConfig& config() const { return config_; }
  /// The map, its inner nodes brought up to date first.
  const octomap::OcTree& tree() const;

  /// Adds every cell's log-odds to the map (octomap's clamped update).
  /// Returns false, leaving the map unchanged, if the update is inconsistent
  /// or of another resolution; @p why says why.
  bool integrate(const GridUpdate& update, std::string* why = nullptr);

  /// Drops the cells outside the cube of max_extent_m around the latest
  /// sensor origin; returns how many leaves were dropped.
  size_t prune();

  /// Empties the map.
  void reset();

  /// Number of updates integrated since the last reset.
  size_t updates() const { return updates_; }

  /// Writes <directory>/<base_name>.bt and .ot, each through a temporary file
  /// renamed into place, so a crash never leaves a half-written map.
  /// @return the two paths. @throws std::runtime_error.
  std::vector<std::string> save(const std::string& directory, const std::string& base_name) const;

 private:
  void applyThresholds();

  MapAccumulatorConfig config_;
  std::unique_ptr<AccumulatingOcTree> tree_;
  Eigen::Vector3d W_last_origin_ = Eigen::Vector3d::Zero();
  size_t updates_ = 0;
  mutable bool inner_stale_ = false;  ///< inner nodes lag the leaves until tree() is called
};

}  // namespace stereo_occupancy
