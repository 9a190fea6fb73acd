#pragma once
/// @file
/// The threads one mapper uses to draw and blur an image (beyond the paper):
/// a job's parts run on all of them, the caller's thread included.

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace stereo_occupancy {

/// Bytes of a cache line on the targets (x86-64, aarch64).
constexpr size_t kCacheLineBytes = 64;

/// A value one worker writes, alone on its cache line: workers writing
/// neighbouring values (counters bumped once a line drawn) would pass the
/// line back and forth between their cores on every write.
template <typename T>
struct alignas(kCacheLineBytes) PerWorker {
  T value{};
};

/// A fixed set of threads that run the parts of one job at a time. The
/// caller's thread is worker 0, so a pool of one starts no thread. Not for
/// jobs from several threads at once (one pool per drawer).
class WorkerPool {
 public:
  /// What a `threads` parameter of 0 means: the machine's cores, at most kMaxDefaultThreads.
  static unsigned defaultThreads();
  static constexpr unsigned kMaxDefaultThreads = 4;  ///< more rarely pays for one camera's image
  /// How long an idle worker polls for the next job before it sleeps: one
  /// image is several short jobs in a row (draw, merge, the blur's passes),
  /// and waking a sleeping thread costs a virtual machine about as much as a job.
  static constexpr int kSpinMicroseconds = 200;

  /// @param threads workers, >= 1 (0: defaultThreads()).
  explicit WorkerPool(unsigned threads);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  unsigned size() const { return static_cast<unsigned>(threads_.size()) + 1; }
  /// Calls task(i, worker) once for each i in [0, n), in any order on any
  /// worker (worker < size()), and returns when all have returned. The
  /// first exception a task throws is rethrown here, after the others ran.
  void run(size_t n, const std::function<void(size_t i, unsigned worker)>& task);

  /// Calls part(begin, end) for the consecutive ranges of at most @p chunk
  /// (> 0) that cover [0, n), as run()'s parts.
  template <typename Part>
  void runInChunks(size_t n, size_t chunk, const Part& part) {
    run((n + chunk - 1) / chunk, [&](size_t i, unsigned) { part(i * chunk, std::min(n, (i + 1) * chunk)); });
  }

 private:
  void serve(unsigned worker);
  /// Polls @p ready for up to kSpinMicroseconds; true if it came true.
  template <typename Ready>
  static bool spinUntil(const Ready& ready);
  void work(unsigned worker);

  std::vector<std::thread> threads_;
  std::mutex mutex_;
  std::condition_variable start_, done_;
  const std::function<void(size_t, unsigned)>* task_ = nullptr;
  size_t n_ = 0, next_ = 0;              ///< the job's parts; the next one to hand out
  std::atomic<unsigned> generation_{0};  ///< counts jobs: a worker joins each one once; written under mutex_
  std::atomic<unsigned> busy_{0};        ///< workers still in the current job; written under mutex_
  std::atomic<bool> stop_{false};
  std::exception_ptr error_;
};

}  // namespace stereo_occupancy
