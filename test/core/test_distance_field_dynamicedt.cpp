// The distance field against OctoMap's companion library, dynamicEDT3D
// (DynamicEDTOctomap, Lau, Sprunk and Burgard's incremental transform), on
// the same maps. Built only where libdynamicedt3d-dev is installed.

#include <gtest/gtest.h>

#include <dynamicEDT3D/dynamicEDTOctomap.h>

#include <cmath>
#include <memory>
#include <random>
#include <sstream>

#include "distance_field_scene.h"
#include "stereo_occupancy/distance_field.h"

using namespace stereo_occupancy;

namespace {

/// A copy of @p tree (DynamicEDTOctomap wants a tree it may change).
std::unique_ptr<octomap::OcTree> copyOf(const octomap::OcTree& tree) {
  std::stringstream s;
  tree.write(s);
  std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(s));
  auto copy = std::unique_ptr<octomap::OcTree>(dynamic_cast<octomap::OcTree*>(read.release()));
  copy->setOccupancyThres(tree.getOccupancyThres());
  return copy;
}

struct Comparison {
  size_t compared = 0, equal = 0, saturated_both = 0, differ = 0;
  double max_difference_m = 0.0;
};

/// Every window cell at least @p margin cells inside the window: our
/// distance against DynamicEDTOctomap's. Where ours is below max_distance_m
/// theirs is the same distance (both are cell centre to cell centre, sqrt of
/// whole squared cells); where ours saturates theirs is at least as far (it
/// saturates at (floor(max / res) + 1) cells).
Comparison compare(const DistanceField& field, const DynamicEDTOctomap& edt, int margin) {
  Comparison c;
  const double res = field.resolution(), max_m = field.config().max_distance_m;
  const Eigen::AlignedBox3d box = field.window();
  const Eigen::Vector3i first = (box.min() / res).array().round().cast<int>();
  const Eigen::Vector3i size = ((box.max() - box.min()) / res).array().round().cast<int>();
  for (int z = margin; z < size.z() - margin; ++z)
    for (int y = margin; y < size.y() - margin; ++y)
      for (int x = margin; x < size.x() - margin; ++x) {
        const Eigen::Vector3d W_p = ((first + Eigen::Vector3i(x, y, z)).cast<double>().array() + 0.5) * res;
        const double ours = field.sample(W_p).distance_m;
        const double theirs = edt.getDistance(octomap::point3d(W_p.x(), W_p.y(), W_p.z()));
        ++c.compared;
        if (ours >= max_m - 1e-6 && theirs >= max_m - 1e-6) {
          ++c.saturated_both;
        } else if (std::abs(ours - theirs) <= 1e-5) {
          ++c.equal;
        } else {
          ++c.differ;
          c.max_difference_m = std::max(c.max_difference_m, std::abs(std::min(theirs, max_m) - ours));
        }
      }
  return c;
}

}  // namespace

// Random maps fused through the accumulator (as the field's own tests):
// DynamicEDTOctomap built on a copy of the map in the field's window, then
// updated incrementally with the same class changes as the field (set in the
// copy, whose change detection it reads). Where both define the distance
// (below max_distance_m) they agree: on every cell of these maps; the test
// lets 1% differ by at most 0.5 m, since its 3D propagation is not exact
// (Lau et al.), the field's transform is. With unknown_is_occupied only the
// cells farther than the reach from the window's faces compare: beyond its
// box DynamicEDTOctomap sees no obstacles, the field sees unknown = occupied.
// Its maxdist saturates at (floor(max / res) + 1) cells, the field at max.
TEST(DistanceFieldDynamicEDT, SameDistancesAsOctoMapsDistanceTransform) {
  for (bool uio : {false, true}) {
    DistanceFieldConfig config;
    config.window_xy_m = 12.0;  // 48 x 48 x 32 cells: 32 x 32 x 16 at least 8 from the faces
    config.window_z_m = 8.0;
    config.max_distance_m = 2.0;
    config.unknown_is_occupied = uio;
    FieldScene scene(config);
    std::mt19937 rng(11);
    const Eigen::Vector3d W_vehicle(0.1, 0.1, 0.1);
    const Eigen::Vector3i first(-30, -30, -20), size(60, 60, 40);
    // Fewer unknown cells when they are obstacles, for distances beyond a cell or two.
    ASSERT_TRUE(scene.integrate(randomUpdate(&rng, first, size, uio ? 0.001 : 0.3, 0.003), W_vehicle));
    const std::unique_ptr<octomap::OcTree> copy = copyOf(scene.map.tree());
    const double res = scene.field.resolution();
    const Eigen::AlignedBox3d box = scene.field.window();
    const octomap::point3d lo(box.min().x() + res / 2, box.min().y() + res / 2, box.min().z() + res / 2);
    const octomap::point3d hi(box.max().x() - res / 2, box.max().y() - res / 2, box.max().z() - res / 2);
    DynamicEDTOctomap edt(static_cast<float>(config.max_distance_m), copy.get(), lo, hi, uio);
    edt.update();
    const int margin = uio ? 8 : 0;
    Comparison c = compare(scene.field, edt, margin);
    EXPECT_GT(c.equal, c.compared / 4) << "uio " << uio;  // plenty of distances below the saturation
    EXPECT_LE(c.differ, c.compared / 100) << "uio " << uio << ": up to " << c.max_difference_m << " m";
    EXPECT_LE(c.max_difference_m, 0.5) << "uio " << uio;
    std::cout << "[ dynamicEDT3D ] unknown_is_occupied " << uio << ", from scratch: " << c.compared << " cells, "
              << c.equal << " equal, " << c.saturated_both << " saturated in both, " << c.differ << " differ (at most "
              << c.max_difference_m << " m)\n";
    // Incrementally: more updates; their class changes into the copy.
    for (int k = 0; k < 3; ++k) {
      const GridUpdate update =
          randomUpdate(&rng, first + Eigen::Vector3i(10 + 8 * k, 10, 8), Eigen::Vector3i(20, 20, 12), 0.2, 0.05);
      ASSERT_TRUE(scene.map.integrate(update));
      bool all = false;
      const std::vector<CellClassChange> changes = scene.map.takeClassChanges(&all);
      ASSERT_FALSE(all);
      scene.field.update(scene.map.tree(), changes, all, W_vehicle);
      const int offset = static_cast<int>(copy->coordToKey(0.0));
      for (const CellClassChange& change : changes)
        copy->setNodeValue(
            octomap::OcTreeKey(change.cell.x() + offset, change.cell.y() + offset, change.cell.z() + offset),
            change.now == CellClass::kOccupied ? 2.0f : -2.0f, /*lazy_eval=*/true);
      copy->updateInnerOccupancy();
      edt.update();
    }
    c = compare(scene.field, edt, margin);
    EXPECT_GT(c.equal, c.compared / 4) << "uio " << uio;
    EXPECT_LE(c.differ, c.compared / 100) << "uio " << uio << ": up to " << c.max_difference_m << " m";
    EXPECT_LE(c.max_difference_m, 0.5) << "uio " << uio;
    std::cout << "[ dynamicEDT3D ] unknown_is_occupied " << uio << ", incremental: " << c.compared << " cells, "
              << c.equal << " equal, " << c.saturated_both << " saturated in both, " << c.differ << " differ (at most "
              << c.max_difference_m << " m)\n";
  }
}
