#include "audio/spatializer.h"

#include <AL/al.h>
#include <AL/alc.h>
#include <AL/alext.h>
#include <AL/efx.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <map>

#include "audio/sofa_hrtf.h"

namespace holo::audio {

Status SpatializerOptions::Check() const {
  if (sample_rate < 8000 || sample_rate > 192000) {
    return InvalidArgument("sample_rate must be in 8000..192000, got " + std::to_string(sample_rate));
  }
  if (!(ref_distance_m > 0.0f)) return InvalidArgument("ref_distance_m must be > 0, got " + std::to_string(ref_distance_m));
  if (!(directivity_floor >= 0.0f && directivity_floor <= 1.0f)) {
    return InvalidArgument("directivity_floor must be in 0..1, got " + std::to_string(directivity_floor));
  }
  if (!(directivity_hf_exponent >= 0.0f)) {
    return InvalidArgument("directivity_hf_exponent must be >= 0, got " + std::to_string(directivity_hf_exponent));
  }
  return OkStatus();
}

float DistanceGain(const SpatializerOptions& o, float distance_m) {
  return o.ref_distance_m / std::max(distance_m, o.ref_distance_m);
}

float DirectivityGain(const SpatializerOptions& o, const SpeakerPlacement& s, const Eigen::Vector3f& listener) {
  const Eigen::Vector3f d = listener - s.position;
  const float n = d.norm();
  if (n < 1e-6f) return 1.0f;
  const float cos_theta = std::clamp(s.facing.normalized().dot(d / n), -1.0f, 1.0f);
  return o.directivity_floor + (1.0f - o.directivity_floor) * 0.5f * (1.0f + cos_theta);
}

struct Spatializer::Impl {
  SpatializerOptions options;
  ALCdevice* device = nullptr;
  ALCcontext* context = nullptr;
  LPALCRENDERSAMPLESSOFT render = nullptr;
  bool efx = false;
  LPALGENFILTERS gen_filters = nullptr;
  LPALDELETEFILTERS delete_filters = nullptr;
  LPALFILTERI filteri = nullptr;
  LPALFILTERF filterf = nullptr;
  protocol::HeadPose listener;
  std::unique_ptr<SofaHrtf> sofa;  // set: the SOFA path (no OpenAL device)
  struct Speaker {
    ALuint source = 0;
    ALuint filter = 0;
    SpeakerPlacement placement;
    float gain = 1.0f;
    // SOFA path: queued samples, direction in the head frame, convolver.
    std::deque<float> queue;
    Eigen::Vector3f head_dir = Eigen::Vector3f::UnitX();
    std::unique_ptr<HrtfConvolver> conv;
  };
  std::map<int, Speaker> speakers;
  int next_id = 0;

  void MakeCurrent() const { alcMakeContextCurrent(context); }
  void Unqueue(ALuint source) const {
    ALint processed = 0;
    alGetSourcei(source, AL_BUFFERS_PROCESSED, &processed);
    while (processed-- > 0) {
      ALuint b = 0;
      alSourceUnqueueBuffers(source, 1, &b);
      alDeleteBuffers(1, &b);
    }
  }
};

Spatializer::Spatializer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Spatializer::~Spatializer() {
  if (!impl_) return;
  if (impl_->context != nullptr) {
    impl_->MakeCurrent();
    for (auto& [id, s] : impl_->speakers) {
      alSourceStop(s.source);
      alSourcei(s.source, AL_BUFFER, 0);
      impl_->Unqueue(s.source);
      alDeleteSources(1, &s.source);
      if (s.filter != 0 && impl_->delete_filters != nullptr) impl_->delete_filters(1, &s.filter);
    }
    alcMakeContextCurrent(nullptr);
    alcDestroyContext(impl_->context);
  }
  if (impl_->device != nullptr) alcCloseDevice(impl_->device);
}

StatusOr<std::unique_ptr<Spatializer>> Spatializer::Create(const SpatializerOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  if (!options.sofa_path.empty()) {
    HOLO_ASSIGN_OR_RETURN(auto sofa, SofaHrtf::Open(options.sofa_path, options.sample_rate));
    auto impl = std::make_unique<Impl>();
    impl->options = options;
    const std::string title = sofa->description();
    impl->sofa = std::move(sofa);
    std::unique_ptr<Spatializer> sp(new Spatializer(std::move(impl)));
    sp->hrtf_status_ = "sofa: " + options.sofa_path + (title.empty() ? "" : " (" + title + ")");
    return sp;
  }
  if (alcIsExtensionPresent(nullptr, "ALC_SOFT_loopback") != ALC_TRUE) {
    return Unavailable("OpenAL has no ALC_SOFT_loopback extension (OpenAL Soft needed)");
  }
  auto open = reinterpret_cast<LPALCLOOPBACKOPENDEVICESOFT>(alcGetProcAddress(nullptr, "alcLoopbackOpenDeviceSOFT"));
  auto supported = reinterpret_cast<LPALCISRENDERFORMATSUPPORTEDSOFT>(
      alcGetProcAddress(nullptr, "alcIsRenderFormatSupportedSOFT"));
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->render = reinterpret_cast<LPALCRENDERSAMPLESSOFT>(alcGetProcAddress(nullptr, "alcRenderSamplesSOFT"));
  if (open == nullptr || supported == nullptr || impl->render == nullptr) {
    return Unavailable("ALC_SOFT_loopback functions not found");
  }
  impl->device = open(nullptr);
  if (impl->device == nullptr) return Unavailable("alcLoopbackOpenDeviceSOFT failed");
  std::unique_ptr<Spatializer> sp(new Spatializer(std::move(impl)));
  Impl& m = *sp->impl_;
  if (supported(m.device, options.sample_rate, ALC_STEREO_SOFT, ALC_FLOAT_SOFT) != ALC_TRUE) {
    return Unavailable("loopback device cannot render stereo float at " + std::to_string(options.sample_rate) + " Hz");
  }
  const ALCint attrs[] = {ALC_FORMAT_CHANNELS_SOFT, ALC_STEREO_SOFT,        ALC_FORMAT_TYPE_SOFT, ALC_FLOAT_SOFT,
                          ALC_FREQUENCY,            options.sample_rate,    ALC_HRTF_SOFT,
                          options.hrtf ? ALC_TRUE : ALC_FALSE,              0};
  m.context = alcCreateContext(m.device, attrs);
  if (m.context == nullptr) return Internal("alcCreateContext on the loopback device failed");
  m.MakeCurrent();
  ALCint hrtf = 0;
  alcGetIntegerv(m.device, ALC_HRTF_SOFT, 1, &hrtf);
  ALCint hrtf_status = 0;
  alcGetIntegerv(m.device, ALC_HRTF_STATUS_SOFT, 1, &hrtf_status);
  if (hrtf == ALC_TRUE) {
    const ALCchar* name = alcGetString(m.device, ALC_HRTF_SPECIFIER_SOFT);
    sp->hrtf_status_ = std::string("enabled: ") + (name != nullptr ? name : "?");
  } else {
    sp->hrtf_status_ = "disabled (status " + std::to_string(hrtf_status) + ")";
    if (options.hrtf) return Internal("HRTF requested but OpenAL Soft reports " + sp->hrtf_status_);
  }
  // Gains are computed here (distance and directivity), so OpenAL's own
  // distance model is off; sources sit in the listener's head frame.
  alDistanceModel(AL_NONE);
  alListener3f(AL_POSITION, 0, 0, 0);
  const ALfloat orient[] = {0, 0, -1, 0, 1, 0};
  alListenerfv(AL_ORIENTATION, orient);
  if (alcIsExtensionPresent(m.device, "ALC_EXT_EFX") == ALC_TRUE) {
    m.gen_filters = reinterpret_cast<LPALGENFILTERS>(alGetProcAddress("alGenFilters"));
    m.delete_filters = reinterpret_cast<LPALDELETEFILTERS>(alGetProcAddress("alDeleteFilters"));
    m.filteri = reinterpret_cast<LPALFILTERI>(alGetProcAddress("alFilteri"));
    m.filterf = reinterpret_cast<LPALFILTERF>(alGetProcAddress("alFilterf"));
    m.efx = m.gen_filters != nullptr && m.delete_filters != nullptr && m.filteri != nullptr && m.filterf != nullptr;
  }
  if (alGetError() != AL_NO_ERROR) return Internal("OpenAL error while setting up the listener");
  return sp;
}

StatusOr<int> Spatializer::AddSpeaker() {
  Impl& m = *impl_;
  Impl::Speaker s;
  if (m.sofa) {
    s.conv = std::make_unique<HrtfConvolver>(*m.sofa);
    const int id = m.next_id++;
    m.speakers[id] = std::move(s);
    Reposition(id);
    return id;
  }
  m.MakeCurrent();
  alGetError();
  alGenSources(1, &s.source);
  if (alGetError() != AL_NO_ERROR) return Internal("alGenSources failed");
  alSourcei(s.source, AL_SOURCE_RELATIVE, AL_FALSE);
  if (m.efx) {
    m.gen_filters(1, &s.filter);
    m.filteri(s.filter, AL_FILTER_TYPE, AL_FILTER_LOWPASS);
  }
  const int id = m.next_id++;
  m.speakers[id] = std::move(s);
  Reposition(id);
  return id;
}

void Spatializer::SetListener(const protocol::HeadPose& head) {
  impl_->listener = head;
  for (auto& [id, s] : impl_->speakers) Reposition(id);
}

Status Spatializer::SetSpeaker(int id, const SpeakerPlacement& placement) {
  auto it = impl_->speakers.find(id);
  if (it == impl_->speakers.end()) return NotFound("no speaker " + std::to_string(id));
  it->second.placement = placement;
  Reposition(id);
  return OkStatus();
}

void Spatializer::Reposition(int id) {
  Impl& m = *impl_;
  Impl::Speaker& s = m.speakers.at(id);
  const Eigen::Isometry3f room_from_head = HeadToRoom(m.listener);
  const Eigen::Vector3f h = room_from_head.inverse() * s.placement.position;  // x fwd, y left, z up
  if (m.sofa) {
    if (h.norm() > 1e-6f) s.head_dir = h.normalized();
    s.gain = DistanceGain(m.options, h.norm()) * DirectivityGain(m.options, s.placement, room_from_head.translation());
    return;
  }
  m.MakeCurrent();
  // OpenAL: x right, y up, −z ahead.
  alSource3f(s.source, AL_POSITION, -h.y(), h.z(), -h.x());
  const float dist_gain = DistanceGain(m.options, h.norm());
  const float dir_gain = DirectivityGain(m.options, s.placement, room_from_head.translation());
  s.gain = dist_gain * dir_gain;
  alSourcef(s.source, AL_GAIN, s.gain);
  if (m.efx) {
    m.filterf(s.filter, AL_LOWPASS_GAIN, 1.0f);
    m.filterf(s.filter, AL_LOWPASS_GAINHF,
              std::clamp(std::pow(dir_gain, m.options.directivity_hf_exponent), 0.0f, 1.0f));
    alSourcei(s.source, AL_DIRECT_FILTER, static_cast<ALint>(s.filter));
  }
}

float Spatializer::SpeakerGain(int id) const {
  auto it = impl_->speakers.find(id);
  return it == impl_->speakers.end() ? 0.0f : it->second.gain;
}

Status Spatializer::Push(int id, std::span<const float> mono) {
  Impl& m = *impl_;
  auto it = m.speakers.find(id);
  if (it == m.speakers.end()) return NotFound("no speaker " + std::to_string(id));
  if (mono.empty()) return OkStatus();
  if (m.sofa) {
    it->second.queue.insert(it->second.queue.end(), mono.begin(), mono.end());
    return OkStatus();
  }
  m.MakeCurrent();
  m.Unqueue(it->second.source);
  alGetError();
  ALuint b = 0;
  alGenBuffers(1, &b);
  alBufferData(b, AL_FORMAT_MONO_FLOAT32, mono.data(), static_cast<ALsizei>(mono.size() * sizeof(float)),
               m.options.sample_rate);
  alSourceQueueBuffers(it->second.source, 1, &b);
  if (alGetError() != AL_NO_ERROR) return Internal("queueing a buffer on speaker " + std::to_string(id) + " failed");
  return OkStatus();
}

std::vector<float> Spatializer::Render(int frames) {
  Impl& m = *impl_;
  if (m.sofa) {
    const size_t n = static_cast<size_t>(std::max(frames, 0));
    std::vector<float> out(2 * n, 0.0f), x(n);
    for (auto& [id, s] : m.speakers) {
      // A source that runs dry plays silence, as an OpenAL source would.
      const size_t have = std::min(n, s.queue.size());
      std::copy(s.queue.begin(), s.queue.begin() + static_cast<std::ptrdiff_t>(have), x.begin());
      std::fill(x.begin() + static_cast<std::ptrdiff_t>(have), x.end(), 0.0f);
      s.queue.erase(s.queue.begin(), s.queue.begin() + static_cast<std::ptrdiff_t>(have));
      if (n > 0) s.conv->Process(x, s.head_dir, s.gain, out);
    }
    return out;
  }
  m.MakeCurrent();
  for (auto& [id, s] : m.speakers) {
    m.Unqueue(s.source);
    ALint state = 0, queued = 0;
    alGetSourcei(s.source, AL_SOURCE_STATE, &state);
    alGetSourcei(s.source, AL_BUFFERS_QUEUED, &queued);
    if (state != AL_PLAYING && queued > 0) alSourcePlay(s.source);
  }
  std::vector<float> out(static_cast<size_t>(std::max(frames, 0)) * 2, 0.0f);
  if (frames > 0) m.render(m.device, out.data(), frames);
  return out;
}

}  // namespace holo::audio
