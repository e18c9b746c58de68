// Per-speaker jitter buffer in the spirit of WebRTC's NetEq, in injected time.
//
// Insert() takes validated voice frames as they arrive; Pull() is called once
// per 20 ms of the receiver's playout clock and returns 20 ms of audio.
// - Target delay: the 97th percentile of each packet's arrival delay above the
//   fastest packet of the last `window_packets`, plus `margin_ms`.
// - Reordered packets wait in the buffer; duplicates and packets whose turn has
//   passed ("late") are dropped and counted.
// - A missing frame whose successors have arrived is concealed: Opus FEC from
//   the next packet when present, else Opus PLC (zeros for PCM).
// - If nothing has arrived yet (underflow) the decoder's PLC stretches the
//   output without consuming a frame, so the delay grows.
// - Drift and excess delay: decoded audio goes through a linear-interpolation
//   resampler whose ratio is set by a PI controller on the low-pass filtered
//   playout delay (measured in samples, including the partly played frame, at
//   the point where the next pull starts) against the adaptive target, within
//   ±`max_stretch` (0.5% by default). The integral term settles on the clock
//   ratio, so a sender clock 0.1% off is absorbed with no steady-state delay
//   error and without pitch jumps; a delay more than `drop_above_ms` over
//   target drops a whole frame.
// - Lip sync (audio/av_sync.h): SetSyncDelayMs() asks for a longer delay from
//   capture to playout than the jitter needs, to wait for a later picture.
//   The target becomes the larger of the two. The buffer gets there by
//   re-buffering (silence, when it must grow by more than `sync_rebuffer_ms`),
//   by one concealment frame per pull (growing by more than `sync_jump_ms`),
//   by dropping frames (shrinking by more than `sync_jump_ms`), and by the
//   resampler below that.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <vector>

#include "audio/voice_codec.h"
#include "common/clock.h"

namespace holo::audio {

struct JitterBufferOptions {
  // Target delay before any jitter was measured, ms.
  double initial_target_ms = 60.0;
  double min_target_ms = 20.0;
  double max_target_ms = 400.0;
  // Added to the measured jitter percentile, ms.
  double margin_ms = 10.0;
  // Packets the jitter statistics look back over.
  int window_packets = 250;
  // Largest resampling deviation from 1 (0.005 = ±0.5%).
  double max_stretch = 0.005;
  // Proportional gain: stretch per ms of (filtered) delay error
  // (0.0005: 10 ms error → 0.5%).
  double stretch_per_ms = 0.0005;
  // Integral gain: stretch added per ms of delay error per pull (20 ms).
  // With the proportional gain above the loop is about critically damped
  // (time constants ~2 s and ~10 s).
  double stretch_integral_per_ms = 1e-6;
  // Low-pass on the measured delay: weight of each new pull (0..1].
  double delay_filter = 0.05;
  // Delay over target beyond which whole frames are dropped, ms.
  double drop_above_ms = 80.0;
  // Lip sync: a sync delay further than this from the playout delay is
  // reached by whole frames (concealment or drops) instead of resampling, ms.
  double sync_jump_ms = 40.0;
  // Lip sync: when the delay must grow by more than this, playout stops and
  // restarts at the new delay (a silent gap instead of many concealed frames), ms.
  double sync_rebuffer_ms = 100.0;
  Status Check() const;
};

struct JitterBufferStats {
  int64_t inserted = 0;
  int64_t played = 0;          // frames decoded from their own packet
  int64_t concealed = 0;       // frames replaced by FEC or PLC (lost or late)
  int64_t fec_recovered = 0;   // of `concealed`, recovered from the next packet's FEC
  int64_t underflows = 0;      // pulls with nothing to play (output stretched)
  int64_t late = 0;            // packets that arrived after their turn
  int64_t duplicates = 0;
  int64_t dropped_frames = 0;  // frames dropped to cut excess delay
  double current_delay_ms = 0; // playout delay above the fastest packet
  double target_delay_ms = 0;  // what the controller aims at: max(jitter target, sync)
  double jitter_target_ms = 0; // the target the jitter alone asks for
  double transit_min_ms = 0;   // fastest packet of the window: arrival − capture (clock offset included)
  int64_t sync_expands = 0;    // concealment frames inserted to grow the delay for lip sync
  int64_t sync_drops = 0;      // frames dropped to shrink the delay for lip sync
  int64_t sync_rebuffers = 0;  // playout restarts to grow the delay for lip sync
  double stretch = 1.0;        // current resampling ratio (input per output sample)
  double drift_estimate = 0.0; // integral term: estimated sender/receiver clock ratio − 1
  // Lean frames sent without a pose (docs/audio.md "Lean frames"): played with
  // the pose halfway to the next frame's (it was here), extrapolated from the
  // last two poses, or held (no earlier pose to extrapolate from).
  int64_t poses_interpolated = 0;
  int64_t poses_extrapolated = 0;
  int64_t poses_held = 0;
};

// Not thread-safe. `clock` is borrowed for the buffer's lifetime.
class JitterBuffer {
 public:
  static StatusOr<std::unique_ptr<JitterBuffer>> Create(AudioCodec codec, Clock& clock,
                                                        const JitterBufferOptions& options = {});
  JitterBuffer(const JitterBuffer&) = delete;
  JitterBuffer& operator=(const JitterBuffer&) = delete;

  // Takes a frame that arrived now. DataLoss if it fails ValidateVoiceFrame or
  // has another codec than the buffer's (the frame is then ignored).
  Status Insert(AudioPose frame);
  // 20 ms (kFrameSamples) of output for the current instant; silence while
  // buffering. Never fails.
  std::vector<float> Pull();
  // Lip sync: the delay from a sample's capture (sender clock) to the Pull()
  // that returns it (this buffer's clock) is kept at least `ms`; 0 turns it
  // off. Clock offsets between the two clocks are part of it, as in
  // last_pull_capture_us().
  void SetSyncDelayMs(double ms) { sync_delay_ms_ = ms > 0 ? ms : 0.0; }
  double sync_delay_ms() const { return sync_delay_ms_; }
  // Capture time (sender clock, µs) of the first sample the last Pull()
  // returned; 0 if that pull played nothing. Codec delay not included.
  int64_t last_pull_capture_us() const { return last_pull_capture_us_; }
  // Head pose of the frame playing now (the latest one played).
  const HeadPose& pose() const { return pose_; }
  bool playing() const { return playing_; }
  const JitterBufferStats& stats() const { return stats_; }

 private:
  JitterBuffer(Clock& clock, const JitterBufferOptions& options) : clock_(clock), options_(options) {}
  // Decodes frame `next_seq_` (or conceals it) into the FIFO and advances.
  void DecodeNext();
  double DelayMs(int64_t now_us) const;
  // Capture time of the next sample to play (sender clock, µs).
  double PlayCaptureUs() const;
  void UpdateTarget();
  // target_delay_ms from the jitter target and the sync delay.
  void RefreshTarget();

  Clock& clock_;
  JitterBufferOptions options_;
  std::unique_ptr<VoiceDecoder> decoder_;
  std::map<int64_t, AudioPose> packets_;  // by unwrapped sequence
  std::deque<int64_t> transit_us_;        // arrival − capture of recent packets
  std::deque<double> rel_delay_ms_;       // transit − window minimum at arrival
  std::vector<float> fifo_;               // decoded, not yet resampled
  double frac_ = 0.0;                     // resampler phase into fifo_[0..1]
  int64_t next_seq_ = 0;                  // next frame to decode (unwrapped)
  int64_t max_seq_ = -1;
  bool started_ = false;                  // a packet has arrived
  bool playing_ = false;
  int consecutive_underflows_ = 0;
  // Drift controller state.
  bool delay_filter_init_ = false;
  double filtered_delay_ms_ = 0.0;
  double integral_ = 0.0;
  // Anchor for the sender's timeline: capture time of sequence anchor_seq_.
  int64_t anchor_seq_ = 0;
  int64_t anchor_capture_us_ = 0;
  int64_t last_seq32_ = 0;
  HeadPose pose_;
  // The last two poses frames carried, and their sequence numbers (-1: none).
  HeadPose carried_pose_, carried_prev_pose_;
  int64_t carried_seq_ = -1, carried_prev_seq_ = -1;
  double sync_delay_ms_ = 0.0;
  int64_t last_pull_capture_us_ = 0;
  JitterBufferStats stats_;
};

}  // namespace holo::audio
