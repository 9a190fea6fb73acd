// Every command-line tool against bad arguments and bad files: a clear
// "<tool>: error: ..." line and exit status 2 (arguments) or 1 (files), never
// a crash; and bag_to_map skips hostile messages in a bag and maps the rest.

#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <stereo_msgs/DisparityImage.h>
#include <sys/wait.h>
#include <tf2_msgs/TFMessage.h>

#include <array>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "stereo_occupancy/store/tile_store.h"

namespace so = stereo_occupancy;

namespace {

struct Result {
  int status = -1;
  std::string out, err;
};

Result run(const std::string& command) {
  Result r;
  const std::string err_path = ::testing::TempDir() + "tool_errors_stderr.txt";
  FILE* pipe = popen((command + " 2>" + err_path).c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  while (fgets(buf.data(), buf.size(), pipe)) r.out += buf.data();
  r.status = pclose(pipe);
  std::ifstream in(err_path);
  r.err.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  return r;
}

void writeFile(const std::string& path, const std::string& bytes) { std::ofstream(path, std::ios::binary) << bytes; }

/// Runs each command and expects the tool's error line and @p status.
void expectError(const std::string& tool, const std::vector<std::string>& commands, int status) {
  for (const std::string& command : commands) {
    const Result r = run(command);
    ASSERT_TRUE(WIFEXITED(r.status)) << command << " did not exit (signal)\n" << r.err;
    EXPECT_EQ(WEXITSTATUS(r.status), status) << command << "\n" << r.err;
    EXPECT_NE(r.err.find(tool + ": error: "), std::string::npos) << command << "\n" << r.err;
  }
}

const std::string kTmp = ::testing::TempDir();

}  // namespace

TEST(ToolErrors, EvaluateMap) {
  const std::string tool = EVALUATE_MAP_EXE;
  writeFile(kTmp + "garbage.bt", "this is not an octree\n");
  writeFile(kTmp + "garbage.ot", "# Octomap OcTree file\nid NoSuchTree\nsize 12\nres 0.25\ndata\n\x01\x02");
  expectError("evaluate_map",
              {tool, tool + " --map " + kTmp + "garbage.bt", tool + " --map x.bt --scenario posts --frames abc",
               tool + " --map x.bt --scenario posts --max-range -3", tool + " --map x.bt --scenario mars",
               tool + " --map x.bt --scenario posts --frobnicate", tool + " --map x.bt --scenario posts --views"},
              2);
  expectError(
      "evaluate_map",
      {tool + " --map /nonexistent/map.bt --scenario posts", tool + " --map " + kTmp + "garbage.bt --scenario posts",
       tool + " --map " + kTmp + "garbage.ot --scenario posts"},
      1);
}

TEST(ToolErrors, SimulateFlight) {
  const std::string tool = SIMULATE_FLIGHT_EXE;
  expectError("simulate_flight",
              {tool, tool + " --scenario mars --output " + kTmp + "x.bag",
               tool + " --scenario posts --output " + kTmp + "x.bag --frames -3",
               tool + " --scenario posts --output " + kTmp + "x.bag --seed 1.5", tool + " --scenario posts --output",
               tool + " --scenario posts --output " + kTmp + "x.bag --matcher census"},
              2);
  expectError("simulate_flight", {tool + " --scenario posts --frames 1 --output /nonexistent/dir/x.bag"}, 1);
}

TEST(ToolErrors, BenchmarksAndFigures) {
  const std::string compare = COMPARE_OCTOMAP_EXE, table1 = TABLE1_EXE, figures = MAKE_FIGURES_EXE;
  expectError(
      "compare_octomap",
      {compare + " --scenario mars", compare + " --frame-step x", compare + " --frame-step 0",
       compare + " --resolution 0", compare + " --resolution nan", compare + " --truth-pixel-step",
       compare + " --model p_hot=0.7 --frame-step 100", compare + " --map clamping_min_prob=0.7 --frame-step 100",
       compare + " --matcher census", compare + " --matcher"},
      2);
  const std::string pair = EVALUATE_STEREO_PAIR_EXE;
  expectError("evaluate_stereo_pair",
              {pair + " --shrink 0", pair + " --resolution 0", pair + " --model p_hot=0.7", pair + " --frobnicate",
               pair + " --algorithm bresenham", pair + " --sgbm census"},
              2);
  expectError("evaluate_stereo_pair", {pair + " --left /nonexistent.png"}, 1);
  expectError("table1", {table1 + " --repeat 0", table1 + " --repeat x", table1 + " --frobnicate"}, 2);
  expectError("scaling", {std::string(SCALING_EXE) + " --repeat 0", std::string(SCALING_EXE) + " --frobnicate"}, 2);
  const std::string performance = PERFORMANCE_EXE;
  expectError(
      "performance",
      {performance + " --repeat 0", performance + " --only warp_drive", performance + " --scenario mars",
       performance + " --scenario posts --frame 100000", performance + " --flight mars", performance + " --pace-ms 100",
       performance + " --flight posts --pace-ms -1", performance + " --frobnicate",
       performance + " --flight posts --thread-rounds 2", performance + " --stages --scenario posts --thread-rounds 2",
       performance + " --stages --flight posts --thread-rounds 0", performance + " --flight posts --blank",
       performance + " --stages --flight posts --thread-rounds 2 --blank"},
      2);
  expectError("make_figures", {figures + " a b", figures + " --frobnicate"}, 2);
  expectError("make_figures", {figures + " /nonexistent/dir"}, 1);
}

TEST(ToolErrors, BagToMapArgumentsAndFiles) {
  const std::string tool = BAG_TO_MAP_EXE;
  writeFile(kTmp + "garbage.bag", "#ROSBAG V2.0\nnot really");
  expectError("bag_to_map",
              {tool, tool + " --bag x.bag", tool + " --bag x.bag --output y --param algorithm=bresenham",
               tool + " --bag x.bag --output y --param resolution_m=-1", tool + " --bag x.bag --output y --param k",
               tool + " --bag x.bag --output y --frobnicate"},
              2);
  expectError("bag_to_map",
              {tool + " --bag /nonexistent.bag --output " + kTmp + "m",
               tool + " --bag " + kTmp + "garbage.bag --output " + kTmp + "m"},
              1);
}

// A recording cut short (no index): bag_to_map says how to repair it; into a
// log its progress is one line, not a carriage return per frame.
TEST(ToolErrors, BagToMapOnACutBagSaysReindexAndLogsOneProgressLine) {
  const std::string bag = kTmp + "cut_source.bag", cut = kTmp + "cut.bag";
  const Result made = run(std::string(SIMULATE_FLIGHT_EXE) + " --scenario posts --frames 10 --output " + bag);
  ASSERT_EQ(made.status, 0) << made.err;
  EXPECT_EQ(made.err.find('\r'), std::string::npos) << "simulate_flight drew a bar into a file";
  std::ifstream in(bag, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  writeFile(cut, bytes.substr(0, bytes.size() / 2));
  const Result r = run(std::string(BAG_TO_MAP_EXE) + " --bag " + cut + " --output " + kTmp + "cut_map");
  ASSERT_TRUE(WIFEXITED(r.status));
  EXPECT_EQ(WEXITSTATUS(r.status), 1) << r.err;
  EXPECT_NE(r.err.find("rosbag reindex " + cut), std::string::npos) << r.err;
  const Result whole = run(std::string(BAG_TO_MAP_EXE) + " --bag " + bag + " --output " + kTmp + "whole_map");
  ASSERT_EQ(whole.status, 0) << whole.err;
  EXPECT_EQ(whole.err.find('\r'), std::string::npos) << whole.err;
  EXPECT_NE(whole.err.find("10/10 frames"), std::string::npos) << whole.err;
  for (const std::string& f : {bag, bag + ".scene.txt", cut, kTmp + "whole_map.bt", kTmp + "whole_map.ot"})
    std::remove(f.c_str());
}

namespace {

/// The Table I scene's disparity image at a fixed pose, as a bag's frames k
/// stamped t0 + 0.1 s · k.
struct Table1Frames {
  so::StereoCameraModel camera{so::StereoCameraConfig()};
  Eigen::Isometry3d T_W_C;
  cv::Mat image = so::table1Image(camera, &T_W_C);
  ros::Time t0{1000.0};

  ros::Time stamp(int k) const { return t0 + ros::Duration(0.1 * k); }
  /// The pose at the stamps of the first @p frames frames, for /tf.
  tf2_msgs::TFMessage poses(int frames) const {
    tf2_msgs::TFMessage tf;
    for (int k = 0; k < frames; ++k)
      tf.transforms.push_back(so::toTransformMsg(T_W_C, stamp(k), "map", "camera_optical"));
    return tf;
  }
  /// Frame @p k's disparity image.
  stereo_msgs::DisparityImage disparity(int k) const {
    std_msgs::Header header;
    header.stamp = stamp(k);
    header.frame_id = "camera_optical";
    stereo_msgs::DisparityImage m;
    so::toDisparityImageMsg(image, header, camera.config(), 128.0, 1.0 / 16.0, &m);
    return m;
  }
};

}  // namespace

// A bag whose good images share the stream with hostile ones: the hostile ones
// are refused one by one, the good ones mapped.
TEST(ToolErrors, BagToMapSkipsHostileImages) {
  const std::string bag_path = kTmp + "hostile.bag";
  const Table1Frames frames;
  {
    rosbag::Bag bag(bag_path, rosbag::bagmode::Write);
    bag.write("/tf", frames.t0, frames.poses(12));
    std::vector<stereo_msgs::DisparityImage> msgs;
    msgs.push_back(frames.disparity(0));
    stereo_msgs::DisparityImage m = frames.disparity(1);
    m.image.encoding = "mono8";  // wrong encoding
    msgs.push_back(m);
    m = frames.disparity(2);
    m.image.data.resize(100);  // data shorter than step * height
    msgs.push_back(m);
    m = frames.disparity(3);
    m.image.step = 4;  // step shorter than a row
    msgs.push_back(m);
    m = frames.disparity(4);
    m.image.width = m.image.height = 0;  // empty
    m.image.data.clear();
    msgs.push_back(m);
    m = frames.disparity(5);
    m.f = std::numeric_limits<float>::quiet_NaN();
    msgs.push_back(m);
    m = frames.disparity(6);
    m.T = -0.3f;
    msgs.push_back(m);
    m = frames.disparity(7);
    m.image.height = 240;  // another size than the camera_info-less default: fine, a smaller image
    m.image.data.resize(m.image.step * 240);
    msgs.push_back(m);
    msgs.push_back(frames.disparity(8));
    for (const auto& msg : msgs) bag.write("/stereo/disparity", msg.header.stamp, msg);
  }
  const Result r = run(std::string(BAG_TO_MAP_EXE) + " --bag " + bag_path + " --output " + kTmp + "hostile_map");
  ASSERT_TRUE(WIFEXITED(r.status)) << r.err;
  ASSERT_EQ(WEXITSTATUS(r.status), 0) << r.err;
  EXPECT_NE(r.out.find("\"images\": 9"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"mapped\": 3"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"refused\": 6"), std::string::npos) << r.out;
  for (const char* reason : {"encoding", "do not fit together", "shorter than a row", "empty image", "camera from"})
    EXPECT_NE(r.err.find(reason), std::string::npos) << reason << "\n" << r.err;
  std::remove(bag_path.c_str());
}

TEST(ToolErrors, ExportMap) {
  const std::string tool = EXPORT_MAP_EXE;
  writeFile(kTmp + "not_tiles.db", "this is not a database, only text that is long enough to be read as one\n");
  expectError(
      "export_map",
      {tool, tool + " --database x.db", tool + " --database x.db --out y.txt",
       tool + " --database x.db --out y.bt --min 0 0 0", tool + " --database x.db --out y.bt --min 1 1 1 --max 0 0 0",
       tool + " --database x.db --out y.bt --min a b c --max 1 1 1", tool + " --frobnicate"},
      2);
  expectError("export_map",
              {tool + " --database /nonexistent/m.db --out " + kTmp + "e.bt",
               tool + " --database " + kTmp + "not_tiles.db --out " + kTmp + "e.bt"},
              1);
}

namespace {

/// A bag at @p path with one disparity image of the Table I scene and its pose.
void writeOneImageBag(const std::string& path) {
  const Table1Frames frames;
  rosbag::Bag bag(path, rosbag::bagmode::Write);
  bag.write("/tf", frames.t0, frames.poses(1));
  bag.write("/stereo/disparity", frames.t0, frames.disparity(0));
}

}  // namespace

// bag_to_map never replaces a database that a running accumulator holds (it
// lost 49 246 of 66 049 occupied cells so), and a bag whose topic carries
// another type is an error, not an empty map with exit 0.
TEST(ToolErrors, BagToMapHonoursAHeldDatabaseAndTheTopicsType) {
  const std::string bag = kTmp + "one_image.bag", held = kTmp + "held_mission";
  writeOneImageBag(bag);
  for (const char* suffix : {".db", ".db-wal", ".db-shm"}) std::remove((held + suffix).c_str());
  {
    so::TileStore mission(held + ".db", 0.25);  // as an accumulator holds it
    so::MapAccumulator::Leaf leaf;
    leaf.key = octomap::OcTreeKey(32768, 32768, 32768);
    leaf.depth = so::MapAccumulator::kTileDepth;
    leaf.log_odds = 2.0f;
    mission.put(so::MapAccumulator::TileIndex(0, 0, 0), {leaf});
    ASSERT_TRUE(mission.flush());
    const Result r = run(std::string(BAG_TO_MAP_EXE) + " --bag " + bag + " --output " + held);
    ASSERT_TRUE(WIFEXITED(r.status)) << r.err;
    EXPECT_EQ(WEXITSTATUS(r.status), 1) << r.err;
    EXPECT_NE(r.err.find("locked"), std::string::npos) << r.err;
    EXPECT_EQ(mission.tiles().size(), 1u);
  }
  so::TileStore after(held + ".db", 0.25);
  EXPECT_EQ(after.tiles().size(), 1u) << "the held database was replaced";

  const std::string typed = kTmp + "typed.bag";
  {
    rosbag::Bag b(typed, rosbag::bagmode::Write);
    sensor_msgs::Image image;
    image.header.stamp = ros::Time(1000.0);
    b.write("/stereo/disparity", image.header.stamp, image);
  }
  const Result r = run(std::string(BAG_TO_MAP_EXE) + " --bag " + typed + " --output " + kTmp + "typed_map");
  ASSERT_TRUE(WIFEXITED(r.status)) << r.err;
  EXPECT_EQ(WEXITSTATUS(r.status), 1) << r.err;
  EXPECT_NE(r.err.find("carries sensor_msgs/Image, not stereo_msgs/DisparityImage"), std::string::npos) << r.err;
  for (const std::string& f : {bag, typed}) std::remove(f.c_str());
}

// export_map only reads: a 0-byte file stays 0 bytes (it became 4 kB), and a
// database with a row cut short is refused instead of exported as success.
TEST(ToolErrors, ExportMapOnlyReadsAndRefusesADamagedRow) {
  const std::string tool = EXPORT_MAP_EXE;
  const std::string empty = kTmp + "empty_tiles.db";
  writeFile(empty, "");
  expectError("export_map", {tool + " --database " + empty + " --out " + kTmp + "e.ot"}, 1);
  std::ifstream in(empty, std::ios::binary | std::ios::ate);
  EXPECT_EQ(static_cast<long>(in.tellg()), 0L) << "export_map wrote to its input";
  const std::string damaged = kTmp + "cut_row.db";
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((damaged + suffix).c_str());
  {
    so::TileStore store(damaged, 0.25);
    for (int x = 0; x < 2; ++x) {
      so::MapAccumulator::Leaf leaf;
      leaf.key =
          octomap::OcTreeKey(static_cast<octomap::key_type>(32768 + x * so::MapAccumulator::kTileCells), 32768, 32768);
      leaf.depth = so::MapAccumulator::kTileDepth + 2;
      leaf.log_odds = 1.0f;
      store.put(so::MapAccumulator::TileIndex(x, 0, 0), {leaf});
    }
    ASSERT_TRUE(store.flush());
  }
  ASSERT_EQ(run("sqlite3 -version").status, 0) << "the test needs the sqlite3 command (Debian's sqlite3)";
  ASSERT_EQ(
      run("sqlite3 " + damaged + " \"UPDATE tiles SET octree = substr(octree, 1, length(octree) - 5) WHERE x = 1\"")
          .status,
      0);
  for (const char* ext : {".ot", ".bt"}) {
    const std::string out = kTmp + "cut_row_export" + ext;
    std::remove(out.c_str());
    const Result r = run(tool + " --database " + damaged + " --out " + out);
    ASSERT_TRUE(WIFEXITED(r.status)) << r.err;
    EXPECT_EQ(WEXITSTATUS(r.status), 1) << ext << ": " << r.out << r.err;
    EXPECT_NE(r.err.find("damaged"), std::string::npos) << r.err;
    EXPECT_FALSE(std::ifstream(out).good()) << out << " was written";
  }
}
