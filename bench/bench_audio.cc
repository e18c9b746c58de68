// holoport-bench audio: voice bitrate, codec timings, interaural cues and
// directivity measured on OpenAL Soft's loopback device (docs/audio.md).
#include <cmath>
#include <numbers>
#include <random>

#include "audio/ear_measure.h"
#include "audio/spatializer.h"
#include "audio/voice_codec.h"
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
    std::vector<double> enc_ms, dec_ms;
    size_t bytes = 0;
    for (int r = 0; r < std::max(1, args.repeats); ++r) {
      Stopwatch sw_e;
      std::vector<AudioPose> pk;
      for (size_t f = 0; f < frames; ++f) {
        pk.push_back(*(*enc)->EncodeFrame(std::span<const float>(*speech).subspan(f * kFrameSamples, kFrameSamples),
                                          static_cast<uint32_t>(f), 0, {}));
      }
      enc_ms.push_back(sw_e.ElapsedMs() / static_cast<double>(frames));
      bytes = 0;
      for (const auto& p : pk) bytes += SerializeVoiceFrame(p).size() + 32;  // + protocol header
      Stopwatch sw_d;
      for (const auto& p : pk) (void)(*dec)->Decode(p.audio);
      dec_ms.push_back(sw_d.ElapsedMs() / static_cast<double>(frames));
    }
    const double kbps = static_cast<double>(bytes) * 8 / (static_cast<double>(frames) * 20.0);
    EmitFigure("audio", w, "kbps", kbps, "kbit/s", {{"codec", name}, {"includes", "audio+pose+header"}});
    EmitFigure("audio", w, "encode_ms", Median(enc_ms), "ms", {{"codec", name}});
    EmitFigure("audio", w, "decode_ms", Median(dec_ms), "ms", {{"codec", name}});
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

HOLO_REGISTER_BENCH("audio", "voice: kbps, encode/decode ms, ILD/ITD by azimuth, directivity", RunAudio);

}  // namespace holo::bench
