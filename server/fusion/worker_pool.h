// A small persistent pool of worker threads for the fusion hot path. Threads
// are started once and reused for every call, so a frame costs no thread
// creation and no heap allocation.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace holo {

class WorkerPool {
 public:
  // `num_threads` ≥ 1 threads in total, including the caller's: the pool
  // starts num_threads − 1 workers. 0 = std::thread::hardware_concurrency().
  explicit WorkerPool(int num_threads);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int num_threads() const { return static_cast<int>(workers_.size()) + 1; }

  // Calls `fn(task, thread)` once for every task in [0, num_tasks), spread
  // over the threads (tasks are claimed dynamically; `thread` in
  // [0, num_threads()) names the thread, for per-thread scratch). Returns
  // when all tasks are done. The caller works too and never waits for a
  // worker that has not started (on a loaded machine a descheduled worker
  // simply gets no tasks). `fn` must not throw. One Run at a time per pool.
  void Run(size_t num_tasks, const std::function<void(size_t task, int thread)>& fn);

 private:
  void WorkerLoop(int thread);
  // Claims and runs tasks of generation `gen` until none is left.
  void Drain(uint32_t gen, size_t num_tasks, const std::function<void(size_t, int)>& fn, int thread);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable done_;
  const std::function<void(size_t, int)>* fn_ = nullptr;
  size_t num_tasks_ = 0;
  uint32_t generation_ = 0;
  bool stop_ = false;
  // High 32 bits: generation; low 32 bits: next task. A worker that wakes
  // late cannot claim a task of a later Run with a stale function.
  std::atomic<uint64_t> state_{0};
  std::atomic<size_t> done_count_{0};
};

}  // namespace holo
