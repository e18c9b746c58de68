#include "audio/voice_chain.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "audio/ear_measure.h"

namespace holo::audio {
namespace {

std::vector<float> Noise(double seconds) {
  std::mt19937 rng(5);
  std::normal_distribution<float> g(0.0f, 0.1f);
  std::vector<float> x(static_cast<size_t>(seconds * kSampleRate));
  for (float& v : x) v = g(rng);
  return x;
}

struct ChainRun {
  ChainStats stats;
  std::vector<float> stereo;
  std::vector<ChainTick> ticks;  // spans cleared
  int64_t silent_blocks_while_playing = 0;
};

ChainRun RunChain(const HeadPose& remote, const VoiceChainOptions& o, double seconds) {
  SimulatedClock clock(1'000'000);
  auto cap = VoiceCapture::FromSamples(Noise(seconds), clock, [&](int64_t) { return remote; });
  ChainRun r;
  auto st = RunVoiceChain(*cap, clock, o, [&](const ChainTick& t) {
    r.stereo.insert(r.stereo.end(), t.stereo.begin(), t.stereo.end());
    double e = 0;
    for (float v : t.stereo) e += v * v;
    if (t.playing && e == 0) ++r.silent_blocks_while_playing;
    ChainTick c = t;
    c.stereo = {};
    c.source = {};
    r.ticks.push_back(c);
  });
  EXPECT_TRUE(st.ok()) << st.status().ToString();
  if (st.ok()) r.stats = *st;
  return r;
}

// A remote speaker 1 m in front of their display, with the face-to-face call
// config, is heard where the config puts them: the local listener at +x
// facing their display (yaw 180°) would hear them straight ahead; turned
// 90° to the right (yaw −90°), on the right.
TEST(VoiceChain, RemoteSpeakerIsHeardWhereTheCallConfigPutsThem) {
  VoiceChainOptions o;
  o.link = FaceToFaceLink(0.5f);
  o.network.jitter_ms = 20;
  o.network.loss = 0.05;
  o.listener = HeadPose{1.0f, 0.0f, 1.6f, -std::numbers::pi_v<float> / 2, 0, 0};  // looks along -y: display on the right
  const HeadPose remote{1.0f, 0.0f, 1.6f, std::numbers::pi_v<float>, 0, 0};         // 1 m in front of their display, facing it
  const ChainRun r = RunChain(remote, o, 4.0);
  ASSERT_GT(r.ticks.size(), 150u);
  const ChainTick& t = r.ticks[r.ticks.size() / 2];
  EXPECT_TRUE(t.playing);
  // Local room: the remote head lands at (−1.5, 0), facing +x (towards the local user).
  EXPECT_NEAR(t.placement.position.x(), -1.5f, 1e-4);
  EXPECT_NEAR(t.placement.position.y(), 0.0f, 1e-4);
  EXPECT_NEAR(t.placement.facing.x(), 1.0f, 1e-4);
  EXPECT_NEAR(t.azimuth_deg, 90.0f, 1e-3);
  EXPECT_NEAR(t.distance_m, 2.5f, 1e-4);
  // The ears agree: right louder and earlier.
  const size_t frames = r.stereo.size() / 2;
  const EarMeasurement m = MeasureEars(r.stereo, frames / 3, 2 * frames / 3, kSampleRate, 72);
  std::printf("through the chain at +90 deg: ILD %.1f dB, ITD %.3f ms; sent %lld, lost %lld, concealed %lld, late %lld\n",
              m.ild_db, m.itd_ms, static_cast<long long>(r.stats.messages_sent),
              static_cast<long long>(r.stats.lost_in_network), static_cast<long long>(r.stats.jitter_buffer.concealed),
              static_cast<long long>(r.stats.jitter_buffer.late));
  EXPECT_GT(m.ild_db, 6.0);
  EXPECT_NEAR(m.itd_ms, 0.7, 0.1);
  EXPECT_EQ(r.stats.refused, 0);
  EXPECT_EQ(r.stats.messages_sent, 200);
  EXPECT_GT(r.stats.lost_in_network, 0);
  EXPECT_EQ(r.silent_blocks_while_playing, 0);  // loss concealed, no holes
  EXPECT_GE(r.stats.jitter_buffer.concealed, r.stats.lost_in_network);
  // audio + pose + header per 20 ms: Opus 24 kbit/s plus ~31 kbit/s of pose, sequence and header.
  const double kbps = static_cast<double>(r.stats.bytes_sent) * 8 / 1000 / 4.0;
  EXPECT_GT(kbps, 40.0);
  EXPECT_LT(kbps, 70.0);
}

TEST(VoiceChain, FacingAwayThroughTheChainIsQuieter) {
  VoiceChainOptions o;
  o.link = RoomLink{};
  const HeadPose facing{1.0f, 0.0f, 1.6f, std::numbers::pi_v<float>, 0, 0};  // 1 m ahead, facing the listener
  const HeadPose away{1.0f, 0.0f, 1.6f, 0.0f, 0, 0};
  const ChainRun a = RunChain(facing, o, 2.0), b = RunChain(away, o, 2.0);
  const size_t n = std::min(a.stereo.size(), b.stereo.size()) / 2;
  const double la = MeasureEars(a.stereo, n / 3, 2 * n / 3, kSampleRate, 72).level_db;
  const double lb = MeasureEars(b.stereo, n / 3, 2 * n / 3, kSampleRate, 72).level_db;
  std::printf("facing %.1f dB, away %.1f dB\n", la, lb);
  EXPECT_GE(la - lb, 6.0);
}

// The measured mouth-to-ear delay adds up: PCM at no jitter = 20 ms framing +
// 20 ms jitter buffer target + the 20 ms frame playing + 20 ms queued in OpenAL;
// Opus adds its 6.5 ms look-ahead; a network base delay adds itself; jitter
// raises the jitter buffer's target and the delay with it.
TEST(VoiceChain, MouthToEarDelayAddsUp) {
  auto run = [](AudioCodec codec, double base_ms, double jitter_ms) {
    VoiceChainOptions o;
    o.encoder.codec = codec;
    o.network.base_delay_ms = base_ms;
    o.network.jitter_ms = jitter_ms;
    o.link = RoomLink{};
    auto m = MeasureMouthToEar(o, 14.0, 6.0);
    EXPECT_TRUE(m.ok()) << m.status().ToString();
    return m.ok() ? *m : MouthToEar{};
  };
  const MouthToEar pcm = run(AudioCodec::kPcm16, 0, 0), opus = run(AudioCodec::kOpus, 0, 0);
  const MouthToEar far = run(AudioCodec::kPcm16, 30, 0), jittery = run(AudioCodec::kPcm16, 0, 50);
  std::printf("mouth-to-ear median: pcm %.1f ms, opus %.1f, pcm + 30 ms network %.1f, pcm jitter 50 ms %.1f "
              "(target %.1f ms, max %.1f)\n",
              pcm.median_ms, opus.median_ms, far.median_ms, jittery.median_ms, jittery.jb_target_ms, jittery.max_ms);
  EXPECT_GE(pcm.bursts, 15);
  EXPECT_NEAR(pcm.median_ms, 80.0, 4.0);
  EXPECT_NEAR(opus.median_ms - pcm.median_ms, 6.5, 1.5);
  EXPECT_NEAR(far.median_ms - pcm.median_ms, 30.0, 3.0);
  EXPECT_GT(jittery.jb_target_ms, 45.0);
  EXPECT_NEAR(jittery.median_ms - pcm.median_ms, jittery.jb_target_ms - 20.0, 6.0);
  EXPECT_LT(jittery.max_ms, 150.0);  // bounded
}

TEST(VoiceChain, RefusesBadOptions) {
  SimulatedClock clock;
  auto cap = VoiceCapture::FromSamples(Noise(0.1), clock, [](int64_t) { return HeadPose{}; });
  VoiceChainOptions o;
  o.network.loss = 2;
  EXPECT_FALSE(RunVoiceChain(*cap, clock, o, [](const ChainTick&) {}).ok());
  o = {};
  o.playout_phase_ms = 25;
  EXPECT_FALSE(RunVoiceChain(*cap, clock, o, [](const ChainTick&) {}).ok());
}

}  // namespace
}  // namespace holo::audio
