// The offline chain as a user runs it: simulate_flight writes a bag,
// bag_to_map maps it with the nodelets' code, evaluate_map scores the map.

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <octomap/OcTree.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

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

/// The cells of the whole-map table's row "| <cell> | <method> |" (empty if none).
std::vector<std::string> tableRow(const std::string& text, const std::string& cell, const std::string& method) {
  const std::string start = "| " + cell + " | " + method + " |";
  const auto pos = text.find(start);
  if (pos == std::string::npos) return {};
  std::vector<std::string> cells;
  std::stringstream line(text.substr(pos + 1, text.find('\n', pos) - pos - 1));
  for (std::string c; std::getline(line, c, '|');) cells.push_back(c.substr(1, c.size() - 2));
  return cells;
}

}  // namespace

// Every method's whole-map row holds times and scores that fit the method:
// the plain drawings find the posts, line_pyramid calls surfaces free (the
// paper's "risk of remaining holes"), the surface profile leaves fewer
// phantoms than the Gaussian.
TEST(OfflineTools, CompareWithOctomapScoresEveryMethod) {
  const Result r = run(std::string(COMPARE_OCTOMAP_EXE) + " --scenario posts --frame-step 50 --resolution 1.0");
  ASSERT_EQ(r.status, 0);
  // cell, method, draw ms, fusion ms, total ms, precision %, recall %, F1, phantom %, called free %, coverage %, ...
  enum { kDrawMs = 2, kTotalMs = 4, kPrecision = 5, kRecall = 6, kF1 = 7, kPhantom = 8, kCalledFree = 9 };
  std::map<std::string, std::vector<double>> rows;
  for (const char* method :
       {"line", "line_pyramid", "raytrace", "raytrace_pyramid", "line_pyramid_bounded", "line_pyramid_bounded, surface",
        "OctoMap insertPointCloud", "OctoMap insertPointCloud, discretize"}) {
    const std::vector<std::string> cells = tableRow(r.out, "1 m", method);
    ASSERT_GE(cells.size(), 11u) << method << "\n" << r.out;
    std::vector<double>& values = rows[method];
    values.assign(cells.size(), 0.0);  // indices as in the row; "-" (not measured) stays 0
    for (size_t i = kDrawMs; i < cells.size(); ++i) values[i] = std::strtod(cells[i].c_str(), nullptr);
    EXPECT_GT(values[kDrawMs], 0.0) << method;
    EXPECT_GE(values[kTotalMs], values[kDrawMs]) << method;
    EXPECT_GT(values[kRecall], 95.0) << method;
    EXPECT_GT(values[kPrecision], 90.0) << method;
    EXPECT_NEAR(values[kF1], 2.0 / (100.0 / values[kPrecision] + 100.0 / values[kRecall]), 0.002) << method;
  }
  EXPECT_GT(rows["line_pyramid"][kCalledFree], 1.0);
  EXPECT_LT(rows["line_pyramid_bounded"][kCalledFree], 0.5);
  EXPECT_LT(rows["line_pyramid_bounded, surface"][kPhantom], rows["line_pyramid_bounded"][kPhantom]);
}

// A real stereo pair (opencv-doc's Aloe images, StereoSGBM) at 0.1, 0.05 and
// 0.02 m cells, overall and in each range band (near, middle, far), matched
// with a 5 px block and with stereo_image_proc's 15 px. The mapper's default
// gives each pixel its hit, as per-pixel line drawing does, where OctoMap
// puts its endpoint: the same occupied cells as line, hence its recall and
// precision, and OctoMap's within a point. It calls at most half as much of
// the true surface free as OctoMap in every band: without the edge guard the
// near band at 0.1 m was 0.51 of OctoMap's (11.0 against 21.7 %), and
// stereo_image_proc's matcher 0.55 overall (docs/quality_analysis.md).
TEST(OfflineTools, RealStereoPairDefaultAgainstOctomapInEachBand) {
  enum { kPrecision = 3, kRecall = 4, kF1 = 5, kCalledFree = 6, kOccupied = 7 };
  int rows = 0;
  for (const std::string matcher : {"fine", "stereo_image_proc"}) {
    const Result r = run(std::string(EVALUATE_STEREO_PAIR_EXE) +
                         " --resolution 0.1 --resolution 0.05 --resolution 0.02 --sgbm " + matcher);
    ASSERT_EQ(r.status, 0) << r.out;
    for (const char* cell : {"0.1 m", "0.05 m", "0.02 m"})
      for (const char* band : {"all", "near", "middle", "far"}) {
        SCOPED_TRACE(matcher + ", " + cell + ", " + band);
        auto row = [&](const std::string& method) {
          std::vector<double> v;
          for (const std::string& c : tableRow(r.out, cell, method + " | " + band))
            v.push_back(std::strtod(c.c_str(), nullptr));
          return v;
        };
        const std::vector<double> ours = row("line_pyramid_bounded, surface (default)");
        const std::vector<double> line = row("line, surface");
        const std::vector<double> octomap = row("OctoMap insertPointCloud");
        ASSERT_EQ(ours.size(), 8u) << r.out;
        ASSERT_EQ(line.size(), 8u) << r.out;
        ASSERT_EQ(octomap.size(), 8u) << r.out;
        EXPECT_GT(ours[kOccupied], 500.0);
        EXPECT_EQ(ours[kOccupied], line[kOccupied]);  // the same cells, so the same precision and recall
        EXPECT_EQ(ours[kPrecision], line[kPrecision]);
        EXPECT_EQ(ours[kRecall], line[kRecall]);
        EXPECT_GE(ours[kRecall], octomap[kRecall] - 1.0);
        EXPECT_GE(ours[kPrecision], octomap[kPrecision] - 1.0);
        EXPECT_GT(octomap[kCalledFree], 1.0);  // a real pair: the matcher's errors show
        EXPECT_LE(ours[kCalledFree], 0.5 * octomap[kCalledFree]);
        ++rows;
      }
  }
  EXPECT_EQ(rows, 24);
}

// A flight through the real matcher: simulate_flight renders the left and
// right images and matches them with StereoSGBM (stereo_image_proc's
// defaults), bag_to_map maps its disparities, and the map holds the posts
// within one cell (measured: precision 96 %, recall 94 % after 20 frames),
// a map other than the Gaussian flight's. compare_octomap scores the same
// flight with the detection range: the mapper's default shows both posts of
// the first gate, no later than OctoMap.
TEST(OfflineTools, SgbmFlightThroughTheTools) {
  const std::string dir = ::testing::TempDir();
  std::map<std::string, std::string> scores;  // per matcher: evaluate_map's JSON
  for (const std::string matcher : {"sgbm", "gaussian"}) {
    const std::string bag = dir + "offline_" + matcher + ".bag";
    ASSERT_EQ(run(std::string(SIMULATE_FLIGHT_EXE) + " --scenario posts_far --matcher " + matcher +
                  " --frames 20 --output " + bag)
                  .status,
              0);
    const Result mapped =
        run(std::string(BAG_TO_MAP_EXE) + " --bag " + bag + " --output " + dir + "offline_" + matcher);
    ASSERT_EQ(mapped.status, 0) << mapped.out;
    EXPECT_EQ(jsonNumber(mapped.out, "mapped"), 20);
    const Result score = run(std::string(EVALUATE_MAP_EXE) + " --map " + dir + "offline_" + matcher +
                             ".bt --scenario posts_far --frames 20");
    ASSERT_EQ(score.status, 0) << score.out;
    scores[matcher] = score.out;
  }
  EXPECT_GT(jsonNumber(scores["sgbm"], "occupied_precision"), 0.9) << scores["sgbm"];
  EXPECT_GT(jsonNumber(scores["sgbm"], "occupied_recall"), 0.9) << scores["sgbm"];
  EXPECT_NE(jsonNumber(scores["sgbm"], "occupied_cells"), jsonNumber(scores["gaussian"], "occupied_cells"));

  const Result r =
      run(std::string(COMPARE_OCTOMAP_EXE) +
          " --scenario posts_far --matcher sgbm --frame-step 50 --resolution 1.0 --algorithm line_pyramid_bounded");
  ASSERT_EQ(r.status, 0);
  EXPECT_NE(r.out.find("matcher sgbm: StereoSGBM: 64 disparities"), std::string::npos) << r.out;
  const auto section = r.out.find("Detection range:");
  ASSERT_NE(section, std::string::npos) << r.out;
  // cell, method, detected ("N of M"), median m, min m, later than OctoMap, earlier than OctoMap
  const std::vector<std::string> ours = tableRow(r.out.substr(section), "1 m", "line_pyramid_bounded, surface");
  const std::vector<std::string> octomap = tableRow(r.out.substr(section), "1 m", "OctoMap insertPointCloud");
  ASSERT_EQ(ours.size(), 7u) << r.out;
  ASSERT_EQ(octomap.size(), 7u) << r.out;
  EXPECT_EQ(ours[2], "2 of 2");
  EXPECT_EQ(octomap[2], "2 of 2");
  EXPECT_GT(std::strtod(ours[4].c_str(), nullptr), 15.0);  // nearest first sighting [m]
  EXPECT_EQ(ours[5], "0");
}

// The figures are pictures of something: the paper's sizes, and drawn in
// more than one colour over much of the canvas.
TEST(OfflineTools, FiguresAreWritten) {
  const std::string dir = ::testing::TempDir();
  ASSERT_EQ(run(std::string(MAKE_FIGURES_EXE) + " " + dir).status, 0);
  for (const char* f : {"fig1_inverse_sensor_model.png", "fig3_pyramid_levels.png", "fig5_blur.png"}) {
    const cv::Mat image = cv::imread(dir + f, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(image.empty()) << f;
    EXPECT_GE(image.cols, 300) << f;
    EXPECT_GE(image.rows, 200) << f;
    const double drawn = static_cast<double>(cv::countNonZero(image < 250)) / static_cast<double>(image.total());
    EXPECT_GT(drawn, 0.02) << f << ": nearly blank";
    EXPECT_LT(drawn, 0.98) << f << ": nearly filled";
    std::remove((dir + f).c_str());
  }
}

TEST(OfflineTools, SimulateMapAndScoreAFlight) {
  const std::string dir = ::testing::TempDir();
  const std::string bag = dir + "offline_posts.bag";
  ASSERT_EQ(
      run(std::string(SIMULATE_FLIGHT_EXE) + " --scenario posts --frames 30 --seed 3 --true-depth --output " + bag)
          .status,
      0);

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

  const Result score =
      run(std::string(EVALUATE_MAP_EXE) + " --map " + dir + "offline_posts.bt --scenario posts --frames 30");
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
  octomap::OcTree raytraced(dir + "offline_rt.bt");
  EXPECT_DOUBLE_EQ(raytraced.getResolution(), 0.5);
  const octomap::OcTreeNode* raytraced_post = raytraced.search(14.9, 3.4, 4.1);
  ASSERT_NE(raytraced_post, nullptr);
  EXPECT_TRUE(raytraced.isNodeOccupied(raytraced_post));
  const Result bad = run(std::string(BAG_TO_MAP_EXE) + " --bag " + bag + " --output " + dir + "x --param nonsense=1");
  ASSERT_TRUE(WIFEXITED(bad.status));
  EXPECT_EQ(WEXITSTATUS(bad.status), 2);
  for (const char* f : {"offline_posts.bag", "offline_posts.bag.scene.txt", "offline_posts.bt", "offline_posts.ot",
                        "offline_rt.bt", "offline_rt.ot", "offline_depth.bt", "offline_depth.ot"})
    std::remove((dir + f).c_str());
}
