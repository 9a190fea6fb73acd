#pragma once
/// @file
/// Test helpers for the distance field: maps built through the accumulator's
/// fusion (with its class change recording, the field's feed) and the
/// field's distances by brute force.

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "stereo_occupancy/distance_field.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/map_accumulator.h"

namespace stereo_occupancy {

/// A map fed to a field as the ROS glue does: integrate, take the changes, update.
struct FieldScene {
  FieldScene(const DistanceFieldConfig& field_config, int threads = 1)
      : map(mapConfig(threads)), field(field_config, 0.25) {
    map.recordClassChanges(true);
  }
  static MapAccumulatorConfig mapConfig(int threads) {
    MapAccumulatorConfig c;
    c.threads = threads;
    return c;
  }
  /// Integrates @p update and brings the field up to date around @p W_vehicle.
  bool integrate(const GridUpdate& update, const Eigen::Vector3d& W_vehicle) {
    if (!map.integrate(update)) return false;
    refresh(W_vehicle);
    return true;
  }
  void refresh(const Eigen::Vector3d& W_vehicle) {
    bool all = false;
    std::vector<CellBox> regions;
    const std::vector<CellClassChange> changes = map.takeClassChanges(&all, &regions);
    // As the ROS glue does: the map made current only where the field reads it.
    read_boxes.clear();
    field.update(
        [this](const CellBox& cells) -> const octomap::OcTree& {
          if (!cells.isEmpty()) read_boxes.push_back(cells);
          return map.leafTree(cells);
        },
        changes, regions, all, W_vehicle);
    map_reads += !read_boxes.empty();
  }
  size_t map_reads = 0;             ///< the updates that read cells of the map
  std::vector<CellBox> read_boxes;  ///< the boxes of cells the last update read
  MapAccumulator map;
  DistanceField field;
};

/// An update of the box [@p first, @p first + @p size) whose cells are each
/// left out with @p p_unknown, else +2 (a hit; occupied at once) with
/// @p p_occupied, else -2 (free at once, an occupied cell freed).
inline GridUpdate randomUpdate(std::mt19937* rng, const Eigen::Vector3i& first, const Eigen::Vector3i& size,
                               double p_unknown, double p_occupied) {
  LocalGrid grid;
  grid.reset(first, size, 0.25);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int z = 0; z < size.z(); ++z)
    for (int y = 0; y < size.y(); ++y)
      for (int x = 0; x < size.x(); ++x) {
        if (u(*rng) < p_unknown) continue;
        grid.at(x, y, z) = u(*rng) < p_occupied ? 2.0f : -2.0f;
      }
  GridUpdate update;
  encodeGridUpdate(grid, grid.cellCentre(size.x() / 2, size.y() / 2, size.z() / 2), &update);
  return update;
}

/// The class of the global cell @p g in @p tree (a coarse leaf's too).
inline CellClass classInTree(const octomap::OcTree& tree, const Eigen::Vector3i& g) {
  const int offset = static_cast<int>(tree.coordToKey(0.0));
  if (((g.array() + offset) < 0).any() || ((g.array() + offset) > 65535).any()) return CellClass::kUnknown;
  const octomap::OcTreeNode* node = tree.search(octomap::OcTreeKey(g.x() + offset, g.y() + offset, g.z() + offset));
  return node ? classOfLogOdds(node->getLogOdds(), tree.getOccupancyThresLog()) : CellClass::kUnknown;
}

/// The window's cells, their classes from @p tree and their squared distances
/// (cells) to the nearest obstacle by brute force: every cell within the
/// reach, those outside the window obstacles if unknown_is_occupied; capped
/// at the first saturated squared distance.
struct BruteForceField {
  BruteForceField(const DistanceField& field, const octomap::OcTree& tree) {
    const double res = field.resolution();
    const Eigen::AlignedBox3d box = field.window();
    first = (box.min() / res).array().round().cast<int>();
    size = ((box.max() - box.min()) / res).array().round().cast<int>();
    const double reach = field.config().max_distance_m / res;
    saturated_sq = static_cast<int>(std::ceil(reach * reach - 1e-9));
    const int d = static_cast<int>(std::floor(std::sqrt(saturated_sq - 1.0)));
    const bool uio = field.config().unknown_is_occupied;
    classes.resize(static_cast<size_t>(size.prod()));
    std::vector<char> obstacle(classes.size());
    for (int z = 0; z < size.z(); ++z)
      for (int y = 0; y < size.y(); ++y)
        for (int x = 0; x < size.x(); ++x) {
          const size_t i = index(Eigen::Vector3i(x, y, z));
          classes[i] = classInTree(tree, first + Eigen::Vector3i(x, y, z));
          obstacle[i] = classes[i] == CellClass::kOccupied || (uio && classes[i] == CellClass::kUnknown);
        }
    sq.assign(classes.size(), saturated_sq);
    for (int z = 0; z < size.z(); ++z)
      for (int y = 0; y < size.y(); ++y)
        for (int x = 0; x < size.x(); ++x) {
          int best = saturated_sq;
          for (int dz = -d; dz <= d; ++dz)
            for (int dy = -d; dy <= d; ++dy)
              for (int dx = -d; dx <= d; ++dx) {
                const int q = dx * dx + dy * dy + dz * dz;
                if (q >= best) continue;
                const Eigen::Vector3i n(x + dx, y + dy, z + dz);
                const bool in = (n.array() >= 0).all() && (n.array() < size.array()).all();
                if (in ? obstacle[index(n)] : uio) best = q;
              }
          sq[index(Eigen::Vector3i(x, y, z))] = best;
        }
  }
  size_t index(const Eigen::Vector3i& l) const {
    return static_cast<size_t>(l.x() + size.x() * (l.y() + size.y() * l.z()));
  }
  /// The field's distance of squared distance @p q, as DistanceSample gives it.
  float distance(int q, const DistanceField& field) const {
    return q >= saturated_sq ? static_cast<float>(field.config().max_distance_m)
                             : std::sqrt(static_cast<float>(q)) * static_cast<float>(field.resolution());
  }
  Eigen::Vector3d centre(const Eigen::Vector3i& l, double res) const {
    return ((first + l).cast<double>() + Eigen::Vector3d::Constant(0.5)) * res;
  }

  Eigen::Vector3i first, size;
  int saturated_sq = 0;
  std::vector<CellClass> classes;
  std::vector<int> sq;
};

}  // namespace stereo_occupancy
