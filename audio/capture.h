// Voice capture: 20 ms frames of 48 kHz mono, each tagged with the speaker's
// head pose at that moment, a sequence number and its capture time on an
// injected clock. From a microphone through OpenAL capture
// (alcCaptureOpenDevice) when a device exists, otherwise from a WAV file
// (resampled to 48 kHz mono with libsoxr).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "audio/voice_codec.h"
#include "common/clock.h"
#include "common/status.h"

namespace holo::audio {

struct CapturedFrame {
  std::vector<float> samples;    // kFrameSamples, 48 kHz mono, [-1, 1]
  uint32_t sequence = 0;         // 0, 1, 2, ... per capture
  int64_t capture_time_us = 0;   // when the frame's first sample was spoken (capture clock)
  HeadPose pose;                 // speaker's head at capture_time_us, their room's frame
};

// The speaker's head pose (their room's frame) at time `t_us` of the capture
// clock. Called once per frame, from the thread that calls Next().
using PoseSource = std::function<HeadPose(int64_t t_us)>;

struct CaptureOptions {
  // Try a microphone first (OpenAL capture); `device` names it, empty = default.
  bool use_device = true;
  std::string device;
  // WAV file used when no device opens (or use_device is false).
  std::string wav_path;
  // The device must deliver 20 ms within this time or Next() fails.
  int64_t device_timeout_ms = 1000;
};

class VoiceCapture {
 public:
  // Opens an OpenAL capture device at 48 kHz mono s16. Unavailable with the
  // reason (no device, OpenAL error) if none opens.
  static StatusOr<std::unique_ptr<VoiceCapture>> OpenDevice(const std::string& device, Clock& clock,
                                                            PoseSource pose, int64_t timeout_ms = 1000);
  // Reads a WAV file (any rate, channels mixed to mono) and plays it out in
  // capture time: frame k is captured at open time + k·20 ms.
  static StatusOr<std::unique_ptr<VoiceCapture>> OpenWav(const std::string& path, Clock& clock, PoseSource pose);
  // As OpenWav, from samples already at 48 kHz mono (benches, tests).
  static std::unique_ptr<VoiceCapture> FromSamples(std::vector<float> samples, Clock& clock, PoseSource pose,
                                                   std::string name = "samples");
  // A device if `options.use_device` and one opens, else the WAV file. `*note`
  // (if given) tells which source was chosen and why the device was not.
  // Fails if neither source works, naming both reasons.
  static StatusOr<std::unique_ptr<VoiceCapture>> Open(const CaptureOptions& options, Clock& clock, PoseSource pose,
                                                      std::string* note = nullptr);

  ~VoiceCapture();
  VoiceCapture(const VoiceCapture&) = delete;
  VoiceCapture& operator=(const VoiceCapture&) = delete;

  // Waits on the clock until the next 20 ms are complete (a simulated clock
  // jumps there) and returns them. OutOfRange at the end of a file (the last
  // partial frame is padded with zeros); Unavailable if a device stops
  // delivering.
  StatusOr<CapturedFrame> Next();
  // "OpenAL capture device 'X'" or "WAV 'path' (22050 Hz, 1 ch -> 48 kHz mono)".
  const std::string& description() const { return description_; }
  bool is_device() const { return device_ != nullptr; }
  // Samples left in a file source (0 for a device).
  size_t remaining_samples() const;

 private:
  VoiceCapture(Clock& clock, PoseSource pose) : clock_(clock), pose_(std::move(pose)) {}
  Clock& clock_;
  PoseSource pose_;
  std::string description_;
  uint32_t sequence_ = 0;
  // File source.
  std::vector<float> file_;
  size_t pos_ = 0;
  int64_t start_us_ = 0;
  // Device source (ALCdevice*, opaque here).
  void* device_ = nullptr;
  int64_t timeout_us_ = 1000000;
  std::vector<int16_t> buf_;
};

}  // namespace holo::audio
