// MapSaver in a real roscore: the whole mission from its database, the live
// map alone (under another name) when the database could not be opened,
// ~save_map's answers, the periodic checkpoints and the shutdown save.

#include <gtest/gtest.h>
#include <octomap/OcTree.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cell_update.h"
#include "stereo_occupancy/ros/map_saver.h"
#include "stereo_occupancy/ros/mapping_pipeline.h"
#include "wait_for.h"

using namespace stereo_occupancy;

namespace {

bool exists(const std::string& path) {
  struct stat s {};
  return ::stat(path.c_str(), &s) == 0;
}

/// True if the map file at @p path (.bt or .ot) holds the cell of global index @p cell (0.25 m) as occupied.
bool holdsCell(const std::string& path, const Eigen::Vector3i& cell) {
  std::unique_ptr<octomap::OcTree> tree;
  if (path.size() > 3 && path.compare(path.size() - 3, 3, ".bt") == 0) {
    tree = std::make_unique<octomap::OcTree>(0.25);
    if (!tree->readBinary(path)) return false;
  } else {
    tree.reset(dynamic_cast<octomap::OcTree*>(octomap::AbstractOcTree::read(path)));
    if (!tree) return false;
  }
  const Eigen::Vector3d p = (cell.cast<double>().array() + 0.5) * 0.25;
  const octomap::OcTreeNode* n = tree->search(p.x(), p.y(), p.z());
  return n && tree->isNodeOccupied(n);
}

/// A map, its lock and a saver writing to a new directory under the test's temporary one.
class MapSaverTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "map_saver_" + ::testing::UnitTest::GetInstance()->current_test_info()->name() + "_" +
           std::to_string(::getpid());
    config_.save_dir = dir_;
    config_.map_name = "flight";
  }

  std::unique_ptr<MapSaver> saver(MapFusion* fusion) {
    return std::make_unique<MapSaver>(
        config_, MapAccumulatorConfig(), fusion, &fusion_mutex_,
        [this](const std::string& problem) { problems_.push_back(problem); }, "map_saver_test");
  }

  void fuse(MapFusion* fusion, const Eigen::Vector3i& cell, double stamp_s) {
    std::lock_guard<std::mutex> lock(fusion_mutex_);
    std::string why;
    ASSERT_TRUE(fusion->fuse(cellUpdate({cell}, 2.0f, stamp_s), &why)) << why;
  }

  std::string dir_;
  MapSaverConfig config_;
  std::mutex fusion_mutex_;
  std::vector<std::string> problems_;  ///< what the saver noted, under fusion_mutex_
  MapFusion fusion_{OctomapAccumulatorParameters()};
};

const Eigen::Vector3i kCell(4, 0, 2);

}  // namespace

TEST_F(MapSaverTest, TheWholeMissionFromItsDatabase) {
  auto saving = saver(&fusion_);
  saving->openDatabase();
  EXPECT_TRUE(saving->databaseProblem().empty()) << saving->databaseProblem();
  ASSERT_TRUE(fusion_.mission().store());
  EXPECT_TRUE(exists(dir_ + "/flight.db"));
  fuse(&fusion_, kCell, 1.0);
  std::unique_lock<std::mutex> lock(fusion_mutex_);
  const std::vector<std::string> paths = saving->save(lock);
  ASSERT_TRUE(lock.owns_lock());  // let go while the files were written, held again
  ASSERT_EQ(paths, (std::vector<std::string>{dir_ + "/flight.bt", dir_ + "/flight.ot"}));
  EXPECT_TRUE(holdsCell(paths[0], kCell));
  EXPECT_TRUE(holdsCell(paths[1], kCell));
  EXPECT_FALSE(saving->lastSaveFailed());
}

// A second accumulator on the same database (locked by the first) maps
// without one: its saves write the live map under <map_name>_live_only and
// fail, never over the mission's files.
TEST_F(MapSaverTest, WithoutItsDatabaseOnlyTheLiveMapUnderAnotherName) {
  auto first = saver(&fusion_);
  first->openDatabase();
  ASSERT_TRUE(first->databaseProblem().empty()) << first->databaseProblem();
  MapFusion second_map{OctomapAccumulatorParameters()};
  auto second = saver(&second_map);
  second->openDatabase();
  EXPECT_FALSE(second->databaseProblem().empty());
  EXPECT_FALSE(second_map.mission().store());
  fuse(&second_map, kCell, 1.0);
  std::unique_lock<std::mutex> lock(fusion_mutex_);
  try {
    second->save(lock);
    ADD_FAILURE() << "a save without the database succeeded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("flight.bt and .ot stay as they were"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(holdsCell(dir_ + "/flight_live_only.bt", kCell));
  EXPECT_FALSE(exists(dir_ + "/flight.bt"));
}

TEST_F(MapSaverTest, SaveMapAnswersWithTheFilesOrWhy) {
  ros::NodeHandle nh("/answers"), private_nh("/answers/saver");
  auto saving = saver(&fusion_);
  saving->openDatabase();
  saving->advertise(nh, private_nh);
  fuse(&fusion_, kCell, 1.0);
  std_srvs::Trigger trigger;
  ASSERT_TRUE(ros::service::waitForService("/answers/saver/save_map", ros::Duration(10.0)));
  ASSERT_TRUE(ros::service::call("/answers/saver/save_map", trigger));
  EXPECT_TRUE(trigger.response.success) << trigger.response.message;
  EXPECT_EQ(trigger.response.message, dir_ + "/flight.bt " + dir_ + "/flight.ot");

  // No save_dir: nothing to do, said.
  config_.save_dir = "";
  MapFusion nowhere_map{OctomapAccumulatorParameters()};
  auto nowhere = saver(&nowhere_map);
  ros::NodeHandle nowhere_nh("/nowhere/saver");
  nowhere->advertise(nowhere_nh, nowhere_nh);
  ASSERT_TRUE(ros::service::waitForService("/nowhere/saver/save_map", ros::Duration(10.0)));
  ASSERT_TRUE(ros::service::call("/nowhere/saver/save_map", trigger));
  EXPECT_FALSE(trigger.response.success);
  EXPECT_EQ(trigger.response.message, "save_dir is not set");

  // A save_dir that cannot be made (under a file): false, counted, noted.
  std::ofstream(dir_ + "/a_file") << "x";
  config_.save_dir = dir_ + "/a_file/maps";
  MapFusion failing_map{OctomapAccumulatorParameters()};
  auto failing = saver(&failing_map);
  ros::NodeHandle failing_nh("/failing/saver");
  failing->advertise(failing_nh, failing_nh);
  fuse(&failing_map, kCell, 1.0);
  ASSERT_TRUE(ros::service::waitForService("/failing/saver/save_map", ros::Duration(10.0)));
  ASSERT_TRUE(ros::service::call("/failing/saver/save_map", trigger));
  EXPECT_FALSE(trigger.response.success);
  std::lock_guard<std::mutex> lock(fusion_mutex_);
  EXPECT_EQ(failing->savesFailed(), 1u);
  EXPECT_TRUE(failing->lastSaveFailed());
  ASSERT_EQ(problems_.size(), 1u);
  EXPECT_EQ(problems_[0].rfind("save failed: ", 0), 0u) << problems_[0];
}

// Without a database, every save_period_s the map goes to its files when it
// changed; a checkpoint that fails is counted and noted.
TEST_F(MapSaverTest, CheckpointsWriteTheChangedMapWithoutADatabase) {
  config_.save_period_s = 0.1;
  ::mkdir(dir_.c_str(), 0755);
  ros::NodeHandle nh("/checkpoints");
  auto saving = saver(&fusion_);  // no openDatabase(): the live map alone, under its own name
  saving->advertise(nh, nh);
  ros::WallDuration(0.3).sleep();
  EXPECT_FALSE(exists(dir_ + "/flight.bt"));  // nothing fused yet: nothing written
  fuse(&fusion_, kCell, 1.0);
  ASSERT_TRUE(waitFor(
      fusion_mutex_, [&] { return exists(dir_ + "/flight.bt"); }, 5.0));
  EXPECT_TRUE(holdsCell(dir_ + "/flight.bt", kCell));

  config_.save_dir = dir_ + "/flight.bt/maps";  // under a file: every checkpoint fails
  MapFusion failing_map{OctomapAccumulatorParameters()};
  auto failing = saver(&failing_map);
  ros::NodeHandle failing_nh("/failing_checkpoints");
  failing->advertise(failing_nh, failing_nh);
  fuse(&failing_map, kCell, 1.0);
  ASSERT_TRUE(waitFor(
      fusion_mutex_, [&] { return failing->savesFailed() > 0; }, 5.0));
  std::lock_guard<std::mutex> lock(fusion_mutex_);
  EXPECT_TRUE(failing->lastSaveFailed());
  ASSERT_FALSE(problems_.empty());
  EXPECT_EQ(problems_[0].rfind("periodic save failed: ", 0), 0u) << problems_[0];
}

TEST_F(MapSaverTest, TheShutdownSaveOnlyOnceSomethingWasFused) {
  ::mkdir(dir_.c_str(), 0755);
  auto saving = saver(&fusion_);
  {
    std::unique_lock<std::mutex> lock(fusion_mutex_);
    saving->saveOnShutdown(lock);
  }
  EXPECT_FALSE(exists(dir_ + "/flight.bt"));
  fuse(&fusion_, kCell, 1.0);
  std::unique_lock<std::mutex> lock(fusion_mutex_);
  saving->saveOnShutdown(lock);
  EXPECT_TRUE(holdsCell(dir_ + "/flight.bt", kCell));
  EXPECT_TRUE(holdsCell(dir_ + "/flight.ot", kCell));
}

TEST(MapSaverConfig, TheMapNameStaysInSaveDir) {
  MapSaverConfig config;
  std::string why;
  EXPECT_TRUE(config.isValid(&why)) << why;
  config.map_name = "../escape";
  EXPECT_FALSE(config.isValid(&why));
  EXPECT_NE(why.find("map_name"), std::string::npos) << why;
  config = MapSaverConfig();
  config.save_period_s = -1.0;
  EXPECT_FALSE(config.isValid(&why));
  EXPECT_EQ(why.rfind("save_period_s must be in", 0), 0u) << why;
}
