// The maps and their messages (no roscore needed).

#include <gtest/gtest.h>
#include <ros/message_traits.h>
#include <ros/service_traits.h>

#include <array>
#include <cmath>
#include <set>

#include "stereo_occupancy/BoundingBoxQuery.h"
#include "stereo_occupancy/GetOctomap.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/sim/synthetic_scene.h"

using namespace stereo_occupancy;

TEST(Messages, OctomapIsWireCompatibleWithOctomapMsgs) {
  // octomap_msgs/Octomap's MD5 sum: octomap_rviz_plugins and octomap tools subscribe to ours.
  EXPECT_STREQ(ros::message_traits::MD5Sum<Octomap>::value(), "9a45536b45c5e409cd49f04bb2d9999f");
  EXPECT_STREQ(ros::message_traits::DataType<Octomap>::value(), "stereo_occupancy/Octomap");
}

TEST(Conversions, OccupancyUpdateRoundTrip) {
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(-5, 7, -2), Eigen::Vector3i(6, 5, 4), 0.25);
  grid.at(0, 0, 0) = -0.6f;
  grid.at(1, 0, 0) = 1.2f;
  grid.at(5, 4, 3) = 2.0f;
  grid.at(3, 2, 1) = 0.0f;  // known but zero: carries nothing
  GridUpdate update;
  encodeGridUpdate(grid, Eigen::Vector3d(1, 2, 3), &update);
  ASSERT_TRUE(update.isConsistent());
  EXPECT_EQ(update.run_start, (std::vector<uint32_t>{0, 119}));
  EXPECT_EQ(update.run_length, (std::vector<uint32_t>{2, 1}));
  OccupancyUpdate msg;
  std_msgs::Header header;
  header.frame_id = "map";
  const float* cells_before = update.log_odds.data();
  toMsg(std::move(update), header, &msg);
  EXPECT_EQ(msg.log_odds.data(), cells_before);  // moved into the message, not copied
  GridUpdateView back;
  std::string why;
  ASSERT_TRUE(viewOf(msg, &back, &why)) << why;
  EXPECT_EQ(back.log_odds.begin(), msg.log_odds.data());  // read in place
  ASSERT_TRUE(back.isConsistent(&why)) << why;
  std::vector<std::pair<Eigen::Vector3i, float>> cells;
  back.forEachCell([&](const Eigen::Vector3i& g, float v) { cells.emplace_back(g, v); });
  ASSERT_EQ(cells.size(), 3u);
  EXPECT_EQ(cells[0].first, Eigen::Vector3i(-5, 7, -2));
  EXPECT_FLOAT_EQ(cells[0].second, -0.6f);
  EXPECT_EQ(cells[1].first, Eigen::Vector3i(-4, 7, -2));
  EXPECT_EQ(cells[2].first, Eigen::Vector3i(0, 11, 1));
  EXPECT_FLOAT_EQ(cells[2].second, 2.0f);
  EXPECT_EQ(back.W_sensor_origin, Eigen::Vector3d(1, 2, 3));

  // Inconsistent messages are seen as such, with a reason.
  auto consistent = [&](const OccupancyUpdate& m) {
    GridUpdateView view;
    return viewOf(m, &view, &why) && view.isConsistent(&why);
  };
  OccupancyUpdate bad = msg;
  bad.log_odds.pop_back();
  EXPECT_FALSE(consistent(bad));
  bad = msg;
  bad.run_start[1] = 1000;  // beyond the grid
  EXPECT_FALSE(consistent(bad));
  bad = msg;
  bad.log_odds[0] = std::nanf("");
  EXPECT_FALSE(consistent(bad));
  bad = msg;
  bad.resolution = 0.0;
  EXPECT_FALSE(consistent(bad));
  bad = msg;
  bad.size[0] = 0x80000000u;  // not an int
  GridUpdateView view;
  EXPECT_FALSE(viewOf(bad, &view, &why));
}

TEST(Conversions, OctreeToMessageAndBack) {
  octomap::OcTree tree(0.25);
  tree.updateNode(octomap::point3d(1.1f, 2.2f, 0.3f), true);
  tree.updateNode(octomap::point3d(-3.0f, 0.2f, 1.0f), false);
  Octomap msg;
  std_msgs::Header header;
  toMsg(tree, true, header, &msg);
  EXPECT_TRUE(msg.binary);
  EXPECT_EQ(msg.id, "OcTree");
  EXPECT_DOUBLE_EQ(msg.resolution, 0.25);
  std::ostringstream written;
  tree.writeBinaryData(written);
  EXPECT_TRUE(std::string(msg.data.begin(), msg.data.end()) == written.str()) << "not the tree's bytes";
  toMsg(tree, true, header, &msg);  // a message used again holds the new data only
  EXPECT_EQ(msg.data.size(), written.str().size());
  const std::unique_ptr<octomap::OcTree> back_tree = treeFromMsg(msg);
  ASSERT_TRUE(back_tree);
  const octomap::OcTree& back = *back_tree;
  ASSERT_NE(back.search(1.1, 2.2, 0.3), nullptr);
  EXPECT_TRUE(back.isNodeOccupied(back.search(1.1, 2.2, 0.3)));
  EXPECT_FALSE(back.isNodeOccupied(back.search(-3.0, 0.2, 1.0)));
  // The full map keeps the log-odds: binary false, as octomap_server's octomap_full.
  Octomap full;
  toMsg(tree, false, header, &full);
  EXPECT_FALSE(full.binary);
  EXPECT_EQ(full.id, "OcTree");
  const std::unique_ptr<octomap::OcTree> full_back = treeFromMsg(full);
  ASSERT_TRUE(full_back);
  ASSERT_NE(full_back->search(1.1, 2.2, 0.3), nullptr);
  EXPECT_FLOAT_EQ(full_back->search(1.1, 2.2, 0.3)->getLogOdds(), tree.search(1.1, 2.2, 0.3)->getLogOdds());
  Octomap other = full;
  other.id = "ColorOcTree";  // not ours to read as an OcTree
  EXPECT_FALSE(treeFromMsg(other));
}

TEST(Messages, ServicesAreWireCompatibleWithOctomapMsgs) {
  // octomap_msgs' MD5 sums: octomap_server's clients call ours as they are.
  EXPECT_STREQ(ros::service_traits::MD5Sum<BoundingBoxQuery>::value(), "93aa3d73b866f04880927745f4aab303");
  EXPECT_STREQ(ros::service_traits::MD5Sum<GetOctomap>::value(), "be9d2869d24fe40d6bc21ac21f6bb2c5");
}

TEST(Conversions, ProjectedMapToOccupancyGrid) {
  ProjectedMap map;
  map.resolution_m = 0.5;
  map.origin_x_m = -2.0;
  map.origin_y_m = 3.5;
  map.width = 3;
  map.height = 2;
  map.cells = {ProjectedMap::kUnknown, ProjectedMap::kFree, ProjectedMap::kOccupied, 0, 0, 100};
  std_msgs::Header header;
  header.frame_id = "map";
  nav_msgs::OccupancyGrid msg;
  toMsg(map, header, &msg);
  EXPECT_EQ(msg.header.frame_id, "map");
  EXPECT_FLOAT_EQ(msg.info.resolution, 0.5f);
  EXPECT_EQ(msg.info.width, 3u);
  EXPECT_EQ(msg.info.height, 2u);
  EXPECT_DOUBLE_EQ(msg.info.origin.position.x, -2.0);
  EXPECT_DOUBLE_EQ(msg.info.origin.position.y, 3.5);
  EXPECT_DOUBLE_EQ(msg.info.origin.orientation.w, 1.0);
  EXPECT_EQ(msg.data, (std::vector<int8_t>{-1, 0, 100, 0, 0, 100}));
}

// A block's marker holds the block's occupied cells, a coarse leaf's cells
// inside the block included (a leaf larger than the block gives the block's
// part of it); an emptied block is a DELETE; the whole map starts with a
// DELETEALL.
TEST(Conversions, BlockMarkers) {
  octomap::OcTree tree(0.25);
  tree.updateNode(octomap::point3d(0.125f, 0.125f, 0.125f), true);   // global cell (0, 0, 0): block (0, 0, 0)
  tree.updateNode(octomap::point3d(0.375f, 0.125f, 0.125f), false);  // free: not drawn
  // Block (1, 0, 0): cells (16..17, 0..1, 0..1) occupied, pruned to one leaf of 2 cells a side.
  for (int i = 0; i < 8; ++i)
    tree.updateNode(
        octomap::point3d(4.125f + 0.25f * (i & 1), 0.125f + 0.25f * ((i >> 1) & 1), 0.125f + 0.25f * (i >> 2)), true);
  // Cells (32..63)^3 occupied, pruned to one leaf of 32 cells a side: blocks (2..3, 2..3, 2..3).
  for (int i = 0; i < 32 * 32 * 32; ++i)
    tree.updateNode(
        octomap::point3d(8.125f + 0.25f * (i % 32), 8.125f + 0.25f * ((i / 32) % 32), 8.125f + 0.25f * (i / 1024)),
        true);
  tree.prune();
  std::multiset<double> leaf_sides;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) leaf_sides.insert(it.getSize());
  ASSERT_EQ(leaf_sides, (std::multiset<double>{0.25, 0.25, 0.5, 8.0})) << "the coarse leaves were not built";
  std_msgs::Header header;
  header.frame_id = "map";
  visualization_msgs::MarkerArray markers;
  blockMarkers(tree,
               {Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(1, 0, 0), Eigen::Vector3i(3, 2, 2), Eigen::Vector3i(5, 5, 5)},
               true, header, &markers);
  ASSERT_EQ(markers.markers.size(), 5u);
  EXPECT_EQ(markers.markers[0].action, visualization_msgs::Marker::DELETEALL);
  // The centres of a marker's cubes, in cells (global index), and the colours' count.
  auto cellsOf = [](const visualization_msgs::Marker& m) {
    EXPECT_EQ(m.colors.size(), m.points.size()) << m.ns << " " << m.id;
    std::set<std::array<double, 3>> cells;
    for (const auto& p : m.points) cells.insert({p.x / 0.25 - 0.5, p.y / 0.25 - 0.5, p.z / 0.25 - 0.5});
    EXPECT_EQ(cells.size(), m.points.size()) << "a cell drawn twice in " << m.ns << " " << m.id;
    return cells;
  };
  const auto& single = markers.markers[1];
  EXPECT_EQ(single.action, visualization_msgs::Marker::ADD);
  EXPECT_EQ(single.ns, "occupied_cells_z0");
  EXPECT_DOUBLE_EQ(single.scale.x, 0.25);
  EXPECT_EQ(cellsOf(single), (std::set<std::array<double, 3>>{{0, 0, 0}}));
  // The 2-cell leaf: its eight cells.
  const auto& coarse = markers.markers[2];
  EXPECT_EQ(coarse.action, visualization_msgs::Marker::ADD);
  EXPECT_EQ(coarse.ns, "occupied_cells_z0");
  EXPECT_NE(coarse.id, single.id);
  std::set<std::array<double, 3>> eight;
  for (int i = 0; i < 8; ++i)
    eight.insert({16.0 + (i & 1), static_cast<double>((i >> 1) & 1), static_cast<double>(i >> 2)});
  EXPECT_EQ(cellsOf(coarse), eight);
  // The 32-cell leaf: the 16^3 cells of block (3, 2, 2) that it covers, and no others.
  const auto& part = markers.markers[3];
  EXPECT_EQ(part.action, visualization_msgs::Marker::ADD);
  EXPECT_EQ(part.ns, "occupied_cells_z2");
  const auto drawn = cellsOf(part);  // distinct cells: 16^3 of them inside the block are all of it
  EXPECT_EQ(drawn.size(), 16u * 16u * 16u);
  size_t inside = 0;
  for (const auto& c : drawn)
    inside += c[0] >= 48 && c[0] <= 63 && c[1] >= 32 && c[1] <= 47 && c[2] >= 32 && c[2] <= 47 &&
              c[0] == std::floor(c[0]) && c[1] == std::floor(c[1]) && c[2] == std::floor(c[2]);
  EXPECT_EQ(inside, drawn.size());
  EXPECT_EQ(markers.markers[4].action, visualization_msgs::Marker::DELETE);  // a block without occupied cells
  EXPECT_TRUE(markers.markers[4].points.empty());
}

// A block's free leaves by size: a fine free cell in its own marker, a leaf
// larger than the block as the whole block; the occupied cell is not drawn;
// an emptied block is a DELETE per size, the whole map starts with a
// DELETEALL and leaves the empty sizes out.
TEST(Conversions, FreeBlockMarkers) {
  octomap::OcTree tree(0.25);
  tree.updateNode(octomap::point3d(0.125f, 0.125f, 0.125f), false);  // global cell (0, 0, 0): block (0, 0, 0)
  tree.updateNode(octomap::point3d(0.375f, 0.125f, 0.125f), true);   // occupied: not drawn
  for (float x = 8.125f; x < 16.0f; x += 0.25f)  // block (2, 0, 0) and (3, 0, 0) all free: pruned to one leaf
    for (float y = 0.125f; y < 8.0f; y += 0.25f)
      for (float z = 0.125f; z < 8.0f; z += 0.25f) tree.updateNode(octomap::point3d(x, y, z), false);
  tree.prune();
  std_msgs::Header header;
  header.frame_id = "map";
  visualization_msgs::MarkerArray markers;
  freeBlockMarkers(tree, {Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(2, 0, 0), Eigen::Vector3i(5, 5, 5)}, false, header,
                   &markers);
  ASSERT_EQ(markers.markers.size(), 15u);  // 3 blocks, 5 sizes
  const auto& fine = markers.markers[0];
  EXPECT_EQ(fine.ns, "free_cells_z0_s1");
  EXPECT_EQ(fine.action, visualization_msgs::Marker::ADD);
  ASSERT_EQ(fine.points.size(), 1u);
  EXPECT_DOUBLE_EQ(fine.points[0].x, 0.125);
  EXPECT_DOUBLE_EQ(fine.scale.x, 0.25);
  const auto& whole = markers.markers[9];  // block (2, 0, 0), side 16
  EXPECT_EQ(whole.ns, "free_cells_z0_s16");
  ASSERT_EQ(whole.points.size(), 1u);
  EXPECT_DOUBLE_EQ(whole.points[0].x, 10.0);  // the block's centre
  EXPECT_DOUBLE_EQ(whole.scale.x, 4.0);
  for (int s = 10; s < 15; ++s) EXPECT_EQ(markers.markers[s].action, visualization_msgs::Marker::DELETE);
  // Next to a pruned 8-cell leaf at the end of block (2, 0, 0), blocks
  // (1, 0, 0) and (3, 0, 0) hold nothing (octomap 1.9's box iterator also
  // hands out a coarse leaf that ends just before the box).
  octomap::OcTree beside(0.25);
  for (int i = 0; i < 512; ++i)
    beside.updateNode(
        octomap::point3d(10.125f + 0.25f * (i % 8), 0.125f + 0.25f * ((i / 8) % 8), 0.125f + 0.25f * (i / 64)), false);
  beside.prune();
  ASSERT_EQ(beside.getNumLeafNodes(), 1u);
  for (const auto& b : {Eigen::Vector3i(1, 0, 0), Eigen::Vector3i(3, 0, 0)}) {
    freeBlockMarkers(beside, {b}, false, header, &markers);
    ASSERT_EQ(markers.markers.size(), 5u);
    for (const auto& m : markers.markers) EXPECT_EQ(m.action, visualization_msgs::Marker::DELETE) << m.ns;
  }
  freeBlockMarkers(tree, {Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(5, 5, 5)}, true, header, &markers);
  ASSERT_EQ(markers.markers.size(), 2u);
  EXPECT_EQ(markers.markers[0].action, visualization_msgs::Marker::DELETEALL);
  EXPECT_EQ(markers.markers[1].ns, "free_cells_z0_s1");
}
