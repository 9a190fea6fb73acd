// The worker pool that draws and blurs one image on several threads.

#include <gtest/gtest.h>

#include <atomic>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include "stereo_occupancy/worker_pool.h"

using namespace stereo_occupancy;

TEST(WorkerPool, DefaultIsTheMachinesCoresCapped) {
  const unsigned hw = std::thread::hardware_concurrency();
  const unsigned d = WorkerPool::defaultThreads();
  EXPECT_GE(d, 1u);
  EXPECT_LE(d, WorkerPool::kMaxDefaultThreads);
  if (hw >= 1) EXPECT_EQ(d, std::min(hw, WorkerPool::kMaxDefaultThreads));
  EXPECT_EQ(WorkerPool(0).size(), d);
  EXPECT_EQ(WorkerPool(3).size(), 3u);
}

// Each part runs once, on a worker the pool has, and all of them before
// run() returns; the pool serves many jobs in a row.
TEST(WorkerPool, RunsEachPartOnceOnItsWorkers) {
  for (unsigned threads : {1u, 2u, 4u}) {
    WorkerPool pool(threads);
    for (size_t n : {0u, 1u, 2u, 7u, 1000u}) {
      for (int job = 0; job < 20; ++job) {
        std::vector<std::atomic<int>> runs(n);
        std::vector<std::atomic<unsigned>> worker_of(n);
        pool.run(n, [&](size_t i, unsigned w) {
          runs[i].fetch_add(1);
          worker_of[i].store(w);
        });
        for (size_t i = 0; i < n; ++i) {
          ASSERT_EQ(runs[i].load(), 1) << threads << " threads, part " << i << " of " << n;
          ASSERT_LT(worker_of[i].load(), pool.size());
        }
      }
    }
  }
}

// The parts of one job really run side by side: two parts wait for each
// other, which only returns when two threads hold them at once.
TEST(WorkerPool, PartsRunConcurrently) {
  WorkerPool pool(2);
  std::atomic<int> arrived{0};
  std::set<unsigned> workers;
  std::mutex m;
  pool.run(2, [&](size_t, unsigned w) {
    ++arrived;
    while (arrived.load() < 2) std::this_thread::yield();
    std::lock_guard<std::mutex> lock(m);
    workers.insert(w);
  });
  EXPECT_EQ(workers.size(), 2u);
}

// A part that throws: the others still run, run() rethrows the first
// error, and the pool works afterwards.
TEST(WorkerPool, RethrowsAPartsErrorAfterTheOthersRan) {
  for (unsigned threads : {1u, 3u}) {
    WorkerPool pool(threads);
    std::atomic<int> ran{0};
    EXPECT_THROW(pool.run(50,
                          [&](size_t i, unsigned) {
                            ++ran;
                            if (i == 10) throw std::runtime_error("part 10");
                          }),
                 std::runtime_error);
    EXPECT_EQ(ran.load(), 50);
    std::atomic<int> after{0};
    pool.run(8, [&](size_t, unsigned) { ++after; });
    EXPECT_EQ(after.load(), 8);
  }
}
