// Lip sync rules (audio/av_sync.h) in simulated time, with a voice that
// plays at the delay asked of it: which stream waits, by how much, the
// bounds, and the measured offset. The whole path (jitter buffer, messages,
// picture queue) is tests/net/lip_sync_test.cc.
#include "audio/av_sync.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>

namespace holo::audio {
namespace {

struct Scenario {
  double voice_natural_ms = 80;     // capture → playout without sync
  double picture_base_ms = 400;     // capture → ready, plus U(0, picture_jitter_ms)
  double picture_jitter_ms = 40;
  double render_ms = 20;
  double seconds = 10;
  bool voice = true;
  bool pictures_stop_at_half = false;
  // > 0: pictures arrive in bursts, all those captured in one burst_ms
  // at the next boundary (a broadcast's parts), jitter ignored.
  double burst_ms = 0;
};

struct Outcome {
  AvSyncStats stats;
  double max_hold_ms = 0;
  double final_voice_target_ms = 0;
  int shown = 0, skipped = 0;  // pictures displayed, and passed over for a newer one
  double max_gap_ms = 0;       // longest time between two displayed pictures
};

// 30 fps pictures and a 20 ms voice step; measured over the second half.
Outcome Simulate(const Scenario& sc, AvSyncOptions o = {}) {
  AvSync sync(o);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  const int64_t t0 = 1'000'000'000;
  const auto end = t0 + static_cast<int64_t>(sc.seconds * 1e6);
  int64_t next_picture_capture = t0;
  int64_t busy_until = 0;
  struct Pending {
    int64_t capture, show;
  };
  std::vector<Pending> queue;
  Outcome out;
  int64_t last_shown = 0;
  bool reset = false;
  for (int64_t t = t0; t < end; t += 1000) {
    if (!reset && t >= t0 + static_cast<int64_t>(sc.seconds * 5e5)) {
      sync.ResetStats();
      reset = true;
    }
    // Voice step: it plays at the larger of its natural delay and the target.
    if (sc.voice && (t - t0) % 20000 == 0) {
      const double target = sync.VoiceTargetMs(t);
      const double delay = std::max(sc.voice_natural_ms, target);
      sync.VoicePlayout(1, t - static_cast<int64_t>(delay * 1000), t, sc.voice_natural_ms);
    }
    // Pictures become ready base + jitter after capture.
    const bool pictures_on = !sc.pictures_stop_at_half || t < t0 + static_cast<int64_t>(sc.seconds * 5e5);
    while (pictures_on && next_picture_capture + static_cast<int64_t>(sc.picture_base_ms * 1000) <= t) {
      int64_t ready = t + static_cast<int64_t>(u(rng) * sc.picture_jitter_ms * 1000);
      if (sc.burst_ms > 0) {
        const auto burst = static_cast<int64_t>(sc.burst_ms * 1000);
        ready = (t - t0) / burst * burst + burst + t0;
      }
      const int64_t show = sync.PictureReady(next_picture_capture, ready);
      out.max_hold_ms = std::max(out.max_hold_ms, (show - ready) / 1000.0);
      EXPECT_GE(show, ready);
      EXPECT_LE(show - ready, static_cast<int64_t>(o.max_picture_delay_ms * 1000) + 1);
      queue.push_back({next_picture_capture, show});
      next_picture_capture += 33333;
    }
    // The render loop: the newest due picture, rendered in render_ms.
    if (t >= busy_until) {
      int due = -1;
      for (size_t i = 0; i < queue.size(); ++i)
        if (queue[i].show <= t) due = static_cast<int>(i);
      if (due >= 0) {
        const int64_t shown = t + static_cast<int64_t>(sc.render_ms * 1000);
        sync.PictureDisplayed(queue[due].capture, t, shown);
        if (reset) {
          out.skipped += due;
          ++out.shown;
          if (last_shown > 0) out.max_gap_ms = std::max(out.max_gap_ms, (shown - last_shown) / 1000.0);
        }
        last_shown = shown;
        busy_until = shown;
        queue.erase(queue.begin(), queue.begin() + due + 1);
      }
    }
  }
  out.stats = sync.stats();
  out.final_voice_target_ms = sync.VoiceTargetMs(end);
  return out;
}

void ExpectWithinBt1359(const AvSyncStats& s) {
  EXPECT_GT(s.offsets, 100);
  EXPECT_GE(s.av_offset_ms_p50, -40.0);
  EXPECT_LE(s.av_offset_ms_p50, 40.0);
  EXPECT_GE(s.av_offset_ms_p1, -45.0);
  EXPECT_LE(s.av_offset_ms_p99, 125.0);
}

TEST(AvSync, LatePictureDelaysTheVoice) {
  Scenario sc;
  const Outcome r = Simulate(sc);
  ExpectWithinBt1359(r.stats);
  // The voice waits until 90 % of the pictures are there (400 + U(0, 40) +
  // render 20 ms) − its own 80 ms; the earlier pictures wait for it.
  EXPECT_GT(r.stats.voice_sync_delay_ms, 350.0);
  EXPECT_LT(r.stats.voice_sync_delay_ms, 400.0);
  EXPECT_GT(r.stats.pictures_held, r.stats.pictures / 2);
  EXPECT_LE(r.max_hold_ms, 45.0);
  // What the same pictures would have had without sync: the voice ≈ 360 ms early.
  EXPECT_LT(r.stats.unsynced_offset_ms_p50, -300.0);
  // Without holding pictures, the voice follows their median and nothing waits for it.
  AvSyncOptions no_hold;
  no_hold.hold_pictures = false;
  const Outcome n = Simulate(sc, no_hold);
  ExpectWithinBt1359(n.stats);
  EXPECT_EQ(n.stats.pictures_held, 0);
  EXPECT_EQ(n.max_hold_ms, 0.0);
}

TEST(AvSync, HeldPicturesStayInSyncWhenTheirDelaysSpread) {
  // Picture delays spread over 200 ms: held until their voice, 90 % are in
  // step with it; the last 10 % see it at most ≈ 20 ms early.
  Scenario sc;
  sc.picture_jitter_ms = 200;
  const Outcome r = Simulate(sc);
  EXPECT_GT(r.stats.offsets, 50);
  EXPECT_NEAR(r.stats.av_offset_ms_p50, 0.0, 10.0);
  EXPECT_GE(r.stats.av_offset_ms_p1, -45.0);
  EXPECT_LE(r.stats.av_offset_ms_p99, 125.0);
  EXPECT_EQ(r.stats.offsets_early + r.stats.offsets_late, 0);
  EXPECT_LE(r.max_hold_ms, 200.0);
}

TEST(AvSync, LateVoiceHoldsThePicture) {
  Scenario sc;
  sc.voice_natural_ms = 280;
  sc.picture_base_ms = 10;
  sc.picture_jitter_ms = 10;
  const Outcome r = Simulate(sc);
  ExpectWithinBt1359(r.stats);
  EXPECT_GT(r.stats.pictures_held, r.stats.pictures / 2);
  EXPECT_GT(r.stats.picture_sync_delay_ms, 200.0);
  EXPECT_LT(r.stats.voice_sync_delay_ms, 15.0);  // the voice is not delayed further
  EXPECT_GT(r.stats.unsynced_offset_ms_p50, 200.0);
}

TEST(AvSync, WithoutSyncTheDifferenceShows) {
  AvSyncOptions off;
  off.enabled = false;
  Scenario late_picture;
  const Outcome a = Simulate(late_picture, off);
  // Voice at 80 ms, pictures at ≈ 440 ms: the voice is ≈ 360 ms early.
  EXPECT_LT(a.stats.av_offset_ms_p50, -300.0);
  EXPECT_NEAR(a.stats.unsynced_offset_ms_p50, a.stats.av_offset_ms_p50, 1.0);
  EXPECT_EQ(a.stats.offsets_early, a.stats.offsets);
  Scenario late_voice;
  late_voice.voice_natural_ms = 280;
  late_voice.picture_base_ms = 10;
  late_voice.picture_jitter_ms = 10;
  const Outcome b = Simulate(late_voice, off);
  EXPECT_GT(b.stats.av_offset_ms_p50, 200.0);
  EXPECT_EQ(b.stats.offsets_late, b.stats.offsets);
  EXPECT_EQ(b.stats.pictures_held, 0);
}

TEST(AvSync, BoundsAreKeptAndCounted) {
  // A voice 800 ms late: pictures wait at most 300 ms, then the voice lags.
  Scenario late_voice;
  late_voice.voice_natural_ms = 800;
  late_voice.picture_base_ms = 10;
  late_voice.picture_jitter_ms = 0;
  const Outcome a = Simulate(late_voice);
  EXPECT_LE(a.max_hold_ms, 300.0 + 1e-3);
  EXPECT_GT(a.stats.pictures_hold_capped, 0);
  EXPECT_GT(a.stats.av_offset_ms_p50, 400.0);
  // Pictures 2.5 s late: the voice waits at most 1 s more than its own delay.
  Scenario late_picture;
  late_picture.picture_base_ms = 2500;
  late_picture.seconds = 14;
  const Outcome b = Simulate(late_picture);
  EXPECT_GT(b.stats.voice_delay_capped, 0);
  EXPECT_NEAR(b.stats.voice_sync_delay_ms, 1000.0, 1.0);
  EXPECT_LT(b.stats.av_offset_ms_p50, -1000.0);
}

TEST(AvSync, NoVoiceNoHoldAndNoPicturesNoVoiceDelay) {
  Scenario no_voice;
  no_voice.voice = false;
  no_voice.picture_base_ms = 10;
  const Outcome a = Simulate(no_voice);
  EXPECT_EQ(a.max_hold_ms, 0.0);
  EXPECT_EQ(a.stats.offsets, 0);
  // Pictures stop: after a window without pictures the voice goes back to its own delay.
  Scenario stop;
  stop.pictures_stop_at_half = true;
  const Outcome b = Simulate(stop);
  EXPECT_EQ(b.final_voice_target_ms, 0.0);
}

// A broadcast's pictures arrive a quarter second at a time. Unpaced, the
// viewer shows the newest of each burst; paced, every picture at its
// capture rhythm (no voice, and with a voice as well).
TEST(AvSync, PicturesInBurstsArePacedAtTheirCaptureRhythm) {
  Scenario sc;
  sc.voice = false;
  sc.burst_ms = 250;
  sc.picture_base_ms = 150;
  const Outcome unpaced = Simulate(sc);
  EXPECT_GT(unpaced.skipped, 3 * unpaced.shown);
  EXPECT_GT(unpaced.max_gap_ms, 200.0);
  AvSyncOptions pace;
  pace.pace_pictures = true;
  const Outcome paced = Simulate(sc, pace);
  EXPECT_LT(paced.skipped, paced.shown / 20);
  EXPECT_GT(paced.shown, 140);  // 5 s at 30 fps: 150
  EXPECT_LT(paced.max_gap_ms, 80.0);
  EXPECT_LE(paced.max_hold_ms, pace.max_picture_delay_ms);
  sc.voice = true;
  const Outcome with_voice = Simulate(sc, pace);
  EXPECT_LT(with_voice.skipped, with_voice.shown / 20);
  EXPECT_LT(with_voice.max_gap_ms, 80.0);
}

TEST(AvSync, WithoutHoldsSpreadPicturesLeanTheVoiceLate) {
  // Pictures not held, their delays spread over 200 ms: a voice at their
  // median would be early for the late half; it moves up to 35 ms later.
  Scenario sc;
  sc.picture_jitter_ms = 200;
  AvSyncOptions no_hold;
  no_hold.hold_pictures = false;
  const Outcome r = Simulate(sc, no_hold);
  EXPECT_GT(r.stats.offsets, 50);  // pictures overtake each other: the older ones are not shown
  EXPECT_GE(r.stats.av_offset_ms_p50, -40.0);
  EXPECT_LE(r.stats.av_offset_ms_p50, 40.0);
  EXPECT_GT(r.stats.av_offset_ms_p50, 10.0) << "biased towards a late voice";
}

TEST(AvSync, OptionsAreChecked) {
  AvSyncOptions o;
  o.max_voice_delay_ms = -1;
  EXPECT_FALSE(o.Check().ok());
  o = {};
  o.window_s = 0;
  EXPECT_FALSE(o.Check().ok());
  EXPECT_TRUE(AvSyncOptions{}.Check().ok());
}

}  // namespace
}  // namespace holo::audio
