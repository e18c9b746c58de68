#include "server/pods/frame_grouper.h"

#include <algorithm>
#include <climits>
#include <cstdlib>
#include <string>

namespace holo::pods {

Status GrouperOptions::Check() const {
  if (tolerance_us <= 0) return InvalidArgument("tolerance_us must be > 0, got " + std::to_string(tolerance_us));
  if (timeout_us < 0) return InvalidArgument("timeout_us must be >= 0, got " + std::to_string(timeout_us));
  if (max_pending < 1) return InvalidArgument("max_pending must be >= 1");
  return OkStatus();
}

FrameGrouper::FrameGrouper(int num_pods, GrouperOptions options)
    : num_pods_(num_pods), options_(options), expected_(static_cast<size_t>(num_pods), true) {
  HOLO_CHECK(num_pods > 0);
  HOLO_CHECK(options.Check().ok());
}

void FrameGrouper::SetExpected(int pod, bool expected) {
  HOLO_CHECK(pod >= 0 && pod < num_pods_);
  expected_[static_cast<size_t>(pod)] = expected;
}

bool FrameGrouper::Complete(const GroupedSet& s) const {
  for (int p = 0; p < num_pods_; ++p)
    if (expected_[static_cast<size_t>(p)] && s.pods[static_cast<size_t>(p)].site_time_us == INT64_MIN)
      return false;
  return true;
}

AddResult FrameGrouper::Add(PodSample sample, int64_t now_us) {
  HOLO_CHECK(sample.pod >= 0 && sample.pod < num_pods_);
  const int64_t t = sample.site_time_us;
  if (released_any_ && t <= last_released_us_ + options_.tolerance_us) return AddResult::kLate;
  // The nearest pending set within the tolerance.
  GroupedSet* best = nullptr;
  int64_t best_d = 0;
  for (GroupedSet& s : pending_) {
    const int64_t d = std::llabs(s.time_us - t);
    if (d <= options_.tolerance_us && (!best || d < best_d)) {
      best = &s;
      best_d = d;
    }
  }
  if (!best) {
    GroupedSet s;
    s.time_us = t;
    s.opened_us = now_us;
    s.pods.resize(static_cast<size_t>(num_pods_));
    for (int p = 0; p < num_pods_; ++p) {
      s.pods[static_cast<size_t>(p)].pod = p;
      s.pods[static_cast<size_t>(p)].site_time_us = INT64_MIN;  // INT64_MIN: no frame yet
    }
    auto it = std::upper_bound(pending_.begin(), pending_.end(), t,
                               [](int64_t v, const GroupedSet& g) { return v < g.time_us; });
    best = &*pending_.insert(it, std::move(s));
  }
  PodSample& slot = best->pods[static_cast<size_t>(sample.pod)];
  if (slot.site_time_us != INT64_MIN) return AddResult::kDuplicate;
  slot = std::move(sample);
  best->present++;
  return AddResult::kAccepted;
}

void FrameGrouper::Release(std::vector<GroupedSet>* out) {
  GroupedSet s = std::move(pending_.front());
  pending_.pop_front();
  s.complete = Complete(s);
  int64_t lo = INT64_MAX, hi = INT64_MIN;
  for (PodSample& p : s.pods) {
    if (p.site_time_us == INT64_MIN) {
      p.site_time_us = 0;
      p.frame.reset();
      continue;
    }
    lo = std::min(lo, p.site_time_us);
    hi = std::max(hi, p.site_time_us);
  }
  s.spread_us = s.present > 0 ? hi - lo : 0;
  released_any_ = true;
  last_released_us_ = std::max(last_released_us_, s.time_us);
  out->push_back(std::move(s));
}

void FrameGrouper::Poll(int64_t now_us, std::vector<GroupedSet>* out) {
  while (!pending_.empty()) {
    const GroupedSet& s = pending_.front();
    if (Complete(s) || now_us >= s.opened_us + options_.timeout_us || pending_.size() > options_.max_pending) {
      Release(out);
    } else {
      break;
    }
  }
}

int64_t FrameGrouper::NextDeadlineUs() const {
  if (pending_.empty()) return INT64_MAX;
  int64_t d = INT64_MAX;  // the front set leaves first, but any may time out before it
  for (const GroupedSet& s : pending_) d = std::min(d, s.opened_us + options_.timeout_us);
  return d;
}

}  // namespace holo::pods
