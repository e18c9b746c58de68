// Capture-side echo cancellation and noise suppression for calls on
// loudspeakers. The far-end reference is what the spatializer played (both
// ears, interleaved stereo); the microphone signal is cleaned of its echo and
// of stationary room noise before it is encoded.
//
// The delay between playout and capture (sound-card buffers, speaker → mic
// distance) is estimated, not assumed: a GCC-PHAT cross-correlation of the
// played mix against the microphone, on 1.4 s windows every 0.25 s, decimated
// to 12 kHz. Once two estimates agree the reference is re-aligned so the
// adaptive filter sees the echo a few ms after its reference; the filter's
// tail covers the room's reverberation after that.
//
// Three engines, the default chosen by measurement (docs/audio.md,
// `holoport-bench audio`):
// * twopath (default): a two-path partitioned-block frequency-domain adaptive
//   filter written here (one 140 ms filter per ear; a background filter
//   adapts, the output's foreground filter takes its coefficients only when
//   they cancel clearly better, so double talk cannot make the output filter
//   diverge), then speexdsp's preprocessor for noise suppression only.
//   Written here because measurement showed where speexdsp loses the near
//   end under double talk: its 80 ms filter cannot cover the room's tail
//   (linear ERLE ≈ 18 dB in single talk), with a filter long enough it
//   diverges while both talk (linear ERLE 27 → 12 dB), and its residual echo
//   suppressor then lowers the near end. No residual echo suppressor here:
//   the linear filter alone keeps single-talk ERLE at 43 dB on the test room
//   (24.7 dB with a −50 dBFS microphone). When the delay estimate moves, the
//   filter's taps move with it instead of re-converging. Near-end fwSNRseg
//   under double talk: 24.7 dB vs 25.1 dB without echo (speexdsp 14.4 dB).
//   140 ms suits rooms up to RT60 ≈ 0.3 s; set filter_ms 250 for ≈ 0.5 s.
// * speex: speexdsp's MDF echo canceller (two-speaker multichannel mode) + its
//   preprocessor (residual echo suppression and noise suppression).
// * webrtc: the WebRTC audio processing module 0.3 (AEC with extended filter
//   + NS).
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/status.h"

namespace holo::audio {

enum class AecEngine { kTwoPath, kSpeex, kWebRtc };
const char* AecEngineName(AecEngine e);
StatusOr<AecEngine> ParseAecEngine(const std::string& name);  // "twopath" | "speex" | "webrtc"

struct EchoCancellerOptions {
  // Engine; the default is the one that measured best (docs/audio.md).
  AecEngine engine = AecEngine::kTwoPath;
  // Cancel the echo of the played audio (off with headphones).
  bool echo_cancellation = true;
  // Suppress stationary noise.
  bool noise_suppression = true;
  int sample_rate = 48000;  // 16000, 32000 or 48000
  // Residual echo suppression after the linear filter: 0 low, 1 moderate,
  // 2 high (WebRTC's levels; speexdsp: −20/−30/−40 dB with a far end, and half
  // that while the near end talks too). twopath has no residual suppressor.
  int suppression = 0;
  // twopath and speexdsp: adaptive filter length after the aligned delay, ms
  // (the room's tail). 0: the engine's measured best, FilterMs().
  int filter_ms = 0;
  // Reference = the mean of both ears (one adaptive filter) instead of one
  // per ear. The ears carry filtered copies of the same voices, so two filters
  // see nearly collinear inputs (speexdsp converges slowly), and WebRTC's AEC
  // runs one canceller per reverse channel in cascade, suppressing twice
  // (measured: near-end fwSNRseg under double talk 5.3 dB stereo, see docs).
  bool mono_reference = false;
  // Largest playout → capture delay searched, ms.
  int max_delay_ms = 400;
  // The reference is aligned to arrive this long before its echo (causality
  // margin for the filter), ms.
  int align_margin_ms = 8;
  Status Check() const;
  // filter_ms, or the engine's default when 0: twopath 140 ms, speexdsp 80 ms
  // (longer measured worse for speexdsp: it converges slower and diverges more
  // under double talk).
  int FilterMs() const;
};

// Not thread-safe: the audio thread that plays should hand its blocks to the
// thread that captures through a queue, in the order they were played.
class EchoCanceller {
 public:
  // InvalidArgument for bad options, Internal if an engine fails to start.
  static StatusOr<std::unique_ptr<EchoCanceller>> Create(const EchoCancellerOptions& options);
  ~EchoCanceller();
  EchoCanceller(const EchoCanceller&) = delete;
  EchoCanceller& operator=(const EchoCanceller&) = delete;

  // What was played (interleaved L, R at the options' rate), in playout order.
  void PushPlayed(std::span<const float> stereo);
  // Cleans microphone samples (mono, [-1, 1]); returns the same number of
  // samples, delayed by at most one 10 ms block (held until complete).
  std::vector<float> ProcessCapture(std::span<const float> mic);

  // Estimated playout → capture delay, ms (< 0: no confident estimate yet).
  double estimated_delay_ms() const;
  int delay_updates() const;
  const EchoCancellerOptions& options() const { return options_; }

  struct Engine;  // one implementation per AecEngine

 private:
  explicit EchoCanceller(const EchoCancellerOptions& o);
  void ProcessBlock(const float* mic, float* out);
  void EstimateDelay();

  EchoCancellerOptions options_;
  std::unique_ptr<Engine> engine_;
  int block_ = 480;  // 10 ms
  // Played stereo history (absolute sample index played_base_ is front()).
  std::deque<float> played_;       // interleaved
  int64_t played_base_ = 0, played_count_ = 0;
  std::vector<float> mic_pending_, out_ready_;
  int64_t mic_count_ = 0;          // mic samples processed (blocks)
  // Delay estimation on 12 kHz mono signals.
  std::deque<float> far_dec_, mic_dec_;
  std::vector<float> far_acc_, mic_acc_;
  int64_t far_dec_count_ = 0, mic_dec_count_ = 0;  // decimated samples ever pushed
  int64_t since_estimate_ = 0;
  int applied_delay_ = 0;          // samples at the options' rate
  double last_estimate_ = -1;      // samples, last raw estimate
  double confident_delay_ms_ = -1;
  int updates_ = 0;
};

// A synthetic speaker → room → microphone path for tests and the bench:
// per loudspeaker an impulse response with a direct path after `delay_ms`
// (device buffers + propagation), early reflections and an exponentially
// decaying diffuse tail (RT60 `rt60_s`), scaled to `gain` (echo level).
struct EchoPathOptions {
  double delay_ms = 37.0;
  double rt60_s = 0.25;
  double ir_ms = 120.0;   // IR length after the direct path
  double gain = 0.25;
  uint64_t seed = 3;
};
struct EchoPath {
  std::vector<float> ir_left, ir_right;  // at 48 kHz
};
EchoPath MakeEchoPath(const EchoPathOptions& o);
// Microphone pickup of `played` (interleaved stereo) through `path`.
std::vector<float> ApplyEchoPath(const EchoPath& path, std::span<const float> played);

// Echo return loss enhancement: 10·log10(Σ echo[i]² / Σ (out[i] − near[i − `near_lag`])²)
// over samples i in [`begin`, `end`); `near` may be empty (single talk). With a
// near end (double talk) the residual also holds whatever the processing did
// to the near-end speech, so the figure is a lower bound of the echo's ERLE.
double ErleDb(std::span<const float> echo, std::span<const float> out, std::span<const float> near, size_t begin,
              size_t end, int near_lag = 0);

// SNR improvement of a noise suppressor, dB: SNR of `processed` minus SNR of
// `noisy`, each estimated the same way from 20 ms frames after `skip` samples:
// frames where `clean` is within 30 dB of its loudest frame are speech, those
// more than 50 dB below are pauses; SNR = (P_speech − P_pause) / P_pause.
double NoiseSuppressionGainDb(std::span<const float> clean, std::span<const float> noisy,
                              std::span<const float> processed, size_t skip);

}  // namespace holo::audio
