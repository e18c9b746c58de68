// Injected clocks: pipelines, jitter buffers and predictors take a Clock& so
// tests run in simulated time.
#pragma once

#include <atomic>
#include <cstdint>

namespace holo {

class Clock {
 public:
  virtual ~Clock() = default;
  // Monotonic time, microseconds.
  virtual int64_t NowUs() const = 0;
  // Sleeps (real clock) or advances (simulated clock) until `deadline_us`.
  virtual void SleepUntilUs(int64_t deadline_us) = 0;
};

// steady_clock based.
class RealClock final : public Clock {
 public:
  int64_t NowUs() const override;
  void SleepUntilUs(int64_t deadline_us) override;
  static RealClock& Instance();
};

// system_clock based (µs since the Unix epoch): the clock capture times on
// the wire use, so times compare across processes and machines (up to their
// clock offset). Not monotonic if the system time is set.
class WallClock final : public Clock {
 public:
  int64_t NowUs() const override;
  void SleepUntilUs(int64_t deadline_us) override;
  static WallClock& Instance();
};

// Time moves only when told to; SleepUntilUs jumps forward.
class SimulatedClock final : public Clock {
 public:
  explicit SimulatedClock(int64_t start_us = 0) : now_us_(start_us) {}
  int64_t NowUs() const override { return now_us_.load(); }
  void SleepUntilUs(int64_t deadline_us) override;
  void AdvanceUs(int64_t delta_us) { now_us_ += delta_us; }
  void SetUs(int64_t t_us) { now_us_ = t_us; }

 private:
  std::atomic<int64_t> now_us_;
};

// CPU time of the calling thread so far, ms (CLOCK_THREAD_CPUTIME_ID): what
// one thread's work cost, steadier than wall time on a shared machine.
double ThreadCpuTimeMs();

// Measures elapsed wall time, for stage timings.
class Stopwatch {
 public:
  Stopwatch();
  void Restart();
  double ElapsedMs() const;

 private:
  int64_t start_ns_;
};

}  // namespace holo
