// One side of a two-site call (docs/sessions.md, docs/viewer.md "Demo"),
// shared by holoport-call (headless, no GL) and holoport-client --call:
//  * watches the REMOTE site (viewer token): frames for the caller to pull
//    from viewer(), remote participants' audio+pose;
//  * publishes the own voice (a WAV, looped; or a 440 Hz tone) as Opus
//    20 ms AudioPose frames with the own head pose to the LOCAL site
//    (publisher token);
//  * plays the remote voices (one jitter buffer per remote stream,
//    RemoteVoices) in sync with the remote picture (av_sync(): the viewer
//    that shows the picture reports its display times there);
//  * optionally spatializes them: listener = own head pose, source = remote head pose
//    through the call config's room transform, HRTF through OpenAL Soft's
//    loopback device; the stereo output is written as a WAV at Stop().
// All times on the wire are wall-clock microseconds (system_clock).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "audio/av_sync.h"
#include "client/net/call_config.h"
#include "client/net/site_av_sync.h"
#include "common/status.h"
#include "net/site_client.h"
#include "protocol/messages.h"

namespace holo::net {

// Own head pose at wall time t_us, in the own room frame (audio/room.h: z up,
// x forward of the head).
using HeadPoseFn = std::function<protocol::HeadPose(int64_t t_us)>;

// A participant standing `distance_m` in front of their display (display at
// the room origin, looking along −x), swaying ±0.15 m sideways and turning
// ±12° (periods 9 s and 7 s), eyes at 1.6 m: a stand-in for head tracking.
protocol::HeadPose SyntheticHead(double t_s, float distance_m = 2.0f, float phase = 0.0f);

struct ParticipantOptions {
  CallConfig call;
  std::string name = "participant";
  // Own voice: a WAV file (any rate, mixed to mono, looped); empty: a quiet
  // 440 Hz tone (what holoport-call sent before WAVs).
  std::string audio_in;
  bool send_voice = true;
  // Spatialized stereo WAV of the remote voices (48 kHz), written by Stop().
  // Empty: remote audio is only counted.
  std::string audio_out;
  bool hrtf = true;
  // Personal HRTF (SOFA file) for the spatialized output; empty: OpenAL Soft's set.
  std::string hrtf_sofa;
  // Echo cancellation + noise suppression of the own voice against what the
  // spatializer played (loudspeakers: on; headphones: off). Noise suppression
  // runs whenever this is on.
  bool aec = false;
  // The canceller's filter length, ms (0: the engine's default, 140 ms: rooms
  // up to RT60 ≈ 0.3 s; ≈ 250 for RT60 ≈ 0.5 s; docs/audio.md).
  int aec_filter_ms = 0;
  HeadPoseFn head;  // default: SyntheticHead(t)
  // Lip sync of the remote voices with the remote picture (effective when
  // the viewer reports displayed pictures to av_sync()).
  audio::AvSyncOptions av_sync;
  VoicePlayoutOptions voice;
  ClientOptions view_template;  // decode, reconnect, backoff, … (host/port/token/role come from `call`)
};

struct ParticipantStats {
  int64_t voice_frames_sent = 0;
  int64_t remote_audio_frames = 0;  // AudioPose received from the remote site
  int64_t remote_speakers = 0;      // distinct participant streams heard
  // Medians over the last 1–2 minutes of frames.
  double audio_network_ms_median = 0;  // remote capture → received (wall clocks)
  double jitter_buffer_ms_median = 0;  // playout delay in the jitter buffers
  double audio_delay_ms = 0;           // mouth → ear estimate: the two above + 20 ms frame
  int64_t concealed = 0, late = 0, underflows = 0;
  double output_seconds = 0;  // spatialized audio rendered
  double output_rms = 0;      // of the spatialized output
  std::string hrtf_status;
  double aec_delay_ms = -1;  // estimated playout → capture delay (< 0: none yet / off)
  // Last remote voice position in the own room (metres) and its azimuth for
  // the own head, degrees (+ right).
  float remote_x = 0, remote_y = 0, remote_z = 0, remote_azimuth_deg = 0;
};

class Participant {
 public:
  static StatusOr<std::unique_ptr<Participant>> Start(ParticipantOptions options, ClientCallbacks view_callbacks = {});
  ~Participant();  // Stop()
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;

  // The client watching the remote site (frames: PollFrame/LatestFrame).
  SiteClient& viewer();
  // Lip sync of the remote voices with the remote site's picture.
  audio::AvSync& av_sync();
  // Own head pose now (what is published with the voice).
  protocol::HeadPose OwnHead() const;
  const CallConfig& call() const;
  ParticipantStats stats() const;
  // Stops the threads and clients and writes --audio-out; idempotent.
  Status Stop();

  struct Impl;

 private:
  explicit Participant(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// HOST:PORT → host, port; false if malformed.
bool ParseSiteAddress(const std::string& spec, std::string* host, uint16_t* port);

}  // namespace holo::net
