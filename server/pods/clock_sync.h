// Clock offset of a pod against the site, from Ping/Pong exchanges (as NTP):
// the site sends a Ping at t0 (site clock), the pod stamps its receive t1 and
// send t2 (pod clock), the site receives the Pong at t3:
//   offset = ((t1 − t0) + (t2 − t3)) / 2   (pod clock − site clock)
//   rtt    = (t3 − t0) − (t2 − t1)
// The sample with the lowest RTT among the most recent `window` has the
// least queueing asymmetry, so its offset is the estimate. A window of a few
// seconds follows a drifting pod clock (100 ppm = 0.1 ms per second) while
// still holding an uncongested exchange.
#pragma once

#include <cstdint>
#include <cstddef>
#include <deque>

namespace holo::pods {

class ClockOffsetEstimator {
 public:
  explicit ClockOffsetEstimator(size_t window = 16) : window_(window) {}
  // Adds one exchange. Samples with t3 < t0 or a negative RTT are ignored
  // (returns false).
  bool Add(int64_t t0_site, int64_t t1_pod, int64_t t2_pod, int64_t t3_site);
  bool has_estimate() const { return !samples_.empty(); }
  // Pod clock − site clock, µs (0 before the first sample).
  int64_t offset_us() const;
  // RTT of the sample the estimate uses, µs.
  int64_t rtt_us() const;
  // Maps a pod-clock time onto the site clock.
  int64_t ToSite(int64_t pod_time_us) const { return pod_time_us - offset_us(); }
  void Reset() { samples_.clear(); }

 private:
  struct Sample {
    int64_t offset, rtt;
  };
  const Sample* Best() const;
  size_t window_;
  std::deque<Sample> samples_;
};

}  // namespace holo::pods
