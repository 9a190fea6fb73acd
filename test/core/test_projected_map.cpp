// The map projected onto the ground plane (projected_map.h).

#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include "stereo_occupancy/projected_map.h"

using namespace stereo_occupancy;

// Columns: occupied where a cell in the band is, free where only free cells
// are, unknown elsewhere; cells outside the band do not count; a coarse
// (pruned) leaf fills every column it covers.
TEST(ProjectedMap, ColumnsInTheBand) {
  octomap::OcTree tree(0.5);
  tree.updateNode(octomap::point3d(1.25f, 0.25f, 1.25f), true);   // occupied, in the band
  tree.updateNode(octomap::point3d(0.25f, 0.25f, 1.25f), false);  // free, in the band
  tree.updateNode(octomap::point3d(0.25f, 0.25f, 0.75f), true);   // occupied under a free cell, in the band
  tree.updateNode(octomap::point3d(2.25f, 0.25f, 9.25f), true);   // occupied, above the band
  tree.updateNode(octomap::point3d(2.25f, 1.25f, 1.25f), false);  // free, in the band
  const ProjectedMap map = projectOccupancy(tree, 0.5, 2.0);
  EXPECT_DOUBLE_EQ(map.resolution_m, 0.5);
  EXPECT_DOUBLE_EQ(map.origin_x_m, 0.0);
  EXPECT_DOUBLE_EQ(map.origin_y_m, 0.0);
  ASSERT_EQ(map.width, 5);                           // x in [0, 2.5)
  ASSERT_EQ(map.height, 3);                          // y in [0, 1.5)
  EXPECT_EQ(map.at(0, 0), ProjectedMap::kOccupied);  // occupied wins over the free cell above it
  EXPECT_EQ(map.at(2, 0), ProjectedMap::kOccupied);
  EXPECT_EQ(map.at(4, 0), ProjectedMap::kUnknown);  // only a cell above the band
  EXPECT_EQ(map.at(4, 2), ProjectedMap::kFree);
  EXPECT_EQ(map.at(1, 1), ProjectedMap::kUnknown);

  octomap::OcTree coarse(0.5);
  for (float x = 0.25f; x < 2.0f; x += 0.5f)
    for (float y = 0.25f; y < 2.0f; y += 0.5f)
      for (float z = 0.25f; z < 2.0f; z += 0.5f) coarse.updateNode(octomap::point3d(x, y, z), false);
  coarse.updateInnerOccupancy();
  coarse.prune();
  ASSERT_EQ(coarse.getNumLeafNodes(), 1u);  // one 2 m leaf
  const ProjectedMap floor = projectOccupancy(coarse, 0.0, 1.0);
  ASSERT_EQ(floor.width, 4);
  ASSERT_EQ(floor.height, 4);
  for (int8_t cell : floor.cells) EXPECT_EQ(cell, ProjectedMap::kFree);
  EXPECT_TRUE(projectOccupancy(coarse, 5.0, 6.0).cells.empty());
}
