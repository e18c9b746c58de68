// Lip sync over the real message path. A site's pictures (G1 + C1, 30 fps)
// and its voice (Opus; a syllable at the capture instant of every 15th
// picture) go through a session server to a client over loopback; the
// messages received there are then fed, at simulated arrival times, to a
// viewer (SiteClient decoding them, SiteAvSync playing the voice through its
// jitter buffer and handing out pictures when due, a 20 ms render). A known
// extra delay on the voice path or the picture path must not move the
// offset out of ITU-R BT.1359's bounds (−45 … +125 ms, p50 within ±40 ms)
// with sync on, and shows up in full with sync off. The offset is measured
// twice: by the viewer (AvSync) and from the content (syllable onsets
// detected in the audio played, against the display time of their picture).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <random>
#include <thread>

#include "audio/synthetic_voice.h"
#include "audio/voice_codec.h"
#include "client/net/site_av_sync.h"
#include "common/quantile.h"
#include "net/net_fixtures.h"
#include "net/site_client.h"
#include "net/wire_message.h"

namespace holo::net {
namespace {

constexpr int64_t kT0 = 1'700'000'000'000'000;  // capture times: a wall-clock-like origin
constexpr double kSeconds = 8.0;
constexpr int kFrames = static_cast<int>(kSeconds * 30);
constexpr int kVoiceFrames = static_cast<int>(kSeconds * 50);
constexpr int kOnsetEvery = 15;     // pictures: a syllable every 0.5 s
constexpr int64_t kMeasureFrom = kT0 + 3'000'000;

int64_t PictureCapture(int i) { return kT0 + static_cast<int64_t>(i) * 1000000 / 30; }

struct Captured {
  std::vector<RawMessage> messages;  // in the order received
};

// The site's stream through a session server to a recorder over loopback.
Captured CaptureOverLoopback() {
  Captured c;
  ServerConfig cfg = test::LoopbackConfig();
  cfg.queue_video_frames = 1000;
  cfg.queue_priority_messages = 4096;
  auto server = Server::Start(cfg);
  if (!server.ok()) {
    ADD_FAILURE() << server.status().ToString();
    return c;
  }
  std::mutex mu;
  ClientOptions o;
  o.port = (*server)->port();
  o.token = "view-secret";
  o.name = "capture";
  o.role = protocol::Role::kRecorder;
  o.decode = false;
  ClientCallbacks cb;
  int frames = 0, voices = 0;
  cb.on_raw = [&](const RawMessage& m) {
    const auto t = m.header.type;
    if (t != protocol::MessageType::kMeshFrame && t != protocol::MessageType::kColorFrame &&
        t != protocol::MessageType::kAudioPose)
      return;
    std::lock_guard<std::mutex> l(mu);
    c.messages.push_back(m);
    frames += t == protocol::MessageType::kColorFrame;
    voices += t == protocol::MessageType::kAudioPose;
  };
  auto rec = SiteClient::Start(o, cb);
  if (!rec.ok() || !(*rec)->WaitConnected(5.0) ||
      !test::Eventually([&] { return (*server)->num_subscribed(kContentAudio) == 1; })) {
    ADD_FAILURE() << "recorder did not connect";
    return c;
  }
  const test::EncodedContent content = test::MakeContent(20, 30);
  auto enc = audio::VoiceEncoder::Create({});
  if (!enc.ok()) {
    ADD_FAILURE() << enc.status().ToString();
    return c;
  }
  // The voice: a syllable starting exactly at the capture time of every 15th picture.
  audio::SyntheticVoice voice(3);
  for (int i = kOnsetEvery; i < kFrames; i += kOnsetEvery)
    voice.Start(audio::SyntheticVoice::Sound::kSyllable, (PictureCapture(i) - kT0) * audio::kSampleRate / 1000000);
  std::vector<float> pcm(audio::kFrameSamples);
  int next_frame = 0;
  for (int j = 0; j < kVoiceFrames; ++j) {
    const int64_t capture = kT0 + j * audio::kFrameUs;
    // Pictures captured before this voice frame is complete go first (capture order).
    while (next_frame < kFrames && PictureCapture(next_frame) < capture + audio::kFrameUs) {
      (*server)->PublishVideo(MakeVideoFrame(next_frame, PictureCapture(next_frame), protocol::GeometryCodec::kG1,
                                             content.geometry, &content.color, cfg.fragment_bytes));
      ++next_frame;
    }
    voice.Render(pcm);
    auto a = (*enc)->EncodeFrame(pcm, static_cast<uint32_t>(j), capture, protocol::HeadPose{0, 0, 1.6f, 0, 0, 0});
    if (!a.ok()) {
      ADD_FAILURE() << a.status().ToString();
      return c;
    }
    (*server)->PublishAudio(*a, kSiteVoiceStreamId);
    if (j % 10 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (!test::Eventually([&] {
        std::lock_guard<std::mutex> l(mu);
        return frames == kFrames && voices == kVoiceFrames;
      })) {
    std::lock_guard<std::mutex> l(mu);
    ADD_FAILURE() << "received " << frames << " of " << kFrames << " pictures, " << voices << " of " << kVoiceFrames
                  << " voice frames";
  }
  (*rec)->Stop();
  return c;
}

const Captured& Stream() {
  static const Captured c = CaptureOverLoopback();
  return c;
}

struct Case {
  double extra_voice_ms = 0;    // on the voice path
  double extra_picture_ms = 0;  // on the picture path
  bool sync = true;
  // > 0: a broadcast's parts: everything captured within one part arrives
  // at once, 100 ms after the part ends (the network delays above ignored).
  double part_ms = 0;
  bool voice = true;   // the voice's messages are fed
  bool pace = false;   // AvSyncOptions::pace_pictures
};

struct Result {
  audio::AvSyncStats stats;
  std::vector<double> content_offsets_ms;  // syllable heard − its picture shown, after kMeasureFrom
  int64_t displayed = 0;
  int64_t displayed_measured = 0;  // of them, after kMeasureFrom
};

// Voice: a frame leaves when complete (20 ms), network 2 ms + U(0, 8 ms).
// Pictures: the site's pipeline and the network 60 ms + U(0, 20 ms); the
// viewer renders each in 20 ms. Without extra delays both streams are heard
// and seen ≈ 90 ms after capture.
Result Simulate(const Case& k) {
  const Captured& cap = Stream();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  struct Arrival {
    int64_t t;
    size_t index;
  };
  std::vector<Arrival> arrivals;
  std::map<int64_t, int64_t> picture_arrival;  // frame index → arrival (mesh and colour together)
  for (size_t i = 0; i < cap.messages.size(); ++i) {
    const RawMessage& m = cap.messages[i];
    const int64_t c = m.header.capture_time_us;
    int64_t t = 0;
    if (m.header.type == protocol::MessageType::kAudioPose && !k.voice) continue;
    if (k.part_ms > 0) {
      const auto part = static_cast<int64_t>(k.part_ms * 1000);
      arrivals.push_back({(c - kT0) / part * part + part + 100000 + kT0, i});
      continue;
    }
    if (m.header.type == protocol::MessageType::kAudioPose) {
      t = c + audio::kFrameUs + 2000 + static_cast<int64_t>(u(rng) * 8000 + k.extra_voice_ms * 1000);
    } else {
      auto it = picture_arrival.find(static_cast<int64_t>(m.header.sequence));
      if (it == picture_arrival.end())
        it = picture_arrival
                 .emplace(m.header.sequence, c + 60000 + static_cast<int64_t>(u(rng) * 20000 + k.extra_picture_ms * 1000))
                 .first;
      t = it->second;
    }
    arrivals.push_back({t, i});
  }
  std::stable_sort(arrivals.begin(), arrivals.end(), [](const Arrival& a, const Arrival& b) { return a.t < b.t; });

  Result r;
  SimulatedClock clock(kT0);
  ClientOptions co;
  co.fed = true;
  co.max_pending_frames = 64;
  co.max_pending_audio = 4096;
  auto client = SiteClient::Start(co);
  EXPECT_TRUE(client.ok());
  if (!client.ok()) return r;
  struct Played {
    int64_t playout_us, capture_us;
    std::vector<float> pcm;
  };
  std::vector<Played> played;
  SiteAvSyncOptions so;
  so.clock = &clock;
  so.voice_thread = false;
  so.sync.enabled = k.sync;
  so.sync.pace_pictures = k.pace;
  so.on_voice = [&](const RemoteVoices::Block& b) {
    if (b.playing) played.push_back({b.playout_us, b.capture_us, b.pcm});
  };
  auto av = SiteAvSync::Start(client->get(), so);
  EXPECT_TRUE(av.ok()) << av.status().ToString();
  if (!av.ok()) return r;
  std::map<int64_t, int64_t> displayed_at;  // frame index → display time
  size_t next = 0;
  uint64_t fed_frames = 0, fed_voices = 0;
  int64_t busy_until = 0;
  bool rendering = false;
  ReceivedFrame shown;
  int64_t render_start = 0;
  bool reset = false;
  for (int64_t t = kT0; t < kT0 + static_cast<int64_t>(kSeconds * 1e6) + 500000; t += 1000) {
    clock.SetUs(t);
    bool fed = false;
    for (; next < arrivals.size() && arrivals[next].t <= t; ++next) {
      RawMessage m = cap.messages[arrivals[next].index];
      m.received_us = t;
      fed_frames += m.header.type == protocol::MessageType::kColorFrame;
      fed_voices += m.header.type == protocol::MessageType::kAudioPose;
      (*client)->Feed(std::move(m));
      fed = true;
    }
    if (fed) {
      // Fed messages are decoded on the client's strand: wait until they are.
      bool delivered = false;
      for (int spin = 0; spin < 100000 && !delivered; ++spin) {
        const ClientStats s = (*client)->stats();
        delivered = s.frames_received == fed_frames && s.audio_received == fed_voices;
        if (!delivered) std::this_thread::sleep_for(std::chrono::microseconds(50));
      }
      EXPECT_TRUE(delivered);
      if (!delivered) return r;
    }
    if (!reset && t >= kMeasureFrom) {
      (*av)->sync().ResetStats();
      reset = true;
    }
    if ((t - kT0) % audio::kFrameUs == 10000) (*av)->TickVoice();  // 10 ms out of phase with the sender
    if (rendering && t >= busy_until) {
      (*av)->Displayed(shown, render_start, busy_until);
      displayed_at[shown.frame_index] = busy_until;
      ++r.displayed;
      rendering = false;
    }
    if (!rendering && (*av)->NextFrame(&shown)) {
      if (reset) ++r.displayed_measured;
      render_start = t;
      busy_until = t + 20000;
      rendering = true;
    }
  }
  r.stats = (*av)->stats();
  (*av)->Stop();
  (*client)->Stop();
  // Syllable onsets in what was played: above 0.05 after ≥ 60 ms below it.
  int quiet = 1 << 20;
  for (const Played& p : played) {
    for (int n = 0; n < audio::kFrameSamples; ++n) {
      const float a = std::abs(p.pcm[n]);
      if (a > 0.05f && quiet > 2880) {
        // Which syllable: the nearest onset capture instant (they are 0.5 s apart).
        const int64_t capture = p.capture_us + n * 1000000LL / audio::kSampleRate;
        const int frame = static_cast<int>(std::lround(static_cast<double>(capture - kT0) * 30 / 1e6 / kOnsetEvery)) *
                          kOnsetEvery;
        const int64_t heard = p.playout_us + n * 1000000LL / audio::kSampleRate;
        auto d = displayed_at.find(frame);
        if (frame > 0 && d != displayed_at.end() && PictureCapture(frame) >= kMeasureFrom)
          r.content_offsets_ms.push_back(static_cast<double>(heard - d->second) / 1000.0);
      }
      quiet = a > 0.05f ? 0 : quiet + 1;
    }
  }
  if (k.part_ms > 0)
    std::printf("parts of %.0f ms, %s, pace %s: %lld pictures shown after the first 3 s; ", k.part_ms,
                k.voice ? "voice" : "no voice", k.pace ? "on" : "off", static_cast<long long>(r.displayed_measured));
  std::printf("voice +%.0f ms, picture +%.0f ms, sync %s: av offset p1 %.1f p50 %.1f p99 %.1f ms (%lld offsets); "
              "content: median %.1f ms over %zu syllables; voice sync delay %.0f ms, picture hold %.0f ms, %lld of %lld "
              "pictures held\n",
              k.extra_voice_ms, k.extra_picture_ms, k.sync ? "on" : "off", r.stats.av_offset_ms_p1,
              r.stats.av_offset_ms_p50, r.stats.av_offset_ms_p99, static_cast<long long>(r.stats.offsets),
              Quantile(r.content_offsets_ms, 0.5), r.content_offsets_ms.size(), r.stats.voice_sync_delay_ms,
              r.stats.picture_sync_delay_ms, static_cast<long long>(r.stats.pictures_held),
              static_cast<long long>(r.stats.pictures));
  return r;
}

void ExpectInSync(const Result& r) {
  EXPECT_GT(r.stats.offsets, 100);
  EXPECT_GE(r.stats.av_offset_ms_p50, -40.0);
  EXPECT_LE(r.stats.av_offset_ms_p50, 40.0);
  EXPECT_GE(r.stats.av_offset_ms_p1, -45.0);
  EXPECT_LE(r.stats.av_offset_ms_p99, 125.0);
  // What is heard against what is seen agrees with the viewer's own measure.
  ASSERT_GE(r.content_offsets_ms.size(), 6u);
  for (double o : r.content_offsets_ms) {
    EXPECT_GE(o, -45.0);
    EXPECT_LE(o, 125.0);
  }
  EXPECT_NEAR(Quantile(r.content_offsets_ms, 0.5), r.stats.av_offset_ms_p50, 15.0);
}

TEST(LipSync, InSyncOverTheMessagePath) {
  ASSERT_FALSE(Stream().messages.empty());
  ExpectInSync(Simulate({}));
}

TEST(LipSync, VoiceDelayed200MsHoldsThePictures) {
  ASSERT_FALSE(Stream().messages.empty());
  const Result on = Simulate({200, 0, true});
  ExpectInSync(on);
  EXPECT_GT(on.stats.pictures_held, on.stats.pictures / 2);
  EXPECT_GT(on.stats.picture_sync_delay_ms, 150.0);
  // Without sync the 200 ms show up: the voice is late beyond +125 ms.
  const Result off = Simulate({200, 0, false});
  EXPECT_GT(off.stats.av_offset_ms_p50, 150.0);
  EXPECT_GT(Quantile(off.content_offsets_ms, 0.5), 150.0);
  EXPECT_EQ(off.stats.pictures_held, 0);
}

TEST(LipSync, PictureDelayed200MsDelaysTheVoice) {
  ASSERT_FALSE(Stream().messages.empty());
  const Result on = Simulate({0, 200, true});
  ExpectInSync(on);
  EXPECT_GT(on.stats.voice_sync_delay_ms, 150.0);
  // Without sync the voice runs 200 ms ahead of the lips.
  const Result off = Simulate({0, 200, false});
  EXPECT_LT(off.stats.av_offset_ms_p50, -150.0);
  EXPECT_LT(Quantile(off.content_offsets_ms, 0.5), -150.0);
}

// A broadcast: the player hands over a quarter second of messages at once.
// Paced, the viewer shows nearly every picture (at its capture rhythm), with
// or without a voice, and stays in sync with the voice; unpaced and without
// a voice it showed the newest picture of each part.
TEST(LipSync, ABroadcastsPartsArePacedAtTheirCaptureRhythm) {
  ASSERT_FALSE(Stream().messages.empty());
  const int64_t measured = static_cast<int64_t>((kSeconds - 3.0) * 30);  // pictures captured after kMeasureFrom
  Case silent{0, 0, true, 250, false, false};
  const Result unpaced = Simulate(silent);
  EXPECT_LT(unpaced.displayed_measured, measured / 3);
  silent.pace = true;
  const Result paced = Simulate(silent);
  EXPECT_GT(paced.displayed_measured, measured * 9 / 10);
  const Result with_voice = Simulate({0, 0, true, 250, true, true});
  EXPECT_GT(with_voice.displayed_measured, measured * 9 / 10);
  ExpectInSync(with_voice);
}

}  // namespace
}  // namespace holo::net
