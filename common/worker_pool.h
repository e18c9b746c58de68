// A fixed set of worker threads that run batches of small tasks, so a stage
// called every frame starts no threads and allocates nothing per call. Shared
// by segmentation, fusion and texturing (each stage owns its own pool).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <type_traits>
#include <vector>

namespace holo {

class WorkerPool {
 public:
  // `num_threads` counts the calling thread: 2 starts one worker; 0 means
  // std::thread::hardware_concurrency().
  explicit WorkerPool(int num_threads);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int num_threads() const { return static_cast<int>(workers_.size()) + 1; }

  // Calls `fn(task, thread)` for every task in [0, num_tasks), tasks handed
  // out dynamically, `thread` in [0, num_threads()) naming the calling thread
  // (for per-thread scratch). Returns when all tasks are done. `fn` must not
  // throw. Not reentrant: one Run at a time.
  template <typename N, typename F>
  void Run(N num_tasks, F&& fn) {
    static_assert(std::is_integral_v<N>);
    RunImpl(static_cast<int>(num_tasks),
            [](void* ctx, int task, int thread) { (*static_cast<std::remove_reference_t<F>*>(ctx))(task, thread); },
            &fn);
  }

  // Calls `fn(i)` for every i in [0, n).
  template <typename F>
  void ParallelFor(int n, F&& fn) {
    Run(n, [&fn](int i, int) { fn(i); });
  }

 private:
  using TaskFn = void (*)(void* ctx, int task, int thread);
  void RunImpl(int num_tasks, TaskFn fn, void* ctx);
  void Work(int thread);
  void WorkerLoop(int thread);

  std::mutex mu_;
  std::condition_variable start_cv_, done_cv_;
  uint64_t generation_ = 0;
  int busy_workers_ = 0;
  bool stop_ = false;
  TaskFn fn_ = nullptr;
  void* ctx_ = nullptr;
  int num_tasks_ = 0;
  std::atomic<int> next_task_{0};
  std::vector<std::thread> workers_;
};

}  // namespace holo
