// holoport-bench audio: voice bitrate, codec timings, interaural cues and
// directivity measured on OpenAL Soft's loopback device (docs/audio.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numbers>
#include <random>

#include <CLI/CLI.hpp>

#include "audio/capture.h"
#include "audio/echo_canceller.h"
#include "audio/sofa_hrtf.h"
#include "audio/ear_measure.h"
#include "audio/spatializer.h"
#include "audio/speech_quality.h"
#include "audio/voice_chain.h"
#include "audio/voice_codec.h"
#include "audio/wav.h"
#include "bench.h"
#include "bench_audio_lean.h"
#include "common/clock.h"
#include "common/log.h"

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

// Echo cancellation on a simulated loudspeaker call: 10 s of read speech
// played as stereo (the far end), through a synthetic room (37 ms
// playout → capture delay, RT60 0.25 s), picked up with −80 dBFS sensor noise;
// the near-end talker (espeak-ng speech) starts at 5 s.
struct AecFigures {
  double erle_st = 0, erle_dt = 0, q_dt = 0, q_clean = 0, q_mix = 0, delay_ms = -1, cpu_ms_per_10ms = 0;
  int cpu_runs = 0;
};

std::vector<float> Cancel(AecEngine e, bool aec, bool ns, const std::vector<float>& far, const std::vector<float>& mic,
                          double* delay_ms, double* cpu_ms, int filter_ms = 0) {
  EchoCancellerOptions o;
  o.engine = e;
  o.filter_ms = filter_ms;
  o.echo_cancellation = aec;
  o.noise_suppression = ns;
  auto ec = EchoCanceller::Create(o);
  if (!ec.ok()) return {};
  std::vector<float> out;
  const double cpu0 = ProcessCpuMs();
  for (size_t i = 0; i + 960 <= mic.size(); i += 960) {
    (*ec)->PushPlayed(std::span<const float>(far).subspan(2 * i, 1920));
    const auto y = (*ec)->ProcessCapture(std::span<const float>(mic).subspan(i, 960));
    out.insert(out.end(), y.begin(), y.end());
  }
  if (cpu_ms) *cpu_ms = (ProcessCpuMs() - cpu0) / (static_cast<double>(mic.size()) / 480.0);
  if (delay_ms) *delay_ms = (*ec)->estimated_delay_ms();
  return out;
}

// `near_gain` scales the near-end talker (0.25: 2.8 dB below the echo over
// 5–10 s; 0.125: 8.9 dB below); `filter_ms` 0 is the engine's default.
// `noise_std`: microphone noise (1e-4: −80 dBFS; 3e-3: −50 dBFS).
// CPU per 10 ms block: median of `cpu_runs` single-talk runs.
// `room`: the synthetic echo path (default RT60 0.25 s, IR 120 ms).
StatusOr<AecFigures> MeasureAec(AecEngine e, bool ns, float near_gain = 0.25f, int filter_ms = 0,
                                float noise_std = 1e-4f, int cpu_runs = 1, const EchoPathOptions& room = {}) {
  const int rate = kSampleRate;
  HOLO_ASSIGN_OR_RETURN(auto far_m, ReadMonoWav(std::string(HOLO_SOURCE_DIR) + "/tests/data/audio/speech_48k.wav", rate));
  HOLO_ASSIGN_OR_RETURN(auto near_m, ReadMonoWav(std::string(HOLO_SOURCE_DIR) + "/tests/data/audio/espeak_speech_22k.wav", rate));
  const size_t n = 10 * static_cast<size_t>(rate);
  std::vector<float> far(2 * n);
  for (size_t i = 0; i < n; ++i) {
    far[2 * i] = far_m[i % far_m.size()];
    far[2 * i + 1] = i >= 15 ? 0.7f * far_m[(i - 15) % far_m.size()] : 0.0f;
  }
  const std::vector<float> echo = ApplyEchoPath(MakeEchoPath(room), far);
  std::mt19937 rng(5);
  std::normal_distribution<float> noise(0.0f, noise_std);
  std::vector<float> near(n, 0.0f), mic_st(n), mic_dt(n), mic_ne(n);
  const size_t t5 = 5 * static_cast<size_t>(rate);
  for (size_t i = 0; i < near_m.size() && t5 + i < n; ++i) near[t5 + i] = near_gain * near_m[i];
  for (size_t i = 0; i < n; ++i) {
    const float z = noise(rng);
    mic_st[i] = echo[i] + z;
    mic_dt[i] = echo[i] + near[i] + z;
    mic_ne[i] = near[i] + z;  // no echo: the same near end and noise
  }
  AecFigures f;
  const auto st = Cancel(e, true, ns, far, mic_st, &f.delay_ms, &f.cpu_ms_per_10ms, filter_ms);
  std::vector<double> cpu = {f.cpu_ms_per_10ms};
  for (int r = 1; r < cpu_runs; ++r) {
    double c = 0;
    (void)Cancel(e, true, ns, far, mic_st, nullptr, &c, filter_ms);
    cpu.push_back(c);
  }
  f.cpu_ms_per_10ms = Median(cpu);
  f.cpu_runs = static_cast<int>(cpu.size());
  const auto dt = Cancel(e, true, ns, far, mic_dt, nullptr, nullptr, filter_ms);
  const std::vector<float> silent(far.size(), 0.0f);
  const auto clean = Cancel(e, true, ns, silent, mic_ne, nullptr, nullptr, filter_ms);
  if (st.size() != n || dt.size() != n || clean.size() != n) return Internal("echo canceller failed");
  f.erle_st = ErleDb(echo, st, {}, 4 * static_cast<size_t>(rate), n);
  // The suppressors delay their output by a few ms (overlap-add): compare at the best lag.
  const std::span<const float> ref = std::span<const float>(near).subspan(t5);
  auto quality = [&](const std::vector<float>& y, int* lag_out) {
    const std::span<const float> out = std::span<const float>(y).subspan(t5);
    const int lag = BestLag(ref, out, 960);
    if (lag_out) *lag_out = lag;
    return FwSegSnrDb(ref, out, lag, rate);
  };
  int lag = 0;
  f.q_dt = quality(dt, &lag);
  f.q_clean = quality(clean, nullptr);
  f.q_mix = quality(mic_dt, nullptr);
  // Double talk: echo power over the near-end talk vs what is left besides the near end.
  f.erle_dt = ErleDb(echo, dt, near, t5, n, lag);
  return f;
}

int RunEchoAndHrtf(const BenchArgs& args) {
  // Each engine at its defaults (twopath is the default), then the steps
  // that led to it: filter length, noise suppression off; then harder
  // conditions: a quieter near end, a noisier microphone.
  struct AecRun {
    AecEngine engine;
    bool ns;
    float near_gain;
    int filter_ms;  // 0: the engine's default
    float noise_std = 1e-4f;
    double rt60_s = 0.25, ir_ms = 120;  // the room
  };
  const AecRun runs[] = {
      {AecEngine::kWebRtc, true, 0.25f, 0},   {AecEngine::kSpeex, true, 0.25f, 0},
      {AecEngine::kTwoPath, true, 0.25f, 0},  {AecEngine::kSpeex, true, 0.25f, 140},
      {AecEngine::kTwoPath, true, 0.25f, 80}, {AecEngine::kSpeex, false, 0.25f, 0},
      {AecEngine::kTwoPath, false, 0.25f, 0}, {AecEngine::kSpeex, true, 0.125f, 0},
      {AecEngine::kTwoPath, true, 0.125f, 0}, {AecEngine::kSpeex, true, 0.25f, 0, 3e-3f},
      {AecEngine::kTwoPath, true, 0.25f, 0, 3e-3f},
      // A more reverberant room: RT60 0.5 s, IR 300 ms.
      {AecEngine::kSpeex, true, 0.25f, 0, 1e-4f, 0.5, 300},   {AecEngine::kTwoPath, true, 0.25f, 0, 1e-4f, 0.5, 300},
      {AecEngine::kTwoPath, true, 0.25f, 250, 1e-4f, 0.5, 300}, {AecEngine::kTwoPath, true, 0.25f, 250},
  };
  for (const AecRun& run : runs) {
    // The engines at their defaults (the first three runs) get a CPU median.
    const bool defaults =
        run.ns && run.filter_ms == 0 && run.near_gain == 0.25f && run.noise_std == 1e-4f && run.rt60_s == 0.25;
    EchoPathOptions room;
    room.rt60_s = run.rt60_s;
    room.ir_ms = run.ir_ms;
    auto f = MeasureAec(run.engine, run.ns, run.near_gain, run.filter_ms, run.noise_std,
                        defaults ? std::max(1, args.repeats) : 1, room);
    if (!f.ok()) {
      spdlog::error("{}", f.status().ToString());
      return 1;
    }
    EchoCancellerOptions eo;
    eo.engine = run.engine;
    eo.filter_ms = run.filter_ms;
    const std::string name = AecEngineName(run.engine);
    const std::string workload = run.rt60_s == 0.25 ? "speech_10s_room_rt60_0.25s_delay_37ms"
                                                    : "speech_10s_room_rt60_0.5s_ir_300ms_delay_37ms";
    const std::string ns = run.ns ? "on" : "off", filter = std::to_string(eo.FilterMs());
    const std::string near = Fixed(run.near_gain, 3);
    const std::string mic_noise = Fixed(20.0 * std::log10(run.noise_std), 0);
    EmitFigure("audio", workload, "erle_db", f->erle_st, "dB",
               {{"engine", name}, {"talk", "single"}, {"ns", ns}, {"filter_ms", filter}, {"near_gain", near},
                {"mic_noise_dbfs", mic_noise}, {"delay_estimated_ms", Fixed(f->delay_ms, 1)},
                {"cpu_ms_per_10ms", Fixed(f->cpu_ms_per_10ms, 4)},
                {"cpu_runs", std::to_string(f->cpu_runs)}});
    EmitFigure("audio", workload, "erle_db", f->erle_dt, "dB",
               {{"engine", name}, {"talk", "double"}, {"ns", ns}, {"filter_ms", filter}, {"near_gain", near},
                {"mic_noise_dbfs", mic_noise}, {"note", "lower bound: near-end distortion counts as echo"}});
    EmitFigure("audio", workload, "fwsnrseg_db", f->q_dt, "dB",
               {{"engine", name}, {"talk", "double"}, {"ns", ns}, {"filter_ms", filter}, {"near_gain", near},
                {"mic_noise_dbfs", mic_noise}, {"against", "clean near-end"}, {"no_echo_db", Fixed(f->q_clean, 1)},
                {"echo_uncancelled_db", Fixed(f->q_mix, 1)}});
  }
  // Noise suppression: espeak-ng speech in white noise at 10 dB SNR, 1 s of noise first.
  {
    auto sp = ReadMonoWav(std::string(HOLO_SOURCE_DIR) + "/tests/data/audio/espeak_speech_22k.wav", kSampleRate);
    if (!sp.ok()) return 1;
    const size_t lead = kSampleRate;
    std::vector<float> clean(lead + sp->size(), 0.0f);
    double ps = 0;
    for (size_t i = 0; i < sp->size(); ++i) {
      clean[lead + i] = 0.5f * (*sp)[i];
      ps += static_cast<double>(clean[lead + i]) * clean[lead + i];
    }
    ps /= static_cast<double>(sp->size());
    std::mt19937 rng(9);
    std::normal_distribution<float> noise(0.0f, static_cast<float>(std::sqrt(ps / 10.0)));
    std::vector<float> noisy = clean;
    for (float& v : noisy) v += noise(rng);
    const std::vector<float> silent(2 * noisy.size(), 0.0f);
    for (AecEngine e : {AecEngine::kWebRtc, AecEngine::kSpeex, AecEngine::kTwoPath}) {
      const auto out = Cancel(e, false, true, silent, noisy, nullptr, nullptr);
      EmitFigure("audio", "espeak_speech_white_noise_10db", "ns_snr_gain_db",
                 NoiseSuppressionGainDb(clean, noisy, out, lead), "dB", {{"engine", AecEngineName(e)}});
    }
  }
  // Personal HRTF: the MIT KEMAR SOFA file through the SOFA path of the
  // spatializer (white noise, 1 m), against the cues of the file's own IRs.
  const std::string sofa = "/usr/share/libmysofa/MIT_KEMAR_normal_pinna.sofa";
  for (int az = -90; az <= 90; az += 30) {
    SpatializerOptions o;
    o.sofa_path = sofa;
    auto sp = Spatializer::Create(o);
    auto file = SofaFileCues(sofa, az);
    if (!sp.ok() || !file.ok()) {
      spdlog::error("{}", (!sp.ok() ? sp.status() : file.status()).ToString().c_str());
      return 1;
    }
    (*sp)->SetListener({0, 0, 1.6f, 0, 0, 0});
    auto id = (*sp)->AddSpeaker();
    const float a = -static_cast<float>(az) * std::numbers::pi_v<float> / 180.0f;
    SpeakerPlacement s;
    s.position = {std::cos(a), std::sin(a), 1.6f};
    s.facing = {-std::cos(a), -std::sin(a), 0.0f};
    if (!id.ok() || !(*sp)->SetSpeaker(*id, s).ok()) return 1;
    std::mt19937 rng(1);
    std::normal_distribution<float> noise(0.0f, 0.1f);
    std::vector<float> x(24000);
    for (float& v : x) v = noise(rng);
    if (!(*sp)->Push(*id, x).ok()) return 1;
    const auto y = (*sp)->Render(24000);
    const EarMeasurement m = MeasureEars(y, 2400, 21600, kSampleRate, 72);
    const std::string azs = std::to_string(az);
    EmitFigure("audio", "white_noise_1m", "itd_ms", m.itd_ms, "ms",
               {{"azimuth_deg", azs}, {"hrtf", "sofa"}, {"file_itd_ms", Fixed(file->itd_ms, 4)}});
    EmitFigure("audio", "white_noise_1m", "ild_db", m.ild_db, "dB",
               {{"azimuth_deg", azs}, {"hrtf", "sofa"}, {"file_ild_db", Fixed(file->ild_db, 1)}});
  }
  return 0;
}

int RunAudio(const BenchArgs& args) {
  if (const int rc = RunEchoAndHrtf(args); rc != 0) return rc;
  const std::string w = "speech_48k";
  auto speech = ReadMonoWav(std::string(HOLO_SOURCE_DIR) + "/tests/data/audio/speech_48k.wav", kSampleRate);
  if (!speech.ok()) {
    spdlog::error("{}", speech.status().ToString());
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
               {{"codec", name}, {"mode", "cpu"}, {"wall_ms", Fixed(Median(enc_ms), 4)}, {"runs", std::to_string(enc_ms.size())}});
    EmitFigure("audio", w, "decode_ms", Median(dec_cpu), "ms",
               {{"codec", name}, {"mode", "cpu"}, {"wall_ms", Fixed(Median(dec_ms), 4)}, {"runs", std::to_string(dec_ms.size())}});
  }
  // Intelligibility of the Opus round trip against the PCM path (stated measures:
  // fwSNRseg after Hu & Loizou 2008, and waveform segmental SNR).
  {
    auto es = ReadMonoWav(std::string(HOLO_SOURCE_DIR) + "/tests/data/audio/espeak_speech_22k.wav", kSampleRate);
    if (!es.ok()) {
      spdlog::error("{}", es.status().ToString());
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
  // Opus bitrate vs quality and wire rate with today's AudioPose frame (the
  // data for choosing a lean frame's Opus setting): espeak-ng speech.
  {
    auto es = ReadMonoWav(std::string(HOLO_SOURCE_DIR) + "/tests/data/audio/espeak_speech_22k.wav", kSampleRate);
    if (!es.ok()) return 1;
    for (int kbit : {12, 16, 20, 24, 32}) {
      VoiceEncoderOptions o;
      o.bitrate_bps = kbit * 1000;
      auto enc = VoiceEncoder::Create(o);
      auto dec = VoiceDecoder::Create(AudioCodec::kOpus);
      if (!enc.ok() || !dec.ok()) return 1;
      std::vector<float> out;
      size_t opus_bytes = 0, wire_bytes = 0, frames_n = 0;
      for (size_t i = 0; i + kFrameSamples <= es->size(); i += kFrameSamples) {
        auto f = (*enc)->EncodeFrame(std::span<const float>(*es).subspan(i, kFrameSamples), static_cast<uint32_t>(i), 0, {});
        if (!f.ok()) return 1;
        opus_bytes += f->audio.size();
        wire_bytes += SerializeVoiceFrame(*f).size() + 32;
        ++frames_n;
        auto pcm = (*dec)->Decode(f->audio);
        if (!pcm.ok()) return 1;
        out.insert(out.end(), pcm->begin(), pcm->end());
      }
      const int lag = BestLag(*es, out, 960);
      const double secs = static_cast<double>(frames_n) * 0.02;
      EmitFigure("audio", "espeak_speech", "fwsnrseg_db", FwSegSnrDb(*es, out, lag, kSampleRate), "dB",
                 {{"codec", "opus"}, {"bitrate_kbps", std::to_string(kbit)},
                  {"opus_kbps", Fixed(static_cast<double>(opus_bytes) * 8 / secs / 1000, 1)},
                  {"wire_kbps_v1_frame", Fixed(static_cast<double>(wire_bytes) * 8 / secs / 1000, 1)}});
    }
  }
  for (AudioCodec codec : {AudioCodec::kOpus, AudioCodec::kPcm16}) {
    for (int jitter : {0, 20, 50}) {
      if (!args.json)
        spdlog::info("audio: mouth-to-ear, {}, jitter {} ms", codec == AudioCodec::kOpus ? "opus" : "pcm", jitter);
      VoiceChainOptions o;
      o.encoder.codec = codec;
      o.network.jitter_ms = jitter;  // no base delay: propagation is not part of the figure
      o.network.seed = 7;
      o.link = RoomLink{};
      auto l = MeasureMouthToEar(o, 30.0, 5.0);
      if (!l.ok()) {
        spdlog::error("{}", l.status().ToString());
        return 1;
      }
      EmitFigure("audio", "bursts_30s", "mouth_to_ear_ms", l->median_ms, "ms",
                 {{"codec", codec == AudioCodec::kOpus ? "opus" : "pcm"},
                  {"jitter_ms", std::to_string(jitter)},
                  {"p95_ms", Fixed(l->p95_ms, 1)},
                  {"jb_target_ms", Fixed(l->jb_target_ms, 1)},
                  {"bursts", std::to_string(l->bursts)},
                  {"includes", "framing 20 ms, codec look-ahead, network U(0,jitter) without base delay, jitter buffer, "
                               "10 ms playout-tick phase, one 20 ms block queued in OpenAL, HRTF; excludes encode/decode "
                               "CPU time, sound-card buffers, propagation"}});
    }
  }
  for (int az = -90; az <= 90; az += 30) {
    const Ears e = Measure(static_cast<float>(az), 180);
    EmitFigure("audio", "white_noise_1m", "ild_db", e.ild_db, "dB", {{"azimuth_deg", std::to_string(az)}, {"hrtf", "openal-default"}});
    EmitFigure("audio", "white_noise_1m", "itd_ms", e.itd_ms, "ms", {{"azimuth_deg", std::to_string(az)}, {"hrtf", "openal-default"}});
  }
  const Ears facing = Measure(30, 180), away = Measure(30, 0);
  EmitFigure("audio", "white_noise_1m", "directivity_db", facing.level_db - away.level_db, "dB",
             {{"azimuth_deg", "30"}, {"compare", "facing vs facing away"}});
  return 0;
}

}  // namespace

HOLO_REGISTER_BENCH_OPTIONS("audio",
                            "voice: kbps, encode/decode ms, speech quality, mouth-to-ear ms, ILD/ITD by azimuth, "
                            "directivity",
                            [](CLI::App& app) -> BenchFn {
                              // Its rooms and signals are its own: no workload, no frame count.
                              DropCommonOptions(app, {"--workload", "--frames"});
                              auto lean_only = std::make_shared<bool>(false);
                              app.add_flag("--lean-only", *lean_only,
                                           "only the lean-frame figures (kbps per frame format, Opus settings, "
                                           "pose error, mouth-to-ear)");
                              return [lean_only](const BenchArgs& a) {
                                if (*lean_only) return RunLeanFrames(a);
                                const int rc = RunAudio(a);
                                return rc != 0 ? rc : RunLeanFrames(a);
                              };
                            });

}  // namespace holo::bench
