// A fixed set of worker threads that run batches of small tasks, so a stage
// called every frame starts no threads and allocates nothing per call. The
// one thread pool of the code base: segmentation, fusion, texturing, the
// studio, stereo, temporal tracking (each owns its own pool) and the metrics
// (a pool per call, ParallelForBlocks).
#pragma once

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <thread>
#include <type_traits>
#include <vector>

namespace holo {

// Threads for a `requested` count: `requested` if > 0, otherwise
// std::thread::hardware_concurrency() (at least 1).
int ResolveThreadCount(int requested);

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

  // Calls `fn(begin, end)` on disjoint contiguous blocks covering [0, n),
  // blocks of `block` indices (the last one shorter) handed out dynamically,
  // so uneven per-index cost does not leave a thread idle. Every index goes
  // to exactly one call: results written per index do not depend on the
  // thread count.
  template <typename F>
  void ParallelForBlocks(size_t n, size_t block, F&& fn) {
    if (n == 0) return;
    block = std::max<size_t>(block, 1);
    const size_t blocks = (n + block - 1) / block;
    Run(blocks, [&fn, n, block](int b, int) {
      const size_t begin = static_cast<size_t>(b) * block;
      fn(begin, std::min(n, begin + block));
    });
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

// ParallelForBlocks on a pool made for this call only, of up to
// `num_threads` threads (see ResolveThreadCount) and no more than blocks of
// at least `min_block` indices; runs inline when one thread suffices. For
// one-shot work such as the metrics; a stage called every frame keeps its
// own WorkerPool instead, so it starts no threads per call.
template <typename F>
void ParallelForBlocks(size_t n, int num_threads, size_t min_block, F&& fn) {
  if (n == 0) return;
  min_block = std::max<size_t>(min_block, 1);
  const size_t threads =
      std::min(static_cast<size_t>(ResolveThreadCount(num_threads)), (n + min_block - 1) / min_block);
  if (threads <= 1) {
    fn(size_t{0}, n);
    return;
  }
  // About 16 blocks per thread: small enough to even out uneven per-index
  // cost, large enough that handing them out costs nothing.
  WorkerPool pool(static_cast<int>(threads));
  pool.ParallelForBlocks(n, std::max(min_block, n / (threads * 16)), fn);
}

}  // namespace holo
