// HRTF spatialisation of remote speakers through OpenAL Soft. The listener is
// the local user's head; each remote speaker is one streaming OpenAL source
// placed in the listener's head frame. Rendering goes through OpenAL Soft's
// loopback device (ALC_SOFT_loopback), so no sound card is needed: the caller
// pulls stereo float samples and plays or writes them.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "audio/room.h"
#include "audio/wav.h"  // WAV helpers used with the spatializer
#include "common/status.h"

namespace holo::audio {

struct SpatializerOptions {
  int sample_rate = 48000;
  // Binaural rendering with OpenAL Soft's built-in HRTF (ALC_HRTF_SOFT).
  bool hrtf = true;
  // A personal HRTF: a SOFA file (SimpleFreeFieldHRIR). When set, sources are
  // rendered by convolution with its impulse responses (audio/sofa_hrtf.h:
  // interpolated between measured directions, crossfaded when a direction
  // changes) instead of OpenAL Soft; `hrtf` is then ignored. Directivity acts
  // on the level only on this path (no high-frequency cut).
  std::string sofa_path{};
  // Inverse-distance attenuation: gain = ref_distance_m / max(d, ref_distance_m).
  float ref_distance_m = 1.0f;
  // Cardioid directivity: gain = floor + (1 − floor) · (1 + cos θ) / 2, θ the
  // angle between the speaker's facing and the direction to the listener.
  // The floor keeps a speaker facing away audible (room reflections).
  float directivity_floor = 0.25f;
  // High frequencies fall faster than the level when the speaker turns away:
  // EFX low-pass with HF gain = directivity gain ^ hf_exponent (if EFX exists).
  float directivity_hf_exponent = 1.0f;
  Status Check() const;
};

// Pure helpers (no OpenAL): the gains a speaker gets.
float DistanceGain(const SpatializerOptions& o, float distance_m);
float DirectivityGain(const SpatializerOptions& o, const SpeakerPlacement& speaker, const Eigen::Vector3f& listener);

class Spatializer {
 public:
  // Opens a loopback device: stereo float at `options.sample_rate`.
  // Unavailable if OpenAL Soft or its loopback extension is missing; Internal
  // if HRTF was requested and could not be enabled.
  static StatusOr<std::unique_ptr<Spatializer>> Create(const SpatializerOptions& options);
  ~Spatializer();
  Spatializer(const Spatializer&) = delete;
  Spatializer& operator=(const Spatializer&) = delete;

  // "enabled: default-48000", "sofa: FILE (title)" or why not.
  const std::string& hrtf_status() const { return hrtf_status_; }

  // Adds a remote speaker, returns its id.
  StatusOr<int> AddSpeaker();
  // The local user's head in the local room.
  void SetListener(const protocol::HeadPose& head);
  // Where speaker `id` is (local room); applies distance and directivity gains.
  Status SetSpeaker(int id, const SpeakerPlacement& placement);
  // Queues mono samples at the device rate for speaker `id`; they play after
  // what is already queued.
  Status Push(int id, std::span<const float> mono);
  // Renders `frames` stereo frames (interleaved L, R). Sources that run dry go
  // silent and resume with the next Push.
  std::vector<float> Render(int frames);
  // Gain last applied to speaker `id` (distance × directivity).
  float SpeakerGain(int id) const;

 private:
  struct Impl;
  explicit Spatializer(std::unique_ptr<Impl> impl);
  void Reposition(int id);
  std::unique_ptr<Impl> impl_;
  std::string hrtf_status_;
};

}  // namespace holo::audio
