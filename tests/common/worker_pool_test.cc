// WorkerPool: every task runs exactly once, on a thread index in range, for
// any thread count; ParallelForBlocks covers a range with disjoint blocks.
#include <atomic>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "common/worker_pool.h"

namespace holo {
namespace {

TEST(WorkerPool, EveryTaskOnceOnAThreadInRange) {
  for (int threads : {1, 2, 4}) {
    WorkerPool pool(threads);
    ASSERT_EQ(pool.num_threads(), threads);
    for (int n : {0, 1, 3, 1000}) {
      std::vector<std::atomic<int>> runs(static_cast<size_t>(n));
      std::atomic<int> bad_thread{0};
      pool.Run(n, [&](int task, int thread) {
        runs[static_cast<size_t>(task)].fetch_add(1);
        if (thread < 0 || thread >= threads) bad_thread.fetch_add(1);
      });
      for (int i = 0; i < n; ++i) EXPECT_EQ(runs[static_cast<size_t>(i)].load(), 1) << "task " << i << " of " << n;
      EXPECT_EQ(bad_thread.load(), 0);
    }
  }
}

TEST(WorkerPool, RunsAgainAfterRun) {
  // A pool is used once per frame: many batches in a row on the same threads.
  WorkerPool pool(3);
  std::atomic<long> sum{0};
  for (int batch = 0; batch < 200; ++batch) pool.ParallelFor(50, [&](int i) { sum.fetch_add(i); });
  EXPECT_EQ(sum.load(), 200L * (49 * 50 / 2));
}

TEST(WorkerPool, ZeroMeansAllCores) {
  WorkerPool pool(0);
  EXPECT_EQ(pool.num_threads(), ResolveThreadCount(0));
  EXPECT_GE(ResolveThreadCount(0), 1);
  EXPECT_EQ(ResolveThreadCount(3), 3);
}

// Blocks are disjoint, contiguous, cover [0, n) and respect the block size.
void CheckBlocks(size_t n, int threads, size_t min_block) {
  std::vector<std::atomic<int>> hits(n);
  std::atomic<int> bad{0};
  ParallelForBlocks(n, threads, min_block, [&](size_t begin, size_t end) {
    if (!(begin < end && end <= n)) bad.fetch_add(1);
    if (end - begin < min_block && end != n) bad.fetch_add(1);  // only the last block may be short
    for (size_t i = begin; i < end; ++i) hits[i].fetch_add(1);
  });
  EXPECT_EQ(bad.load(), 0) << "n " << n << ", threads " << threads;
  for (size_t i = 0; i < n; ++i) ASSERT_EQ(hits[i].load(), 1) << "index " << i << " of " << n;
}

TEST(WorkerPool, ParallelForBlocksCoversTheRangeOnce) {
  for (int threads : {0, 1, 2, 3}) {
    for (size_t n : {size_t{0}, size_t{1}, size_t{255}, size_t{256}, size_t{257}, size_t{10000}, size_t{100003}})
      CheckBlocks(n, threads, 256);
    CheckBlocks(1000, threads, 1);
  }
}

TEST(WorkerPool, ParallelForBlocksResultsDoNotDependOnThreads) {
  const size_t n = 50000;
  auto run = [&](int threads) {
    std::vector<double> out(n);
    ParallelForBlocks(n, threads, 64, [&](size_t begin, size_t end) {
      for (size_t i = begin; i < end; ++i) out[i] = static_cast<double>(i) * 0.5 + 1.0 / static_cast<double>(i + 1);
    });
    return out;
  };
  const std::vector<double> one = run(1);
  EXPECT_EQ(run(2), one);
  EXPECT_EQ(run(4), one);
}

}  // namespace
}  // namespace holo
