// The run-length encoded update of a local grid (grid_update.h): encoding,
// consistency checks and the sibling-block walk the fusion uses.

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "avx2_paths.h"
#include "stereo_occupancy/grid_update.h"

using namespace stereo_occupancy;

TEST(GridUpdate, EncodesKnownCellsAsRuns) {
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(10, 20, 30), Eigen::Vector3i(4, 3, 2), 0.5);
  for (int x = 1; x < 4; ++x) grid.at(x, 1, 0) = 0.5f;  // one run of 3
  grid.at(0, 0, 1) = -0.2f;                             // a run of 1
  GridUpdate u;
  encodeGridUpdate(grid, Eigen::Vector3d(1, 2, 3), &u);
  EXPECT_EQ(u.run_start, (std::vector<uint32_t>{5, 12}));
  EXPECT_EQ(u.run_length, (std::vector<uint32_t>{3, 1}));
  EXPECT_EQ(u.numCells(), 4u);
  std::string why;
  EXPECT_TRUE(u.isConsistent(&why)) << why;
  int seen = 0;
  u.forEachCell([&](const Eigen::Vector3i& g, float v) {
    if (seen < 3) {
      EXPECT_EQ(g, Eigen::Vector3i(11 + seen, 21, 30));
      EXPECT_FLOAT_EQ(v, 0.5f);
    } else {
      EXPECT_EQ(g, Eigen::Vector3i(10, 20, 31));
    }
    ++seen;
  });
  EXPECT_EQ(seen, 4);
  GridUpdate bad = u;
  bad.run_start = {5, 6};  // overlapping runs
  EXPECT_FALSE(bad.isConsistent(&why));
  bad = u;
  bad.size = Eigen::Vector3i(2, 2, 2);  // runs past the grid's end
  EXPECT_FALSE(bad.isConsistent(&why));
}

// On a pool, the grid's parts are scanned at once and their runs joined:
// the update is one scan's bit for bit, with runs across the parts'
// borders (a part is 2^16 cells), a run across a whole part, a part all
// unknown, runs at the grid's ends, zeros inside runs, and a grid just
// above one part.
TEST(GridUpdate, EncodingOnAPoolEqualsOneScan) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> value(-2.0f, 3.0f);
  const std::vector<Eigen::Vector3i> sizes = {{64, 32, 40}, {33, 47, 61}, {256, 256, 2}, {65537, 1, 1}, {100, 70, 40}};
  int border_runs = 0;
  for (const Eigen::Vector3i& size : sizes) {
    LocalGrid grid;
    grid.reset(Eigen::Vector3i(-5, 7, 100), size, 0.25);
    float* cells = grid.data();
    const size_t n = grid.numCells();
    // Stretches of known cells (some zeros among them) between unknown gaps, of 1 to 4915 cells.
    std::uniform_int_distribution<size_t> stretch(1, 3 * 65536 / 40);
    for (size_t i = 0; i < n;) {
      const size_t known = std::min(n - i, stretch(rng)), unknown = std::min(n - i - known, stretch(rng));
      for (size_t k = i; k < i + known; ++k) cells[k] = rng() % 13 == 0 ? 0.0f : value(rng);
      i += known + unknown;
    }
    for (size_t k = 65530; k < std::min(n, size_t{65542}); ++k) cells[k] = 1.0f;  // across the first border
    if (n > 3 * 65536) {  // one run over a whole part and two borders; the part after it unknown
      for (size_t k = 65536 - 3; k < 2 * 65536 + 3; ++k) cells[k] = 2.0f;
      for (size_t k = 2 * 65536 + 3; k < 3 * 65536; ++k) cells[k] = LocalGrid::kUnknown;
    }
    cells[0] = cells[n - 1] = 0.5f;
    GridUpdate one;
    encodeGridUpdate(grid, Eigen::Vector3d(1, 2, 3), &one);
    for (const size_t border : {size_t{65536}, size_t{131072}})
      for (size_t k = 0; k < one.run_start.size(); ++k)
        border_runs += one.run_start[k] < border && one.run_start[k] + one.run_length[k] > border;
    for (unsigned threads : {2u, 3u}) {
      WorkerPool pool(threads);
      GridUpdate many;
      many.run_start = {1, 2, 3};  // what was there is replaced
      encodeGridUpdate(grid, Eigen::Vector3d(1, 2, 3), &many, &pool);
      EXPECT_EQ(many.run_start, one.run_start) << size.transpose() << ", " << threads << " threads";
      EXPECT_EQ(many.run_length, one.run_length);
      ASSERT_EQ(many.log_odds.size(), one.log_odds.size());
      EXPECT_EQ(0, std::memcmp(many.log_odds.data(), one.log_odds.data(), one.log_odds.size() * sizeof(float)));
      EXPECT_EQ(many.origin_index, one.origin_index);
      EXPECT_EQ(many.size, one.size);
      std::string why;
      EXPECT_TRUE(many.isConsistent(&why)) << why;
    }
  }
  EXPECT_GE(border_runs, 4);  // the joins were tested, one across two borders
  LocalGrid unknown;          // nothing known: no run
  unknown.reset(Eigen::Vector3i::Zero(), Eigen::Vector3i(300, 300, 2), 0.25);
  WorkerPool pool(2);
  GridUpdate none;
  encodeGridUpdate(unknown, Eigen::Vector3d::Zero(), &none, &pool);
  EXPECT_TRUE(none.run_start.empty() && none.log_odds.empty());
}

// The runs are the maximal stretches of informative cells (known, not 0),
// cell for cell as a plain scan finds them: short runs and gaps of every
// length around the 16-cell blocks the encoding reads at once, zeros (also
// -0) inside known stretches, and grids whose size is no multiple of 16.
// Every other round has long stretches with few zeros, so that four blocks
// at once are all empty or all in a run, across the batches of blocks whose
// masks the encoding computes together (4096 cells); the last round has NaN
// and +inf cells, which hold information (an update with them is refused
// later, by isConsistent()). With the AVX2 paths (where the CPU has them)
// and without.
TEST(GridUpdate, RunsAreThoseOfACellByCellScan) {
  const AllowAvx2AtEnd restore;
  for (const bool avx2 : {true, false}) {
    allowAvx2(avx2);
    std::mt19937 rng(11);
    std::uniform_int_distribution<int> short_length(1, 40), long_length(60, 400);
    std::uniform_real_distribution<float> value(-2.0f, 3.0f);
    for (const Eigen::Vector3i& size : {Eigen::Vector3i(37, 11, 5), Eigen::Vector3i(16, 4, 2), Eigen::Vector3i(7, 1, 1),
                                        Eigen::Vector3i(200, 9, 3), Eigen::Vector3i(257, 37, 3)}) {
      for (int round = 0; round < 20; ++round) {
        LocalGrid grid;
        grid.reset(Eigen::Vector3i::Zero(), size, 0.25);
        float* cells = grid.data();
        const size_t n = grid.numCells();
        const bool long_stretches = round % 2 == 1, non_finite = round == 19;
        const unsigned zero_one_in = long_stretches ? 500 : 9;
        auto known = [&]() {
          const unsigned kind = rng() % zero_one_in;
          if (kind == 0) return rng() % 2 ? 0.0f : -0.0f;
          if (non_finite && kind == 1) return rng() % 2 ? std::numeric_limits<float>::quiet_NaN() : INFINITY;
          return value(rng);
        };
        for (size_t i = 0; i < n;) {  // alternating stretches: known (some zeros) and unknown
          const int stretch = long_stretches ? long_length(rng) : short_length(rng);
          const size_t end = std::min(n, i + static_cast<size_t>(stretch));
          const bool is_known = rng() % 2 == 0;
          for (; i < end; ++i) cells[i] = is_known ? known() : LocalGrid::kUnknown;
        }
        std::vector<uint32_t> start, run_length;
        bool finite = true;
        for (size_t i = 0; i < n; ++i) {
          const bool informative = cells[i] != LocalGrid::kUnknown && cells[i] != 0.0f;  // NaN: informative
          finite &= !informative || std::isfinite(cells[i]);
          const bool continues = !start.empty() && start.back() + run_length.back() == i;
          if (!informative) continue;
          if (continues) {
            ++run_length.back();
          } else {
            start.push_back(static_cast<uint32_t>(i));
            run_length.push_back(1);
          }
        }
        GridUpdate u;
        encodeGridUpdate(grid, Eigen::Vector3d::Zero(), &u);
        ASSERT_EQ(u.run_start, start) << size.transpose() << ", round " << round << ", avx2 " << avx2;
        ASSERT_EQ(u.run_length, run_length);
        std::string why;
        EXPECT_EQ(u.isConsistent(&why), finite) << why;
      }
    }
  }
}

// Every value is checked, wherever it stands; finite extremes pass.
TEST(GridUpdate, RefusesNonFiniteValues) {
  LocalGrid grid;
  grid.reset(Eigen::Vector3i(0, 0, 0), Eigen::Vector3i(37, 1, 1), 0.25);
  for (int x = 0; x < 37; ++x) grid.at(x, 0, 0) = 0.1f * (x + 1);
  GridUpdate u;
  encodeGridUpdate(grid, Eigen::Vector3d::Zero(), &u);
  ASSERT_EQ(u.numCells(), 37u);
  std::string why;
  const float finite[] = {std::numeric_limits<float>::max(), -std::numeric_limits<float>::max(),
                          std::numeric_limits<float>::denorm_min(), -0.0f};
  for (float v : finite) {
    GridUpdate ok = u;
    ok.log_odds[36] = v;
    EXPECT_TRUE(ok.isConsistent(&why)) << v << ": " << why;
  }
  const float not_finite[] = {std::numeric_limits<float>::quiet_NaN(), -std::numeric_limits<float>::quiet_NaN(),
                              std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()};
  for (float v : not_finite)
    for (size_t at : {size_t{0}, size_t{17}, size_t{36}}) {
      GridUpdate bad = u;
      bad.log_odds[at] = v;
      why.clear();
      EXPECT_FALSE(bad.isConsistent(&why)) << v << " at " << at;
      EXPECT_NE(why.find("not finite"), std::string::npos) << why;
    }
}

// The order the accumulator walks an update in: every cell once, with its
// value, and the eight cells of each even-aligned 2x2x2 block one after
// another, whatever the parity of the grid's origin and sizes, also for
// runs that go on into the next row.
TEST(GridUpdate, SiblingOrderVisitsEveryCellOnceBlockByBlock) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 40; ++trial) {
    LocalGrid grid;
    const Eigen::Vector3i origin(static_cast<int>(rng() % 21) - 10, static_cast<int>(rng() % 21) - 10,
                                 static_cast<int>(rng() % 21) - 10);
    const Eigen::Vector3i size(1 + rng() % 9, 1 + rng() % 7, 1 + rng() % 6);
    grid.reset(origin, size, 0.25);
    const double density = (rng() % 100) / 100.0;
    for (int z = 0; z < size.z(); ++z)
      for (int y = 0; y < size.y(); ++y)
        for (int x = 0; x < size.x(); ++x)
          if ((rng() % 1000) / 1000.0 < density) grid.at(x, y, z) = 0.01f * static_cast<float>(1 + rng() % 300);
    GridUpdate u;
    encodeGridUpdate(grid, Eigen::Vector3d::Zero(), &u);
    std::map<std::array<int, 3>, float> expected, seen;
    u.forEachCell([&](const Eigen::Vector3i& g, float v) { expected[{g.x(), g.y(), g.z()}] = v; });
    std::set<std::array<int, 3>> finished_blocks;
    std::array<int, 3> block{};
    bool first = true;
    u.forEachCellBySiblings([&](const Eigen::Vector3i& g, float v) {
      const std::array<int, 3> cell{g.x(), g.y(), g.z()};
      EXPECT_EQ(seen.count(cell), 0u) << "a cell twice";
      seen[cell] = v;
      const std::array<int, 3> b{g.x() >> 1, g.y() >> 1, g.z() >> 1};  // floor(g / 2): even-aligned blocks
      if (!first && b != block) {
        EXPECT_EQ(finished_blocks.count(b), 0u) << "a block visited again, trial " << trial;
        finished_blocks.insert(block);
      }
      block = b;
      first = false;
    });
    ASSERT_EQ(seen, expected) << "trial " << trial;
    // The same cells a block at a time: blocks at even global indices, each once and holding a cell.
    std::map<std::array<int, 3>, float> from_blocks;
    std::set<std::array<int, 3>> blocks;
    u.forEachSiblingBlock([&](const Eigen::Vector3i& g, const float(&values)[8]) {
      EXPECT_TRUE(((g.x() | g.y() | g.z()) & 1) == 0) << g.transpose();
      EXPECT_TRUE(blocks.insert({g.x(), g.y(), g.z()}).second) << "a block twice";
      int held = 0;
      for (int i = 0; i < 8; ++i)
        if (values[i] == values[i]) {
          ++held;
          from_blocks[{g.x() + (i & 1), g.y() + ((i >> 1) & 1), g.z() + (i >> 2)}] = values[i];
        }
      EXPECT_GT(held, 0);
    });
    ASSERT_EQ(from_blocks, expected) << "trial " << trial;
  }
}
