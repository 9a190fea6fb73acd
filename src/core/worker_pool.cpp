#include "stereo_occupancy/worker_pool.h"

#include <algorithm>
#include <chrono>

namespace stereo_occupancy {

unsigned WorkerPool::defaultThreads() {
  const unsigned cores = std::thread::hardware_concurrency();  // 0: unknown
  return std::clamp(cores, 1u, kMaxDefaultThreads);
}

WorkerPool::WorkerPool(unsigned threads) {
  const unsigned n = threads == 0 ? defaultThreads() : threads;
  for (unsigned w = 1; w < n; ++w) threads_.emplace_back([this, w] { serve(w); });
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  start_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void WorkerPool::run(size_t n, const std::function<void(size_t i, unsigned worker)>& task) {
  if (n == 0) return;
  if (threads_.empty() || n == 1) {  // nothing to share: no locks, no wake-ups
    std::exception_ptr error;
    for (size_t i = 0; i < n; ++i) {
      try {
        task(i, 0);
      } catch (...) {
        if (!error) error = std::current_exception();
      }
    }
    if (error) std::rethrow_exception(error);
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    task_ = &task;
    n_ = n;
    next_ = 0;
    busy_ = static_cast<unsigned>(threads_.size()) + 1;
    error_ = nullptr;
    ++generation_;
  }
  start_.notify_all();
  work(0);
  spinUntil([this] { return busy_.load() == 0; });
  std::unique_lock<std::mutex> lock(mutex_);
  done_.wait(lock, [this] { return busy_ == 0; });
  task_ = nullptr;
  if (error_) std::rethrow_exception(error_);
}

template <typename Ready>
bool WorkerPool::spinUntil(const Ready& ready) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(kSpinMicroseconds);
  while (!ready()) {
    if (std::chrono::steady_clock::now() > until) return false;
    std::this_thread::yield();  // the core to anyone who needs it
  }
  return true;
}

void WorkerPool::serve(unsigned worker) {
  unsigned seen = 0;
  for (;;) {
    spinUntil([&] { return stop_.load() || generation_.load() != seen; });
    {
      std::unique_lock<std::mutex> lock(mutex_);
      start_.wait(lock, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = generation_;
    }
    work(worker);
  }
}

void WorkerPool::work(unsigned worker) {
  for (;;) {
    size_t i;
    {
      // One part at a time: parts are whole blocks of an image (tens of
      // microseconds), so the lock costs little and balances the load.
      std::lock_guard<std::mutex> lock(mutex_);
      if (next_ >= n_) break;
      i = next_++;
    }
    try {
      (*task_)(i, worker);
    } catch (...) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!error_) error_ = std::current_exception();
    }
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (--busy_ == 0) done_.notify_one();
}

}  // namespace stereo_occupancy
