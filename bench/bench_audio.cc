// holoport-bench audio: voice bitrate, codec timings, interaural cues and
// directivity measured on OpenAL Soft's loopback device (docs/audio.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "audio/capture.h"
#include "audio/ear_measure.h"
#include "audio/spatializer.h"
#include "audio/speech_quality.h"
#include "audio/voice_chain.h"
#include "audio/voice_codec.h"
#include "audio/wav.h"
#include "bench.h"
#include "common/clock.h"

namespace holo::bench {
namespace {

using namespace holo::audio;

struct Ears {
  double ild_db = 0, itd_ms = 0, level_db = 0;
};

Ears Measure(float azimuth_deg, float facing_offset_deg) {
  Ears e;
  auto sp = Spatializer::Create({});
  if (!sp.ok()) return e;
  (*sp)->SetListener({0, 0, 1.6f, 0, 0, 0});
  auto id = (*sp)->AddSpeaker();
  const float a = -azimuth_deg * std::numbers::pi_v<float> / 180.0f;
  const float face = a + facing_offset_deg * std::numbers::pi_v<float> / 180.0f;
  SpeakerPlacement s;
  s.position = {std::cos(a), std::sin(a), 1.6f};
  s.facing = {std::cos(face), std::sin(face), 0.0f};
  if (!id.ok() || !(*sp)->SetSpeaker(*id, s).ok()) return e;
  std::mt19937 rng(1);
  std::normal_distribution<float> noise(0.0f, 0.1f);
  std::vector<float> x(24000);
  for (float& v : x) v = noise(rng);
  if (!(*sp)->Push(*id, x).ok()) return e;
  const auto y = (*sp)->Render(24000);
  const EarMeasurement m = MeasureEars(y, 2400, 21600, kSampleRate, 72);
  e.ild_db = m.ild_db;
  e.itd_ms = m.itd_ms;
  e.level_db = m.level_db;
  return e;
}

// Mouth-to-ear delay through the whole chain in simulated time: 10 ms tone
// bursts every 500 ms are captured in 20 ms frames, encoded, sent as AudioPose
// messages over a network with U(0, jitter) delay (no base delay: propagation
// excluded), buffered by the adaptive jitter buffer, decoded and rendered by the
// HRTF spatializer (source 1 m ahead). The delay of each burst is the shift of
// its energy centroid from the capture timeline to the ear timeline; the first
// 5 s (jitter buffer warm-up) are skipped.
struct Latency {
  double median_ms = 0, p95_ms = 0, target_ms = 0;
  int bursts = 0;
};

StatusOr<Latency> MeasureMouthToEar(AudioCodec codec, double jitter_ms, double seconds) {
  constexpr double kPeriod = 0.5, kBurst = 0.010, kOffset = 0.1037;
  const size_t n = static_cast<size_t>(seconds * kSampleRate);
  std::vector<float> in(n, 0.0f);
  std::vector<double> in_centroid;
  for (double t0 = kOffset; t0 + kPeriod < seconds; t0 += kPeriod) {
    const size_t a = static_cast<size_t>(t0 * kSampleRate), len = static_cast<size_t>(kBurst * kSampleRate);
    double num = 0, den = 0;
    for (size_t i = 0; i < len; ++i) {
      const double w = 0.5 - 0.5 * std::cos(2 * std::numbers::pi * (i + 0.5) / len);
      in[a + i] = static_cast<float>(0.5 * w * std::sin(2 * std::numbers::pi * 1000.0 * i / kSampleRate));
      num += static_cast<double>(a + i) / kSampleRate * in[a + i] * in[a + i];
      den += in[a + i] * in[a + i];
    }
    in_centroid.push_back(num / den);
  }
  SimulatedClock clock(0);
  const HeadPose speaker{1.0f, 0.0f, 1.6f, std::numbers::pi_v<float>, 0.0f, 0.0f};  // 1 m ahead, facing the listener
  auto cap = VoiceCapture::FromSamples(std::move(in), clock, [&](int64_t) { return speaker; }, "bursts");
  VoiceChainOptions o;
  o.encoder.codec = codec;
  o.network.jitter_ms = jitter_ms;
  o.network.seed = 7;
  o.link = RoomLink{};
  std::vector<float> ear;  // (L + R) / 2 on the ear timeline, from t = 0
  auto on_tick = [&](const ChainTick& t) {
    const size_t at = static_cast<size_t>(t.time_us * kSampleRate / 1000000);
    if (ear.size() < at + kFrameSamples) ear.resize(at + kFrameSamples, 0.0f);
    for (int i = 0; i < kFrameSamples; ++i) ear[at + i] = 0.5f * (t.stereo[2 * i] + t.stereo[2 * i + 1]);
  };
  HOLO_ASSIGN_OR_RETURN(ChainStats st, RunVoiceChain(*cap, clock, o, on_tick));
  std::vector<double> delays;
  for (double c : in_centroid) {
    if (c < 5.0) continue;
    const size_t a = static_cast<size_t>(c * kSampleRate);
    const size_t b = std::min(ear.size(), a + static_cast<size_t>(0.45 * kSampleRate));
    double num = 0, den = 0;
    for (size_t i = a; i < b; ++i) {
      num += static_cast<double>(i) / kSampleRate * ear[i] * ear[i];
      den += ear[i] * ear[i];
    }
    if (den > 0) delays.push_back((num / den - c) * 1000.0);
  }
  if (delays.empty()) return Internal("no burst reached the ears");
  Latency l;
  l.bursts = static_cast<int>(delays.size());
  l.median_ms = Median(delays);
  std::sort(delays.begin(), delays.end());
  l.p95_ms = delays[std::min(delays.size() - 1, static_cast<size_t>(0.95 * static_cast<double>(delays.size())))];
  l.target_ms = st.jitter_buffer.target_delay_ms;
  return l;
}

std::string Fmt(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.1f", v);
  return b;
}

std::string Fmt3(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.4f", v);
  return b;
}

int RunAudio(const BenchArgs& args) {
  const std::string w = "speech_48k";
  auto speech = ReadMonoWav(std::string(HOLO_SOURCE_DIR) + "/tests/data/audio/speech_48k.wav", kSampleRate);
  if (!speech.ok()) {
    std::fprintf(stderr, "%s\n", speech.status().ToString().c_str());
    return 1;
  }
  const size_t frames = speech->size() / kFrameSamples;
  for (AudioCodec codec : {AudioCodec::kOpus, AudioCodec::kPcm16}) {
    const std::string name = codec == AudioCodec::kOpus ? "opus" : "pcm";
    VoiceEncoderOptions o;
    o.codec = codec;
    auto enc = VoiceEncoder::Create(o);
    auto dec = VoiceDecoder::Create(codec);
    if (!enc.ok() || !dec.ok()) return 1;
    std::vector<double> enc_ms, dec_ms, enc_cpu, dec_cpu;
    size_t bytes = 0;
    for (int r = 0; r < std::max(1, args.repeats); ++r) {
      Stopwatch sw_e;
      const double cpu_e = ProcessCpuMs();
      std::vector<AudioPose> pk;
      for (size_t f = 0; f < frames; ++f) {
        pk.push_back(*(*enc)->EncodeFrame(std::span<const float>(*speech).subspan(f * kFrameSamples, kFrameSamples),
                                          static_cast<uint32_t>(f), 0, {}));
      }
      enc_ms.push_back(sw_e.ElapsedMs() / static_cast<double>(frames));
      enc_cpu.push_back((ProcessCpuMs() - cpu_e) / static_cast<double>(frames));
      bytes = 0;
      for (const auto& p : pk) bytes += SerializeVoiceFrame(p).size() + 32;  // + protocol header
      Stopwatch sw_d;
      const double cpu_d = ProcessCpuMs();
      for (const auto& p : pk) (void)(*dec)->Decode(p.audio);
      dec_ms.push_back(sw_d.ElapsedMs() / static_cast<double>(frames));
      dec_cpu.push_back((ProcessCpuMs() - cpu_d) / static_cast<double>(frames));
    }
    const double kbps = static_cast<double>(bytes) * 8 / (static_cast<double>(frames) * 20.0);
    EmitFigure("audio", w, "kbps", kbps, "kbit/s", {{"codec", name}, {"includes", "audio+pose+header"}});
    // Per 20 ms frame: CPU time (steady on the shared machine), wall time beside it.
    EmitFigure("audio", w, "encode_ms", Median(enc_cpu), "ms",
               {{"codec", name}, {"mode", "cpu"}, {"wall_ms", Fmt3(Median(enc_ms))}, {"runs", std::to_string(enc_ms.size())}});
    EmitFigure("audio", w, "decode_ms", Median(dec_cpu), "ms",
               {{"codec", name}, {"mode", "cpu"}, {"wall_ms", Fmt3(Median(dec_ms))}, {"runs", std::to_string(dec_ms.size())}});
  }
  // Intelligibility of the Opus round trip against the PCM path (stated measures:
  // fwSNRseg after Hu & Loizou 2008, and waveform segmental SNR).
  {
    auto es = ReadMonoWav(std::string(HOLO_SOURCE_DIR) + "/tests/data/audio/espeak_speech_22k.wav", kSampleRate);
    if (!es.ok()) {
      std::fprintf(stderr, "%s\n", es.status().ToString().c_str());
      return 1;
    }
    for (AudioCodec codec : {AudioCodec::kOpus, AudioCodec::kPcm16}) {
      VoiceEncoderOptions o;
      o.codec = codec;
      auto enc = VoiceEncoder::Create(o);
      auto dec = VoiceDecoder::Create(codec);
      if (!enc.ok() || !dec.ok()) return 1;
      std::vector<float> out;
      for (size_t i = 0; i + kFrameSamples <= es->size(); i += kFrameSamples) {
        auto pk = (*enc)->Encode(std::span<const float>(*es).subspan(i, kFrameSamples));
        auto pcm = pk.ok() ? (*dec)->Decode(*pk) : StatusOr<std::vector<float>>(pk.status());
        if (!pcm.ok()) return 1;
        out.insert(out.end(), pcm->begin(), pcm->end());
      }
      const int lag = BestLag(*es, out, 960);
      const std::string name = codec == AudioCodec::kOpus ? "opus" : "pcm";
      EmitFigure("audio", "espeak_speech", "fwsnrseg_db", FwSegSnrDb(*es, out, lag, kSampleRate), "dB",
                 {{"codec", name}, {"bitrate_kbps", codec == AudioCodec::kOpus ? "24" : "768"}});
      EmitFigure("audio", "espeak_speech", "segsnr_db", SegmentalSnrDb(*es, out, lag), "dB",
                 {{"codec", name}, {"bitrate_kbps", codec == AudioCodec::kOpus ? "24" : "768"}});
    }
  }
  for (AudioCodec codec : {AudioCodec::kOpus, AudioCodec::kPcm16}) {
    for (int jitter : {0, 20, 50}) {
      if (!args.json) std::fprintf(stderr, "audio: mouth-to-ear, %s, jitter %d ms\n", codec == AudioCodec::kOpus ? "opus" : "pcm", jitter);
      auto l = MeasureMouthToEar(codec, jitter, 30.0);
      if (!l.ok()) {
        std::fprintf(stderr, "%s\n", l.status().ToString().c_str());
        return 1;
      }
      EmitFigure("audio", "bursts_30s", "mouth_to_ear_ms", l->median_ms, "ms",
                 {{"codec", codec == AudioCodec::kOpus ? "opus" : "pcm"},
                  {"jitter_ms", std::to_string(jitter)},
                  {"p95_ms", Fmt(l->p95_ms)},
                  {"jb_target_ms", Fmt(l->target_ms)},
                  {"bursts", std::to_string(l->bursts)},
                  {"includes", "framing 20 ms, codec look-ahead, network U(0,jitter) without base delay, jitter buffer, "
                               "10 ms playout-tick phase, one 20 ms block queued in OpenAL, HRTF; excludes encode/decode "
                               "CPU time, sound-card buffers, propagation"}});
    }
  }
  for (int az = -90; az <= 90; az += 30) {
    const Ears e = Measure(static_cast<float>(az), 180);
    EmitFigure("audio", "white_noise_1m", "ild_db", e.ild_db, "dB", {{"azimuth_deg", std::to_string(az)}});
    EmitFigure("audio", "white_noise_1m", "itd_ms", e.itd_ms, "ms", {{"azimuth_deg", std::to_string(az)}});
  }
  const Ears facing = Measure(30, 180), away = Measure(30, 0);
  EmitFigure("audio", "white_noise_1m", "directivity_db", facing.level_db - away.level_db, "dB",
             {{"azimuth_deg", "30"}, {"compare", "facing vs facing away"}});
  return 0;
}

}  // namespace

HOLO_REGISTER_BENCH("audio", "voice: kbps, encode/decode ms, speech quality, mouth-to-ear ms, ILD/ITD by azimuth, directivity", RunAudio);

}  // namespace holo::bench
