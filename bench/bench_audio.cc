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
      VoiceChainOptions o;
      o.encoder.codec = codec;
      o.network.jitter_ms = jitter;  // no base delay: propagation is not part of the figure
      o.network.seed = 7;
      o.link = RoomLink{};
      auto l = MeasureMouthToEar(o, 30.0, 5.0);
      if (!l.ok()) {
        std::fprintf(stderr, "%s\n", l.status().ToString().c_str());
        return 1;
      }
      EmitFigure("audio", "bursts_30s", "mouth_to_ear_ms", l->median_ms, "ms",
                 {{"codec", codec == AudioCodec::kOpus ? "opus" : "pcm"},
                  {"jitter_ms", std::to_string(jitter)},
                  {"p95_ms", Fmt(l->p95_ms)},
                  {"jb_target_ms", Fmt(l->jb_target_ms)},
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
