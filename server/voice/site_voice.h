// The voice of the person a site's pods capture, published with the picture
// (holoport-server --voice; docs/live.md "Voice and picture in sync").
//
// Every 20 ms a voice frame is made, encoded (Opus by default) and handed to
// `publish` as an AudioPose: its capture time is the time of its first
// sample on the wall clock — the clock the site stamps its pictures with
// (their acquisition time) — and its pose is where the person's head was.
// Sources:
//  * synthetic: the studio's person talks: a syllable starts each time a
//    foot lands and a knock sounds each time the ball touches the floor
//    (audio/synthetic_voice.h), at the instant the cameras see it, so that
//    voice and picture can be checked against each other;
//  * mic[:DEVICE]: a microphone (OpenAL capture);
//  * a WAV file, looped.
// The head pose is the studio's figure's head (synthetic studio), else a
// person standing at the room's centre (0, 0, 1.6 m, facing +x).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include <Eigen/Geometry>

#include "audio/voice_codec.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo {
class SyntheticStudio;
}

namespace holo::voice {

struct SiteVoiceOptions {
  // "synthetic", "mic", "mic:DEVICE" or the path of a WAV file ("off" is
  // handled by the caller: no SiteVoice).
  std::string source = "synthetic";
  // Lean frames (PROTOCOL.md §9.1) by default; the server sends viewers that
  // only know the classic layout the same packets in it.
  audio::VoiceEncoderOptions encoder = audio::LeanVoiceEncoderOptions();
  // Seed of the synthetic voice's syllables.
  uint64_t seed = 1;
};

// The studio time (seconds) of what the cameras see at time `t_us` of the
// pipeline clock (RealClock), or NaN while the site is not capturing yet.
using StudioTimeFn = std::function<double(int64_t t_us)>;
// Receives every frame, on the voice thread.
using PublishFn = std::function<void(const protocol::AudioPose&)>;

struct SiteVoiceStats {
  int64_t frames = 0;        // published
  int64_t onsets = 0;        // synthetic: syllables and knocks started
  int64_t late_frames = 0;   // frames made more than 20 ms late, or skipped after a stall over 0.5 s
  double cpu_ms = 0;         // CPU time of the voice thread so far (synthesis + Opus + publishing)
  std::string description;   // the source, for logs
};

class SiteVoice {
 public:
  // Starts the voice thread. `studio` (borrowed, may be null) gives the
  // sound events and the head pose; `studio_time` (may be empty: publish at
  // once, head at the room's centre) maps capture time to studio time, and
  // nothing is published while it is NaN. InvalidArgument for a source that
  // does not exist or needs the studio; Unavailable if the microphone does
  // not open.
  static StatusOr<std::unique_ptr<SiteVoice>> Start(const SiteVoiceOptions& options, const SyntheticStudio* studio,
                                                    StudioTimeFn studio_time, PublishFn publish);
  ~SiteVoice();  // Stop()
  SiteVoice(const SiteVoice&) = delete;
  SiteVoice& operator=(const SiteVoice&) = delete;
  void Stop();
  SiteVoiceStats stats() const;

  struct Impl;

 private:
  explicit SiteVoice(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The HeadPose (audio/room.h conventions) of a world_from_head transform
// whose head frame has x forward, y left, z up.
protocol::HeadPose HeadPoseFromTransform(const Eigen::Isometry3f& world_from_head);

}  // namespace holo::voice
