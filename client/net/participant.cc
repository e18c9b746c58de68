#include "client/net/participant.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include "audio/jitter_buffer.h"
#include "audio/room.h"
#include "audio/echo_canceller.h"
#include "audio/spatializer.h"
#include "audio/voice_codec.h"
#include "audio/wav.h"
#include "common/quantile.h"
#include "common/recent.h"

namespace holo::net {
namespace {

// Medians over the newest 3000–6000 samples (1–2 minutes of 20 ms frames):
// the recent past, memory and the cost of a median bounded however long the
// call lasts.
constexpr size_t kRecentSamples = 3000;

}  // namespace

protocol::HeadPose SyntheticHead(double t_s, float distance_m, float phase) {
  const auto t = static_cast<float>(t_s);
  constexpr float kPi = 3.14159265f;
  protocol::HeadPose p;
  p.x = distance_m;
  p.y = 0.15f * std::sin(2 * kPi * t / 9.0f + phase);
  p.z = 1.6f;
  p.yaw = kPi + 12.0f * kPi / 180.0f * std::sin(2 * kPi * t / 7.0f + 0.5f + phase);
  p.pitch = -8.0f * kPi / 180.0f;
  p.roll = 0;
  return p;
}

bool ParseSiteAddress(const std::string& spec, std::string* host, uint16_t* port) {
  const size_t c = spec.rfind(':');
  if (c == std::string::npos || c == 0 || c + 1 >= spec.size()) return false;
  char* end = nullptr;
  const long p = std::strtol(spec.c_str() + c + 1, &end, 10);
  if (end == nullptr || *end != '\0' || p < 1 || p > 65535) return false;
  *host = spec.substr(0, c);
  *port = static_cast<uint16_t>(p);
  return true;
}

struct Participant::Impl {
  ParticipantOptions o;
  // Wall clock, so capture times compare across processes and with the
  // site's clock offset estimate.
  WallClock clock;
  std::unique_ptr<audio::AvSync> sync;
  int64_t start_us = 0;
  std::unique_ptr<SiteClient> viewer, talker;
  std::unique_ptr<audio::VoiceEncoder> encoder;
  std::vector<float> voice;  // own voice, 48 kHz mono (WAV), empty: tone
  std::unique_ptr<audio::Spatializer> spatializer;
  // The voice thread captures, the audio thread plays: the canceller is shared.
  std::mutex aec_mu;
  std::unique_ptr<audio::EchoCanceller> aec;
  std::thread voice_thread, audio_thread;
  std::atomic<bool> stop{false};
  bool stopped = false;
  Status stop_status;

  mutable std::mutex mu;  // guards everything below
  ParticipantStats stats;
  // The newest samples only (a call lasts hours; stats() sorts a copy).
  std::vector<double> network_ms, jb_ms;
  std::vector<float> output;  // interleaved stereo
  double sum_sq = 0;
  size_t rendered = 0;  // interleaved samples rendered

  protocol::HeadPose Head(int64_t t_us) const {
    if (o.head) return o.head(t_us);
    return SyntheticHead((t_us - start_us) / 1e6);
  }

  void VoiceLoop() {
    uint32_t seq = 0;
    size_t pos = 0;
    int64_t next_us = clock.NowUs();
    std::vector<float> frame(audio::kFrameSamples);
    while (!stop) {
      clock.SleepUntilUs(next_us + audio::kFrameUs);  // the frame is complete 20 ms after its first sample
      if (stop) break;
      if (voice.empty()) {
        for (int i = 0; i < audio::kFrameSamples; ++i) {
          frame[i] = 0.1f * static_cast<float>(std::sin(2 * M_PI * 440 * (seq * 960.0 + i) / audio::kSampleRate));
        }
      } else {
        for (int i = 0; i < audio::kFrameSamples; ++i) {
          frame[i] = voice[pos];
          pos = (pos + 1) % voice.size();
        }
      }
      if (aec) {
        std::lock_guard<std::mutex> l(aec_mu);
        frame = aec->ProcessCapture(frame);
        std::lock_guard<std::mutex> l2(mu);
        stats.aec_delay_ms = aec->estimated_delay_ms();
      }
      // Capture time on the local site's clock (the clock its pictures are
      // stamped with), so that viewers can line this voice up with them.
      auto a = encoder->EncodeFrame(frame, seq, next_us + talker->stats().clock_offset_us, Head(next_us));
      if (a.ok()) {
        talker->SendAudioPose(*a);
        std::lock_guard<std::mutex> l(mu);
        ++stats.voice_frames_sent;
      }
      ++seq;
      next_us += audio::kFrameUs;
      // After a stall (loaded machine) no burst of stale frames.
      audio::SkipStalledFrames(clock.NowUs(), 200000, &next_us, &seq);
    }
  }

  void AudioLoop() {
    RemoteVoices voices(clock, o.voice, sync.get());
    std::map<uint32_t, int> spatial_ids;  // stream → spatializer speaker
    int64_t next_us = clock.NowUs();
    const bool render = spatializer != nullptr;
    while (!stop) {
      clock.SleepUntilUs(next_us + audio::kFrameUs);
      if (stop) break;
      next_us += audio::kFrameUs;
      // Arrivals.
      protocol::AudioPose a;
      uint32_t sid = 0;
      while (viewer->PollAudio(&a, &sid)) {
        const double net_ms = (clock.NowUs() - a.capture_time_us) / 1000.0;
        voices.Insert(sid, std::move(a));
        std::lock_guard<std::mutex> l(mu);
        ++stats.remote_audio_frames;
        AppendRecent(&network_ms, net_ms, kRecentSamples);
      }
      // One 20 ms block: listener = own head, each speaker at its head pose through the room link.
      const std::vector<RemoteVoices::Block> blocks = voices.Pull();
      const protocol::HeadPose me = Head(clock.NowUs());
      if (render) spatializer->SetListener(me);
      for (const RemoteVoices::Block& b : blocks) {
        if (b.new_speaker && render) {
          auto id = spatializer->AddSpeaker();
          if (id.ok()) {
            spatial_ids[b.stream] = *id;
            const std::vector<float> silence(audio::kFrameSamples, 0.0f);
            (void)spatializer->Push(*id, silence);  // one block of lead: the source never runs dry
          }
        }
        const auto sp = spatial_ids.find(b.stream);
        const int id = sp == spatial_ids.end() ? -1 : sp->second;
        if (b.playing) {
          const audio::SpeakerPlacement place = audio::PlaceRemoteSpeaker(b.pose, o.call.room);
          std::lock_guard<std::mutex> l(mu);
          AppendRecent(&jb_ms, b.buffer_delay_ms, kRecentSamples);
          stats.remote_x = place.position.x();
          stats.remote_y = place.position.y();
          stats.remote_z = place.position.z();
          stats.remote_azimuth_deg = audio::AzimuthDeg(me, place.position);
          if (render && id >= 0) (void)spatializer->SetSpeaker(id, place);
        }
        if (render && id >= 0) (void)spatializer->Push(id, b.pcm);
      }
      if (render) {
        std::vector<float> block = spatializer->Render(audio::kFrameSamples);
        if (aec) {
          std::lock_guard<std::mutex> l(aec_mu);
          aec->PushPlayed(block);
        }
        std::lock_guard<std::mutex> l(mu);
        for (float v : block) sum_sq += static_cast<double>(v) * v;
        rendered += block.size();
        if (!o.audio_out.empty()) output.insert(output.end(), block.begin(), block.end());
      }
      {
        const RemoteVoicesStats vs = voices.stats();
        std::lock_guard<std::mutex> l(mu);
        stats.remote_speakers = vs.speakers;
        stats.concealed = vs.concealed;
        stats.late = vs.late;
        stats.underflows = vs.underflows;
      }
      // Far behind (the machine stalled): skip ahead rather than render a burst.
      if (clock.NowUs() - next_us > 500000) next_us = clock.NowUs();
    }
  }
};

Participant::Participant(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Participant::~Participant() { (void)Stop(); }

StatusOr<std::unique_ptr<Participant>> Participant::Start(ParticipantOptions options,
                                                          ClientCallbacks view_callbacks) {
  auto impl = std::make_unique<Impl>();
  impl->o = std::move(options);
  Impl& m = *impl;
  m.start_us = m.clock.NowUs();
  const CallConfig& call = m.o.call;
  HOLO_RETURN_IF_ERROR(m.o.av_sync.Check());
  HOLO_RETURN_IF_ERROR(m.o.voice.Check());
  m.sync = std::make_unique<audio::AvSync>(m.o.av_sync);
  if (!m.o.audio_in.empty()) {
    auto r = audio::ReadMonoWav(m.o.audio_in, audio::kSampleRate);
    if (!r.ok()) return r.status().WithContext("--audio-in " + m.o.audio_in);
    m.voice = std::move(*r);
    if (m.voice.empty()) return InvalidArgument("--audio-in " + m.o.audio_in + ": no samples");
    // Half a second of silence between repetitions.
    m.voice.resize(m.voice.size() + audio::kSampleRate / 2, 0.0f);
  }
  // The echo canceller needs what was played: --aec renders even without --audio-out.
  if (!m.o.audio_out.empty() || m.o.aec) {
    audio::SpatializerOptions so;
    so.hrtf = m.o.hrtf;
    so.sofa_path = m.o.hrtf_sofa;
    HOLO_ASSIGN_OR_RETURN(m.spatializer, audio::Spatializer::Create(so));
    m.stats.hrtf_status = m.spatializer->hrtf_status();
  }
  if (m.o.aec) {
    audio::EchoCancellerOptions eo;
    eo.filter_ms = m.o.aec_filter_ms;
    HOLO_ASSIGN_OR_RETURN(m.aec, audio::EchoCanceller::Create(eo));
  }

  ClientOptions view = m.o.view_template;
  view.host = call.remote.host;
  view.port = call.remote.port;
  view.role = protocol::Role::kViewer;
  view.token = call.remote.viewer_token;
  view.name = m.o.name + "-view";
  view.tls.enabled = call.tls;
  view.tls.ca_file = call.tls_ca_file;
  HOLO_ASSIGN_OR_RETURN(m.viewer, SiteClient::Start(view, std::move(view_callbacks)));

  if (m.o.send_voice) {
    ClientOptions pub = m.o.view_template;
    pub.host = call.local.host;
    pub.port = call.local.port;
    pub.role = protocol::Role::kPublisher;
    pub.token = call.local.publisher_token;
    pub.name = m.o.name + "-voice";
    pub.decode = false;
    pub.subscribe = 0;
    pub.tls.enabled = call.tls;
    pub.tls.ca_file = call.tls_ca_file;
    HOLO_ASSIGN_OR_RETURN(m.talker, SiteClient::Start(pub));
    // Lean frames; SiteClient sends them in the classic layout to a site that has only that.
    HOLO_ASSIGN_OR_RETURN(m.encoder, audio::VoiceEncoder::Create(audio::LeanVoiceEncoderOptions()));
    m.voice_thread = std::thread([&m] { m.VoiceLoop(); });
  }
  m.audio_thread = std::thread([&m] { m.AudioLoop(); });
  return std::unique_ptr<Participant>(new Participant(std::move(impl)));
}

SiteClient& Participant::viewer() { return *impl_->viewer; }
audio::AvSync& Participant::av_sync() { return *impl_->sync; }
protocol::HeadPose Participant::OwnHead() const { return impl_->Head(impl_->clock.NowUs()); }
const CallConfig& Participant::call() const { return impl_->o.call; }

ParticipantStats Participant::stats() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  ParticipantStats s = impl_->stats;
  s.audio_network_ms_median = Quantile(impl_->network_ms, 0.5);
  s.jitter_buffer_ms_median = Quantile(impl_->jb_ms, 0.5);
  s.audio_delay_ms = s.remote_audio_frames > 0
                         ? s.audio_network_ms_median + s.jitter_buffer_ms_median + audio::kFrameUs / 1000.0
                         : 0;
  const size_t n = impl_->rendered;  // samples rendered (kept in `output` only with --audio-out)
  s.output_seconds = static_cast<double>(n / 2) / audio::kSampleRate;
  s.output_rms = n ? std::sqrt(impl_->sum_sq / static_cast<double>(n)) : 0;
  return s;
}

Status Participant::Stop() {
  Impl& m = *impl_;
  if (m.stopped) return m.stop_status;
  m.stopped = true;
  m.stop = true;
  if (m.voice_thread.joinable()) m.voice_thread.join();
  if (m.audio_thread.joinable()) m.audio_thread.join();
  if (m.viewer) m.viewer->Stop();
  if (m.talker) m.talker->Stop();
  if (!m.o.audio_out.empty()) {
    std::lock_guard<std::mutex> l(m.mu);
    m.stop_status = audio::WriteWav(m.o.audio_out, m.output, 2, audio::kSampleRate);
  }
  return m.stop_status;
}

}  // namespace holo::net
