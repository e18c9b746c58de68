// Groups pods' frames into frame sets by capture time (site clock, after
// each pod's clock offset is taken out), not by frame number: pods number
// their frames independently, restart from 0, and drop frames.
//
// A frame joins the pending set whose time is within `tolerance_us` of its
// own (the nearest, if several), or opens a new one. Sets leave in time
// order: the oldest pending set is released when every expected pod is in
// it (complete), when `timeout_us` has passed since its first frame arrived
// (the pods that are missing are late or gone: fusion runs without them;
// counting from the first arrival rather than from the capture time keeps
// sets whole when every pod's frames are delayed alike, e.g. on a loaded
// site or a slow link), or
// when more than `max_pending` sets are pending. A frame for a time at or
// before the last released set (within the tolerance) is late; a second
// frame of a pod for the same set is a duplicate. Both are dropped and
// counted. The grouper is pure logic (times are passed in), so tests drive
// it with simulated clocks.
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <vector>

#include "common/rgbd.h"
#include "common/status.h"

namespace holo::pods {

struct GrouperOptions {
  // Frames whose site times differ by at most this are one set, µs. Pods on
  // a shared trigger capture within microseconds; the offset estimate adds
  // its error: < 1 ms on an idle link, but 2–4 ms in the first seconds on a
  // loaded site (bench pods: RTTs of 3–20 ms until a quiet exchange comes),
  // which split sets at 8 ms. 12 ms still keeps the instants of a 30 fps
  // trigger (33 ms apart) apart.
  int64_t tolerance_us = 12000;
  // An incomplete set is released this long after its first frame arrived,
  // µs: what a late pod may cost the site in latency. 60 ms ≈ two frames at 30 fps.
  int64_t timeout_us = 60000;
  // Pending sets at most (older ones are released incomplete).
  size_t max_pending = 8;
  Status Check() const;
};

// One pod's frame on its way into a set.
struct PodSample {
  int pod = 0;                 // index into the rig's pods
  int64_t site_time_us = 0;    // capture time on the site clock
  int64_t frame_number = 0;    // the pod's own number
  std::shared_ptr<RgbdFrame> frame;  // decoded frame (may be null in tests)
};

struct GroupedSet {
  int64_t time_us = 0;                 // the set's capture time (its first frame's), site clock
  int64_t opened_us = 0;               // when its first frame arrived, site clock
  std::vector<PodSample> pods;         // one per rig pod; `frame` null where missing
  int present = 0;                     // pods with a frame
  bool complete = false;               // every expected pod was in it when released
  int64_t spread_us = 0;               // max − min capture time of the present frames
};

enum class AddResult { kAccepted, kLate, kDuplicate };

class FrameGrouper {
 public:
  FrameGrouper(int num_pods, GrouperOptions options);
  // Whether sets wait for pod `pod` (connected pods are expected; a pod that
  // is gone is not waited for).
  void SetExpected(int pod, bool expected);
  bool expected(int pod) const { return expected_[static_cast<size_t>(pod)]; }
  // Adds a frame that arrived at site time `now_us`.
  AddResult Add(PodSample sample, int64_t now_us);
  // Whether a frame captured at site time `t` would be late (its set has left).
  bool IsLate(int64_t t) const { return released_any_ && t <= last_released_us_ + options_.tolerance_us; }
  // Moves the sets ready at site time `now_us` to `out` (appended, in time order).
  void Poll(int64_t now_us, std::vector<GroupedSet>* out);
  // Earliest site time at which Poll may release a set by timeout (INT64_MAX if none pending).
  int64_t NextDeadlineUs() const;
  size_t pending() const { return pending_.size(); }

 private:
  bool Complete(const GroupedSet& s) const;
  void Release(std::vector<GroupedSet>* out);
  int num_pods_;
  GrouperOptions options_;
  std::vector<bool> expected_;
  std::deque<GroupedSet> pending_;  // by time
  bool released_any_ = false;
  int64_t last_released_us_ = 0;
};

}  // namespace holo::pods
