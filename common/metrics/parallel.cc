#include "common/metrics/parallel.h"

#include <algorithm>
#include <atomic>
#include <thread>
#include <vector>

namespace holo::metrics {

int ResolveThreadCount(int requested) {
  if (requested > 0) return requested;
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

void ParallelFor(size_t n, int num_threads, const std::function<void(size_t, size_t)>& fn) {
  if (n == 0) return;
  // Below this many items per block a thread hand-off costs more than it saves.
  constexpr size_t kMinBlock = 256;
  const size_t threads = std::min<size_t>(static_cast<size_t>(ResolveThreadCount(num_threads)),
                                          (n + kMinBlock - 1) / kMinBlock);
  if (threads <= 1) {
    fn(0, n);
    return;
  }
  // Blocks are handed out dynamically so that uneven per-item cost (points
  // far from the surface) does not leave a thread idle; each index still goes
  // to exactly one call, so per-index results are deterministic.
  const size_t block = std::max(kMinBlock, n / (threads * 16));
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (;;) {
      const size_t begin = next.fetch_add(block);
      if (begin >= n) return;
      fn(begin, std::min(n, begin + block));
    }
  };
  std::vector<std::thread> workers;
  workers.reserve(threads - 1);
  for (size_t t = 1; t < threads; ++t) workers.emplace_back(work);
  work();
  for (auto& w : workers) w.join();
}

}  // namespace holo::metrics
