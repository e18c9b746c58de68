// holoport-voice: plays speech (a WAV, espeak-ng, or a microphone when one
// exists) as a remote speaker moving along a path around a listener, through
// the whole voice chain in simulated time (capture → Opus/PCM → AudioPose
// message → simulated network → jitter buffer → room transform → HRTF), and
// writes what the listener's ears get as a stereo WAV. --analyse reads that
// WAV back and prints the interaural level/time difference and level per
// window beside where the speaker truly was. See docs/audio.md.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <numbers>
#include <string>
#include <vector>

#include <AL/al.h>
#include <AL/alc.h>
#include <AL/alext.h>

#include <chrono>
#include <thread>

#include <CLI/CLI.hpp>

#include "audio/capture.h"
#include "audio/ear_measure.h"
#include "audio/voice_chain.h"
#include "audio/wav.h"
#include "common/clock.h"
#include "common/log.h"

namespace {

using namespace holo;
using namespace holo::audio;

constexpr float kDeg = std::numbers::pi_v<float> / 180.0f;

struct PathOptions {
  std::string path = "circle";      // circle | walk-past | fixed
  std::string facing = "listener";  // listener | path | away | spin | fixed
  float radius_m = 1.5f;            // circle radius, fixed distance
  float period_s = 8.0f;            // one turn of the circle
  float azimuth_deg = 0.0f;         // circle start / fixed position, + right of the listener
  float passing_m = 1.0f;           // walk-past: closest distance (in front of the listener)
  float length_m = 6.0f;            // walk-past: walked from left to right
  float speed_mps = 1.0f;           // walk-past speed
  float spin_period_s = 4.0f;       // facing spin: one turn in place
  float facing_yaw_deg = 0.0f;      // facing fixed: yaw in the local room
  float height_m = 1.6f;
};

// Where the speaker is (local room) and which way they face, at t seconds.
struct LocalPose {
  Eigen::Vector3f position;
  Eigen::Vector3f facing;
};

LocalPose PathAt(const PathOptions& o, const HeadPose& listener, double t) {
  const Eigen::Vector3f l(listener.x, listener.y, listener.z);
  const float ly = listener.yaw;
  // Listener frame in the room: forward f, left g (horizontal).
  const Eigen::Vector3f f(std::cos(ly), std::sin(ly), 0), g(-std::sin(ly), std::cos(ly), 0);
  auto dir = [&](float az_deg) {  // horizontal unit vector at azimuth az (+ right)
    const float a = az_deg * kDeg;
    return Eigen::Vector3f(std::cos(a) * f - std::sin(a) * g);
  };
  LocalPose p;
  Eigen::Vector3f velocity = Eigen::Vector3f::Zero();
  if (o.path == "circle") {
    const float az = o.azimuth_deg + static_cast<float>(360.0 * t / o.period_s);
    p.position = l + o.radius_m * dir(az);
    velocity = dir(az + 90.0f);  // clockwise seen from above: front → right → back → left
  } else if (o.path == "walk-past") {
    const float s = std::min(static_cast<float>(t) * o.speed_mps, o.length_m);
    p.position = l + o.passing_m * f + (o.length_m / 2 - s) * g;  // from the left to the right
    velocity = -g;
  } else {  // fixed
    p.position = l + o.radius_m * dir(o.azimuth_deg);
  }
  p.position.z() = o.height_m;
  const Eigen::Vector3f to_listener = Eigen::Vector3f(l.x() - p.position.x(), l.y() - p.position.y(), 0).normalized();
  if (o.facing == "listener") {
    p.facing = to_listener;
  } else if (o.facing == "away") {
    p.facing = -to_listener;
  } else if (o.facing == "path") {
    p.facing = velocity.norm() > 0 ? velocity : to_listener;
  } else if (o.facing == "spin") {  // turns left in place, starting towards the listener
    const float a = static_cast<float>(2 * std::numbers::pi * t / o.spin_period_s);
    p.facing = Eigen::AngleAxisf(a, Eigen::Vector3f::UnitZ()) * to_listener;
  } else {  // fixed
    p.facing = Eigen::Vector3f(std::cos(o.facing_yaw_deg * kDeg), std::sin(o.facing_yaw_deg * kDeg), 0);
  }
  return p;
}

// The remote head pose (remote room) that the call config maps onto `p`.
HeadPose ToRemote(const LocalPose& p, const RoomLink& link) {
  const Eigen::Isometry3f remote_from_local = link.local_from_remote.inverse();
  const Eigen::Vector3f pos = remote_from_local * p.position;
  const Eigen::Vector3f fac = remote_from_local.linear() * p.facing;
  return HeadPose{pos.x(), pos.y(), pos.z(), std::atan2(fac.y(), fac.x()), 0.0f, 0.0f};
}

// Runs espeak-ng (no shell; the text goes through a file, so text starting
// with '-' is not taken for an option) to make `wav` from `text`.
Status Speak(const std::string& text, const std::string& voice, const std::string& wav) {
  const std::string txt = wav + ".txt";
  {
    std::ofstream f(txt);
    f << text << '\n';
    if (!f) return Unavailable("cannot write " + txt);
  }
  const pid_t pid = fork();
  if (pid < 0) {
    std::remove(txt.c_str());
    return Internal("fork failed");
  }
  if (pid == 0) {
    execlp("espeak-ng", "espeak-ng", "-v", voice.c_str(), "-w", wav.c_str(), "-f", txt.c_str(),
           static_cast<char*>(nullptr));
    _exit(127);
  }
  int status = 0;
  const pid_t waited = waitpid(pid, &status, 0);
  std::remove(txt.c_str());
  if (waited < 0) return Internal("waitpid failed");
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    return Unavailable(WIFEXITED(status) && WEXITSTATUS(status) == 127
                           ? std::string("espeak-ng not found (Debian package espeak-ng)")
                           : "espeak-ng failed (exit " + std::to_string(WEXITSTATUS(status)) + ")");
  }
  return OkStatus();
}

// Records `seconds` from a microphone in real time, if one exists.
StatusOr<std::vector<float>> RecordMicrophone(const std::string& device, double seconds, bool quiet) {
  HOLO_ASSIGN_OR_RETURN(auto cap, VoiceCapture::OpenDevice(device, RealClock::Instance(), [](int64_t) { return HeadPose{}; }));
  std::vector<float> out;
  if (!quiet) spdlog::info("holoport-voice: recording {:.1f} s from {}", seconds, cap->description());
  while (static_cast<double>(out.size()) < seconds * kSampleRate) {
    HOLO_ASSIGN_OR_RETURN(CapturedFrame f, cap->Next());
    out.insert(out.end(), f.samples.begin(), f.samples.end());
  }
  return out;
}

// Plays the already spatialised stereo on the default output device (HRTF off
// there and direct channels on, so the binaural signal is not processed again).
Status PlayOnDefaultDevice(const std::vector<float>& stereo) {
  ALCdevice* dev = alcOpenDevice(nullptr);
  if (dev == nullptr) {
    return Unavailable("no sound output: OpenAL could not open the default playback device (no sound card?)");
  }
  const ALCint attrs[] = {ALC_HRTF_SOFT, ALC_FALSE, ALC_FREQUENCY, kSampleRate, 0};
  ALCcontext* ctx = alcCreateContext(dev, attrs);
  if (ctx == nullptr) {
    alcCloseDevice(dev);
    return Unavailable("cannot create an OpenAL context on the default playback device");
  }
  alcMakeContextCurrent(ctx);
  std::vector<int16_t> pcm(stereo.size());
  for (size_t i = 0; i < stereo.size(); ++i) {
    pcm[i] = static_cast<int16_t>(std::lrint(std::clamp(stereo[i], -1.0f, 1.0f) * 32767.0f));
  }
  ALuint buf = 0, src = 0;
  alGenBuffers(1, &buf);
  alBufferData(buf, AL_FORMAT_STEREO16, pcm.data(), static_cast<ALsizei>(pcm.size() * sizeof(int16_t)), kSampleRate);
  alGenSources(1, &src);
  alSourcei(src, AL_DIRECT_CHANNELS_SOFT, AL_TRUE);
  alSourcei(src, AL_BUFFER, static_cast<ALint>(buf));
  alSourcePlay(src);
  Status result = alGetError() == AL_NO_ERROR ? OkStatus() : Internal("OpenAL error while starting playback");
  ALint state = AL_PLAYING;
  while (result.ok() && state == AL_PLAYING) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    alGetSourcei(src, AL_SOURCE_STATE, &state);
  }
  alDeleteSources(1, &src);
  alDeleteBuffers(1, &buf);
  alcMakeContextCurrent(nullptr);
  alcDestroyContext(ctx);
  alcCloseDevice(dev);
  return result;
}

struct Truth {
  double t_s;
  float azimuth_deg, distance_m, gain;
  bool playing;
  double source_energy;  // sum of squares of the mono block rendered (before spatialisation)
  double source_diff_energy;  // ... of its first difference (a brightness proxy)
};

// Reads the written WAV back and prints per-window ear measurements against
// the truth of the blocks played in that window.
int Analyse(const std::string& path, const std::vector<Truth>& truth, double window_s) {
  auto w = ReadWav(path);
  if (!w.ok() || w->channels != 2) {
    spdlog::error("holoport-voice: cannot analyse {}: {}", path, w.ok() ? "not stereo" : w.status().message().c_str());
    return 1;
  }
  const size_t win = static_cast<size_t>(window_s * w->sample_rate);
  const size_t frames = w->frames();
  const int max_lag = w->sample_rate * 15 / 10000;  // ±1.5 ms
  struct Row {
    double t0, az, dist, gain_db;
    EarMeasurement m;
    double rel_db;     // ear level re the source block level: what the spatialiser did
    double bright_db;  // ear brightness re the source's (first-difference energy / energy)
  };
  std::vector<Row> rows;
  double max_level = -1e9;
  for (size_t b = static_cast<size_t>(max_lag); b + win + static_cast<size_t>(max_lag) <= frames; b += win) {
    const double t0 = static_cast<double>(b) / w->sample_rate, t1 = t0 + window_s;
    double az_s = 0, az_c = 0, dist = 0, gain = 0, src = 0, src_d = 0;
    int n = 0;
    for (const Truth& t : truth) {
      if (t.t_s >= t0 && t.t_s < t1 && t.playing) {
        az_s += std::sin(t.azimuth_deg * kDeg), az_c += std::cos(t.azimuth_deg * kDeg);
        dist += t.distance_m, gain += t.gain, src += t.source_energy, src_d += t.source_diff_energy;
        ++n;
      }
    }
    if (n == 0) continue;
    Row r{t0, std::atan2(az_s, az_c) / kDeg, dist / n, 20 * std::log10(std::max(gain / n, 1e-6)),
          MeasureEars(w->samples, b, b + win, w->sample_rate, max_lag), 0.0, 0.0};
    if (!std::isfinite(r.m.level_db) || src <= 0) continue;
    r.rel_db = r.m.level_db - 10 * std::log10(src / static_cast<double>(n * kFrameSamples));
    double ee = 0, ed = 0;
    for (size_t i = b; i < b + win; ++i) {
      for (int c = 0; c < 2; ++c) {
        const double x = w->samples[2 * i + c], dx = x - w->samples[2 * (i - 1) + c];
        ee += x * x, ed += dx * dx;
      }
    }
    r.bright_db = (ee > 0 && src_d > 0) ? 10 * std::log10(ed / ee) - 10 * std::log10(src_d / src) : 0.0;
    max_level = std::max(max_level, r.m.level_db);
    rows.push_back(r);
  }
  std::printf("# analysis of %s, %.2f s windows (quiet windows, > 30 dB under the loudest, marked '-')\n",
              path.c_str(), window_s);
  std::printf("# rel_dB: ear level (L and R power summed) re the level of the source blocks rendered in the window\n");
  std::printf("# bright_dB: (first-difference energy / energy) of the ears re that of the source: < 0 = duller\n");
  std::printf("#  t_s   true_az_deg  dist_m  gain_db |  ILD_dB  ITD_ms  level_dB  rel_dB  bright_dB\n");
  int agree = 0, counted = 0;
  double sxy = 0, sxx = 0, syy = 0;
  double gx = 0, gy = 0, gxx = 0, gyy = 0, gxy = 0, gn = 0, rel_min = 1e9, rel_max = -1e9;
  for (const Row& r : rows) {
    const bool quiet = r.m.level_db < max_level - 30;
    std::printf("%6.2f  %+8.1f  %7.2f  %7.1f | %+7.1f  %+6.3f  %7.1f  %6.1f  %+8.1f%s\n", r.t0, r.az, r.dist,
                r.gain_db, r.m.ild_db, r.m.itd_ms, r.m.level_db, r.rel_db, r.bright_db, quiet ? "  -" : "");
    if (quiet) continue;
    const double s = std::sin(r.az * kDeg);
    if (std::abs(s) > 0.26) {  // more than 15° off the median plane
      ++counted;
      agree += (s > 0) == (r.m.ild_db > 0) && (s > 0) == (r.m.itd_ms > 0);
    }
    sxy += s * r.m.ild_db, sxx += s * s, syy += r.m.ild_db * r.m.ild_db;
    gx += r.gain_db, gy += r.rel_db, gxx += r.gain_db * r.gain_db, gyy += r.rel_db * r.rel_db,
        gxy += r.gain_db * r.rel_db, ++gn;
    rel_min = std::min(rel_min, r.rel_db), rel_max = std::max(rel_max, r.rel_db);
  }
  const double cov = gxy / gn - gx / gn * gy / gn, vx = gxx / gn - gx / gn * gx / gn, vy = gyy / gn - gy / gn * gy / gn;
  std::printf("# level: rel_dB spans %.1f dB (%.1f .. %.1f); corr(gain_dB, rel_dB) = %.2f\n", rel_max - rel_min,
              rel_min, rel_max, gn > 1 && vx > 1e-9 && vy > 1e-9 ? cov / std::sqrt(vx * vy) : 0.0);
  std::printf("# side right: ILD and ITD sign agree with the true side in %d of %d windows >15 deg off centre; "
              "corr(sin(azimuth), ILD) = %.2f\n",
              agree, counted, sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : 0.0);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "holoport-voice: a remote speaker moving around a listener, through the whole spatial voice chain in\n"
      "simulated time (capture -> Opus/PCM -> AudioPose message -> network with jitter/loss -> jitter buffer\n"
      "-> room transform -> OpenAL Soft HRTF on the loopback device); writes the listener's stereo WAV.\n"
      "Input: a microphone (--mic, if one exists), a WAV (--audio-in) or espeak-ng speech (--say)."};
  holo::AddLogLevelOption(app);
  std::string audio_in, say, voice = "en-us", out, trace_path, link_name = "face-to-face", codec = "opus", mic_device;
  bool mic = false, no_fec = false, no_hrtf = false, quiet = false, analyse = false, play = false;
  double duration_s = 0, mic_seconds = 5, jitter_ms = 20, loss = 0, delay_ms = 20, gap_m = 0.5, window_s = 0.25,
         listener_yaw_deg = 0, gap_between_loops_s = 0.3;
  int bitrate = 24000;
  int64_t seed = 1;
  float floor = 0.25f;
  PathOptions po;
  app.add_option("--audio-in", audio_in, "speech WAV (any rate/channels; resampled to 48 kHz mono)");
  app.add_option("--say", say, "speak this text with espeak-ng instead of a WAV");
  app.add_option("--voice", voice, "espeak-ng voice for --say")->capture_default_str();
  app.add_flag("--mic", mic, "record from a microphone (OpenAL capture) first; falls back to --audio-in / --say");
  app.add_option("--mic-device", mic_device, "OpenAL capture device name (default device if empty)");
  app.add_option("--mic-seconds", mic_seconds, "seconds to record from the microphone")->capture_default_str()->check(CLI::Range(0.1, 600.0));
  app.add_option("-o,--out", out, "stereo WAV to write (48 kHz, 16-bit); required");
  app.add_option("--path", po.path, "speaker path: circle, walk-past or fixed")
      ->capture_default_str()->check(CLI::IsMember({"circle", "walk-past", "fixed"}));
  app.add_option("--facing", po.facing, "speaker faces: listener, away, path (direction of walking), spin (turns in place) or fixed")
      ->capture_default_str()->check(CLI::IsMember({"listener", "away", "path", "spin", "fixed"}));
  app.add_option("--radius", po.radius_m, "circle radius / fixed distance, m")->capture_default_str()->check(CLI::Range(0.2, 50.0));
  app.add_option("--period", po.period_s, "seconds per turn of the circle")->capture_default_str()->check(CLI::Range(0.5, 3600.0));
  app.add_option("--azimuth", po.azimuth_deg, "start (circle) or fixed azimuth, deg, + right of the listener")->capture_default_str()->check(CLI::Range(-360.0, 360.0));
  app.add_option("--passing", po.passing_m, "walk-past: distance in front of the listener, m")->capture_default_str()->check(CLI::Range(0.2, 50.0));
  app.add_option("--length", po.length_m, "walk-past: metres walked, left to right")->capture_default_str()->check(CLI::Range(0.5, 200.0));
  app.add_option("--speed", po.speed_mps, "walk-past: m/s")->capture_default_str()->check(CLI::Range(0.1, 10.0));
  app.add_option("--spin-period", po.spin_period_s, "facing spin: seconds per turn")->capture_default_str()->check(CLI::Range(0.5, 3600.0));
  app.add_option("--facing-yaw", po.facing_yaw_deg, "facing fixed: yaw in the local room, deg")->capture_default_str();
  app.add_option("--listener-yaw", listener_yaw_deg, "listener's yaw in the local room, deg (+ left)")->capture_default_str();
  app.add_option("--link", link_name, "call config mapping the remote room into the local one: face-to-face or identity")
      ->capture_default_str()->check(CLI::IsMember({"face-to-face", "identity"}));
  app.add_option("--gap", gap_m, "face-to-face: distance between the two displays' rooms, m")->capture_default_str()->check(CLI::Range(0.0, 100.0));
  app.add_option("--duration", duration_s, "seconds of speech to play (the input repeats); 0 = one circle / one walk / the input once")
      ->capture_default_str()->check(CLI::Range(0.0, 600.0));
  app.add_option("--codec", codec,
                 "opus (classic frame), opus-lean (lean frame: PROTOCOL.md 9.1, its measured Opus settings) or pcm")
      ->capture_default_str()
      ->check(CLI::IsMember({"opus", "opus-lean", "pcm"}));
  auto* bitrate_opt = app.add_option("--bitrate", bitrate, "Opus bitrate, bit/s (opus-lean: 14000 unless given)")
                          ->capture_default_str()
                          ->check(CLI::Range(6000, 510000));
  app.add_flag("--no-fec", no_fec, "Opus without in-band FEC");
  app.add_option("--delay-ms", delay_ms, "network one-way delay, ms")->capture_default_str()->check(CLI::Range(0.0, 10000.0));
  app.add_option("--jitter-ms", jitter_ms, "network jitter: extra delay U(0, J) ms per packet")->capture_default_str()->check(CLI::Range(0.0, 10000.0));
  app.add_option("--loss", loss, "packet loss probability 0..1")->capture_default_str()->check(CLI::Range(0.0, 1.0));
  app.add_option("--seed", seed, "network simulation seed")->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_flag("--no-hrtf", no_hrtf, "plain stereo panning instead of the HRTF");
  std::string hrtf_sofa;
  app.add_option("--hrtf", hrtf_sofa, "personal HRTF: a SOFA file (SimpleFreeFieldHRIR), e.g. "
                                      "/usr/share/libmysofa/MIT_KEMAR_normal_pinna.sofa");
  app.add_option("--directivity-floor", floor, "cardioid gain floor behind the speaker, 0..1")->capture_default_str()->check(CLI::Range(0.0, 1.0));
  app.add_option("--trace", trace_path, "write per-20 ms truth (time, azimuth, distance, gain, jitter buffer) as CSV");
  app.add_flag("--analyse,--analyze", analyse, "read the output WAV back and print ILD/ITD/level per window vs the true azimuth");
  app.add_option("--window", window_s, "analysis window, s")->capture_default_str()->check(CLI::Range(0.05, 10.0));
  app.add_flag("--play", play, "also play the result on the default output device (if there is one)");
  app.add_flag("-q,--quiet", quiet, "no progress output");
  CLI11_PARSE(app, argc, argv);
  // Checked after parsing so that an unknown option is named first.
  if (out.empty()) {
    spdlog::error("holoport-voice: --out FILE.wav is required (see --help)");
    return 2;
  }

  auto fail = [](const std::string& m) {
    spdlog::error("holoport-voice: {}", m);
    return 1;
  };
  if (!audio_in.empty() && !say.empty()) return fail("give --audio-in or --say, not both");
  if (audio_in.empty() && say.empty() && !mic) return fail("no input: give --audio-in FILE, --say TEXT or --mic");

  // ---- input speech, 48 kHz mono
  std::vector<float> speech;
  std::string source;
  if (mic) {
    auto rec = RecordMicrophone(mic_device, mic_seconds, quiet);
    if (rec.ok()) {
      speech = std::move(rec).value();
      source = "microphone";
    } else if (audio_in.empty() && say.empty()) {
      return fail(rec.status().message() + "; give --audio-in FILE or --say TEXT to run without one");
    } else {
      spdlog::warn("holoport-voice: {}; using {} instead", rec.status().message(),
                   audio_in.empty() ? "--say" : "--audio-in");
    }
  }
  if (speech.empty()) {
    std::string wav = audio_in;
    if (!say.empty()) {
      char tmpl[] = "/tmp/holoport-voice-say-XXXXXX";
      const int fd = mkstemp(tmpl);
      if (fd < 0) return fail("cannot create a temporary file for espeak-ng");
      close(fd);
      wav = tmpl;
      const Status s = Speak(say, voice, wav);
      if (!s.ok()) {
        std::remove(wav.c_str());
        return fail(s.message());
      }
    }
    auto w = ReadMonoWav(wav, kSampleRate);
    if (!say.empty()) std::remove(wav.c_str());
    if (!w.ok()) return fail("bad input audio: " + w.status().message());
    speech = std::move(w).value();
    source = say.empty() ? "WAV " + audio_in : "espeak-ng (" + voice + ")";
  }
  // ---- how long: repeat the speech (with a short pause) to fill the path
  if (duration_s == 0) {
    duration_s = po.path == "circle"      ? po.period_s
                 : po.path == "walk-past" ? po.length_m / po.speed_mps
                                          : static_cast<double>(speech.size()) / kSampleRate;
  }
  if (duration_s > 600) return fail("the run would last " + std::to_string(duration_s) + " s; at most 600 s (--duration)");
  const size_t want = static_cast<size_t>(duration_s * kSampleRate);
  std::vector<float> input;
  input.reserve(want);
  while (input.size() < want) {
    const size_t take = std::min(speech.size(), want - input.size());
    input.insert(input.end(), speech.begin(), speech.begin() + static_cast<std::ptrdiff_t>(take));
    input.resize(std::min(want, input.size() + static_cast<size_t>(gap_between_loops_s * kSampleRate)), 0.0f);
  }

  // ---- the chain
  VoiceChainOptions o;
  if (codec == "opus-lean") {
    o.encoder = LeanVoiceEncoderOptions();
    if (bitrate_opt->count() == 0) bitrate = o.encoder.bitrate_bps;
  } else {
    o.encoder.codec = codec == "opus" ? AudioCodec::kOpus : AudioCodec::kPcm16;
  }
  o.encoder.bitrate_bps = bitrate;
  o.encoder.fec = !no_fec;
  o.network.base_delay_ms = delay_ms;
  o.network.jitter_ms = jitter_ms;
  o.network.loss = loss;
  o.network.seed = static_cast<uint64_t>(seed);
  o.spatializer.hrtf = !no_hrtf;
  o.spatializer.sofa_path = hrtf_sofa;
  o.spatializer.directivity_floor = floor;
  o.link = link_name == "identity" ? RoomLink{} : FaceToFaceLink(static_cast<float>(gap_m));
  o.listener = HeadPose{0.0f, 0.0f, 1.6f, static_cast<float>(listener_yaw_deg) * kDeg, 0.0f, 0.0f};
  SimulatedClock clock(0);
  const HeadPose listener = o.listener;
  const RoomLink link = o.link;
  auto pose_source = [&](int64_t t_us) { return ToRemote(PathAt(po, listener, static_cast<double>(t_us) * 1e-6), link); };
  auto capture = VoiceCapture::FromSamples(std::move(input), clock, pose_source, source);
  if (!quiet) {
    spdlog::info(
        "holoport-voice: {}, {:.1f} s; path {}, facing {}; {} {} kbit/s; network {:.0f} ms + U(0, {:.0f}) ms, "
        "loss {:.1f}%; link {}",
        source, duration_s, po.path, po.facing, codec, bitrate / 1000, delay_ms, jitter_ms, loss * 100, link_name);
  }
  std::vector<float> stereo;
  stereo.reserve(static_cast<size_t>((duration_s + 1) * kSampleRate * 2));
  std::vector<Truth> truth;
  std::ofstream trace;
  if (!trace_path.empty()) {
    trace.open(trace_path);
    if (!trace) return fail("cannot write " + trace_path);
    trace << "t_s,playing,azimuth_deg,distance_m,gain,remote_x,remote_y,remote_yaw_deg,local_x,local_y,facing_x,facing_y\n";
  }
  int64_t next_progress_us = 1'000'000;
  auto on_tick = [&](const ChainTick& t) {
    stereo.insert(stereo.end(), t.stereo.begin(), t.stereo.end());
    const double ts = static_cast<double>(t.time_us) * 1e-6;
    double e = 0, de = 0;
    for (size_t i = 0; i < t.source.size(); ++i) {
      e += static_cast<double>(t.source[i]) * t.source[i];
      if (i > 0) de += std::pow(static_cast<double>(t.source[i]) - t.source[i - 1], 2);
    }
    truth.push_back({ts, t.azimuth_deg, t.distance_m, t.gain, t.playing, e, de});
    if (trace) {
      trace << ts << ',' << t.playing << ',' << t.azimuth_deg << ',' << t.distance_m << ',' << t.gain << ','
            << t.remote_head.x << ',' << t.remote_head.y << ',' << t.remote_head.yaw / kDeg << ','
            << t.placement.position.x() << ',' << t.placement.position.y() << ',' << t.placement.facing.x() << ','
            << t.placement.facing.y() << '\n';
    }
    if (!quiet && t.time_us >= next_progress_us) {
      spdlog::info("  t {:5.1f} s  speaker at {:+6.1f} deg, {:.2f} m, gain {:5.1f} dB{}", ts, t.azimuth_deg,
                   t.distance_m, 20 * std::log10(std::max(t.gain, 1e-6f)), t.playing ? "" : "  (buffering)");
      next_progress_us += 1'000'000;
    }
  };
  auto stats = RunVoiceChain(*capture, clock, o, on_tick);
  if (!stats.ok()) return fail(stats.status().message());
  const Status ws = WriteStereoWav(out, stereo, kSampleRate);
  if (!ws.ok()) return fail(ws.message());
  const auto& jb = stats->jitter_buffer;
  const double seconds = static_cast<double>(stats->frames_captured) * 0.02;
  if (!quiet) {
    spdlog::info(
        "holoport-voice: wrote {} ({:.1f} s stereo, HRTF {}). sent {} messages, {:.1f} kbit/s incl. headers; "
        "lost {}; jitter buffer: concealed {} (FEC {}), late {}, underflows {} while the speech "
        "ran (+{} draining at the end), target {:.0f} ms, delay {:.0f} ms when the speech ended",
        out, static_cast<double>(stereo.size()) / 2 / kSampleRate, stats->hrtf_status, stats->messages_sent,
        seconds > 0 ? static_cast<double>(stats->bytes_sent) * 8 / 1000 / seconds : 0.0, stats->lost_in_network,
        jb.concealed, jb.fec_recovered, jb.late, stats->jitter_buffer_speech_end.underflows,
        jb.underflows - stats->jitter_buffer_speech_end.underflows, stats->jitter_buffer_speech_end.target_delay_ms,
        stats->jitter_buffer_speech_end.current_delay_ms);
  }
  if (stats->refused > 0) return fail(std::to_string(stats->refused) + " messages were refused by the receiver");
  const int rc = analyse ? Analyse(out, truth, window_s) : 0;
  if (play) {
    if (!quiet) spdlog::info("holoport-voice: playing {} on the default output device", out);
    const Status ps = PlayOnDefaultDevice(stereo);
    if (!ps.ok()) return fail(ps.message() + "; the WAV " + out + " is written");
  }
  return rc;
}
