// The whole voice path of one remote speaker in simulated time, for
// holoport-voice and the audio bench: capture (20 ms frames tagged with the
// speaker's head pose) → Opus/PCM encode → AudioPose message (protocol header
// + payload) → simulated network (delay, jitter, loss, reordering) → protocol
// decode and validation → jitter buffer → decode / conceal → room-to-room
// transform of the frame's head pose → HRTF spatializer (OpenAL Soft loopback)
// → stereo blocks for the listener's ears.
#pragma once

#include <cstdint>
#include <functional>
#include <span>

#include "audio/capture.h"
#include "audio/jitter_buffer.h"
#include "audio/room.h"
#include "audio/spatializer.h"
#include "audio/voice_codec.h"
#include "common/clock.h"

namespace holo::audio {

struct NetworkSimOptions {
  double base_delay_ms = 0.0;  // one-way delay every packet has
  double jitter_ms = 0.0;      // plus U(0, jitter_ms) per packet (packets overtake each other)
  double loss = 0.0;           // probability a packet is lost, 0..1
  uint64_t seed = 1;
  Status Check() const;
};

struct VoiceChainOptions {
  VoiceEncoderOptions encoder;
  NetworkSimOptions network;
  JitterBufferOptions jitter_buffer;
  SpatializerOptions spatializer;
  RoomLink link;                     // call config: remote room → local room
  protocol::HeadPose listener{0, 0, 1.6f, 0, 0, 0};  // local user's head, local room
  // The receiver's 20 ms playout ticks lag the sender's frame grid by this much.
  double playout_phase_ms = 10.0;
  // Playout continues this long after the capture ends (drains the buffer).
  double tail_ms = 400.0;
  Status Check() const;
};

// One 20 ms playout block.
struct ChainTick {
  int64_t time_us = 0;                // when the block's first sample reaches the ears
  std::span<const float> stereo;      // kFrameSamples frames, interleaved L, R
  std::span<const float> source;      // the mono block (jitter buffer output) rendered into `stereo`
  bool playing = false;               // the jitter buffer is playing (not buffering)
  protocol::HeadPose remote_head;     // speaker's head of the audio in this block (their room)
  SpeakerPlacement placement;         // ... transformed into the local room
  float azimuth_deg = 0;              // from the listener, + right
  float distance_m = 0;
  float gain = 0;                     // distance × directivity gain applied
};

struct ChainStats {
  int64_t frames_captured = 0;
  int64_t messages_sent = 0;
  int64_t bytes_sent = 0;             // protocol header + AudioPose payload
  int64_t lost_in_network = 0;
  int64_t refused = 0;                // messages the receiver refused (never expected here)
  JitterBufferStats jitter_buffer;            // at the end of the run
  JitterBufferStats jitter_buffer_speech_end; // when the capture ended (before draining: the
                                              // underflows after it are the stream running out)
  std::string hrtf_status;
};

// Runs the capture to its end (plus options.tail_ms) on `clock`, calling
// `on_tick` for every playout block. The spatializer renders one block behind
// what the jitter buffer hands it (one 20 ms block queued in OpenAL), which is
// part of the measured delay.
StatusOr<ChainStats> RunVoiceChain(VoiceCapture& capture, SimulatedClock& clock, const VoiceChainOptions& options,
                                   const std::function<void(const ChainTick&)>& on_tick);

// Mouth-to-ear delay through RunVoiceChain in simulated time: 10 ms 1 kHz tone
// bursts every 500 ms, spoken by a source 1 m ahead of the listener (facing
// them); each burst's delay is the shift of its energy centroid from the
// capture timeline to the ear timeline ((L + R) / 2). Bursts in the first
// `warmup_s` (jitter buffer adaptation) are not counted. Includes everything
// RunVoiceChain models (framing, codec look-ahead, network, jitter buffer,
// playout tick phase, the block queued in OpenAL, HRTF); not CPU time.
struct MouthToEar {
  double median_ms = 0, p95_ms = 0, min_ms = 0, max_ms = 0;
  int bursts = 0;
  double jb_target_ms = 0;  // jitter buffer target at the end
  // Lean frames without a pose, how the receiver filled them (JitterBufferStats).
  int64_t poses_interpolated = 0, poses_extrapolated = 0, poses_held = 0;
};
StatusOr<MouthToEar> MeasureMouthToEar(const VoiceChainOptions& options, double seconds = 30.0,
                                       double warmup_s = 5.0);

}  // namespace holo::audio
