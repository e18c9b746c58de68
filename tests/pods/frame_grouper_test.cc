// Frame sets by capture time: pods' clocks offset and drifting (mapped onto
// the site clock by the Ping/Pong estimate), late and duplicate frames, pods
// that are gone, out-of-order arrival.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "server/pods/clock_sync.h"
#include "server/pods/frame_grouper.h"

namespace holo::pods {
namespace {

constexpr int64_t kPeriod = 33333;  // 30 fps

// A simulated pod clock: site time + offset + drift·(site time).
struct PodClockSim {
  int64_t offset_us = 0;
  double drift_ppm = 0;
  int64_t At(int64_t site_us) const {
    return site_us + offset_us + static_cast<int64_t>(std::llround(static_cast<double>(site_us) * drift_ppm * 1e-6));
  }
};

// One Ping/Pong exchange at site time `t0` over a link with one-way delays
// `up` and `down` and `hold` µs inside the pod.
void Exchange(ClockOffsetEstimator* e, const PodClockSim& pod, int64_t t0, int64_t up, int64_t down, int64_t hold) {
  const int64_t t1 = pod.At(t0 + up);
  const int64_t t2 = pod.At(t0 + up + hold);
  const int64_t t3 = t0 + up + hold + down;
  e->Add(t0, t1, t2, t3);
}

// A frame arriving at its capture time (no transport delay).
AddResult AddAt(FrameGrouper& g, PodSample s) {
  const int64_t t = s.site_time_us;
  return g.Add(std::move(s), t);
}

TEST(ClockOffsetEstimator, LowestRttSampleWinsOverQueueingAsymmetry) {
  const PodClockSim pod{100000, 0};
  ClockOffsetEstimator e(16);
  std::mt19937 rng(3);
  for (int i = 0; i < 16; ++i) {
    // Mostly congested uplink (asymmetric), once a clean exchange.
    const int64_t up = i == 9 ? 60 : 60 + static_cast<int64_t>(rng() % 4000);
    Exchange(&e, pod, 1000000 + i * 100000, up, 60, 30);
  }
  ASSERT_TRUE(e.has_estimate());
  EXPECT_NEAR(static_cast<double>(e.offset_us()), 100000.0, 1.0);
  EXPECT_EQ(e.rtt_us(), 120);
  EXPECT_EQ(e.ToSite(pod.At(5000000)), 5000000);
  // Impossible exchanges are ignored.
  EXPECT_FALSE(e.Add(100, 0, 0, 50));
}

TEST(ClockOffsetEstimator, FollowsADriftingClock) {
  const PodClockSim pod{-250000, 200};  // 200 ppm: 12 ms per minute
  ClockOffsetEstimator e(16);
  std::mt19937 rng(4);
  for (int64_t t = 0; t < 60000000; t += 100000) {
    Exchange(&e, pod, t, 50 + rng() % 300, 50 + rng() % 300, 20);
    const int64_t truth = pod.At(t) - t;
    if (t > 2000000) {
      ASSERT_NEAR(static_cast<double>(e.offset_us()), static_cast<double>(truth), 400.0) << t;
    }
  }
}

// Eight pods on a shared trigger, clocks offset by up to ±100 ms and drifting
// by up to ±100 ppm, frames arriving in random order with random delays:
// every set is complete and its capture times agree within the estimate's error.
TEST(FrameGrouper, GroupsPodsWithOffsetAndDriftingClocks) {
  const int n = 8;
  std::vector<PodClockSim> clocks;
  std::vector<ClockOffsetEstimator> est(n);
  for (int p = 0; p < n; ++p) clocks.push_back({(p % 2 ? 1 : -1) * 100000 + p * 1000, (p - 3.5) * 25.0});
  FrameGrouper g(n, GrouperOptions{});
  std::mt19937 rng(5);
  struct Arrival {
    int64_t at;
    PodSample s;
  };
  std::vector<GroupedSet> out;
  int64_t next_ping = 0;
  const int frames = 300;
  std::vector<Arrival> arrivals;
  for (int64_t k = 0; k < frames; ++k) {
    const int64_t trigger = 10000000 + k * kPeriod;
    for (int p = 0; p < n; ++p) arrivals.push_back({trigger + 3000 + static_cast<int64_t>(rng() % 15000), {p, clocks[p].At(trigger), k, nullptr}});
  }
  std::sort(arrivals.begin(), arrivals.end(), [](const Arrival& a, const Arrival& b) { return a.at < b.at; });
  for (Arrival& a : arrivals) {
    while (next_ping <= a.at) {
      for (int p = 0; p < n; ++p) Exchange(&est[p], clocks[p], next_ping, 40 + rng() % 200, 40 + rng() % 200, 10);
      next_ping += 100000;
    }
    // The site maps the pod's stamp with its current estimate.
    a.s.site_time_us = est[a.s.pod].ToSite(a.s.site_time_us);
    ASSERT_EQ(g.Add(a.s, a.at), AddResult::kAccepted);
    g.Poll(a.at, &out);
  }
  g.Poll(INT64_MAX, &out);
  ASSERT_EQ(out.size(), static_cast<size_t>(frames));
  for (size_t i = 0; i < out.size(); ++i) {
    EXPECT_TRUE(out[i].complete) << i;
    EXPECT_EQ(out[i].present, n);
    EXPECT_LT(out[i].spread_us, 1000) << i;  // offset estimates within ±0.5 ms
    for (const PodSample& s : out[i].pods) EXPECT_EQ(s.frame_number, static_cast<int64_t>(i));
    if (i > 0) {
      EXPECT_GT(out[i].time_us, out[i - 1].time_us);
    }
  }
}

TEST(FrameGrouper, ReleasesAnIncompleteSetAtTheTimeoutAndCountsTheLateFrame) {
  GrouperOptions o;
  o.timeout_us = 50000;
  FrameGrouper g(3, o);
  std::vector<GroupedSet> out;
  EXPECT_EQ(AddAt(g, {0, 1000000, 0, nullptr}), AddResult::kAccepted);
  EXPECT_EQ(AddAt(g, {1, 1000400, 0, nullptr}), AddResult::kAccepted);
  g.Poll(1040000, &out);
  EXPECT_TRUE(out.empty());  // pod 2 may still come
  EXPECT_EQ(g.NextDeadlineUs(), 1050000);
  g.Poll(1050000, &out);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_FALSE(out[0].complete);
  EXPECT_EQ(out[0].present, 2);
  EXPECT_EQ(out[0].spread_us, 400);
  EXPECT_EQ(out[0].pods[2].frame, nullptr);
  // Pod 2's frame for that instant is late now; its next one is on time.
  EXPECT_EQ(AddAt(g, {2, 1000100, 0, nullptr}), AddResult::kLate);
  EXPECT_EQ(AddAt(g, {2, 1000000 + kPeriod, 1, nullptr}), AddResult::kAccepted);
}

TEST(FrameGrouper, KeepsSetsWholeWhenEveryPodIsDelayedAlike) {
  // A loaded site: every frame arrives 400 ms after capture, the pods within
  // 20 ms of each other. The timeout counts from the first arrival.
  GrouperOptions o;
  o.timeout_us = 60000;
  FrameGrouper g(3, o);
  std::vector<GroupedSet> out;
  for (int k = 0; k < 5; ++k) {
    const int64_t t = 1000000 + k * kPeriod;
    for (int p = 0; p < 3; ++p) {
      const int64_t arrival = t + 400000 + p * 10000;
      ASSERT_EQ(g.Add({p, t, k, nullptr}, arrival), AddResult::kAccepted);
      g.Poll(arrival, &out);
    }
  }
  ASSERT_EQ(out.size(), 5u);
  for (const GroupedSet& s : out) EXPECT_TRUE(s.complete);
}

TEST(FrameGrouper, RefusesADuplicateFrameOfAPodInOneSet) {
  FrameGrouper g(2, GrouperOptions{});
  EXPECT_EQ(AddAt(g, {0, 500000, 7, nullptr}), AddResult::kAccepted);
  EXPECT_EQ(AddAt(g, {0, 501000, 7, nullptr}), AddResult::kDuplicate);
  EXPECT_EQ(AddAt(g, {1, 499000, 3, nullptr}), AddResult::kAccepted);
  std::vector<GroupedSet> out;
  g.Poll(500000, &out);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_TRUE(out[0].complete);
  EXPECT_EQ(out[0].pods[0].frame_number, 7);  // the first one was kept
}

TEST(FrameGrouper, DoesNotWaitForAPodThatIsGoneAndWaitsAgainWhenItReturns) {
  FrameGrouper g(3, GrouperOptions{});
  std::vector<GroupedSet> out;
  g.SetExpected(2, false);  // pod 2 disconnected
  AddAt(g, {0, 1000000, 0, nullptr});
  AddAt(g, {1, 1000000, 0, nullptr});
  g.Poll(1000000, &out);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_TRUE(out[0].complete);  // complete: every expected pod is in it
  EXPECT_EQ(out[0].present, 2);
  g.SetExpected(2, true);  // pod 2 reconnected
  AddAt(g, {0, 1000000 + kPeriod, 1, nullptr});
  AddAt(g, {1, 1000000 + kPeriod, 1, nullptr});
  g.Poll(1000000 + kPeriod, &out);
  EXPECT_EQ(out.size(), 1u);  // waits for pod 2
  AddAt(g, {2, 1000000 + kPeriod + 200, 0, nullptr});  // a restarted pod numbers from 0 again
  g.Poll(1000000 + kPeriod, &out);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_TRUE(out[1].complete);
  EXPECT_EQ(out[1].present, 3);
}

TEST(FrameGrouper, ReleasesInTimeOrderWhenFramesArriveOutOfOrder) {
  FrameGrouper g(2, GrouperOptions{});
  std::vector<GroupedSet> out;
  AddAt(g, {0, 2000000 + kPeriod, 1, nullptr});  // a newer frame first
  AddAt(g, {0, 2000000, 0, nullptr});
  AddAt(g, {1, 2000000 + kPeriod, 1, nullptr});
  g.Poll(2000000 + kPeriod, &out);
  EXPECT_TRUE(out.empty());  // the older set is still waiting for pod 1
  AddAt(g, {1, 2000000, 0, nullptr});
  g.Poll(2000000 + kPeriod, &out);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].time_us, 2000000);
  EXPECT_EQ(out[1].time_us, 2000000 + kPeriod);
}

TEST(FrameGrouper, BoundsPendingSets) {
  GrouperOptions o;
  o.max_pending = 3;
  o.timeout_us = 10000000;
  FrameGrouper g(2, o);
  std::vector<GroupedSet> out;
  for (int k = 0; k < 10; ++k) {
    AddAt(g, {0, 1000000 + k * kPeriod, k, nullptr});
    g.Poll(1000000, &out);
  }
  EXPECT_EQ(g.pending(), 3u);
  EXPECT_EQ(out.size(), 7u);
  GrouperOptions bad;
  bad.tolerance_us = 0;
  EXPECT_FALSE(bad.Check().ok());
}

}  // namespace
}  // namespace holo::pods
