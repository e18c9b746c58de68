// holoport-bench audio, lean frames (AudioPose codec 3, PROTOCOL.md §9.1;
// docs/audio.md "Lean frames"): wire kbit/s per frame format on the same
// speech, fwSNRseg of every Opus setting tried, the pose quantization error
// and the error of sending the pose every other frame, mouth-to-ear delay
// of both formats. Run alone with `holoport-bench audio --lean-only`.
#include <opus/opus.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "audio/speech_quality.h"
#include "audio/voice_chain.h"
#include "audio/voice_codec.h"
#include "audio/wav.h"
#include "bench.h"
#include "bench_audio_lean.h"
#include "common/log.h"

namespace holo::bench {
namespace {

using namespace holo::audio;


struct Speech {
  std::string name;  // workload
  std::vector<float> samples;
};

struct Run {
  double wire_kbps = 0, opus_kbps = 0, fw_db = 0, fields_bytes = 0;
  double wideband_share = 0;  // packets with bandwidth ≤ wideband (8 kHz audio)
};

// Every frame encoded, framed as a protocol message (32-byte header +
// payload) and parsed back as a receiver would; kbit/s from those bytes.
// With `loss` > 0 that share of frames (seeded, independent) is lost and the
// decoder conceals it (from the next packet's in-band FEC when it has some).
StatusOr<Run> Measure(const Speech& s, const VoiceEncoderOptions& o, double loss = 0.0) {
  HOLO_ASSIGN_OR_RETURN(auto enc, VoiceEncoder::Create(o));
  HOLO_ASSIGN_OR_RETURN(auto dec, VoiceDecoder::Create(o.codec));
  size_t wire = 0, opus = 0, frames = 0, wb = 0;
  std::vector<AudioPose> got;
  for (size_t i = 0; i + kFrameSamples <= s.samples.size(); i += kFrameSamples, ++frames) {
    const HeadPose pose{1.0f + 0.001f * static_cast<float>(frames), -0.7f, 1.65f, 0.01f * static_cast<float>(frames), 0.05f, 0};
    HOLO_ASSIGN_OR_RETURN(AudioPose f, enc->EncodeFrame(std::span<const float>(s.samples).subspan(i, kFrameSamples),
                                                        static_cast<uint32_t>(frames),
                                                        20000 * static_cast<int64_t>(frames), pose));
    const std::vector<uint8_t> msg = protocol::EncodeMessage(protocol::Header{}, f);
    wire += msg.size();
    opus += f.audio.size();
    HOLO_ASSIGN_OR_RETURN(protocol::Header h, protocol::DecodeHeader(msg.data(), msg.size()));
    HOLO_ASSIGN_OR_RETURN(AudioPose g, ParseVoiceFrame(h, std::span<const uint8_t>(msg).subspan(protocol::kHeaderSize)));
    if (IsOpus(o.codec) && opus_packet_get_bandwidth(g.audio.data()) <= OPUS_BANDWIDTH_WIDEBAND) ++wb;
    got.push_back(std::move(g));
  }
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<bool> lost(got.size());
  for (size_t i = 0; i < got.size(); ++i) lost[i] = loss > 0 && u01(rng) < loss;
  std::vector<float> out;
  for (size_t i = 0; i < got.size(); ++i) {
    if (lost[i]) {
      bool fec = false;
      const std::span<const uint8_t> next =
          i + 1 < got.size() && !lost[i + 1] ? std::span<const uint8_t>(got[i + 1].audio) : std::span<const uint8_t>();
      const std::vector<float> pcm = dec->Conceal(next, &fec);
      out.insert(out.end(), pcm.begin(), pcm.end());
      continue;
    }
    HOLO_ASSIGN_OR_RETURN(std::vector<float> pcm, dec->Decode(got[i].audio));
    out.insert(out.end(), pcm.begin(), pcm.end());
  }
  Run r;
  const double ms = static_cast<double>(frames) * 20.0;
  r.wire_kbps = static_cast<double>(wire) * 8 / ms;
  r.opus_kbps = static_cast<double>(opus) * 8 / ms;
  r.fields_bytes = static_cast<double>(wire - opus) / static_cast<double>(frames) - protocol::kHeaderSize;
  r.fw_db = FwSegSnrDb(s.samples, out, BestLag(s.samples, out, 960), kSampleRate);
  r.wideband_share = static_cast<double>(wb) / static_cast<double>(std::max<size_t>(frames, 1));
  return r;
}

std::string RateName(OpusRateControl r) {
  return r == OpusRateControl::kVbr ? "vbr" : r == OpusRateControl::kConstrainedVbr ? "cvbr" : "cbr";
}

// A head walking at 1.2 m/s on a 2 m circle while turning ±60° at 0.5 Hz
// (peak 190°/s) and nodding ±15° at 0.7 Hz: the pose at time `t`.
HeadPose MovingHead(double t) {
  HeadPose p;
  const double w = 1.2 / 2.0;
  p.x = static_cast<float>(2.0 * std::cos(w * t));
  p.y = static_cast<float>(2.0 * std::sin(w * t));
  p.z = static_cast<float>(1.65 + 0.03 * std::sin(2 * std::numbers::pi * 1.8 * t));
  p.yaw = static_cast<float>(std::remainder(w * t + std::numbers::pi / 2 +
                                                std::numbers::pi / 3 * std::sin(2 * std::numbers::pi * 0.5 * t),
                                            2 * std::numbers::pi));
  p.pitch = static_cast<float>(std::numbers::pi / 12 * std::sin(2 * std::numbers::pi * 0.7 * t));
  p.roll = static_cast<float>(0.05 * std::sin(2 * std::numbers::pi * 0.3 * t));
  return p;
}

struct PoseError {
  double max_mm = 0, p95_mm = 0, max_deg = 0, p95_deg = 0;
};

PoseError Errors(std::vector<double> mm, std::vector<double> deg) {
  auto pct = [](std::vector<double>& v, double q) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
  };
  PoseError e;
  e.max_mm = pct(mm, 1.0);
  e.p95_mm = pct(mm, 0.95);
  e.max_deg = pct(deg, 1.0);
  e.p95_deg = pct(deg, 0.95);
  return e;
}

void AddError(const HeadPose& truth, const HeadPose& got, std::vector<double>* mm, std::vector<double>* deg) {
  const double dx = truth.x - got.x, dy = truth.y - got.y, dz = truth.z - got.z;
  mm->push_back(1000.0 * std::sqrt(dx * dx + dy * dy + dz * dz));
  double worst = 0;
  for (auto [a, b] : {std::pair{truth.yaw, got.yaw}, {truth.pitch, got.pitch}, {truth.roll, got.roll}})
    worst = std::max(worst, std::fabs(std::remainder(static_cast<double>(a) - b, 2 * std::numbers::pi)));
  deg->push_back(worst * 180.0 / std::numbers::pi);
}

int PoseFigures() {
  // Quantization alone: random poses in a 60 m room, any angle.
  {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> pos(-30.0f, 30.0f), ang(-3.14159f, 3.14159f);
    std::vector<double> mm, deg;
    for (int i = 0; i < 100000; ++i) {
      const HeadPose p{pos(rng), pos(rng), pos(rng), ang(rng), ang(rng), ang(rng)};
      AddError(p, protocol::QuantizeLeanPose(p), &mm, &deg);
    }
    const PoseError e = Errors(mm, deg);
    EmitFigure("audio", "random_poses_60m", "pose_error_mm", e.max_mm, "mm",
               {{"frame", "lean"}, {"stat", "max"}, {"pose_bytes", "12"}, {"step", "1 mm, 2pi/65536 rad"}});
    EmitFigure("audio", "random_poses_60m", "pose_error_deg", e.max_deg, "deg",
               {{"frame", "lean"}, {"stat", "max"}, {"pose_bytes", "12"}});
  }
  // A moving head, pose every frame vs every other frame (midway between
  // its neighbours when the next frame is in the jitter buffer, else held).
  std::vector<double> mm1, deg1, mm2, deg2, mmh, degh, mme, dege;
  for (int f = 1; f + 1 < 50 * 60; ++f) {
    const HeadPose truth = MovingHead(f * 0.02);
    AddError(truth, protocol::QuantizeLeanPose(truth), &mm1, &deg1);
    if (f % 2 == 1) {
      const HeadPose prev = protocol::QuantizeLeanPose(MovingHead((f - 1) * 0.02));
      const HeadPose next = protocol::QuantizeLeanPose(MovingHead((f + 1) * 0.02));
      AddError(truth, protocol::MidwayPose(prev, next), &mm2, &deg2);
      AddError(truth, prev, &mmh, &degh);
      if (f >= 3) {  // the next frame not there yet: on from the two poses before
        const HeadPose prev2 = protocol::QuantizeLeanPose(MovingHead((f - 3) * 0.02));
        AddError(truth, protocol::LerpPose(prev2, prev, 1.5f), &mme, &dege);
      }
    } else {  // a frame with its pose: the quantization error alone
      for (auto* v : {&mm2, &mmh, &mme}) v->push_back(mm1.back());
      for (auto* v : {&deg2, &degh, &dege}) v->push_back(deg1.back());
    }
  }
  struct Case {
    const char* name;
    const char* bytes;
    PoseError e;
  };
  for (const Case& c : {Case{"every_frame", "12", Errors(mm1, deg1)},
                        Case{"every_other_frame_interpolated", "6", Errors(mm2, deg2)},
                        Case{"every_other_frame_extrapolated", "6", Errors(mme, dege)},
                        Case{"every_other_frame_held", "6", Errors(mmh, degh)}}) {
    EmitFigure("audio", "moving_head_60s", "pose_error_mm", c.e.max_mm, "mm",
               {{"frame", "lean"}, {"pose", c.name}, {"stat", "max"}, {"p95", Fixed(c.e.p95_mm, 2)}, {"pose_bytes_per_frame", c.bytes},
                {"motion", "1.2 m/s walk, yaw +-60 deg at 0.5 Hz, pitch +-15 deg at 0.7 Hz"}});
    EmitFigure("audio", "moving_head_60s", "pose_error_deg", c.e.max_deg, "deg",
               {{"frame", "lean"}, {"pose", c.name}, {"stat", "max"}, {"p95", Fixed(c.e.p95_deg, 2)}, {"pose_bytes_per_frame", c.bytes}});
  }
  return 0;
}

}  // namespace

int RunLeanFrames(const BenchArgs& args) {
  std::vector<Speech> speech;
  for (auto [name, file] : {std::pair{"espeak_speech", "espeak_speech_22k.wav"}, {"librivox_speech", "speech_48k.wav"}}) {
    auto s = ReadMonoWav(std::string(HOLO_SOURCE_DIR) + "/tests/data/audio/" + file, kSampleRate);
    if (!s.ok()) {
      spdlog::error("{}", s.status().ToString());
      return 1;
    }
    speech.push_back({name, std::move(*s)});
  }
  // 1. Frame formats on the same content.
  struct Format {
    const char* frame;
    VoiceEncoderOptions o;
  };
  VoiceEncoderOptions lean1 = LeanVoiceEncoderOptions();
  lean1.pose_every = 1;
  VoiceEncoderOptions lean24 = LeanVoiceEncoderOptions();
  lean24.bitrate_bps = 24000;
  VoiceEncoderOptions classic14 = LeanVoiceEncoderOptions();
  classic14.codec = AudioCodec::kOpus;
  classic14.pose_every = 1;
  for (const Speech& s : speech) {
    for (const Format& f : {Format{"classic", VoiceEncoderOptions{}}, Format{"lean", LeanVoiceEncoderOptions()},
                            Format{"lean_pose_every_frame", lean1}, Format{"lean_opus_24k", lean24},
                            Format{"classic_opus_lean_settings", classic14}}) {
      auto r = Measure(s, f.o);
      if (!r.ok()) {
        spdlog::error("{}", r.status().ToString());
        return 1;
      }
      const std::map<std::string, std::string> q = {{"frame", f.frame},
                                                    {"codec", f.o.codec == AudioCodec::kOpusLean ? "opus-lean" : "opus"},
                                                    {"bitrate_kbps", std::to_string(f.o.bitrate_bps / 1000)},
                                                    {"opus_kbps", Fixed(r->opus_kbps, 2)},
                                                    {"fields_bytes_per_frame", Fixed(r->fields_bytes, 1)},
                                                    {"header_bytes", "32"},
                                                    {"includes", "audio+pose+header"}};
      EmitFigure("audio", s.name, "kbps", r->wire_kbps, "kbit/s", q);
      auto qf = q;
      qf.erase("includes");
      EmitFigure("audio", s.name, "fwsnrseg_db", r->fw_db, "dB", qf);
    }
  }
  // Under packet loss (what in-band FEC is for): classic default vs lean.
  for (const Speech& s : speech) {
    for (double loss : {0.05, 0.10}) {
      for (const Format& f : {Format{"classic", VoiceEncoderOptions{}}, Format{"lean", LeanVoiceEncoderOptions()}}) {
        auto r = Measure(s, f.o, loss);
        if (!r.ok()) return 1;
        EmitFigure("audio", s.name, "fwsnrseg_db", r->fw_db, "dB",
                   {{"frame", f.frame}, {"bitrate_kbps", std::to_string(f.o.bitrate_bps / 1000)},
                    {"loss_pct", std::to_string(static_cast<int>(loss * 100))},
                    {"concealment", "opus plc, in-band fec when the encoder made some"}});
      }
    }
  }
  // 2. Opus settings tried (in the lean frame; wire kbit/s beside).
  struct Setting {
    int kbit;
    OpusRateControl rc;
    bool voip;
    int max_bw;
    int complexity;
    bool fec;
  };
  std::vector<Setting> settings;
  for (bool voip : {true, false})
    for (int kbit : {12, 13, 14, 15, 16, 20, 24})
      for (OpusRateControl rc : {OpusRateControl::kVbr, OpusRateControl::kConstrainedVbr, OpusRateControl::kCbr})
        settings.push_back({kbit, rc, voip, 0, 9, true});
  for (int kbit : {14, 16}) {
    settings.push_back({kbit, OpusRateControl::kVbr, false, 16000, 9, true});  // wideband at most
    settings.push_back({kbit, OpusRateControl::kVbr, false, 0, 10, true});     // complexity 10
    settings.push_back({kbit, OpusRateControl::kVbr, false, 0, 5, true});      // complexity 5
    settings.push_back({kbit, OpusRateControl::kVbr, false, 0, 9, false});     // no FEC
  }
  for (const Speech& s : speech) {
    for (const Setting& st : settings) {
      VoiceEncoderOptions o = LeanVoiceEncoderOptions();
      o.bitrate_bps = st.kbit * 1000;
      o.rate_control = st.rc;
      o.voip_application = st.voip;
      o.max_bandwidth_hz = st.max_bw;
      o.complexity = st.complexity;
      o.fec = st.fec;
      auto r = Measure(s, o);
      if (!r.ok()) return 1;
      EmitFigure("audio", s.name, "fwsnrseg_db", r->fw_db, "dB",
                 {{"frame", "lean"}, {"sweep", "opus"}, {"bitrate_kbps", std::to_string(st.kbit)},
                  {"rate_control", RateName(st.rc)}, {"application", st.voip ? "voip" : "audio"},
                  {"max_bandwidth", st.max_bw == 0 ? "auto" : "wideband"}, {"complexity", std::to_string(st.complexity)},
                  {"fec", st.fec ? "on" : "off"}, {"opus_kbps", Fixed(r->opus_kbps, 2)}, {"wire_kbps", Fixed(r->wire_kbps, 2)},
                  {"wideband_share", Fixed(r->wideband_share, 2)}});
    }
  }
  // 3. Pose.
  if (const int rc = PoseFigures(); rc != 0) return rc;
  // 4. Mouth-to-ear, both frames, same chain (simulated time, 20 ms jitter).
  for (bool lean : {false, true}) {
    for (int jitter : {0, 20}) {
      VoiceChainOptions o;
      o.encoder = lean ? LeanVoiceEncoderOptions() : VoiceEncoderOptions{};
      o.network.jitter_ms = jitter;
      o.network.seed = 7;
      o.link = RoomLink{};
      auto l = MeasureMouthToEar(o, 30.0, 5.0);
      if (!l.ok()) {
        spdlog::error("{}", l.status().ToString());
        return 1;
      }
      EmitFigure("audio", "bursts_30s", "mouth_to_ear_ms", l->median_ms, "ms",
                 {{"frame", lean ? "lean" : "classic"}, {"codec", lean ? "opus-lean" : "opus"},
                  {"jitter_ms", std::to_string(jitter)}, {"p95_ms", Fixed(l->p95_ms, 1)}, {"jb_target_ms", Fixed(l->jb_target_ms, 1)}});
      if (lean) {
        const double n = static_cast<double>(l->poses_interpolated + l->poses_extrapolated + l->poses_held);
        EmitFigure("audio", "bursts_30s", "pose_interpolated_share", n > 0 ? l->poses_interpolated / n : 0.0, "ratio",
                   {{"frame", "lean"}, {"jitter_ms", std::to_string(jitter)},
                    {"extrapolated_share", Fixed(n > 0 ? l->poses_extrapolated / n : 0.0, 2)},
                    {"held_share", Fixed(n > 0 ? l->poses_held / n : 0.0, 2)}});
      }
    }
  }
  (void)args;
  return 0;
}

}  // namespace holo::bench
