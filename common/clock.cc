#include "common/clock.h"

#include <time.h>

#include <chrono>
#include <thread>

namespace holo {

namespace {
int64_t SteadyNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}
}  // namespace

int64_t RealClock::NowUs() const { return SteadyNs() / 1000; }

void RealClock::SleepUntilUs(int64_t deadline_us) {
  const int64_t now = NowUs();
  if (deadline_us > now) std::this_thread::sleep_for(std::chrono::microseconds(deadline_us - now));
}

RealClock& RealClock::Instance() {
  static RealClock clock;
  return clock;
}

int64_t WallClock::NowUs() const {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

void WallClock::SleepUntilUs(int64_t deadline_us) {
  const int64_t now = NowUs();
  if (deadline_us > now) std::this_thread::sleep_for(std::chrono::microseconds(deadline_us - now));
}

WallClock& WallClock::Instance() {
  static WallClock clock;
  return clock;
}

void SimulatedClock::SleepUntilUs(int64_t deadline_us) {
  int64_t now = now_us_.load();
  while (deadline_us > now && !now_us_.compare_exchange_weak(now, deadline_us)) {
  }
}

Stopwatch::Stopwatch() : start_ns_(SteadyNs()) {}
void Stopwatch::Restart() { start_ns_ = SteadyNs(); }
double Stopwatch::ElapsedMs() const { return static_cast<double>(SteadyNs() - start_ns_) * 1e-6; }

double ThreadCpuTimeMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

}  // namespace holo
