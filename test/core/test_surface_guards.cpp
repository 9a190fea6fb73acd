// The surface profile's guards (surface_guards.h) on grids set by hand:
// which cells each guard changes, on a pool's workers as on one thread.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/surface_guards.h"
#include "stereo_occupancy/worker_pool.h"

using namespace stereo_occupancy;

namespace {
constexpr double kCell = 0.25;

/// The sky and gap guards (the edge guard off).
SurfaceGuards skyAndGap(float sky, int sky_radius, float free, int gap_radius) {
  SurfaceGuards guards;
  guards.sky_value = sky;
  guards.sky_radius = sky_radius;
  guards.free_value = free;
  guards.gap_radius = gap_radius;
  return guards;
}

/// A grid of @p size whose cells take one of @p kinds (6 values) at random,
/// with runs of 1-5 hits along x, a run starting at a cell with probability
/// @p run_start.
LocalGrid randomGridWithRuns(const Eigen::Vector3i& size, const float (&kinds)[6], float hit, double run_start,
                             unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> kind(0, 5), run_length(1, 5);
  std::bernoulli_distribution starts_run(run_start);
  LocalGrid grid;
  grid.reset({0, 0, 0}, size, kCell);
  for (size_t i = 0; i < grid.numCells(); ++i) grid.data()[i] = kinds[kind(rng)];
  for (int z = 0; z < size.z(); ++z)
    for (int y = 0; y < size.y(); ++y)
      for (int x = 0; x < size.x(); ++x)
        if (starts_run(rng))
          for (int end = std::min(size.x(), x + run_length(rng)); x < end; ++x) grid.at(x, y, z) = hit;
  return grid;
}

/// The flags of the blocks that hold a cell of value @p hit, as the lines flag them (LineDrawer::hitBlocks()).
std::vector<uint8_t> hitBlockFlags(const LocalGrid& grid, float hit) {
  std::vector<uint8_t> flags(grid.numBlocks(), 0);
  const Eigen::Vector3i n = grid.size();
  for (int z = 0; z < n.z(); ++z)
    for (int y = 0; y < n.y(); ++y)
      for (int x = 0; x < n.x(); ++x)
        if (grid.at(x, y, z) == hit)
          flags[(static_cast<size_t>(z) * n.y() + y) * grid.blocksPerRow() + x / kInformationBlock] = 1;
  return flags;
}
}  // namespace

// The guard itself: only cells holding exactly the given value, only within
// the radius of an occupied cell, and nothing at radius 0.
TEST(SurfaceGuards, SilenceNearOccupiedTouchesOnlyTheSkyNearHits) {
  LocalGrid grid;
  grid.reset({0, 0, 0}, {8, 8, 8}, kCell);
  const float sky = -0.8f, free = -0.7f;
  for (size_t i = 0; i < grid.numCells(); ++i) grid.data()[i] = sky;
  grid.at(4, 4, 4) = 0.9f;
  grid.at(5, 4, 4) = free;
  EXPECT_EQ(silenceNearOccupied(&grid, sky, 0), 0u);
  EXPECT_EQ(silenceNearOccupied(&grid, sky, 1), 25u);  // the 26 neighbours but the one measured free
  EXPECT_EQ(grid.at(3, 3, 3), 0.0f);
  EXPECT_EQ(grid.at(5, 4, 4), free);
  EXPECT_EQ(grid.at(2, 4, 4), sky);
  EXPECT_EQ(grid.at(4, 4, 4), 0.9f);
  grid.at(0, 0, 0) = 0.9f;  // at the grid's corner: stays inside
  // Around (4, 4, 4) the 124 within two cells but the 26 within one; around
  // the corner 26, one of them, (2, 2, 2), shared.
  EXPECT_EQ(silenceNearOccupied(&grid, sky, 2), (124u - 26u) + 26u - 1u);
  // Silencing 0 changes no cell, and counts none (the zeros it made above
  // lie next to two occupied cells).
  EXPECT_EQ(silenceNearOccupied(&grid, 0.0f, 2), 0u);
  EXPECT_EQ(silenceNearOccupied(&grid, -0.0f, 1), 0u);
}

// The guard's pass itself: only zeros, only farther than the radius from
// every occupied cell; nothing at radius 0; the same on a pool's workers.
TEST(SurfaceGuards, FreeZerosAwayFromOccupiedKeepsZerosNearHits) {
  LocalGrid grid;
  grid.reset({0, 0, 0}, {72, 64, 64}, kCell);  // more cells than one part of the pool's pass
  const float free = -0.85f, other = -0.7f;
  grid.at(10, 10, 10) = 0.9f;
  grid.at(11, 10, 10) = 0.0f;  // Chebyshev distances 1, 2, 3 from the hit
  grid.at(12, 11, 10) = 0.0f;
  grid.at(13, 10, 8) = 0.0f;
  grid.at(9, 10, 10) = other;  // not a zero: kept
  grid.at(70, 60, 60) = 0.0f;  // far from every hit
  const LocalGrid drawn = grid;
  EXPECT_EQ(freeZerosAwayFromOccupied(&grid, free, 0), 0u);
  EXPECT_EQ(std::memcmp(grid.data(), drawn.data(), drawn.numCells() * sizeof(float)), 0);
  EXPECT_EQ(freeZerosAwayFromOccupied(&grid, free, 1), 3u);
  EXPECT_EQ(grid.at(11, 10, 10), 0.0f);
  EXPECT_EQ(grid.at(12, 11, 10), free);
  EXPECT_EQ(grid.at(13, 10, 8), free);
  EXPECT_EQ(grid.at(70, 60, 60), free);
  EXPECT_EQ(grid.at(9, 10, 10), other);
  EXPECT_EQ(grid.at(10, 10, 10), 0.9f);
  EXPECT_EQ(grid.at(0, 0, 0), LocalGrid::kUnknown);
  LocalGrid radius_two = drawn;
  EXPECT_EQ(freeZerosAwayFromOccupied(&radius_two, free, 2), 2u);
  EXPECT_EQ(radius_two.at(12, 11, 10), 0.0f);
  EXPECT_EQ(radius_two.at(13, 10, 8), free);
  for (unsigned threads : {2u, 3u}) {
    WorkerPool pool(threads);
    LocalGrid shared = drawn;
    EXPECT_EQ(freeZerosAwayFromOccupied(&shared, free, 1, &pool), 3u) << threads;
    EXPECT_EQ(std::memcmp(shared.data(), grid.data(), grid.numCells() * sizeof(float)), 0) << threads;
  }
}

// Both guards in one pass are the gap guard, then the sky guard: the same
// grid for every pair of radii, on one thread and on a pool.
TEST(SurfaceGuards, BothGuardsAtOnceAreTheGapGuardThenTheSkyGuard) {
  const float free = -0.85f, sky = std::nextafter(free, -1.0f);
  LocalGrid drawn;
  drawn.reset({0, 0, 0}, {73, 63, 65}, kCell);  // not a whole number of 16-cell blocks
  // Hits, and around them zeros, sky and free cells at Chebyshev distances
  // 1-3, also in other slabs of z (the pool's chunks are slabs).
  const float values[] = {0.0f, sky, free, 0.0f, sky};
  int n = 0;
  for (int z = 4; z < 60; z += 9)
    for (int y = 4; y < 60; y += 7)
      for (int x = 4; x < 68; x += 8) {
        drawn.at(x, y, z) = 0.9f;
        for (int d = 1; d <= 3; ++d) {
          drawn.at(x + d, y, z) = values[n++ % 5];
          drawn.at(x - d, y + (d > 1), z) = values[n++ % 5];
          drawn.at(x, y - 1, z + d) = values[n++ % 5];
        }
      }
  drawn.at(72, 62, 64) = 0.0f;  // far from every hit, in the grid's last cell
  for (int sky_radius : {0, 1, 2})
    for (int gap_radius : {0, 1, 2}) {
      LocalGrid expected = drawn;
      const size_t freed = freeZerosAwayFromOccupied(&expected, free, gap_radius);
      silenceNearOccupied(&expected, sky, sky_radius);
      for (unsigned threads : {1u, 2u, 3u}) {
        WorkerPool pool(threads);
        LocalGrid both = drawn;
        EXPECT_EQ(applySurfaceGuards(&both, skyAndGap(sky, sky_radius, free, gap_radius), &pool), freed)
            << sky_radius << gap_radius << threads;
        EXPECT_EQ(std::memcmp(both.data(), expected.data(), expected.numCells() * sizeof(float)), 0)
            << sky_radius << " " << gap_radius << " " << threads;
        EXPECT_EQ(both.at(72, 62, 64), gap_radius > 0 ? free : 0.0f);  // the last, partial block too
      }
    }
  LocalGrid one_guard = drawn;
  EXPECT_GT(applySurfaceGuards(&one_guard, skyAndGap(sky, 1, free, 1)), 100u);  // zeros freed
  EXPECT_GT(silenceNearOccupied(&drawn, sky, 1), 100u);  // and sky silenced: both guards act here
}

// Both guards against a plain reference on random grids with runs of
// adjacent hits in a row (the guard visits a run's neighbourhood once):
// sky within sky_radius of a hit becomes 0, a zero within gap_radius of a
// hit stays 0, every other zero becomes free; radii that differ too, and
// the sky guard alone (the default). With the blocks that hold hits
// flagged (as the lines flag them) the guards look only there: the same.
TEST(SurfaceGuards, BothGuardsMatchAPlainReferenceAroundRunsOfHits) {
  const float free = -0.85f, sky = std::nextafter(free, -1.0f), hit = 0.9f;
  const float kinds[] = {LocalGrid::kUnknown, sky, sky, free, 0.0f, 0.0f};
  const LocalGrid drawn = randomGridWithRuns({37, 6, 9}, kinds, hit, 0.04, 11);
  const Eigen::Vector3i n = drawn.size();
  std::vector<int> nearest(drawn.numCells(), 1 << 20);  // Chebyshev distance to the nearest hit
  for (int z = 0; z < n.z(); ++z)
    for (int y = 0; y < n.y(); ++y)
      for (int x = 0; x < n.x(); ++x)
        for (int k = 0; k < n.z(); ++k)
          for (int j = 0; j < n.y(); ++j)
            for (int h = 0; h < n.x(); ++h)
              if (drawn.at(h, j, k) == hit) {
                int& best = nearest[drawn.linearIndex(x, y, z)];
                best = std::min(best, std::max({std::abs(h - x), std::abs(j - y), std::abs(k - z)}));
              }
  auto nearestHit = [&](int x, int y, int z) { return nearest[drawn.linearIndex(x, y, z)]; };
  const std::vector<uint8_t> hit_blocks = hitBlockFlags(drawn, hit);  // 3 blocks a row, the last of 5 cells
  for (const auto& [sky_radius, gap_radius] :
       {std::pair{1, 2}, std::pair{2, 1}, std::pair{1, 1}, std::pair{2, 2}, std::pair{1, 0}, std::pair{2, 0}}) {
    LocalGrid expected = drawn;
    size_t freed = 0, silenced = 0;
    for (int z = 0; z < n.z(); ++z)
      for (int y = 0; y < n.y(); ++y)
        for (int x = 0; x < n.x(); ++x) {
          float& cell = expected.at(x, y, z);
          if (cell == sky && nearestHit(x, y, z) <= sky_radius) {
            cell = 0.0f;
            ++silenced;
          }
          if (gap_radius > 0 && drawn.at(x, y, z) == 0.0f && nearestHit(x, y, z) > gap_radius) {
            cell = free;
            ++freed;
          }
        }
    ASSERT_GT(silenced, 0u);
    ASSERT_EQ(freed > 0, gap_radius > 0);
    for (unsigned threads : {1u, 2u})
      for (const uint8_t* flags : {static_cast<const uint8_t*>(nullptr), std::as_const(hit_blocks).data()}) {
        WorkerPool pool(threads);
        LocalGrid both = drawn;
        const std::string what = "sky " + std::to_string(sky_radius) + " gap " + std::to_string(gap_radius) +
                                 " threads " + std::to_string(threads) + (flags ? " flags" : "");
        EXPECT_EQ(applySurfaceGuards(&both, skyAndGap(sky, sky_radius, free, gap_radius), &pool, flags), freed) << what;
        EXPECT_EQ(std::memcmp(both.data(), expected.data(), expected.numCells() * sizeof(float)), 0) << what;
      }
  }
}

// The sky guard on a pool's workers against a plain one on small grids of
// random cells, thin in z so that chunks meet everywhere: the cells of the
// value within r of an occupied cell, and only those, become 0.
TEST(SurfaceGuards, SkyGuardOnWorkersMatchesAPlainGuard) {
  constexpr float kSky = -0.9f, kFree = -0.85f, kHit = 0.4f;
  std::mt19937 rng(7);
  const float kinds[] = {LocalGrid::kUnknown, kSky, kSky, kFree, 0.0f, kHit};
  std::uniform_int_distribution<int> kind(0, 5);
  for (int size_z : {3, 7, 12, 23}) {
    LocalGrid grid;
    grid.reset(Eigen::Vector3i::Zero(), Eigen::Vector3i(37, 5, size_z), 1.0);
    for (size_t i = 0; i < grid.numCells(); ++i) grid.data()[i] = kinds[kind(rng)];
    for (int radius : {1, 2}) {
      LocalGrid plain = grid;
      size_t expected = 0;
      const Eigen::Vector3i n = grid.size();
      for (int z = 0; z < n.z(); ++z)
        for (int y = 0; y < n.y(); ++y)
          for (int x = 0; x < n.x(); ++x) {
            if (!(grid.at(x, y, z) > 0.0f)) continue;
            for (int k = std::max(0, z - radius); k <= std::min(n.z() - 1, z + radius); ++k)
              for (int j = std::max(0, y - radius); j <= std::min(n.y() - 1, y + radius); ++j)
                for (int h = std::max(0, x - radius); h <= std::min(n.x() - 1, x + radius); ++h)
                  if (plain.at(h, j, k) == kSky) {
                    plain.at(h, j, k) = 0.0f;
                    ++expected;
                  }
          }
      ASSERT_GT(expected, 0u);
      for (unsigned threads : {1u, 2u, 3u, 5u}) {
        WorkerPool pool(threads);
        LocalGrid guarded = grid;
        const std::string what =
            "z " + std::to_string(size_z) + " radius " + std::to_string(radius) + " threads " + std::to_string(threads);
        EXPECT_EQ(silenceNearOccupied(&guarded, kSky, radius, &pool), expected) << what;
        EXPECT_EQ(std::memcmp(guarded.data(), plain.data(), plain.numCells() * sizeof(float)), 0) << what;
      }
    }
  }
}

// The edge guard by hand: a hit at (4, 4, 4) seen along +x from far away.
// The free cells beside it and behind it say nothing; the nine in front of
// it (x = 3) stay free, and so do the cells out of reach.
TEST(SurfaceGuards, EdgeGuardSilencesFreeSpaceBesideAHitNotInFrontOfIt) {
  const float free = -0.85f, sky = std::nextafter(free, -1.0f);
  LocalGrid grid;
  grid.reset({0, 0, 0}, {9, 9, 9}, kCell);
  for (size_t i = 0; i < grid.numCells(); ++i) grid.data()[i] = free;
  grid.at(4, 4, 4) = 0.9f;
  SurfaceGuards guards = skyAndGap(sky, 1, free, 0);
  guards.edge_radius = 1;
  guards.grid_camera = Eigen::Vector3d(-20.0, 4.5, 4.5);
  LocalGrid unguarded = grid;
  guards.edge_radius = 0;
  EXPECT_EQ(applySurfaceGuards(&unguarded, guards), 0u);
  EXPECT_EQ(std::memcmp(unguarded.data(), grid.data(), grid.numCells() * sizeof(float)), 0);  // off: nothing
  guards.edge_radius = 1;
  EXPECT_EQ(applySurfaceGuards(&grid, guards), 0u);  // no zeros set free: the gap guard is off
  int silenced = 0;
  for (int z = 0; z < 9; ++z)
    for (int y = 0; y < 9; ++y)
      for (int x = 0; x < 9; ++x) {
        const int reach = std::max({std::abs(x - 4), std::abs(y - 4), std::abs(z - 4)});
        const float v = grid.at(x, y, z);
        if (reach == 0) continue;
        if (reach > 1 || x == 3) {
          EXPECT_EQ(v, free) << x << " " << y << " " << z;
        } else {
          EXPECT_EQ(v, 0.0f) << x << " " << y << " " << z;
          ++silenced;
        }
      }
  EXPECT_EQ(silenced, 17);  // 8 beside it (x = 4) and 9 behind it (x = 5)
  // Seen from above (along -z), the cells above it (z = 5) are in front.
  grid.reset({0, 0, 0}, {9, 9, 9}, kCell);
  for (size_t i = 0; i < grid.numCells(); ++i) grid.data()[i] = free;
  grid.at(4, 4, 4) = 0.9f;
  guards.grid_camera = Eigen::Vector3d(4.5, 4.5, 30.0);
  applySurfaceGuards(&grid, guards);
  EXPECT_EQ(grid.at(4, 4, 5), free);
  EXPECT_EQ(grid.at(3, 5, 5), free);
  EXPECT_EQ(grid.at(3, 4, 4), 0.0f);
  EXPECT_EQ(grid.at(5, 5, 3), 0.0f);
}

// The edge guard with the sky and gap guards against a plain reference on
// random grids with runs of hits: a free cell within one cell of a hit and
// not in front of it says nothing (0, or kept 0 from the gap guard), and
// the rest is the other guards'; on workers and over the flagged blocks the same.
TEST(SurfaceGuards, EdgeGuardMatchesAPlainReference) {
  const float free = -0.85f, sky = std::nextafter(free, -1.0f), hit = 0.9f;
  const float kinds[] = {LocalGrid::kUnknown, sky, free, free, free, 0.0f};
  const LocalGrid drawn = randomGridWithRuns({35, 7, 9}, kinds, hit, 0.03, 5);
  const Eigen::Vector3i n = drawn.size();
  std::vector<Eigen::Vector3i> hits;
  for (int z = 0; z < n.z(); ++z)
    for (int y = 0; y < n.y(); ++y)
      for (int x = 0; x < n.x(); ++x)
        if (drawn.at(x, y, z) == hit) hits.emplace_back(x, y, z);
  const std::vector<uint8_t> hit_blocks = hitBlockFlags(drawn, hit);
  const Eigen::Vector3d camera(-3.0, 12.0, 20.0);  // above and to the side: rays cross every axis
  for (int gap_radius : {0, 1}) {
    LocalGrid expected = drawn;
    size_t freed = 0;
    int silenced = 0, kept_free = 0;
    for (int z = 0; z < n.z(); ++z)
      for (int y = 0; y < n.y(); ++y)
        for (int x = 0; x < n.x(); ++x) {
          const Eigen::Vector3i f(x, y, z);
          int nearest = 1 << 20;
          bool beside = false;
          for (const Eigen::Vector3i& h : hits) {
            const int d = (f - h).cwiseAbs().maxCoeff();
            nearest = std::min(nearest, d);
            const Eigen::Vector3d ray = h.cast<double>().array() + 0.5 - camera.array();
            if (d == 1 && !((f - h).cast<double>().dot(ray) < -0.5 * ray.norm())) beside = true;
          }
          float& cell = expected.at(x, y, z);
          const float was = drawn.at(x, y, z);
          if (was == sky && nearest <= 1) cell = 0.0f;
          if (was == free && beside) cell = 0.0f, ++silenced;
          if (was == free && nearest == 1 && !beside) ++kept_free;
          if (gap_radius > 0 && was == 0.0f && nearest > gap_radius) cell = free, ++freed;
        }
    ASSERT_GT(silenced, 50);
    ASSERT_GT(kept_free, 20);  // in front of a hit
    for (unsigned threads : {1u, 2u, 3u})
      for (const uint8_t* flags : {static_cast<const uint8_t*>(nullptr), std::as_const(hit_blocks).data()}) {
        WorkerPool pool(threads);
        LocalGrid guarded = drawn;
        SurfaceGuards guards = skyAndGap(sky, 1, free, gap_radius);
        guards.edge_radius = 1;
        guards.grid_camera = camera;
        const std::string what =
            "gap " + std::to_string(gap_radius) + " threads " + std::to_string(threads) + (flags ? " flags" : "");
        EXPECT_EQ(applySurfaceGuards(&guarded, guards, &pool, flags), freed) << what;
        EXPECT_EQ(std::memcmp(guarded.data(), expected.data(), expected.numCells() * sizeof(float)), 0) << what;
      }
  }
}

// A flat ground's hits lie in one slab of z, so the pool's chunks go by
// slabs of y there (a y path that skips a row fails here): the same grid
// and count as on one thread, for all three guards (sky, gap, edge) and for
// the sky guard alone (the first pass's own count), with the blocks that
// hold hits flagged.
TEST(SurfaceGuards, GuardsOnAFlatGroundOnWorkersMatchOneThread) {
  const float free = -0.85f, sky = std::nextafter(free, -1.0f), hit = 0.9f;
  const float kinds[] = {LocalGrid::kUnknown, sky, sky, free, 0.0f, 0.0f};
  LocalGrid ground = randomGridWithRuns({70, 64, 20}, kinds, hit, 0.0, 3);  // no hits yet
  std::mt19937 rng(5);
  std::bernoulli_distribution hit_here(0.3);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 70; ++x)
      if (hit_here(rng)) ground.at(x, y, 6) = hit;  // the ground: z = 6 only
  const std::vector<uint8_t> flags = hitBlockFlags(ground, hit);
  for (int radius : {1, 2}) {
    SurfaceGuards guards = skyAndGap(sky, radius, free, radius);
    guards.edge_radius = radius;
    guards.grid_camera = Eigen::Vector3d(35.0, -10.0, 15.0);  // above the ground, behind the grid
    LocalGrid expected = ground;
    const size_t freed = applySurfaceGuards(&expected, guards, nullptr, flags.data());
    ASSERT_GT(freed, 0u);
    ASSERT_NE(std::memcmp(expected.data(), ground.data(), ground.numCells() * sizeof(float)), 0);
    for (unsigned threads : {2u, 3u}) {
      WorkerPool pool(threads);
      LocalGrid guarded = ground;
      EXPECT_EQ(applySurfaceGuards(&guarded, guards, &pool, flags.data()), freed) << radius << " " << threads;
      EXPECT_EQ(std::memcmp(guarded.data(), expected.data(), expected.numCells() * sizeof(float)), 0)
          << radius << " " << threads;
    }
    LocalGrid sky_expected = ground;
    const size_t silenced = silenceNearOccupied(&sky_expected, sky, radius, nullptr, flags.data());
    ASSERT_GT(silenced, 0u);
    for (unsigned threads : {2u, 3u}) {
      WorkerPool pool(threads);
      LocalGrid guarded = ground;
      EXPECT_EQ(silenceNearOccupied(&guarded, sky, radius, &pool, flags.data()), silenced) << radius << " " << threads;
      EXPECT_EQ(std::memcmp(guarded.data(), sky_expected.data(), sky_expected.numCells() * sizeof(float)), 0)
          << radius << " " << threads;
    }
  }
}
