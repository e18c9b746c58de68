#include "audio/capture.h"

#include <AL/al.h>
#include <AL/alc.h>

#include <algorithm>
#include <cstdio>

#include "audio/wav.h"

namespace holo::audio {
namespace {

ALCdevice* Dev(void* p) { return static_cast<ALCdevice*>(p); }

std::string AlcErrorName(ALCenum e) {
  switch (e) {
    case ALC_NO_ERROR: return "no error code";
    case ALC_INVALID_DEVICE: return "ALC_INVALID_DEVICE";
    case ALC_INVALID_VALUE: return "ALC_INVALID_VALUE";
    case ALC_INVALID_ENUM: return "ALC_INVALID_ENUM";
    case ALC_OUT_OF_MEMORY: return "ALC_OUT_OF_MEMORY";
    default: return "ALC error " + std::to_string(e);
  }
}

// The capture device names OpenAL lists (a list of NUL-terminated strings).
std::string CaptureDeviceList() {
  const ALCchar* l = alcGetString(nullptr, ALC_CAPTURE_DEVICE_SPECIFIER);
  std::string out;
  for (const ALCchar* p = l; p != nullptr && *p != '\0'; p += std::char_traits<char>::length(p) + 1) {
    if (!out.empty()) out += ", ";
    out += std::string("'") + p + "'";
  }
  return out.empty() ? "none" : out;
}

}  // namespace

VoiceCapture::~VoiceCapture() {
  if (device_ != nullptr) {
    alcCaptureStop(Dev(device_));
    alcCaptureCloseDevice(Dev(device_));
  }
}

StatusOr<std::unique_ptr<VoiceCapture>> VoiceCapture::OpenDevice(const std::string& device, Clock& clock,
                                                                 PoseSource pose, int64_t timeout_ms) {
  if (!pose) return InvalidArgument("capture needs a pose source");
  if (timeout_ms <= 0) return InvalidArgument("device timeout must be > 0 ms");
  alcGetError(nullptr);
  // Half a second of ring buffer inside OpenAL.
  ALCdevice* dev = alcCaptureOpenDevice(device.empty() ? nullptr : device.c_str(), kSampleRate, AL_FORMAT_MONO16,
                                        kSampleRate / 2);
  if (dev == nullptr) {
    const ALCenum err = alcGetError(nullptr);
    return Unavailable("no microphone: OpenAL could not open capture device " +
                       (device.empty() ? std::string("(default)") : "'" + device + "'") + " at 48 kHz mono (" +
                       AlcErrorName(err) + "); capture devices listed: " + CaptureDeviceList());
  }
  std::unique_ptr<VoiceCapture> c(new VoiceCapture(clock, std::move(pose)));
  c->device_ = dev;
  c->timeout_us_ = timeout_ms * 1000;
  c->buf_.resize(kFrameSamples);
  const ALCchar* name = alcGetString(dev, ALC_CAPTURE_DEVICE_SPECIFIER);
  c->description_ = std::string("OpenAL capture device '") + (name != nullptr ? name : "?") + "'";
  alcCaptureStart(dev);
  if (alcGetError(dev) != ALC_NO_ERROR) return Unavailable(c->description_ + ": alcCaptureStart failed");
  return c;
}

StatusOr<std::unique_ptr<VoiceCapture>> VoiceCapture::OpenWav(const std::string& path, Clock& clock,
                                                              PoseSource pose) {
  if (!pose) return InvalidArgument("capture needs a pose source");
  HOLO_ASSIGN_OR_RETURN(WavAudio w, ReadWav(path));
  std::vector<float> mono(w.frames());
  for (size_t i = 0; i < mono.size(); ++i) {
    float acc = 0;
    for (int ch = 0; ch < w.channels; ++ch) acc += w.samples[i * static_cast<size_t>(w.channels) + ch];
    mono[i] = acc / static_cast<float>(w.channels);
  }
  HOLO_ASSIGN_OR_RETURN(std::vector<float> at48k, Resample(mono, w.sample_rate, kSampleRate));
  char desc[64];
  std::snprintf(desc, sizeof desc, " (%d Hz, %d ch -> 48 kHz mono)", w.sample_rate, w.channels);
  return FromSamples(std::move(at48k), clock, std::move(pose), "WAV '" + path + "'" + desc);
}

std::unique_ptr<VoiceCapture> VoiceCapture::FromSamples(std::vector<float> samples, Clock& clock, PoseSource pose,
                                                        std::string name) {
  std::unique_ptr<VoiceCapture> c(new VoiceCapture(clock, std::move(pose)));
  c->file_ = std::move(samples);
  c->start_us_ = clock.NowUs();
  c->description_ = std::move(name);
  return c;
}

StatusOr<std::unique_ptr<VoiceCapture>> VoiceCapture::Open(const CaptureOptions& options, Clock& clock,
                                                           PoseSource pose, std::string* note) {
  std::string why_not_device = "device capture not requested";
  if (options.use_device) {
    auto d = OpenDevice(options.device, clock, pose, options.device_timeout_ms);
    if (d.ok()) {
      if (note != nullptr) *note = "capturing from " + (*d)->description();
      return d;
    }
    why_not_device = d.status().message();
  }
  if (options.wav_path.empty()) {
    return Unavailable(why_not_device + "; and no WAV file given to fall back on (--audio-in FILE)");
  }
  auto f = OpenWav(options.wav_path, clock, std::move(pose));
  if (!f.ok()) return Status(f.status().code(), why_not_device + "; WAV fallback failed: " + f.status().message());
  if (note != nullptr) *note = why_not_device + "; capturing from " + (*f)->description() + " instead";
  return f;
}

size_t VoiceCapture::remaining_samples() const { return device_ != nullptr ? 0 : file_.size() - pos_; }

StatusOr<CapturedFrame> VoiceCapture::Next() {
  CapturedFrame f;
  f.samples.assign(kFrameSamples, 0.0f);
  if (device_ == nullptr) {
    if (pos_ >= file_.size()) return OutOfRange(description_ + ": end of audio");
    const size_t n = std::min<size_t>(kFrameSamples, file_.size() - pos_);
    std::copy_n(file_.begin() + static_cast<std::ptrdiff_t>(pos_), n, f.samples.begin());
    pos_ += n;
    f.capture_time_us = start_us_ + static_cast<int64_t>(sequence_) * kFrameUs;
    // The frame is complete once its last sample has been spoken.
    clock_.SleepUntilUs(f.capture_time_us + kFrameUs);
  } else {
    ALCdevice* dev = Dev(device_);
    const int64_t give_up = clock_.NowUs() + timeout_us_;
    ALCint avail = 0;
    for (;;) {
      alcGetIntegerv(dev, ALC_CAPTURE_SAMPLES, 1, &avail);
      if (alcGetError(dev) != ALC_NO_ERROR) return Unavailable(description_ + ": reading the capture level failed");
      if (avail >= kFrameSamples) break;
      if (clock_.NowUs() >= give_up) {
        return Unavailable(description_ + " delivered no 20 ms frame within " + std::to_string(timeout_us_ / 1000) +
                           " ms");
      }
      clock_.SleepUntilUs(clock_.NowUs() + 5000);
    }
    // The frame's first sample entered the device `avail` samples ago.
    f.capture_time_us = clock_.NowUs() - static_cast<int64_t>(avail) * 1000000 / kSampleRate;
    alcCaptureSamples(dev, buf_.data(), kFrameSamples);
    for (int i = 0; i < kFrameSamples; ++i) f.samples[i] = static_cast<float>(buf_[i]) / 32768.0f;
  }
  f.sequence = sequence_++;
  f.pose = pose_(f.capture_time_us);
  return f;
}

}  // namespace holo::audio
