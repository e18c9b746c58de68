// The per-viewer quality layer policy (net/layer_control.h), on a simulated
// clock: when a viewer goes down, when it probes up, how the hold grows after
// a failed probe, and that a switch waits for an independent frame.
#include "net/layer_control.h"

#include <gtest/gtest.h>

#include <array>

namespace holo::net {
namespace {

constexpr int64_t kMs = 1000;
// Layer 0 publishes 1.2 MB/s, layer 1 0.3 MB/s.
const std::array<double, 2> kRates = {1.2e6, 0.3e6};

LayerController TwoLayers(LayerPolicy p = {}) {
  LayerController c(p);
  c.SetNumLayers(2);
  return c;
}

// Offers one frame of each layer (both independent) at `now`: returns the
// layers this viewer took.
int OfferBoth(LayerController* c, int64_t now, bool independent1 = true) {
  int took = 0;
  for (int layer = 0; layer < 2; ++layer) {
    if (layer == c->layer()) c->Update(now, kRates);
    if (c->Take(layer, layer == 0 || independent1, nullptr)) took |= 1 << layer;
  }
  return took;
}

TEST(LayerControl, StaysOnFullLayerWhileTheQueueIsCalm) {
  LayerController c = TwoLayers();
  for (int64_t t = 0; t < 10'000 * kMs; t += 33 * kMs) {
    c.OnEnqueue(t, 1, false);
    c.OnWrite(t, 40'000, 100);  // 400 MB/s: written as fast as it comes
    EXPECT_EQ(OfferBoth(&c, t), 1) << "t=" << t;
  }
  EXPECT_EQ(c.switches(), 0u);
}

TEST(LayerControl, ADroppedFrameMovesTheViewerDownAtTheNextIndependentFrame) {
  LayerController c = TwoLayers();
  c.OnEnqueue(0, 3, true);
  c.Update(0, kRates);
  EXPECT_EQ(c.target(), 1);
  EXPECT_EQ(c.reason(), "drop");
  EXPECT_EQ(c.layer(), 0);
  // Until layer 1 sends an independent frame the viewer keeps layer 0.
  bool switched = true;
  EXPECT_TRUE(c.Take(0, true, &switched));
  EXPECT_FALSE(switched);
  EXPECT_FALSE(c.Take(1, false, &switched));
  EXPECT_FALSE(switched);
  EXPECT_TRUE(c.Take(0, true, &switched));
  EXPECT_TRUE(c.Take(1, true, &switched));
  EXPECT_TRUE(switched);
  EXPECT_EQ(c.layer(), 1);
  EXPECT_FALSE(c.Take(0, true, nullptr));
  EXPECT_EQ(c.switches(), 1u);
  EXPECT_EQ(c.switches_down(), 1u);
}

TEST(LayerControl, AQueueGoesDownOnlyWhenItLasts) {
  LayerPolicy p;
  p.down_queue_s = 0.25;
  LayerController c = TwoLayers(p);
  c.OnEnqueue(0, 2, false);
  c.Update(200 * kMs, kRates);
  EXPECT_EQ(c.target(), 0) << "2 frames waiting for 200 ms is not yet a backlog";
  c.OnEnqueue(220 * kMs, 1, false);  // it drained
  c.OnEnqueue(240 * kMs, 2, false);
  c.Update(400 * kMs, kRates);
  EXPECT_EQ(c.target(), 0) << "the backlog restarted at 240 ms";
  c.Update(500 * kMs, kRates);
  EXPECT_EQ(c.target(), 1);
  EXPECT_EQ(c.reason(), "queue");
}

TEST(LayerControl, ABusySocketBelowTheLayersBitrateGoesDown) {
  LayerController c = TwoLayers();
  // 0.8 s busy per second at 0.6 MB/s: the viewer takes half of layer 0.
  int64_t t = 0;
  for (; t < 3000 * kMs; t += 100 * kMs) {
    c.OnWrite(t, 48'000, 80 * kMs);
    c.Update(t, kRates);
    if (c.target() == 1) break;
  }
  EXPECT_EQ(c.target(), 1);
  EXPECT_EQ(c.reason(), "throughput");
  EXPECT_NEAR(c.throughput_bytes_per_s(), 0.6e6, 1e3);
}

TEST(LayerControl, AnIdleSocketSaysNothingAboutItsLimit) {
  LayerController c = TwoLayers();
  // Slow writes, but rarely: 10 % busy. Not enough to judge a limit.
  for (int64_t t = 0; t < 5000 * kMs; t += 100 * kMs) {
    c.OnWrite(t, 1'000, 10 * kMs);
    c.Update(t, kRates);
  }
  EXPECT_EQ(c.target(), 0);
}

// Moves `c` to layer 1 with a drop at `t`.
void GoDown(LayerController* c, int64_t t) {
  c->OnEnqueue(t, 3, true);
  c->Update(t, kRates);
  ASSERT_EQ(c->target(), 1);
  ASSERT_TRUE(c->Take(1, true, nullptr));
  ASSERT_EQ(c->layer(), 1);
}

TEST(LayerControl, ProbesUpAfterTheHoldWhenThroughputAllows) {
  LayerPolicy p;
  p.up_hold_s = 2;
  p.up_headroom = 1.3;
  LayerController c = TwoLayers(p);
  GoDown(&c, 0);
  // The socket took 2 MB/s while busy: ≥ 1.3 × 1.2 MB/s.
  int64_t t = 0;
  for (; t <= 1900 * kMs; t += 100 * kMs) {
    c.OnEnqueue(t, 0, false);
    c.OnWrite(t, 20'000, 10 * kMs);
    c.Update(t, kRates);
    EXPECT_EQ(c.target(), 1) << "still in the hold at t=" << t;
  }
  c.Update(2000 * kMs, kRates);
  EXPECT_EQ(c.target(), 0);
  EXPECT_EQ(c.reason(), "probe");
  EXPECT_TRUE(c.Take(0, true, nullptr));
  EXPECT_EQ(c.layer(), 0);
  EXPECT_EQ(c.switches(), 2u);
}

TEST(LayerControl, NoProbeWhenTheSocketCannotCarryTheUpperLayer) {
  LayerController c = TwoLayers();
  GoDown(&c, 0);
  // Busy writes at 0.8 MB/s: the reduced layer fits, the full one does not.
  for (int64_t t = 0; t <= 10'000 * kMs; t += 100 * kMs) {
    c.OnEnqueue(t, 0, false);
    c.OnWrite(t, 8'000, 10 * kMs);
    c.Update(t, kRates);
  }
  EXPECT_EQ(c.target(), 1);
  EXPECT_NEAR(c.throughput_bytes_per_s(), 0.8e6, 1e3);
}

TEST(LayerControl, NoProbeWhileFramesPileUp) {
  LayerController c = TwoLayers();
  GoDown(&c, 0);
  for (int64_t t = 0; t <= 10'000 * kMs; t += 100 * kMs) {
    c.OnEnqueue(t, (t / kMs) % 1000 == 0 ? 2 : 0, false);  // a short backlog every second
    c.Update(t, kRates);
  }
  EXPECT_EQ(c.target(), 1);
}

TEST(LayerControl, AFailedProbeDoublesTheHoldAndALongStayResetsIt) {
  LayerPolicy p;
  p.up_hold_s = 1;
  p.max_up_hold_s = 4;
  p.stable_s = 20;
  LayerController c = TwoLayers(p);
  int64_t t = 0;
  GoDown(&c, t);
  double expected_hold = 1;
  for (int round = 0; round < 4; ++round) {
    // Wait on layer 1 until the probe.
    const int64_t down_at = t;
    while (c.target() == 1) {
      t += 50 * kMs;
      c.OnEnqueue(t, 0, false);
      c.Update(t, kRates);
      ASSERT_LT(t - down_at, 10'000 * kMs);
    }
    EXPECT_NEAR((t - down_at) * 1e-6, expected_hold, 0.06) << "round " << round;
    ASSERT_TRUE(c.Take(0, true, nullptr));
    // The full layer does not fit: a drop 300 ms later.
    t += 300 * kMs;
    GoDown(&c, t);
    expected_hold = std::min(2 * expected_hold, 4.0);
    EXPECT_DOUBLE_EQ(c.up_hold_s(), expected_hold);
  }
  // 20 s on a layer: the next hold is the short one again.
  c.Update(t + 20'000 * kMs, kRates);
  EXPECT_DOUBLE_EQ(c.up_hold_s(), 1.0);
}

TEST(LayerControl, ABacklogRightAfterAProbeEndsItAtOnce) {
  LayerPolicy p;
  p.up_hold_s = 1;
  p.probe_s = 1;
  LayerController c = TwoLayers(p);
  GoDown(&c, 0);
  c.Update(1000 * kMs, kRates);
  ASSERT_EQ(c.target(), 0);
  ASSERT_TRUE(c.Take(0, true, nullptr));
  // 100 ms into the probe two frames wait: back down now, not after down_queue_s.
  c.OnEnqueue(1100 * kMs, 2, false);
  c.Update(1100 * kMs, kRates);
  EXPECT_EQ(c.target(), 1);
  EXPECT_EQ(c.reason(), "probe failed");
  // Outside the probe window the same backlog has to last down_queue_s.
  LayerController d = TwoLayers(p);
  d.OnEnqueue(5000 * kMs, 2, false);
  d.Update(5000 * kMs, kRates);
  EXPECT_EQ(d.target(), 0);
}

TEST(LayerControl, UnsentBytesInTheKernelCountAsABacklog) {
  LayerController c = TwoLayers();
  // 0.3 MB unsent at 1.2 MB/s: 250 ms of delay the frame queue does not show.
  c.OnEnqueue(0, 0, false);
  c.OnWrite(0, 40'000, 100, 300'000);
  c.Update(0, kRates);
  EXPECT_EQ(c.target(), 0) << "not at once";
  c.OnWrite(200 * kMs, 40'000, 100, 300'000);
  c.Update(260 * kMs, kRates);
  EXPECT_EQ(c.target(), 1);
  EXPECT_EQ(c.reason(), "socket backlog");
  // 100 KB unsent (83 ms) is not a backlog.
  LayerController d = TwoLayers();
  for (int64_t t = 0; t < 2000 * kMs; t += 33 * kMs) {
    d.OnEnqueue(t, 0, false);
    d.OnWrite(t, 40'000, 100, 100'000);
    d.Update(t, kRates);
  }
  EXPECT_EQ(d.target(), 0);
}

TEST(LayerControl, QualityCapKeepsTheViewerOnTheReducedLayer) {
  EXPECT_EQ(LayerController::MinLayerForQuality(10, 2), 0);
  EXPECT_EQ(LayerController::MinLayerForQuality(5, 2), 0);
  EXPECT_EQ(LayerController::MinLayerForQuality(4, 2), 1);
  EXPECT_EQ(LayerController::MinLayerForQuality(0, 2), 1);
  EXPECT_EQ(LayerController::MinLayerForQuality(0, 1), 0);
  EXPECT_EQ(LayerController::MinLayerForQuality(0, 3), 2);
  LayerController c = TwoLayers();
  c.SetMinLayer(1, 0);
  EXPECT_EQ(c.target(), 1);
  EXPECT_EQ(c.reason(), "quality");
  EXPECT_TRUE(c.Take(1, true, nullptr));
  for (int64_t t = 0; t < 60'000 * kMs; t += 500 * kMs) c.Update(t, kRates);
  EXPECT_EQ(c.layer(), 1) << "never probes above the viewer's own cap";
  c.SetMinLayer(0, 60'000 * kMs);
  c.Update(63'000 * kMs, kRates);
  EXPECT_EQ(c.target(), 0);
}

TEST(LayerControl, NonAdaptiveStaysAndOneLayerNeverSwitches) {
  LayerPolicy p;
  p.adaptive = false;
  LayerController fixed = TwoLayers(p);
  fixed.OnEnqueue(0, 3, true);
  fixed.Update(0, kRates);
  EXPECT_EQ(fixed.target(), 0);
  LayerController one;  // a site without layers
  one.OnEnqueue(0, 3, true);
  one.Update(0, kRates);
  EXPECT_EQ(one.target(), 0);
  EXPECT_FALSE(one.Take(1, true, nullptr));
}

TEST(LayerControl, PolicyCheckNamesTheField) {
  LayerPolicy p;
  EXPECT_TRUE(p.Check().ok());
  p.up_headroom = 0.5;
  EXPECT_NE(p.Check().message().find("layers.up_headroom"), std::string::npos);
  p = {};
  p.max_up_hold_s = 1;  // below up_hold_s
  EXPECT_NE(p.Check().message().find("layers.max_up_hold_s"), std::string::npos);
  p = {};
  p.down_queue_s = -1;
  EXPECT_FALSE(p.Check().ok());
}

}  // namespace
}  // namespace holo::net
