// The draw_disparity command-line tool, run as a user runs it.

#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <sys/wait.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "stereo_occupancy/sim/disparity_files.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "stereo_occupancy/stereo_camera_model.h"

using namespace stereo_occupancy;

namespace {

struct Result {
  int status;
  std::string out;
};

Result run(const std::string& args) {
  const std::string cmd = std::string(DRAW_DISPARITY_EXE) + " " + args + " 2>" + ::testing::TempDir() + "stderr.txt";
  Result r{-1, ""};
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  while (fgets(buf.data(), buf.size(), pipe)) r.out += buf.data();
  r.status = pclose(pipe);
  return r;
}

std::string stderrText() {
  std::FILE* f = std::fopen((::testing::TempDir() + "stderr.txt").c_str(), "r");
  std::string s;
  if (!f) return s;
  int ch;
  while ((ch = std::fgetc(f)) != EOF) s += static_cast<char>(ch);
  std::fclose(f);
  return s;
}

long jsonNumber(const std::string& json, const std::string& key) {
  const auto pos = json.find("\"" + key + "\": ");
  if (pos == std::string::npos) return -1;
  return std::stol(json.substr(pos + key.size() + 4));
}

}  // namespace

// A rendered frame in, an .ot out that octomap::OcTree reads back with the
// obstacle where it should be.
TEST(DrawDisparityCli, RoundTripThroughAnOtFile) {
  // A 2 m wide box 12 m in front of a camera at (0, 0, 2) looking along +x.
  SyntheticScene scene;
  scene.addBox(Eigen::Vector3d(12.0, -1.0, 1.0), Eigen::Vector3d(13.0, 1.0, 3.0));
  const Eigen::Isometry3d T = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 2.0));
  const StereoCameraModel cam{StereoCameraConfig()};
  const std::string pfm = ::testing::TempDir() + "cli_frame.pfm";
  const std::string ot = ::testing::TempDir() + "cli_map.ot";
  writePfm(pfm, renderDisparity(scene, cam, T));
  std::remove(ot.c_str());

  const Eigen::Quaterniond q(T.linear());
  char pose[200];
  std::snprintf(pose, sizeof(pose), "\"0 0 2 %.12f %.12f %.12f %.12f\"", q.x(), q.y(), q.z(), q.w());
  for (const std::string algorithm : {"line", "line_pyramid", "raytrace", "raytrace_pyramid"}) {
    const Result r =
        run("--disparity " + pfm + " --focal 700 --cx 319.5 --cy 239.5 --baseline 0.3 --delta-d 0.5" + " --pose " +
            pose + " --resolution 0.25 --max-range 25 --algorithm " + algorithm + " --repeat 3 --output " + ot);
    ASSERT_EQ(r.status, 0) << stderrText();
    EXPECT_NE(r.out.find("\"algorithm\": \"" + algorithm + "\""), std::string::npos) << r.out;
    EXPECT_GT(jsonNumber(r.out, "grid_cells_drawn"), 0) << r.out;
    EXPECT_GT(jsonNumber(r.out, "different_grid_cells"), 0);
    EXPECT_GT(jsonNumber(r.out, "coordinate_transfers"), 0);
    EXPECT_GT(jsonNumber(r.out, "used_image_pixels"), 0);
    EXPECT_NE(r.out.find("\"grid_size\": ["), std::string::npos);
    EXPECT_NE(r.out.find("\"time_ms\": "), std::string::npos);

    std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(ot));
    auto* tree = dynamic_cast<octomap::OcTree*>(read.get());
    ASSERT_NE(tree, nullptr) << algorithm;
    EXPECT_DOUBLE_EQ(tree->getResolution(), 0.25);
    const octomap::OcTreeNode* face = tree->search(12.1, 0.1, 2.1);    // the box's front face
    const octomap::OcTreeNode* before = tree->search(6.1, 0.1, 2.1);   // between camera and box
    const octomap::OcTreeNode* behind = tree->search(18.1, 0.1, 2.1);  // in the box's shadow
    ASSERT_NE(face, nullptr) << algorithm;
    // The peak of eq. 9 at 12 m: 0.5 + k / (Δl √(2π)) with Δl = 12² · 0.5 / 210 m.
    const double peak = 0.5 + 0.1 / (144.0 * 0.5 / 210.0 * std::sqrt(2.0 * M_PI));
    EXPECT_NEAR(face->getLogOdds(), std::log(peak / (1.0 - peak)), 0.005) << algorithm;
    ASSERT_NE(before, nullptr) << algorithm;
    EXPECT_LT(before->getLogOdds(), 0.0f) << algorithm;
    EXPECT_EQ(behind, nullptr) << algorithm;
  }
  std::remove(pfm.c_str());
  std::remove(ot.c_str());
}

TEST(DrawDisparityCli, BadArgumentsFailWithOneLine) {
  const std::string pfm = ::testing::TempDir() + "cli_small.pfm";
  writePfm(pfm, cv::Mat(48, 64, CV_32FC1, cv::Scalar(5.0f)));
  const std::string ok = "--disparity " + pfm + " --focal 70 --baseline 0.3";
  EXPECT_EQ(run(ok).status, 0) << stderrText();
  for (const std::string& bad : std::vector<std::string>{
           std::string("--focal 700 --baseline 0.3"),  // no disparity
           "--disparity /nonexistent.pfm --focal 700 --baseline 0.3", ok + " --algorithm bresenham",
           ok + " --resolution abc", ok + " --pose \"1 2 3\"", ok + " --pose \"0 0 0 0 0 0 2\"", ok + " --frobnicate",
           ok + " --repeat 0", ok + " --output map.txt", "--disparity " + pfm + " --focal -700 --baseline 0.3"}) {
    const Result r = run(bad);
    ASSERT_TRUE(WIFEXITED(r.status)) << bad;
    EXPECT_EQ(WEXITSTATUS(r.status), 2) << bad;
    const std::string err = stderrText();
    EXPECT_NE(err.find("error"), std::string::npos) << bad;
    EXPECT_EQ(err.find('\n'), err.size() - 1) << "not one line: " << err;
    EXPECT_TRUE(r.out.empty()) << bad;
  }
  std::remove(pfm.c_str());
}
