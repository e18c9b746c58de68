#include "server/pods/clock_sync.h"

namespace holo::pods {

bool ClockOffsetEstimator::Add(int64_t t0, int64_t t1, int64_t t2, int64_t t3) {
  const int64_t rtt = (t3 - t0) - (t2 - t1);
  if (t3 < t0 || t2 < t1 || rtt < 0) return false;
  samples_.push_back({((t1 - t0) + (t2 - t3)) / 2, rtt});
  while (samples_.size() > window_) samples_.pop_front();
  return true;
}

const ClockOffsetEstimator::Sample* ClockOffsetEstimator::Best() const {
  const Sample* best = nullptr;
  for (const Sample& s : samples_)
    if (!best || s.rtt <= best->rtt) best = &s;  // ties: the newer one (drift)
  return best;
}

int64_t ClockOffsetEstimator::offset_us() const {
  const Sample* b = Best();
  return b ? b->offset : 0;
}

int64_t ClockOffsetEstimator::rtt_us() const {
  const Sample* b = Best();
  return b ? b->rtt : 0;
}

}  // namespace holo::pods
