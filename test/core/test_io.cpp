#include <gtest/gtest.h>

#include <octomap/OcTree.h>
#include <opencv2/imgcodecs.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <memory>

#include "stereo_occupancy/disparity_io.h"
#include "stereo_occupancy/octomap_io.h"

using namespace stereo_occupancy;

namespace {
std::string tempPath(const std::string& name) { return ::testing::TempDir() + "stereo_occupancy_" + name; }
}  // namespace

TEST(DisparityIo, PfmRoundTripKeepsNanAndOrientation) {
  cv::Mat img(3, 4, CV_32FC1);
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x) img.at<float>(y, x) = static_cast<float>(10 * y + x) + 0.25f;
  img.at<float>(0, 1) = std::nanf("");
  img.at<float>(2, 3) = 0.0f;
  const std::string path = tempPath("roundtrip.pfm");
  writePfm(path, img);
  const cv::Mat back = readDisparity(path, 0.0);
  ASSERT_EQ(back.size(), img.size());
  EXPECT_TRUE(std::isnan(back.at<float>(0, 1)));
  EXPECT_EQ(back.at<float>(0, 0), 0.25f);  // top-left stays top-left
  EXPECT_EQ(back.at<float>(2, 0), 20.25f);
  EXPECT_EQ(back.at<float>(2, 3), 0.0f);
  std::remove(path.c_str());
}

TEST(DisparityIo, Png16WithScale) {
  cv::Mat raw(2, 3, CV_16UC1);
  raw.at<uint16_t>(0, 0) = 0;
  raw.at<uint16_t>(0, 1) = 336;  // 21 px at 1/16 px
  raw.at<uint16_t>(1, 2) = 65535;
  const std::string path = tempPath("disp16.png");
  ASSERT_TRUE(cv::imwrite(path, raw));
  const cv::Mat d = readDisparity(path, 16.0);
  EXPECT_EQ(d.type(), CV_32FC1);
  EXPECT_EQ(d.at<float>(0, 0), 0.0f);
  EXPECT_FLOAT_EQ(d.at<float>(0, 1), 21.0f);
  EXPECT_FLOAT_EQ(d.at<float>(1, 2), 65535.0f / 16.0f);
  EXPECT_THROW(readDisparity(path, 0.0), std::runtime_error);  // a PNG needs a scale
  std::remove(path.c_str());
}

TEST(DisparityIo, BadFilesThrow) {
  EXPECT_THROW(readPfm(tempPath("does_not_exist.pfm")), std::runtime_error);
  const std::string path = tempPath("bad.pfm");
  {
    std::ofstream out(path);
    out << "PF\n2 2\n-1\n";  // colour PFM: not supported
  }
  EXPECT_THROW(readPfm(path), std::runtime_error);
  {
    std::ofstream out(path);
    out << "Pf\n100 100\n-1\nshort";
  }
  EXPECT_THROW(readPfm(path), std::runtime_error);
  std::remove(path.c_str());
  EXPECT_THROW(readDisparity("image.jpg", 1.0), std::runtime_error);
}

TEST(OctomapIo, LocalGridLogOddsSurviveTheOtFile) {
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

// A writer killed between writing its temporary file and renaming it leaves
// path.tmp<PID> behind; the next write removes those whose process is gone
// and keeps a live process's file and unrelated names.
TEST(OctomapIo, WriteRemovesTemporariesOfDeadWriters) {
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) ::_exit(0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);  // reaped: its pid no longer exists
  const std::string path = tempPath("stale.bt");
  const std::string dead = path + ".tmp" + std::to_string(child);
  const std::string live = path + ".tmp" + std::to_string(::getppid());
  const std::string other = path + ".tmpnotes";
  for (const std::string& p : {dead, live, other}) std::ofstream(p) << "x";
  auto exists = [](const std::string& p) { return std::ifstream(p).good(); };
  octomap::OcTree tree(0.25);
  tree.updateNode(1.0, 2.0, 3.0, true);
  writeOcTree(tree, path);
  EXPECT_FALSE(exists(dead));
  EXPECT_TRUE(exists(live));
  EXPECT_TRUE(exists(other));
  EXPECT_TRUE(exists(path));
  EXPECT_FALSE(exists(path + ".tmp" + std::to_string(::getpid())));  // its own was renamed into place
  EXPECT_EQ(removeStaleTemporaries(path), 0);
  for (const std::string& p : {live, other, path}) std::remove(p.c_str());
}
