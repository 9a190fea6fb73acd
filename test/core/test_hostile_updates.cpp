// Updates as a hostile or broken peer on the ROS graph could send them, and
// saves on a full disk: the map must come out unchanged, the process alive,
// the previous map file whole.

#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "stereo_occupancy/fusion_cache.h"
#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/octomap_io.h"

using namespace stereo_occupancy;

namespace {

constexpr int kIntMax = std::numeric_limits<int>::max();

/// An update of @p size cells at @p origin carrying one cell of value 1 at each linear index in @p cells.
GridUpdate claimedBox(const Eigen::Vector3i& origin, const Eigen::Vector3i& size, std::vector<uint32_t> cells) {
  GridUpdate u;
  u.resolution_m = 0.25;
  u.origin_index = origin;
  u.size = size;
  u.W_sensor_origin = origin.cast<double>() * 0.25;
  for (uint32_t i : cells) {
    u.run_start.push_back(i);
    u.run_length.push_back(1);
    u.log_odds.push_back(1.0f);
  }
  return u;
}

/// The whole tree, every node's value included (.ot format).
std::string fullTree(const octomap::OcTree& tree) {
  std::ostringstream out;
  tree.write(out);
  return out.str();
}

/// A map holding a few cells, as a vehicle's map would before the attack.
std::unique_ptr<MapAccumulator> smallMap() {
  auto map = std::make_unique<MapAccumulator>(MapAccumulatorConfig{});
  GridUpdate u = claimedBox(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(4, 4, 4), {0, 5, 21, 63});
  EXPECT_TRUE(map->integrate(u));
  return map;
}

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kCanLimitAddressSpace = false;  // ASan reserves terabytes of shadow memory
#else
constexpr bool kCanLimitAddressSpace = true;
#endif

/// Runs @p work in a child process whose address space may grow by at most
/// @p extra_bytes; true if it finished normally with exit code 0.
bool runsWithin(size_t extra_bytes, const std::function<bool()>& work) {
  const pid_t child = fork();
  if (child == 0) {
    if (kCanLimitAddressSpace) {
      std::ifstream statm("/proc/self/statm");
      size_t pages = 0;
      statm >> pages;
      const rlim_t limit = static_cast<rlim_t>(pages) * static_cast<rlim_t>(sysconf(_SC_PAGESIZE)) + extra_bytes;
      const rlimit r{limit, limit};
      setrlimit(RLIMIT_AS, &r);
    }
    bool ok = false;
    try {
      ok = work();
    } catch (...) {
      ok = false;
    }
    _exit(ok ? 0 : 1);
  }
  int status = 0;
  waitpid(child, &status, 0);
  return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

/// True if a map on one thread that lets in any box (max_update_cells
/// raised) fuses @p u within @p extra_bytes more address space and then
/// holds @p leaves leaves.
bool fusesWithin(size_t extra_bytes, const GridUpdate& u, size_t leaves) {
  return runsWithin(extra_bytes, [&] {
    MapAccumulatorConfig config;
    config.max_update_cells = kIntMax;
    config.threads = 1;
    MapAccumulator map(config);
    return map.integrate(u) && map.tree().getNumLeafNodes() == leaves;
  });
}

}  // namespace

// A one-cell update claiming 1 x 65535 x 65535 cells (17 GB of rows before
// the fix): the walk over its blocks needs memory for its one cell only.
TEST(HostileUpdates, WorkFollowsTheCellsNotTheClaimedBox) {
  const Eigen::Vector3i size(1, 65535, 65535);
  const uint32_t last = static_cast<uint32_t>(uint64_t{65535} * 65535 - 1);
  const GridUpdate u = claimedBox(Eigen::Vector3i(-32768, -32768, -32768), size, {0, 70000, last});
  ASSERT_TRUE(u.isConsistent());
  EXPECT_TRUE(runsWithin(size_t{64} << 20, [&] {
    int blocks = 0, cells = 0;
    u.forEachSiblingBlock([&](const Eigen::Vector3i&, const float(&values)[8]) {
      ++blocks;
      for (float v : values) cells += v == 1.0f;
    });
    return blocks == 3 && cells == 3;
  })) << "the walk over three cells needed more than 64 MB";
  // And the accumulator refuses the claim by its size before any walk.
  auto map = smallMap();
  const std::string before = fullTree(map->tree());
  std::string why;
  EXPECT_FALSE(map->integrate(u, &why));
  EXPECT_NE(why.find("max_update_cells"), std::string::npos) << why;
  EXPECT_EQ(fullTree(map->tree()), before);
}

// A three-cell update claiming 1 x 46340 x 46340 cells (nearly 2^31, with
// max_update_cells raised to let it in): the fusion works on the rows of
// blocks that its cells lie in, not on the box's 8.4 M rows of blocks.
TEST(HostileUpdates, TheFusionWorksOnTheCellsNotTheClaimedBox) {
  const Eigen::Vector3i size(1, 46340, 46340);
  const uint32_t last = static_cast<uint32_t>(uint64_t{46340} * 46340 - 1);
  const GridUpdate u = claimedBox(Eigen::Vector3i(0, -23170, -23170), size, {0, 70000, last});
  ASSERT_TRUE(u.isConsistent());
  EXPECT_TRUE(fusesWithin(size_t{64} << 20, u, 3)) << "fusing three cells needed more than 64 MB, or failed";
}

// One cell in each 16^3 block of a 640^3 box (64000 blocks, with
// max_update_cells raised to let it in): 1 GB of the fusion's cache before
// the cache kept its bound within an update; now it writes its blocks back
// and lets them go when the next row of blocks might pass kMaxBlocks (68 MB).
TEST(HostileUpdates, ASparseUpdateKeepsTheCacheWithinItsBound) {
  constexpr int kEdge = 640, kBlocksPerEdge = kEdge / FusionCache::kEdge;
  std::vector<uint32_t> cells;
  for (int z = 0; z < kBlocksPerEdge; ++z)
    for (int y = 0; y < kBlocksPerEdge; ++y)
      for (int x = 0; x < kBlocksPerEdge; ++x)
        cells.push_back(static_cast<uint32_t>((int64_t{z} * kEdge * kEdge + int64_t{y} * kEdge + x) *
                                              FusionCache::kEdge));  // each block's first cell
  const GridUpdate u = claimedBox(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i::Constant(kEdge), cells);
  ASSERT_TRUE(u.isConsistent());
  EXPECT_TRUE(fusesWithin(size_t{192} << 20, u, cells.size()))
      << "fusing one cell per block needed more than 192 MB, or failed";
}

// Runs of no cells, in a box of no width or after a cell: nothing more to
// fuse, and no division by the box's width (a fuzzer's find).
TEST(HostileUpdates, RunsOfNoCellsFuseNothing) {
  auto map = smallMap();
  const std::string before = fullTree(map->tree());
  GridUpdate empty = claimedBox(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(0, 4, 4), {});
  empty.run_start.push_back(0);
  empty.run_length.push_back(0);
  map->integrate(empty);  // taken or refused: either way nothing changes
  EXPECT_EQ(fullTree(map->tree()), before);
  GridUpdate one = claimedBox(Eigen::Vector3i(8, 0, 0), Eigen::Vector3i(4, 4, 4), {0});
  one.run_start.push_back(5);
  one.run_length.push_back(0);
  map->integrate(one);
  const octomap::OcTreeNode* cell = map->tree().search(octomap::OcTreeKey(32768 + 8, 32768, 32768));
  if (one.isConsistent()) {
    ASSERT_NE(cell, nullptr);
    EXPECT_EQ(map->tree().getNumLeafNodes(), 5u);
  } else {
    EXPECT_EQ(fullTree(map->tree()), before);
  }
}

// Two cells at the ends of a 2^31 - 1 wide row: no int overflow, and the
// walk visits exactly two blocks, each with its one cell and nothing else.
TEST(HostileUpdates, AFullWidthRowDoesNotOverflow) {
  const GridUpdate u = claimedBox(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(kIntMax, 1, 1), {0, kIntMax - 1u});
  ASSERT_TRUE(u.isConsistent());
  const auto walkVisitsTheTwoBlocks = [&] {
    std::vector<std::pair<Eigen::Vector3i, std::array<float, 8>>> seen;
    u.forEachSiblingBlock([&](const Eigen::Vector3i& g, const float(&values)[8]) {
      std::array<float, 8> v;
      std::copy(values, values + 8, v.begin());
      seen.emplace_back(g, v);
    });
    // Cell 0 and cell 2^31 - 2 (even) are each the first cell (x, y, z even)
    // of their block; the other seven are not in the update (NaN), the
    // second block's x + 1 being past the row's end.
    const Eigen::Vector3i expected[2] = {Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(kIntMax - 1, 0, 0)};
    bool ok = seen.size() == 2;
    for (size_t k = 0; ok && k < 2; ++k) {
      ok = seen[k].first == expected[k] && seen[k].second[0] == 1.0f;
      for (int i = 1; i < 8; ++i) ok = ok && std::isnan(seen[k].second[i]);
    }
    if (!ok) {  // the child's own report: the parent sees only its exit status
      std::fprintf(stderr, "%zu blocks visited, expected 2:\n", seen.size());
      for (const auto& [g, v] : seen)
        std::fprintf(stderr, "  (%d, %d, %d): %g %g %g %g %g %g %g %g\n", g.x(), g.y(), g.z(), v[0], v[1], v[2], v[3],
                     v[4], v[5], v[6], v[7]);
    }
    return ok;
  };
  EXPECT_TRUE(runsWithin(size_t{64} << 20, walkVisitsTheTwoBlocks)) << "out of memory or other blocks (listed above)";
  auto map = smallMap();
  const std::string before = fullTree(map->tree());
  EXPECT_FALSE(map->integrate(u));
  EXPECT_EQ(fullTree(map->tree()), before);
}

// A box whose indices would wrap past 2^31 is inconsistent; one that stays
// in int but leaves the key range is refused; neither lands near the origin.
TEST(HostileUpdates, ABoxFarOutsideTheKeyRangeIsRefused) {
  auto map = smallMap();
  const std::string before = fullTree(map->tree());
  std::string why;
  GridUpdate wrapping = claimedBox(Eigen::Vector3i(kIntMax, 0, 0), Eigen::Vector3i(kIntMax, 1, 1),
                                   {kIntMax - 4u, kIntMax - 3u, kIntMax - 2u, kIntMax - 1u});
  EXPECT_FALSE(wrapping.isConsistent(&why));
  EXPECT_NE(why.find("32-bit index range"), std::string::npos) << why;
  EXPECT_FALSE(map->integrate(wrapping));
  GridUpdate far = claimedBox(Eigen::Vector3i(kIntMax - 100, 0, 0), Eigen::Vector3i(100, 1, 1), {96, 97, 98, 99});
  EXPECT_TRUE(far.isConsistent());
  EXPECT_FALSE(map->integrate(far, &why));
  EXPECT_NE(why.find("key range"), std::string::npos) << why;
  EXPECT_EQ(fullTree(map->tree()), before);
  EXPECT_EQ(map->updates(), 1u);
}

// Each of these is refused and leaves the map as it was.
TEST(HostileUpdates, EveryMalformedUpdateLeavesTheMapUnchanged) {
  auto map = smallMap();
  const std::string before = fullTree(map->tree());
  const GridUpdate good = claimedBox(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(4, 4, 4), {1, 2, 3});
  std::vector<std::pair<const char*, std::function<void(GridUpdate&)>>> cases = {
      {"resolution 0", [](GridUpdate& u) { u.resolution_m = 0.0; }},
      {"resolution NaN", [](GridUpdate& u) { u.resolution_m = std::nan(""); }},
      {"another resolution", [](GridUpdate& u) { u.resolution_m = 0.5; }},
      {"negative size", [](GridUpdate& u) { u.size.y() = -4; }},
      {"runs unsorted", [](GridUpdate& u) { std::swap(u.run_start[0], u.run_start[2]); }},
      {"run past the box", [](GridUpdate& u) { u.run_start[2] = 64; }},
      {"more values than cells", [](GridUpdate& u) { u.log_odds.push_back(0.5f); }},
      {"fewer lengths than starts", [](GridUpdate& u) { u.run_length.pop_back(); }},
      {"an infinite value", [](GridUpdate& u) { u.log_odds[1] = std::numeric_limits<float>::infinity(); }},
      {"sensor origin NaN", [](GridUpdate& u) { u.W_sensor_origin.y() = std::nan(""); }},
      {"sensor origin 1 km from the box", [](GridUpdate& u) { u.W_sensor_origin.x() = 1000.0; }},
      {"box over max_update_cells", [](GridUpdate& u) { u.size = Eigen::Vector3i(1024, 1024, 65); }},
  };
  for (const auto& c : cases) {
    GridUpdate bad = good;
    c.second(bad);
    std::string why;
    EXPECT_FALSE(map->integrate(bad, &why)) << c.first;
    EXPECT_FALSE(why.empty()) << c.first;
    EXPECT_EQ(fullTree(map->tree()), before) << c.first;
  }
  EXPECT_EQ(map->updates(), 1u);
  EXPECT_TRUE(map->integrate(good));  // and a good one still goes in
}

namespace {

/// A tmpfs of @p bytes mounted at a new directory (needs root); unmounted at the end.
class SmallFilesystem {
 public:
  explicit SmallFilesystem(size_t bytes) {
    char pattern[] = "/tmp/stereo_occupancy_fullXXXXXX";
    if (!mkdtemp(pattern)) return;
    dir_ = pattern;
    const std::string options = "size=" + std::to_string(bytes);
    mounted_ = ::mount("tmpfs", dir_.c_str(), "tmpfs", 0, options.c_str()) == 0;
    if (!mounted_) error_ = std::strerror(errno);
  }
  ~SmallFilesystem() {
    if (mounted_) ::umount2(dir_.c_str(), MNT_DETACH);
    if (!dir_.empty()) ::rmdir(dir_.c_str());
  }
  bool mounted() const { return mounted_; }
  const std::string& error() const { return error_; }
  const std::string& dir() const { return dir_; }

  /// Writes a file until the filesystem is full.
  void fill() const {
    std::FILE* f = std::fopen((dir_ + "/filler").c_str(), "wb");
    if (!f) return;
    const std::vector<char> block(4096, 'x');
    while (std::fwrite(block.data(), 1, block.size(), f) == block.size()) {
    }
    std::fclose(f);
  }

 private:
  std::string dir_, error_;
  bool mounted_ = false;
};

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

}  // namespace

// With the disk full, a save throws naming ENOSPC, the previous files stay
// byte for byte, and no temporary file is left.
TEST(HostileUpdates, ASaveOnAFullDiskFailsAndKeepsThePreviousFile) {
  SmallFilesystem fs(size_t{4} << 20);
  if (!fs.mounted()) {
    // CI runs as root (and says CI=true): there a tmpfs that does not mount
    // is a failure, since the test command counts a skip as a pass.
    const char* ci = std::getenv("CI");
    if (::geteuid() == 0 || (ci && std::string(ci) == "true"))
      FAIL() << "cannot mount a tmpfs " << (::geteuid() == 0 ? "as root" : "with CI=true") << ": " << fs.error();
    GTEST_SKIP() << "cannot mount a tmpfs (needs root; a failure as root or with CI=true): " << fs.error();
  }
  auto map = smallMap();
  const std::vector<std::string> paths = map->save(fs.dir(), "map");
  const std::string bt = readFile(paths[0]), ot = readFile(paths[1]);
  ASSERT_FALSE(bt.empty());
  // A map larger than what the disk has left.
  GridUpdate dense = claimedBox(Eigen::Vector3i(-64, -64, -8), Eigen::Vector3i(128, 128, 16), {});
  for (uint32_t i = 0; i < 128 * 128 * 16; i += 1) {
    dense.run_start.push_back(i);
    dense.run_length.push_back(1);
    dense.log_odds.push_back((i * 2654435761u) % 7 == 0 ? 2.0f : -0.4f - 0.001f * static_cast<float>(i % 97));
  }
  dense.W_sensor_origin = Eigen::Vector3d::Zero();
  ASSERT_TRUE(map->integrate(dense));
  fs.fill();
  try {
    map->save(fs.dir(), "map");
    FAIL() << "the save on a full disk reported success";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(std::strerror(ENOSPC)), std::string::npos) << e.what();
  }
  EXPECT_EQ(readFile(paths[0]), bt);
  EXPECT_EQ(readFile(paths[1]), ot);
  octomap::OcTree previous(paths[0]);
  EXPECT_GT(previous.getNumLeafNodes(), 0u);
  EXPECT_EQ(removeStaleTemporaries(paths[0]) + removeStaleTemporaries(paths[1]), 0);
  struct stat st {};
  EXPECT_NE(::stat((paths[0] + ".tmp" + std::to_string(::getpid())).c_str(), &st), 0) << "a temporary file was left";
  EXPECT_NE(::stat((paths[1] + ".tmp" + std::to_string(::getpid())).c_str(), &st), 0) << "a temporary file was left";
  // Room again: the same map saves.
  std::remove((fs.dir() + "/filler").c_str());
  ASSERT_NO_THROW(map->save(fs.dir(), "map"));
  std::unique_ptr<octomap::AbstractOcTree> saved(octomap::AbstractOcTree::read(paths[1]));
  auto* full = dynamic_cast<octomap::OcTree*>(saved.get());
  ASSERT_NE(full, nullptr);
  EXPECT_EQ(full->getNumLeafNodes(), map->tree().getNumLeafNodes());
}

// A directory the process may not write: the reason is in the message.
TEST(HostileUpdates, ASaveNamesWhyItFailed) {
  auto map = smallMap();
  try {
    map->save("/nonexistent_dir_for_test", "m");
    FAIL() << "a save into a missing directory reported success";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(std::strerror(ENOENT)), std::string::npos) << e.what();
  }
}
