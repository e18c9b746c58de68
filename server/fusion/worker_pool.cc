#include "server/fusion/worker_pool.h"

#include <algorithm>

#include "common/status.h"

namespace holo {

WorkerPool::WorkerPool(int num_threads) {
  if (num_threads <= 0) num_threads = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  workers_.reserve(static_cast<size_t>(num_threads - 1));
  for (int t = 1; t < num_threads; ++t) workers_.emplace_back([this, t] { WorkerLoop(t); });
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  for (auto& w : workers_) w.join();
}

void WorkerPool::Drain(uint32_t gen, size_t num_tasks, const std::function<void(size_t, int)>& fn, int thread) {
  uint64_t s = state_.load(std::memory_order_acquire);
  for (;;) {
    if (static_cast<uint32_t>(s >> 32) != gen) return;
    const size_t task = static_cast<size_t>(s & 0xFFFFFFFFu);
    if (task >= num_tasks) return;
    if (!state_.compare_exchange_weak(s, s + 1, std::memory_order_acq_rel, std::memory_order_acquire)) continue;
    fn(task, thread);
    if (done_count_.fetch_add(1, std::memory_order_acq_rel) + 1 == num_tasks) {
      std::lock_guard<std::mutex> lock(mutex_);
      done_.notify_all();
    }
    s = state_.load(std::memory_order_acquire);
  }
}

void WorkerPool::Run(size_t num_tasks, const std::function<void(size_t, int)>& fn) {
  if (num_tasks == 0) return;
  if (workers_.empty() || num_tasks == 1) {
    for (size_t t = 0; t < num_tasks; ++t) fn(t, 0);
    return;
  }
  HOLO_CHECK(num_tasks < 0xFFFFFFFFu);
  uint32_t gen;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    gen = ++generation_;
    fn_ = &fn;
    num_tasks_ = num_tasks;
    done_count_.store(0, std::memory_order_relaxed);
    state_.store(static_cast<uint64_t>(gen) << 32, std::memory_order_release);
  }
  wake_.notify_all();
  Drain(gen, num_tasks, fn, 0);
  if (done_count_.load(std::memory_order_acquire) != num_tasks) {
    std::unique_lock<std::mutex> lock(mutex_);
    done_.wait(lock, [&] { return done_count_.load(std::memory_order_acquire) == num_tasks; });
  }
}

void WorkerPool::WorkerLoop(int thread) {
  uint32_t seen = 0;
  for (;;) {
    uint32_t gen;
    size_t num_tasks;
    const std::function<void(size_t, int)>* fn;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = gen = generation_;
      num_tasks = num_tasks_;
      fn = fn_;
    }
    Drain(gen, num_tasks, *fn, thread);
  }
}

}  // namespace holo
