// Lean voice frames (AudioPose codec 3, PROTOCOL.md §9.1): golden bytes,
// round trip through a protocol message, the pose quantization bound, every
// prefix and bit flip of the decoder, the wire rate over the speech fixtures
// (from the bytes actually encoded, header included) and its speech quality
// against today's classic default, the jitter buffer's pose interpolation.
// HOLO_WRITE_CORPUS=1 writes the fuzz seeds (protocol/fuzz/corpus/lean_audio_pose).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <random>

#include "audio/jitter_buffer.h"
#include "audio/speech_quality.h"
#include "audio/voice_codec.h"
#include "audio/wav.h"
#include "common/clock.h"
#include "protocol/fuzz_decoders.h"
#include "test_util.h"

namespace holo::audio {
namespace {

using protocol::Header;
using protocol::MessageType;

const std::vector<uint8_t> kGoldenPayload = {0x03, 0x01, 0xD2, 0x04, 0x0C, 0xFE, 0x40, 0x06, 0x00,
                                             0x40, 0xED, 0xFB, 0x00, 0x00, 0xF8, 0xFF, 0xFE};

AudioPose GoldenFrame() {
  AudioPose a;
  a.codec = AudioCodec::kOpusLean;
  a.sequence = 42;
  a.capture_time_us = 1000000;
  a.pose = {1.234f, -0.5f, 1.6f, std::numbers::pi_v<float> / 2, -0.1f, 0.0f};
  a.audio = {0xF8, 0xFF, 0xFE};  // a 20 ms CELT silence packet
  return a;
}

double AngleError(double a, double b) { return std::fabs(std::remainder(a - b, 2 * std::numbers::pi)); }

std::vector<float> Fixture(const char* name) {
  auto wav = ReadMonoWav(test::TestDataPath(std::string("audio/") + name), kSampleRate);
  EXPECT_TRUE(wav.ok()) << wav.status().ToString();
  return wav.ok() ? *wav : std::vector<float>{};
}

TEST(LeanFrame, GoldenBytesAndHeaderFields) {
  const std::vector<uint8_t> msg = protocol::EncodeMessage(Header{}, GoldenFrame());
  ASSERT_EQ(msg.size(), protocol::kHeaderSize + kGoldenPayload.size());
  EXPECT_EQ(std::vector<uint8_t>(msg.begin() + protocol::kHeaderSize, msg.end()), kGoldenPayload);
  auto m = protocol::DecodeMessage(msg);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->header.sequence, 42u);  // carried by the header only
  EXPECT_EQ(m->header.capture_time_us, 1000000);
  const auto& a = std::get<AudioPose>(m->payload);
  EXPECT_EQ(a.sequence, 42u);
  EXPECT_EQ(a.capture_time_us, 1000000);
  EXPECT_EQ(a.codec, AudioCodec::kOpusLean);
  EXPECT_TRUE(a.has_pose);
  EXPECT_FLOAT_EQ(a.pose.x, 1.234f);
  EXPECT_FLOAT_EQ(a.pose.y, -0.5f);
  EXPECT_FLOAT_EQ(a.pose.z, 1.6f);
  EXPECT_NEAR(a.pose.yaw, std::numbers::pi / 2, 1e-6);
  EXPECT_NEAR(a.pose.pitch, -0.1, std::numbers::pi / 65536);
  EXPECT_EQ(a.audio, GoldenFrame().audio);
  // The same frame in the classic layout: 46 bytes of fields instead of 14.
  const size_t classic = protocol::EncodePayload(protocol::ToClassicAudioPose(a)).size();
  EXPECT_EQ(classic - a.audio.size(), 46u);
  EXPECT_EQ(kGoldenPayload.size() - a.audio.size(), protocol::LeanAudioPoseOverhead(a));
  // A pose-less frame is 2 bytes of fields.
  AudioPose bare = GoldenFrame();
  bare.has_pose = false;
  const auto bare_payload = protocol::EncodePayload(bare);
  EXPECT_EQ(bare_payload, (std::vector<uint8_t>{0x03, 0x00, 0xF8, 0xFF, 0xFE}));
}

TEST(LeanFrame, VoiceRoundTripThroughAMessage) {
  const std::vector<float> speech = Fixture("speech_48k.wav");
  auto enc = VoiceEncoder::Create(LeanVoiceEncoderOptions());
  auto dec = VoiceDecoder::Create(AudioCodec::kOpusLean);
  ASSERT_TRUE(enc.ok() && dec.ok());
  for (uint32_t f = 0; f < 20; ++f) {
    const HeadPose pose{0.3f * f, -2.0f, 1.7f, 0.2f * f, 0.1f, -0.05f};
    auto frame = (*enc)->EncodeFrame(std::span<const float>(speech).subspan(f * kFrameSamples, kFrameSamples),
                                     1000 + f, 77000000 + 20000 * f, pose);
    ASSERT_TRUE(frame.ok());
    EXPECT_EQ(frame->codec, AudioCodec::kOpusLean);
    const std::vector<uint8_t> msg = protocol::EncodeMessage(Header{}, *frame);
    auto h = protocol::DecodeHeader(msg.data(), msg.size());
    ASSERT_TRUE(h.ok());
    auto parsed = ParseVoiceFrame(*h, std::span<const uint8_t>(msg).subspan(protocol::kHeaderSize));
    ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
    EXPECT_EQ(*parsed, *frame);
    EXPECT_EQ(parsed->sequence, 1000 + f);
    EXPECT_EQ(parsed->capture_time_us, 77000000 + 20000 * static_cast<int64_t>(f));
    // The default sends the pose with even sequence numbers (LeanVoiceEncoderOptions().pose_every = 2).
    EXPECT_EQ(parsed->has_pose, f % 2 == 0);
    EXPECT_EQ(parsed->pose, parsed->has_pose ? protocol::QuantizeLeanPose(pose) : HeadPose{});
    EXPECT_TRUE((*dec)->Decode(parsed->audio).ok());
    // Without its header a lean frame is refused, with the reason.
    auto bare = ParseVoiceFrame(std::span<const uint8_t>(msg).subspan(protocol::kHeaderSize));
    ASSERT_FALSE(bare.ok());
    EXPECT_NE(bare.status().message().find("header"), std::string::npos);
  }
}

// Position within 0.5 mm, each angle within π/65536 rad (0.0027°) modulo 2π,
// over room-sized and far positions and angles beyond ±π.
TEST(LeanFrame, PoseQuantizationBound) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> room(-30.0f, 30.0f), far(-999.0f, 999.0f), ang(-6.28f, 6.28f);
  double max_mm = 0, max_rad = 0;
  for (int i = 0; i < 20000; ++i) {
    const bool wide = i % 4 == 0;
    const HeadPose p{wide ? far(rng) : room(rng), room(rng), room(rng), ang(rng), ang(rng), ang(rng)};
    AudioPose a;
    a.codec = AudioCodec::kOpusLean;
    a.pose = p;
    a.audio = {0xF8, 0xFF, 0xFE};
    auto m = protocol::DecodeMessage(protocol::EncodeMessage(Header{}, a));
    ASSERT_TRUE(m.ok());
    const HeadPose q = std::get<AudioPose>(m->payload).pose;
    EXPECT_EQ(q, protocol::QuantizeLeanPose(p));
    for (auto [u, v] : {std::pair{p.x, q.x}, {p.y, q.y}, {p.z, q.z}})
      max_mm = std::max(max_mm, 1000.0 * std::fabs(static_cast<double>(u) - static_cast<double>(v)));
    for (auto [u, v] : {std::pair{p.yaw, q.yaw}, {p.pitch, q.pitch}, {p.roll, q.roll}}) {
      max_rad = std::max(max_rad, AngleError(u, v));
      EXPECT_LE(std::fabs(v), std::numbers::pi + 1e-6);
    }
  }
  std::printf("lean pose quantization: max position error %.4f mm, max angle error %.6f deg\n", max_mm,
              max_rad * 180 / std::numbers::pi);
  // Float rounding of a far position (~1000 m) adds up to 0.03 mm.
  EXPECT_LE(max_mm, 0.5 + 0.04);
  EXPECT_LE(max_rad, std::numbers::pi / 65536 + 1e-6);
  // Not a number becomes 0; beyond ±1 km is clamped (the audio path refuses those anyway).
  const HeadPose odd = protocol::QuantizeLeanPose({NAN, 5000.0f, -5000.0f, INFINITY, 0, 0});
  EXPECT_EQ(odd.x, 0.0f);
  EXPECT_FLOAT_EQ(odd.y, 1000.0f);
  EXPECT_FLOAT_EQ(odd.z, -1000.0f);
  EXPECT_EQ(odd.yaw, 0.0f);
}

std::vector<std::pair<std::string, std::vector<uint8_t>>> Seeds() {
  std::vector<std::pair<std::string, std::vector<uint8_t>>> seeds;
  seeds.emplace_back("seed-lean-golden", kGoldenPayload);
  AudioPose a = GoldenFrame();
  a.pose.x = 250.0f;  // wide position
  seeds.emplace_back("seed-lean-wide", protocol::EncodePayload(a));
  a.has_pose = false;
  seeds.emplace_back("seed-lean-no-pose", protocol::EncodePayload(a));
  auto enc = VoiceEncoder::Create(LeanVoiceEncoderOptions());
  HOLO_CHECK(enc.ok());
  const std::vector<float> speech = Fixture("speech_48k.wav");
  StatusOr<AudioPose> f = InvalidArgument("none");
  for (int i = 0; i < 30; ++i)  // a frame of speech, not the encoder's first
    f = (*enc)->EncodeFrame(std::span<const float>(speech).subspan(i * kFrameSamples, kFrameSamples), i, 0,
                            {1.0f, 2.0f, 1.6f, 0.5f, 0.0f, 0.0f});
  HOLO_CHECK(f.ok());
  seeds.emplace_back("seed-lean-speech", protocol::EncodePayload(*f));
  return seeds;
}

// Every prefix (each in a buffer of its own size, so a sanitizer sees any
// read past it) and every single-bit flip of each seed: refused with
// DataLoss or decoded to a frame that keeps FuzzLeanAudioPose's invariants.
TEST(LeanFrame, EveryPrefixAndBitFlipIsRefusedOrValid) {
  Header h;
  h.type = MessageType::kAudioPose;
  h.sequence = 5;
  for (const auto& [name, payload] : Seeds()) {
    ASSERT_EQ(protocol::FuzzLeanAudioPose(payload), 2) << name;
    const size_t fields = payload.size() - std::get<AudioPose>(*protocol::DecodePayload(h, payload)).audio.size();
    for (size_t n = 0; n < payload.size(); ++n) {
      std::unique_ptr<uint8_t[]> cut(new uint8_t[n]);
      std::copy(payload.begin(), payload.begin() + static_cast<std::ptrdiff_t>(n), cut.get());
      auto p = protocol::DecodePayload(h, std::span<const uint8_t>(cut.get(), n));
      // Cut before the Opus packet: refused. Within it: a shorter packet, which
      // this layer cannot tell; the audio path's Opus check refuses most.
      EXPECT_EQ(p.ok(), n > fields) << name << " prefix " << n;
      if (!p.ok()) {
        EXPECT_EQ(p.status().code(), StatusCode::kDataLoss);
      }
      protocol::FuzzLeanAudioPose(std::span<const uint8_t>(cut.get(), n));
      (void)ParseVoiceFrame(h, std::span<const uint8_t>(cut.get(), n));
    }
    int refused = 0, valid = 0;
    for (size_t bit = 0; bit < payload.size() * 8; ++bit) {
      std::vector<uint8_t> flipped = payload;
      flipped[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
      const int r = protocol::FuzzLeanAudioPose(flipped);  // aborts on a broken invariant
      (r == 0 ? refused : valid)++;
      auto v = ParseVoiceFrame(h, flipped);
      if (v.ok()) {
        EXPECT_TRUE(ValidateVoiceFrame(*v).ok());
      }
    }
    EXPECT_GT(refused, 0) << name;
    std::printf("%s: %zu prefixes, %zu bit flips: %d refused, %d decoded\n", name.c_str(), payload.size(),
                payload.size() * 8, refused, valid);
  }
  // Named refusals.
  auto why = [&](std::vector<uint8_t> b) {
    auto p = protocol::DecodePayload(h, b);
    return p.ok() ? std::string("ok") : p.status().message();
  };
  EXPECT_NE(why({0x03, 0x04, 0xF8}).find("unknown flag"), std::string::npos);
  EXPECT_NE(why({0x03, 0x02, 0xF8}).find("wide position without a pose"), std::string::npos);
  EXPECT_NE(why({0x03, 0x00}).find("without an Opus packet"), std::string::npos);
  std::vector<uint8_t> big = {0x03, 0x00};
  big.resize(2 + 1276, 0xF8);
  EXPECT_NE(why(big).find("exceeds 1275"), std::string::npos);
  std::vector<uint8_t> far = {0x03, 0x03, 0x41, 0x42, 0x0F, 0x00};  // x = 1,000,001 mm
  far.resize(2 + 12 + 6 + 1, 0);
  far[2] = 0x41, far[3] = 0x42, far[4] = 0x0F, far[5] = 0x00;
  EXPECT_NE(why(far).find("beyond ±1 km"), std::string::npos);
}

// The fuzz seeds in the repository decode as lean frames (regenerate with
// HOLO_WRITE_CORPUS=1); every corpus file runs through the fuzz entry point.
TEST(LeanFrame, FuzzCorpusSeeds) {
  const std::string dir = std::string(HOLO_SOURCE_DIR) + "/protocol/fuzz/corpus/lean_audio_pose";
  if (std::getenv("HOLO_WRITE_CORPUS")) {
    std::filesystem::create_directories(dir);
    for (const auto& [name, bytes] : Seeds()) {
      std::ofstream(dir + "/" + name, std::ios::binary)
          .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    }
  }
  int seeds = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const int r = protocol::FuzzLeanAudioPose(bytes);
    if (entry.path().filename().string().rfind("seed-", 0) == 0) {
      EXPECT_EQ(r, 2) << entry.path();
      ++seeds;
    }
  }
  EXPECT_GE(seeds, 4);
}

struct Wire {
  double kbps = 0, fw_db = 0;
};

// Every frame of `speech` encoded, framed as a protocol message (32-byte
// header + payload), parsed back as a receiver would, decoded: the wire rate
// from the bytes and fwSNRseg of what the receiver hears.
Wire OverTheWire(const std::vector<float>& speech, const VoiceEncoderOptions& o) {
  auto enc = VoiceEncoder::Create(o);
  auto dec = VoiceDecoder::Create(o.codec);
  HOLO_CHECK(enc.ok() && dec.ok());
  size_t bytes = 0, frames = 0;
  std::vector<float> out;
  for (size_t i = 0; i + kFrameSamples <= speech.size(); i += kFrameSamples, ++frames) {
    const HeadPose pose{1.0f + 0.001f * frames, -0.7f, 1.65f, 0.01f * frames, 0.05f, 0.0f};
    auto f = (*enc)->EncodeFrame(std::span<const float>(speech).subspan(i, kFrameSamples),
                                 static_cast<uint32_t>(frames), 20000 * static_cast<int64_t>(frames), pose);
    HOLO_CHECK(f.ok());
    const std::vector<uint8_t> msg = protocol::EncodeMessage(Header{}, *f);
    bytes += msg.size();
    auto h = protocol::DecodeHeader(msg.data(), msg.size());
    HOLO_CHECK(h.ok());
    auto parsed = ParseVoiceFrame(*h, std::span<const uint8_t>(msg).subspan(protocol::kHeaderSize));
    HOLO_CHECK(parsed.ok());
    auto pcm = (*dec)->Decode(parsed->audio);
    HOLO_CHECK(pcm.ok());
    out.insert(out.end(), pcm->begin(), pcm->end());
  }
  Wire w;
  w.kbps = static_cast<double>(bytes) * 8.0 / (static_cast<double>(frames) * 20.0);
  w.fw_db = FwSegSnrDb(speech, out, BestLag(speech, out, 960), kSampleRate);
  return w;
}

// ≤ 32 kbit/s a speaker, header and pose included, counted from the bytes
// encoded; speech quality within 0.5 dB of today's classic default (Opus 24
// kbit/s in 55 kbit/s frames) on both speech fixtures.
TEST(LeanFrame, ThirtyTwoKbitPerSpeakerAtTheSameQuality) {
  for (const char* name : {"espeak_speech_22k.wav", "speech_48k.wav"}) {
    const std::vector<float> speech = Fixture(name);
    ASSERT_GT(speech.size(), 100u * kFrameSamples);
    const Wire classic = OverTheWire(speech, VoiceEncoderOptions{});
    const Wire lean = OverTheWire(speech, LeanVoiceEncoderOptions());
    std::printf("%s: classic %.1f kbit/s fwSNRseg %.2f dB; lean %.1f kbit/s fwSNRseg %.2f dB\n", name, classic.kbps,
                classic.fw_db, lean.kbps, lean.fw_db);
    EXPECT_LE(lean.kbps, 32.0) << name;
    EXPECT_GT(classic.kbps, 45.0) << name;  // what it replaces
    EXPECT_GE(lean.fw_db, classic.fw_db - 0.5) << name;
  }
}

// The lean frame keeps the codec's delay: same look-ahead, so mouth-to-ear does not grow.
TEST(LeanFrame, SameCodecDelay) {
  auto lean = VoiceEncoder::Create(LeanVoiceEncoderOptions());
  auto classic = VoiceEncoder::Create({});
  ASSERT_TRUE(lean.ok() && classic.ok());
  EXPECT_EQ((*lean)->lookahead_samples(), (*classic)->lookahead_samples());
  EXPECT_EQ(CodecDelaySamples(AudioCodec::kOpusLean), CodecDelaySamples(AudioCodec::kOpus));
}

// Frames sent with a pose every other frame: the jitter buffer plays the
// pose-less ones on the line between their neighbours (along the shorter arc
// across ±π), never a zero pose — halfway to the next frame's pose when it is
// there, extrapolated from the two before when the next frame was lost;
// classic and lean frames share one stream.
JitterBufferStats PlayPoseEveryOtherFrame(bool lose_some) {
  VoiceEncoderOptions o = LeanVoiceEncoderOptions();
  o.pose_every = 2;
  auto enc = VoiceEncoder::Create(o);
  HOLO_CHECK(enc.ok());
  SimulatedClock clock;
  auto jb = JitterBuffer::Create(AudioCodec::kOpusLean, clock);
  HOLO_CHECK(jb.ok());
  const std::vector<float> speech = Fixture("speech_48k.wav");
  auto yaw_of = [](double x) { return std::remainder(3.0 + x, 2 * std::numbers::pi); };
  const int kFrames = 40;
  int odd_seen = 0;
  for (int s = 0; s < kFrames + 10; ++s) {
    // Frame s arrives 5 ms after it is complete; a pull every 20 ms.
    clock.SetUs(s * kFrameUs + 5000);
    if (s < kFrames) {
      const double x = 0.1 * s;
      const HeadPose pose{static_cast<float>(x), 0.5f, 1.6f, static_cast<float>(yaw_of(x)), 0, 0};
      auto f = (*enc)->EncodeFrame(std::span<const float>(speech).subspan(s * kFrameSamples, kFrameSamples), s,
                                   s * kFrameUs, pose);
      HOLO_CHECK(f.ok());
      EXPECT_EQ(f->has_pose, s % 2 == 0);
      // Every fifth frame in the classic layout (an old sender's): same stream.
      const AudioPose frame = s % 5 == 4 ? protocol::ToClassicAudioPose(*f, protocol::QuantizeLeanPose(pose)) : *f;
      const bool lost = lose_some && s % 10 == 6;  // a frame with a pose, after a pose-less one
      if (!lost) {
        EXPECT_TRUE((*jb)->Insert(frame).ok()) << s;
      }
    }
    clock.SetUs(s * kFrameUs + 10000);
    (*jb)->Pull();
    if (!(*jb)->playing()) continue;
    const HeadPose p = (*jb)->pose();
    if (p.x == 0.0f) continue;  // the first frame, or none played yet
    const double seq = p.x / 0.1;
    EXPECT_NEAR(seq, std::round(seq), 1e-3) << "a pose off the line: x " << p.x;
    EXPECT_LT(AngleError(p.yaw, yaw_of(p.x)), 2e-3) << "x " << p.x << " yaw " << p.yaw;
    EXPECT_FLOAT_EQ(p.y, 0.5f);
    if (static_cast<int>(std::lround(seq)) % 2 == 1) ++odd_seen;
  }
  EXPECT_GT(odd_seen, 10);
  const JitterBufferStats st = (*jb)->stats();
  std::printf("%s: pose-less frames %lld interpolated, %lld extrapolated, %lld held\n",
              lose_some ? "with losses" : "no loss", static_cast<long long>(st.poses_interpolated),
              static_cast<long long>(st.poses_extrapolated), static_cast<long long>(st.poses_held));
  EXPECT_LE(st.poses_held, 1);  // only before a second pose arrived
  return st;
}

TEST(LeanFrame, JitterBufferInterpolatesPoseLessFrames) {
  const JitterBufferStats st = PlayPoseEveryOtherFrame(false);
  EXPECT_GT(st.poses_interpolated, 10);
}

TEST(LeanFrame, JitterBufferExtrapolatesWhenTheNextPoseIsLost) {
  const JitterBufferStats st = PlayPoseEveryOtherFrame(true);
  EXPECT_GE(st.poses_extrapolated, 3);
  EXPECT_GT(st.poses_interpolated, 5);
}

}  // namespace
}  // namespace holo::audio
