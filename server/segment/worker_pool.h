// A small persistent pool of worker threads for per-frame parallel loops
// (segmentation runs every pod of every frame set on it). Unlike spawning
// threads per call, dispatching a loop costs a few microseconds and no heap
// allocation.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

namespace holo {

class WorkerPool {
 public:
  // `num_threads` threads take part in a loop: the caller and
  // `num_threads` − 1 workers (0 = hardware concurrency).
  explicit WorkerPool(int num_threads);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int num_threads() const { return static_cast<int>(workers_.size()) + 1; }

  // Calls fn(i) for every i in [0, n) on the pool's threads and the caller;
  // returns when all calls have returned. `fn` must not throw. Not reentrant:
  // one ParallelFor at a time per pool.
  template <typename Fn>
  void ParallelFor(int n, Fn&& fn) {
    Run(n, [](void* ctx, int i) { (*static_cast<Fn*>(ctx))(i); }, &fn);
  }

 private:
  using TaskFn = void (*)(void*, int);
  void Run(int n, TaskFn fn, void* ctx);
  void WorkerLoop();
  void Drain();

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable start_cv_;
  std::condition_variable done_cv_;
  uint64_t generation_ = 0;
  bool stop_ = false;
  int busy_workers_ = 0;
  TaskFn fn_ = nullptr;
  void* ctx_ = nullptr;
  int n_ = 0;
  std::atomic<int> next_{0};
};

}  // namespace holo
