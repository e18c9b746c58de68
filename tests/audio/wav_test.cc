#include "audio/wav.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <numbers>
#include <random>

#include "test_util.h"

namespace holo::audio {
namespace {

void Put16(std::vector<uint8_t>& v, uint32_t x) {
  v.push_back(static_cast<uint8_t>(x & 0xFF));
  v.push_back(static_cast<uint8_t>((x >> 8) & 0xFF));
}
void Put32(std::vector<uint8_t>& v, uint32_t x) {
  for (int i = 0; i < 4; ++i) v.push_back(static_cast<uint8_t>((x >> (8 * i)) & 0xFF));
}
void Tag(std::vector<uint8_t>& v, const char* t) { v.insert(v.end(), t, t + 4); }

struct Header {
  uint32_t format = 1, channels = 1, rate = 48000, bits = 16;
  int64_t align = -1;          // -1: channels·bits/8
  int64_t data_size = -1;      // -1: the real size
  int64_t fmt_size = -1;       // -1: 16
};

std::vector<uint8_t> MakeWav(const Header& h, const std::vector<uint8_t>& data) {
  std::vector<uint8_t> b;
  Tag(b, "RIFF");
  Put32(b, static_cast<uint32_t>(36 + data.size()));
  Tag(b, "WAVE");
  Tag(b, "fmt ");
  Put32(b, h.fmt_size < 0 ? 16u : static_cast<uint32_t>(h.fmt_size));
  Put16(b, h.format);
  Put16(b, h.channels);
  Put32(b, h.rate);
  const uint32_t align = h.align < 0 ? h.channels * h.bits / 8 : static_cast<uint32_t>(h.align);
  Put32(b, h.rate * align);
  Put16(b, align);
  Put16(b, h.bits);
  Tag(b, "data");
  Put32(b, h.data_size < 0 ? static_cast<uint32_t>(data.size()) : static_cast<uint32_t>(h.data_size));
  b.insert(b.end(), data.begin(), data.end());
  return b;
}

std::vector<uint8_t> S16(const std::vector<int16_t>& s) {
  std::vector<uint8_t> d;
  for (int16_t v : s) Put16(d, static_cast<uint16_t>(v));
  return d;
}

void ExpectRefused(const std::vector<uint8_t>& bytes, const std::string& why) {
  auto w = ParseWav(bytes);
  ASSERT_FALSE(w.ok()) << why;
  EXPECT_NE(w.status().message().find(why), std::string::npos) << w.status().message();
}

TEST(Wav, WriteReadRoundTrip) {
  const std::string dir = test::MakeTempDir("wav");
  std::vector<float> st = {0.5f, -0.5f, 0.25f, 1.5f, -2.0f, 0.0f};
  ASSERT_TRUE(WriteStereoWav(dir + "/s.wav", st, 44100).ok());
  auto w = ReadWav(dir + "/s.wav");
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  EXPECT_EQ(w->sample_rate, 44100);
  EXPECT_EQ(w->channels, 2);
  ASSERT_EQ(w->frames(), 3u);
  EXPECT_NEAR(w->samples[0], 0.5f, 1e-4);
  EXPECT_NEAR(w->samples[3], 1.0f, 1e-4);   // clipped
  EXPECT_NEAR(w->samples[4], -1.0f, 1e-4);  // clipped
  auto m = ReadMonoWav(dir + "/s.wav", 44100);
  ASSERT_TRUE(m.ok());
  EXPECT_NEAR((*m)[0], 0.0f, 1e-4);  // (0.5 − 0.5) / 2
  auto missing = ReadWav(dir + "/nope.wav");
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("nope.wav"), std::string::npos);
}

TEST(Wav, ReadsEveryPcmAndFloatLayout) {
  {  // 8-bit unsigned
    auto w = ParseWav(MakeWav({.bits = 8}, {0, 128, 255}));
    ASSERT_TRUE(w.ok()) << w.status().ToString();
    EXPECT_NEAR(w->samples[0], -1.0f, 1e-6);
    EXPECT_NEAR(w->samples[1], 0.0f, 1e-6);
  }
  {  // 24-bit
    auto w = ParseWav(MakeWav({.bits = 24}, {0x00, 0x00, 0x40, 0x00, 0x00, 0xC0}));
    ASSERT_TRUE(w.ok()) << w.status().ToString();
    EXPECT_NEAR(w->samples[0], 0.5f, 1e-6);
    EXPECT_NEAR(w->samples[1], -0.5f, 1e-6);
  }
  {  // 32-bit float, non-finite samples become 0
    std::vector<uint8_t> d(8);
    const float a = 0.25f, b = NAN;
    std::memcpy(d.data(), &a, 4);
    std::memcpy(d.data() + 4, &b, 4);
    auto w = ParseWav(MakeWav({.format = 3, .bits = 32}, d));
    ASSERT_TRUE(w.ok()) << w.status().ToString();
    EXPECT_EQ(w->samples[0], 0.25f);
    EXPECT_EQ(w->samples[1], 0.0f);
  }
  {  // WAVE_FORMAT_EXTENSIBLE carrying 16-bit PCM
    std::vector<uint8_t> b;
    Tag(b, "RIFF");
    Put32(b, 0);
    Tag(b, "WAVE");
    Tag(b, "fmt ");
    Put32(b, 40);
    Put16(b, 0xFFFE);
    Put16(b, 1);
    Put32(b, 16000);
    Put32(b, 32000);
    Put16(b, 2);
    Put16(b, 16);
    Put16(b, 22);
    Put16(b, 16);
    Put32(b, 4);
    const uint8_t guid[16] = {1, 0, 0, 0, 0, 0, 0x10, 0, 0x80, 0, 0, 0xAA, 0, 0x38, 0x9B, 0x71};
    b.insert(b.end(), guid, guid + 16);
    Tag(b, "data");
    Put32(b, 4);
    const auto d = S16({16384, -16384});
    b.insert(b.end(), d.begin(), d.end());
    auto w = ParseWav(b);
    ASSERT_TRUE(w.ok()) << w.status().ToString();
    EXPECT_EQ(w->sample_rate, 16000);
    EXPECT_NEAR(w->samples[1], -0.5f, 1e-6);
  }
  {  // streamed header (data size unknown): data runs to the end of the file
    auto w = ParseWav(MakeWav({.data_size = 0xFFFFFFFF}, S16({1, 2, 3})));
    ASSERT_TRUE(w.ok()) << w.status().ToString();
    EXPECT_EQ(w->frames(), 3u);
  }
}

TEST(Wav, RefusesMalformedHeadersWithAReason) {
  const auto d = S16({100, 200, 300, 400});
  ExpectRefused({}, "not a WAV file");
  ExpectRefused({'R', 'I', 'F', 'X', 0, 0, 0, 0, 'W', 'A', 'V', 'E'}, "not a RIFF");
  ExpectRefused({'R', 'I', 'F', 'F', 0, 0, 0, 0, 'A', 'V', 'I', ' '}, "not WAVE");
  ExpectRefused(MakeWav({.channels = 0}, d), "channel count 0");
  ExpectRefused(MakeWav({.channels = 60000, .align = 4}, d), "channel count 60000");
  ExpectRefused(MakeWav({.rate = 0}, d), "sample rate 0");
  ExpectRefused(MakeWav({.rate = 4000000000u}, d), "sample rate 4000000000");
  ExpectRefused(MakeWav({.bits = 12, .align = 2}, d), "unsupported sample format 1 with 12 bits");
  ExpectRefused(MakeWav({.bits = 0, .align = 2}, d), "unsupported");
  ExpectRefused(MakeWav({.format = 2}, d), "unsupported sample format 2");  // ADPCM
  ExpectRefused(MakeWav({.format = 3, .bits = 16}, d), "unsupported sample format 3 with 16 bits");
  ExpectRefused(MakeWav({.align = 3}, d), "block_align 3");
  ExpectRefused(MakeWav({.align = 0}, d), "block_align 0");
  ExpectRefused(MakeWav({.data_size = 0x10000}, d), "truncated: chunk 'data' declares 65536 bytes");
  ExpectRefused(MakeWav({.fmt_size = 0xFFFFFFF0u}, d), "truncated: chunk 'fmt '");
  ExpectRefused(MakeWav({.fmt_size = 8}, d), "wav.fmt.");  // fmt chunk too short for its fields
  ExpectRefused(MakeWav({}, {}), "no audio samples");
  ExpectRefused(MakeWav({.channels = 2}, {1, 2}), "no audio samples");  // less than one frame
  {  // no fmt chunk
    std::vector<uint8_t> b = {'R', 'I', 'F', 'F', 12, 0, 0, 0, 'W', 'A', 'V', 'E', 'd', 'a', 't', 'a', 2, 0, 0, 0, 1, 0};
    ExpectRefused(b, "no 'fmt ' chunk");
  }
  {  // fmt, no data
    auto b = MakeWav({}, d);
    b.resize(36);
    ExpectRefused(b, "no 'data' chunk");
  }
  {  // an hour and a bit at 1 kHz, 8-bit mono: over the duration limit
    std::vector<uint8_t> big(static_cast<size_t>(1000 * (kMaxWavSeconds + 10)), 128);
    ExpectRefused(MakeWav({.rate = 1000, .bits = 8}, big), "exceeds the limit");
  }
}

TEST(Wav, EveryTruncationIsRefused) {
  const auto good = MakeWav({}, S16({1, -1, 2, -2, 3, -3, 4, -4}));
  ASSERT_TRUE(ParseWav(good).ok());
  for (size_t n = 0; n < good.size(); ++n) {
    std::vector<uint8_t> cut(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n));
    EXPECT_FALSE(ParseWav(cut).ok()) << n << " bytes";
  }
}

TEST(Wav, RandomCorruptionNeverCrashes) {
  const auto good = MakeWav({.channels = 2}, S16({1, -1, 2, -2, 3, -3, 4, -4}));
  std::mt19937 rng(7);
  int refused = 0;
  for (int i = 0; i < 5000; ++i) {
    auto b = good;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int k = 0; k < flips; ++k) b[rng() % 44] = static_cast<uint8_t>(rng());
    if (rng() % 4 == 0) b.resize(rng() % b.size());
    auto w = ParseWav(b);
    if (!w.ok()) {
      ++refused;
      EXPECT_FALSE(w.status().message().empty());
    } else {
      EXPECT_GT(w->frames(), 0u);
      EXPECT_EQ(w->samples.size(), w->frames() * static_cast<size_t>(w->channels));
    }
  }
  EXPECT_GT(refused, 1000);
}

TEST(Wav, ResamplesTo48kKeepingPitchAndLevel) {
  const int in_rate = 22050;
  std::vector<float> x(in_rate);  // 1 s of 1 kHz at amplitude 0.5
  for (size_t i = 0; i < x.size(); ++i) x[i] = 0.5f * static_cast<float>(std::sin(2 * std::numbers::pi * 1000.0 * i / in_rate));
  auto y = Resample(x, in_rate, 48000);
  ASSERT_TRUE(y.ok()) << y.status().ToString();
  EXPECT_NEAR(static_cast<double>(y->size()), 48000.0, 2.0);
  int crossings = 0;
  double e = 0;
  for (size_t i = 4800; i < 43200; ++i) {  // skip the filter's edges
    if (((*y)[i - 1] < 0) != ((*y)[i] < 0)) ++crossings;
    e += (*y)[i] * (*y)[i];
  }
  EXPECT_NEAR(crossings, 2 * 800, 2);  // 0.8 s of 1 kHz
  EXPECT_NEAR(std::sqrt(e / 38400), 0.5 / std::sqrt(2.0), 0.005);
  EXPECT_FALSE(Resample(x, 0, 48000).ok());
  // The espeak-ng fixture (22050 Hz) reads as 48 kHz mono.
  auto speech = ReadMonoWav(test::TestDataPath("audio/espeak_speech_22k.wav"), 48000);
  ASSERT_TRUE(speech.ok()) << speech.status().ToString();
  EXPECT_NEAR(static_cast<double>(speech->size()) / 48000.0, 111474.0 / 22050.0, 0.001);
}

}  // namespace
}  // namespace holo::audio
