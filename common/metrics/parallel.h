// A minimal deterministic parallel-for for the metrics: the range is cut
// into contiguous chunks, one per thread, and every index is processed by
// exactly one call, so results written per index do not depend on the thread
// count.
#pragma once

#include <cstddef>
#include <functional>

namespace holo::metrics {

// Number of worker threads for a `requested` count: `requested` if > 0,
// otherwise std::thread::hardware_concurrency() (at least 1).
int ResolveThreadCount(int requested);

// Calls `fn(begin, end)` on disjoint contiguous sub-ranges covering [0, n),
// on up to `num_threads` threads (see ResolveThreadCount); runs inline when
// one thread suffices. `fn` must not throw.
void ParallelFor(size_t n, int num_threads, const std::function<void(size_t begin, size_t end)>& fn);

}  // namespace holo::metrics
