// The offline chain as a user runs it: simulate_flight writes a bag,
// bag_to_map maps it with the nodelets' code, evaluate_map scores the map.

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <octomap/OcTree.h>

#include <array>
#include <cstdio>
#include <string>

namespace {

struct Result {
  int status;
  std::string out;
};

Result run(const std::string& command) {
  Result r{-1, ""};
  FILE* pipe = popen((command + " 2>/dev/null").c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  while (fgets(buf.data(), buf.size(), pipe)) r.out += buf.data();
  r.status = pclose(pipe);
  return r;
}

double jsonNumber(const std::string& json, const std::string& key) {
  const auto pos = json.find("\"" + key + "\": ");
  if (pos == std::string::npos) return -1.0;
  return std::stod(json.substr(pos + key.size() + 4));
}

size_t fileSize(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return 0;
  std::fseek(f, 0, SEEK_END);
  const long n = std::ftell(f);
  std::fclose(f);
  return n > 0 ? static_cast<size_t>(n) : 0;
}

}  // namespace

TEST(OfflineTools, CompareWithOctomapPrintsEveryMethod) {
  const Result r = run(std::string(COMPARE_OCTOMAP_EXE) + " --scenario posts --frame-step 50 --resolution 1.0");
  ASSERT_EQ(r.status, 0);
  for (const char* method : {"| line |", "| line_pyramid |", "| raytrace |", "| raytrace_pyramid |",
                             "| OctoMap insertPointCloud |", "| OctoMap insertPointCloud, discretize |"})
    EXPECT_NE(r.out.find(method), std::string::npos) << method << "\n" << r.out;
}

TEST(OfflineTools, FiguresAreWritten) {
  const std::string dir = ::testing::TempDir();
  ASSERT_EQ(run(std::string(MAKE_FIGURES_EXE) + " " + dir).status, 0);
  for (const char* f : {"fig1_inverse_sensor_model.png", "fig3_pyramid_levels.png", "fig5_blur.png"}) {
    EXPECT_GT(fileSize(dir + f), 10000u) << f;
    std::remove((dir + f).c_str());
  }
}

TEST(OfflineTools, SimulateMapAndScoreAFlight) {
  const std::string dir = ::testing::TempDir();
  const std::string bag = dir + "offline_posts.bag";
  ASSERT_EQ(run(std::string(SIMULATE_FLIGHT_EXE) + " --scenario posts --frames 30 --seed 3 --true-depth --output " + bag).status, 0);

  const Result mapped = run(std::string(BAG_TO_MAP_EXE) + " --bag " + bag + " --output " + dir + "offline_posts");
  ASSERT_EQ(mapped.status, 0) << mapped.out;
  EXPECT_EQ(jsonNumber(mapped.out, "images"), 30);
  EXPECT_EQ(jsonNumber(mapped.out, "mapped"), 30);
  EXPECT_EQ(jsonNumber(mapped.out, "dropped_no_pose"), 0);
  octomap::OcTree map(dir + "offline_posts.bt");
  EXPECT_DOUBLE_EQ(map.getResolution(), 0.25);
  // The first gate's left post (x 14.8..15.2, y 3.3..3.7) is occupied at 4 m height.
  const octomap::OcTreeNode* post = map.search(14.9, 3.4, 4.1);
  ASSERT_NE(post, nullptr);
  EXPECT_TRUE(map.isNodeOccupied(post));

  const Result score = run(std::string(EVALUATE_MAP_EXE) + " --map " + dir + "offline_posts.bt --scenario posts --frames 30");
  ASSERT_EQ(score.status, 0) << score.out;
  // Within one cell, most occupied cells lie at a true surface and nearly every
  // observed surface cell is found; almost none is called free.
  EXPECT_GT(jsonNumber(score.out, "occupied_precision"), 0.85) << score.out;
  EXPECT_GT(jsonNumber(score.out, "occupied_recall"), 0.95) << score.out;
  EXPECT_LT(jsonNumber(score.out, "surface_called_free_fraction"), 0.01) << score.out;
  EXPECT_GT(jsonNumber(score.out, "free_coverage"), 0.3) << score.out;
  // The mapper's surface profile: few phantom obstacles (the paper's Gaussian
  // leaves about 8 % on this flight), and the scores per range band.
  EXPECT_LT(jsonNumber(score.out, "phantom_share"), 0.04) << score.out;
  EXPECT_GT(jsonNumber(score.out, "f1"), 0.95) << score.out;
  EXPECT_NE(score.out.find("\"bands\": {\"0-10 m\": {"), std::string::npos) << score.out;
  EXPECT_NE(score.out.find("\"20+ m\": {"), std::string::npos) << score.out;

  // The depth path: the bag's exact depth images with the left camera_info.
  const Result from_depth = run(std::string(BAG_TO_MAP_EXE) + " --bag " + bag + " --output " + dir +
                                "offline_depth --depth-topic /ground_truth/depth --camera-info-topic "
                                "/stereo/left/camera_info --param depth_baseline_m=0.3");
  ASSERT_EQ(from_depth.status, 0) << from_depth.out;
  EXPECT_EQ(jsonNumber(from_depth.out, "mapped"), 30);
  octomap::OcTree depth_map(dir + "offline_depth.bt");
  ASSERT_NE(depth_map.search(14.9, 3.4, 4.1), nullptr);
  EXPECT_TRUE(depth_map.isNodeOccupied(depth_map.search(14.9, 3.4, 4.1)));

  // Options as in the config: another algorithm, and bad names refused.
  const Result raytrace = run(std::string(BAG_TO_MAP_EXE) + " --bag " + bag + " --output " + dir +
                              "offline_rt --param algorithm=raytrace_pyramid --param resolution_m=0.5");
  ASSERT_EQ(raytrace.status, 0);
  EXPECT_NE(raytrace.out.find("\"algorithm\": \"raytrace_pyramid\""), std::string::npos);
  EXPECT_DOUBLE_EQ(octomap::OcTree(dir + "offline_rt.bt").getResolution(), 0.5);
  const Result bad = run(std::string(BAG_TO_MAP_EXE) + " --bag " + bag + " --output " + dir + "x --param nonsense=1");
  ASSERT_TRUE(WIFEXITED(bad.status));
  EXPECT_EQ(WEXITSTATUS(bad.status), 2);
  for (const char* f : {"offline_posts.bag", "offline_posts.bag.scene.txt", "offline_posts.bt", "offline_posts.ot",
                        "offline_rt.bt", "offline_rt.ot", "offline_depth.bt", "offline_depth.ot"})
    std::remove((dir + f).c_str());
}
