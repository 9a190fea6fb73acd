#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <cstdio>
#include <memory>

#include "stereo_occupancy/octomap_io.h"
#include "stereo_occupancy/sim/local_grid_octree.h"

using namespace stereo_occupancy;

namespace {
std::string tempPath(const std::string& name) { return ::testing::TempDir() + "stereo_occupancy_" + name; }
}  // namespace

TEST(LocalGridOctree, LocalGridLogOddsSurviveTheOtFile) {
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(-10, 4, 0), Eigen::Vector3i(5, 5, 5), 0.25);
  grid.at(1, 2, 3) = 1.5f;
  grid.at(4, 4, 4) = -0.62f;
  grid.at(0, 0, 0) = 0.0f;  // known but zero: nothing to store
  const auto tree = localGridToOcTree(grid);
  EXPECT_EQ(tree->getNumLeafNodes(), 2u);
  const std::string path = tempPath("grid.ot");
  writeOcTree(*tree, path);
  std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(path));
  auto* back = dynamic_cast<octomap::OcTree*>(read.get());
  ASSERT_NE(back, nullptr);
  const Eigen::Vector3d occ = grid.cellCentre(1, 2, 3), fr = grid.cellCentre(4, 4, 4);
  const octomap::OcTreeNode* n1 = back->search(occ.x(), occ.y(), occ.z());
  const octomap::OcTreeNode* n2 = back->search(fr.x(), fr.y(), fr.z());
  ASSERT_NE(n1, nullptr);
  ASSERT_NE(n2, nullptr);
  EXPECT_FLOAT_EQ(n1->getLogOdds(), 1.5f);
  EXPECT_FLOAT_EQ(n2->getLogOdds(), -0.62f);
  std::remove(path.c_str());
  EXPECT_THROW(writeOcTree(*tree, tempPath("grid.txt")), std::runtime_error);
}
