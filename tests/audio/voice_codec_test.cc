#include "audio/voice_codec.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "audio/speech_quality.h"
#include "audio/wav.h"
#include "test_util.h"

namespace holo::audio {
namespace {

std::vector<float> Speech() {
  auto wav = ReadMonoWav(test::TestDataPath("audio/speech_48k.wav"), kSampleRate);
  EXPECT_TRUE(wav.ok()) << wav.status().ToString();
  return wav.ok() ? *wav : std::vector<float>{};
}

// Round trip frame by frame; returns decoded audio.
std::vector<float> RoundTrip(const std::vector<float>& in, const VoiceEncoderOptions& o, size_t* bytes) {
  auto enc = VoiceEncoder::Create(o);
  EXPECT_TRUE(enc.ok());
  auto dec = VoiceDecoder::Create(o.codec);
  EXPECT_TRUE(dec.ok());
  std::vector<float> out;
  *bytes = 0;
  for (size_t i = 0; i + kFrameSamples <= in.size(); i += kFrameSamples) {
    auto f = (*enc)->EncodeFrame(std::span<const float>(in).subspan(i, kFrameSamples), static_cast<uint32_t>(i),
                                 0, HeadPose{});
    EXPECT_TRUE(f.ok());
    const std::vector<uint8_t> payload = SerializeVoiceFrame(*f);
    *bytes += payload.size();
    auto parsed = ParseVoiceFrame(payload);
    EXPECT_TRUE(parsed.ok()) << parsed.status().ToString();
    auto pcm = (*dec)->Decode(parsed->audio);
    EXPECT_TRUE(pcm.ok());
    out.insert(out.end(), pcm->begin(), pcm->end());
  }
  return out;
}

TEST(VoiceCodec, OpusRoundTripKeepsSpeech) {
  const std::vector<float> speech = Speech();
  ASSERT_GT(speech.size(), 48000u);
  size_t opus_bytes = 0, pcm_bytes = 0;
  const auto opus = RoundTrip(speech, {}, &opus_bytes);
  VoiceEncoderOptions pcm_o;
  pcm_o.codec = AudioCodec::kPcm16;
  const auto pcm = RoundTrip(speech, pcm_o, &pcm_bytes);
  const double frames = static_cast<double>(speech.size() / kFrameSamples);
  const double opus_kbps = opus_bytes * 8 / (frames * 20.0);
  const double pcm_kbps = pcm_bytes * 8 / (frames * 20.0);
  const double snr_opus = SegmentalSnrDb(speech, opus, BestLag(speech, opus, 960));
  const double snr_pcm = SegmentalSnrDb(speech, pcm, BestLag(speech, pcm, 960));
  std::printf("opus 24k: %.1f kbit/s payload, segSNR %.1f dB; pcm: %.1f kbit/s, segSNR %.1f dB\n", opus_kbps,
              snr_opus, pcm_kbps, snr_pcm);
  EXPECT_LT(opus_kbps, 50.0);  // 24 kbit/s audio + 18.4 kbit/s of 46-byte pose/sequence fields
  EXPECT_GT(pcm_kbps, 768.0);
  EXPECT_GT(snr_pcm, 30.0);
  // Opus is a perceptual codec: waveform SNR is modest yet speech stays clear.
  EXPECT_GT(snr_opus, 1.0);
}

// Intelligibility of Opus against the PCM path on synthetic speech (espeak-ng,
// tests/data/audio/SOURCE.txt), measured with the frequency-weighted segmental
// SNR (fwSNRseg, Hu & Loizou 2008: 25 Bark bands, clipped to [-10, 35] dB),
// which follows intelligibility; the waveform segmental SNR is printed too.
TEST(VoiceCodec, OpusKeepsEspeakSpeechIntelligible) {
  auto speech = ReadMonoWav(test::TestDataPath("audio/espeak_speech_22k.wav"), kSampleRate);
  ASSERT_TRUE(speech.ok()) << speech.status().ToString();
  size_t bytes = 0;
  VoiceEncoderOptions pcm_o;
  pcm_o.codec = AudioCodec::kPcm16;
  const auto pcm = RoundTrip(*speech, pcm_o, &bytes);
  const int pcm_lag = BestLag(*speech, pcm, 960);
  EXPECT_EQ(pcm_lag, 0);
  const double fw_pcm = FwSegSnrDb(*speech, pcm, pcm_lag, kSampleRate);
  for (int bitrate : {12000, 24000, 32000}) {
    VoiceEncoderOptions o;
    o.bitrate_bps = bitrate;
    const auto opus = RoundTrip(*speech, o, &bytes);
    const int lag = BestLag(*speech, opus, 960);
    const double fw = FwSegSnrDb(*speech, opus, lag, kSampleRate);
    const double seg = SegmentalSnrDb(*speech, opus, lag);
    std::printf("espeak-ng speech: opus %d kbit/s: lag %d samples, fwSNRseg %.1f dB, segSNR %.1f dB; pcm fwSNRseg %.1f dB\n",
                bitrate / 1000, lag, fw, seg, fw_pcm);
    EXPECT_NEAR(lag, 312, 8);  // Opus look-ahead: 6.5 ms at 48 kHz
    EXPECT_GT(fw, 12.0) << bitrate;
    EXPECT_LT(fw, fw_pcm);
  }
  EXPECT_GT(fw_pcm, 30.0);
  // Wrong signals score low, so the bound can fail: the speech 150 ms out of
  // step with itself (other phonemes), and white noise.
  std::vector<float> shifted(speech->size(), 0.0f);
  std::copy(speech->begin(), speech->end() - 7200, shifted.begin() + 7200);
  const double fw_shifted = FwSegSnrDb(*speech, shifted, 0, kSampleRate);
  std::mt19937 rng(3);
  std::normal_distribution<float> g(0.0f, 0.1f);
  std::vector<float> noise(speech->size());
  for (float& v : noise) v = g(rng);
  const double fw_noise = FwSegSnrDb(*speech, noise, 0, kSampleRate);
  std::printf("fwSNRseg of speech 150 ms out of step: %.1f dB; of white noise: %.1f dB\n", fw_shifted, fw_noise);
  EXPECT_LT(fw_shifted, 8.0);
  EXPECT_LT(fw_noise, 8.0);
}

TEST(VoiceCodec, RefusesMalformedPayloads) {
  auto enc = VoiceEncoder::Create({});
  ASSERT_TRUE(enc.ok());
  std::vector<float> tone(kFrameSamples);
  for (int i = 0; i < kFrameSamples; ++i) tone[i] = 0.3f * std::sin(0.05f * i);
  auto f = (*enc)->EncodeFrame(tone, 7, 123, HeadPose{1, 2, 1.6f, 0.5f, 0, 0});
  ASSERT_TRUE(f.ok());
  const std::vector<uint8_t> good = SerializeVoiceFrame(*f);
  ASSERT_TRUE(ParseVoiceFrame(good).ok());
  // Every truncated prefix is refused, each from its own buffer.
  for (size_t n = 0; n < good.size(); ++n) {
    std::vector<uint8_t> cut(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n));
    EXPECT_FALSE(ParseVoiceFrame(cut).ok()) << n;
  }
  auto refused = [&](AudioPose m, const std::string& why) {
    auto r = ParseVoiceFrame(SerializeVoiceFrame(m));
    EXPECT_FALSE(r.ok()) << why;
    if (!r.ok()) {
      EXPECT_NE(r.status().message().find(why), std::string::npos) << r.status().message();
    }
  };
  AudioPose m = *f;
  m.sample_rate = 44100;
  refused(m, "sample_rate");
  m = *f;
  m.channels = 2;
  refused(m, "mono");
  m = *f;
  m.duration_us_div10 = 1000;
  refused(m, "20 ms");
  m = *f;
  m.codec = AudioCodec::kPcm16;
  refused(m, "1920");
  m = *f;
  m.audio = {0xFF, 0xFF, 0xFF};  // code-3 packet with an impossible frame count
  refused(m, "Opus");
  m = *f;
  m.pose.x = 5000;
  refused(m, "position");
  // Non-finite floats are refused by the protocol reader itself.
  m = *f;
  m.pose.yaw = NAN;
  EXPECT_FALSE(ParseVoiceFrame(SerializeVoiceFrame(m)).ok());
}

TEST(VoiceCodec, ConcealmentFillsLostFrames) {
  auto enc = VoiceEncoder::Create({});
  auto dec = VoiceDecoder::Create(AudioCodec::kOpus);
  ASSERT_TRUE(enc.ok() && dec.ok());
  const auto speech = Speech();
  std::vector<std::vector<uint8_t>> pk;
  for (int i = 0; i < 40; ++i) {
    auto p = (*enc)->Encode(std::span<const float>(speech).subspan(static_cast<size_t>(i) * kFrameSamples, kFrameSamples));
    ASSERT_TRUE(p.ok());
    pk.push_back(*p);
  }
  for (int i = 0; i < 20; ++i) ASSERT_TRUE((*dec)->Decode(pk[i]).ok());
  bool fec = false;
  const auto rec = (*dec)->Conceal(pk[21], &fec);
  EXPECT_TRUE(fec);
  double e = 0;
  for (float v : rec) e += v * v;
  EXPECT_GT(e, 0.0);  // speech continues rather than a hole
  EXPECT_EQ(rec.size(), static_cast<size_t>(kFrameSamples));
}

// Lip sync counts the codec's delay in the voice's playout time: the
// constant is the encoder's own look-ahead, and a decoded click comes out
// that many samples late.
TEST(VoiceCodec, CodecDelayIsTheOpusLookAhead) {
  auto enc = VoiceEncoder::Create({});
  ASSERT_TRUE(enc.ok());
  EXPECT_EQ((*enc)->lookahead_samples(), CodecDelaySamples(AudioCodec::kOpus));
  EXPECT_EQ(CodecDelaySamples(AudioCodec::kPcm16), 0);
  auto dec = VoiceDecoder::Create(AudioCodec::kOpus);
  ASSERT_TRUE(dec.ok());
  // A burst starting at sample 400 of frame 2: where does the decoded one start?
  std::vector<float> in(kFrameSamples);
  int first = -1;
  for (int f = 0; f < 5 && first < 0; ++f) {
    for (int i = 0; i < kFrameSamples; ++i) {
      const int n = f * kFrameSamples + i - (2 * kFrameSamples + 400);
      in[i] = n >= 0 && n < 480 ? 0.4f * static_cast<float>(std::sin(0.3 * n)) : 0.0f;
    }
    auto out = (*dec)->Decode(*(*enc)->Encode(in));
    ASSERT_TRUE(out.ok());
    for (int i = 0; i < kFrameSamples && first < 0; ++i)
      if (std::abs((*out)[i]) > 0.05f) first = f * kFrameSamples + i;
  }
  EXPECT_NEAR(first - (2 * kFrameSamples + 400), CodecDelaySamples(AudioCodec::kOpus), 12);
}

// A sender that stalled skips whole frames, capture time and sequence
// together, and only beyond the bound it is given.
TEST(VoiceCodec, StalledSenderSkipsWholeFramesInStep) {
  int64_t next_us = 1000000;
  uint32_t seq = 7;
  EXPECT_EQ(SkipStalledFrames(next_us + 200000, 200000, &next_us, &seq), 0);  // at the bound: no skip
  EXPECT_EQ(next_us, 1000000);
  EXPECT_EQ(seq, 7u);
  // 0.55 s behind: 27 whole frames skipped, the next one is the frame under way.
  EXPECT_EQ(SkipStalledFrames(1550000, 200000, &next_us, &seq), 27);
  EXPECT_EQ(next_us, 1000000 + 27 * kFrameUs);
  EXPECT_EQ(seq, 34u);
  EXPECT_LE(next_us, 1550000);
  EXPECT_GT(next_us + kFrameUs, 1550000);
  // The sequence wraps as the wire's 32-bit counter does.
  uint32_t high = 0xFFFFFFFEu;
  int64_t t = 0;
  EXPECT_EQ(SkipStalledFrames(5 * kFrameUs, 0, &t, &high), 5);
  EXPECT_EQ(high, 3u);
}

}  // namespace
}  // namespace holo::audio
