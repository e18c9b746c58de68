#include "server/voice/site_voice.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <spdlog/spdlog.h>

#include "audio/capture.h"
#include "audio/synthetic_voice.h"
#include "audio/wav.h"
#include "common/clock.h"
#include "studio/studio.h"

namespace holo::voice {
namespace {

// A person standing at the room's centre, facing +x (no studio to ask).
protocol::HeadPose DefaultHead() {
  protocol::HeadPose p;
  p.z = 1.6f;
  return p;
}


// Two sound events of one kind closer than this (studio time crossing an
// event twice where a looped capture turns round) sound once, µs.
constexpr int64_t kRefractoryUs = 150000;

}  // namespace

protocol::HeadPose HeadPoseFromTransform(const Eigen::Isometry3f& world_from_head) {
  // room_from_head = Rz(yaw) · Ry(−pitch) · Rx(roll): row 2 is
  // [sin(pitch), cos(pitch) sin(roll), cos(pitch) cos(roll)].
  const Eigen::Matrix3f r = world_from_head.linear();
  protocol::HeadPose p;
  p.x = world_from_head.translation().x();
  p.y = world_from_head.translation().y();
  p.z = world_from_head.translation().z();
  p.pitch = std::asin(std::clamp(r(2, 0), -1.0f, 1.0f));
  p.roll = std::atan2(r(2, 1), r(2, 2));
  p.yaw = std::atan2(r(1, 0), r(0, 0));
  return p;
}

struct SiteVoice::Impl {
  SiteVoiceOptions o;
  const SyntheticStudio* studio = nullptr;
  StudioTimeFn studio_time;
  PublishFn publish;
  std::unique_ptr<audio::VoiceEncoder> encoder;
  std::unique_ptr<audio::SyntheticVoice> synthetic;
  std::vector<float> wav;  // looped
  size_t wav_pos = 0;
  std::unique_ptr<audio::VoiceCapture> mic;
  std::thread thread;
  std::atomic<bool> stop{false};
  mutable std::mutex mu;
  SiteVoiceStats stats;
  int64_t last_onset_us[2] = {std::numeric_limits<int64_t>::min() / 2, std::numeric_limits<int64_t>::min() / 2};

  double StudioTime(int64_t t_us) const {
    return studio_time ? studio_time(t_us) : std::numeric_limits<double>::quiet_NaN();
  }

  protocol::HeadPose Head(int64_t t_us) const {
    if (studio == nullptr) return DefaultHead();
    const double s = StudioTime(t_us);
    if (std::isnan(s)) return DefaultHead();
    return HeadPoseFromTransform(studio->HeadPose(s));
  }

  // Starts the syllables and knocks whose studio time the cameras pass
  // between `t0_us` and `t0_us` + 20 ms, at the sample where they pass it.
  void ScheduleOnsets(int64_t t0_us) {
    constexpr int kSteps = 4;  // 5 ms steps: a looped capture may turn round inside a frame
    const int64_t step_us = audio::kFrameUs / kSteps;
    double sa = StudioTime(t0_us);
    for (int k = 0; k < kSteps; ++k) {
      const int64_t ta = t0_us + k * step_us;
      const double sb = StudioTime(ta + step_us);
      // A jump (a loop starting over) is no motion: nothing sounds.
      if (!std::isnan(sa) && !std::isnan(sb) && sa != sb && std::abs(sb - sa) < 0.1) {
        for (const StudioSoundEvent& e : studio->SoundEvents(std::min(sa, sb), std::max(sa, sb))) {
          const double f = (e.time_s - sa) / (sb - sa);
          const int64_t at_us = ta + static_cast<int64_t>(std::llround(f * static_cast<double>(step_us)));
          int64_t& last = last_onset_us[e.kind == StudioSoundEvent::kBounce ? 1 : 0];
          if (at_us - last < kRefractoryUs) continue;
          last = at_us;
          const int64_t offset = (at_us - t0_us) * audio::kSampleRate / 1000000;
          synthetic->Start(e.kind == StudioSoundEvent::kBounce ? audio::SyntheticVoice::Sound::kKnock
                                                                : audio::SyntheticVoice::Sound::kSyllable,
                           std::clamp<int64_t>(offset, 0, audio::kFrameSamples - 1));
          std::lock_guard<std::mutex> l(mu);
          ++stats.onsets;
        }
      }
      sa = sb;
    }
  }

  // Pipeline clock (steady) → wall clock. The offset between the two is
  // kept while it stays within 1 ms, so consecutive frames are exactly
  // 20 ms apart on the wire; a step of the system time is followed.
  int64_t wall_minus_steady = 0;
  bool have_offset = false;
  int64_t ToWallUs(int64_t steady_us) {
    const int64_t offset = WallClock::Instance().NowUs() - RealClock::Instance().NowUs();
    if (!have_offset || std::abs(offset - wall_minus_steady) > 1000) {
      wall_minus_steady = offset;
      have_offset = true;
    }
    return steady_us + wall_minus_steady;
  }

  void Send(const std::vector<float>& pcm, uint32_t seq, int64_t capture_steady_us) {
    auto a = encoder->EncodeFrame(pcm, seq, ToWallUs(capture_steady_us), Head(capture_steady_us));
    if (!a.ok()) return;
    publish(*a);
    const double cpu = ThreadCpuTimeMs();
    std::lock_guard<std::mutex> l(mu);
    ++stats.frames;
    stats.cpu_ms = cpu;
  }

  void Loop() {
    Clock& clock = RealClock::Instance();
    uint32_t seq = 0;
    std::vector<float> pcm(audio::kFrameSamples);
    if (mic) {
      while (!stop) {
        auto f = mic->Next();
        if (!f.ok()) {
          spdlog::error("voice: {}; the site's voice stops", f.status().ToString());
          return;
        }
        if (studio_time && std::isnan(StudioTime(f->capture_time_us))) continue;  // not capturing yet
        Send(f->samples, seq++, f->capture_time_us);
      }
      return;
    }
    int64_t t0 = clock.NowUs();
    while (!stop) {
      // The frame [t0, t0 + 20 ms) is complete at its end.
      clock.SleepUntilUs(t0 + audio::kFrameUs);
      if (stop) break;
      if (clock.NowUs() - (t0 + audio::kFrameUs) > audio::kFrameUs) {
        std::lock_guard<std::mutex> l(mu);
        ++stats.late_frames;
      }
      if (studio_time && std::isnan(StudioTime(t0))) {
        t0 += audio::kFrameUs;
        continue;  // the site is not capturing yet
      }
      if (synthetic) {
        ScheduleOnsets(t0);
        synthetic->Render(pcm);
      } else {
        for (float& v : pcm) {
          v = wav[wav_pos];
          wav_pos = (wav_pos + 1) % wav.size();
        }
      }
      Send(pcm, seq++, t0);
      t0 += audio::kFrameUs;
      // After a long stall (a loaded machine) carry on from now, not with a
      // burst of old frames.
      if (const int64_t skipped = audio::SkipStalledFrames(clock.NowUs(), 500000, &t0, &seq); skipped > 0) {
        std::lock_guard<std::mutex> l(mu);
        stats.late_frames += skipped;
      }
    }
  }
};

SiteVoice::SiteVoice(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SiteVoice::~SiteVoice() { Stop(); }

StatusOr<std::unique_ptr<SiteVoice>> SiteVoice::Start(const SiteVoiceOptions& options, const SyntheticStudio* studio,
                                                      StudioTimeFn studio_time, PublishFn publish) {
  if (!publish) return InvalidArgument("site voice: nothing to publish to");
  auto impl = std::make_unique<Impl>();
  Impl& m = *impl;
  m.o = options;
  m.studio = studio;
  m.studio_time = std::move(studio_time);
  m.publish = std::move(publish);
  HOLO_ASSIGN_OR_RETURN(m.encoder, audio::VoiceEncoder::Create(options.encoder));
  const std::string& src = options.source;
  if (src == "synthetic") {
    if (studio == nullptr || !m.studio_time)
      return InvalidArgument("--voice synthetic needs the synthetic studio as the source (its person's motion "
                             "places the syllables)");
    m.synthetic = std::make_unique<audio::SyntheticVoice>(options.seed);
    m.stats.description = "synthetic (syllables at footfalls, knocks at ball bounces)";
  } else if (src == "mic" || src.rfind("mic:", 0) == 0) {
    const std::string device = src.size() > 4 ? src.substr(4) : "";
    Impl* raw = &m;
    HOLO_ASSIGN_OR_RETURN(m.mic, audio::VoiceCapture::OpenDevice(device, RealClock::Instance(),
                                                                  [raw](int64_t t) { return raw->Head(t); }));
    m.stats.description = m.mic->description();
  } else if (src == "off" || src.empty()) {
    return InvalidArgument("site voice: source 'off' has nothing to publish");
  } else {
    auto wav = audio::ReadMonoWav(src, audio::kSampleRate);
    if (!wav.ok()) return wav.status().WithContext("--voice " + src);
    if (wav->empty()) return InvalidArgument("--voice " + src + ": no samples");
    m.wav = std::move(*wav);
    m.wav.resize(m.wav.size() + audio::kSampleRate / 2, 0.0f);  // half a second between repetitions
    m.stats.description = "WAV " + src + " (looped)";
  }
  Impl* raw = impl.get();
  m.thread = std::thread([raw] { raw->Loop(); });
  return std::unique_ptr<SiteVoice>(new SiteVoice(std::move(impl)));
}

void SiteVoice::Stop() {
  if (!impl_) return;
  impl_->stop = true;
  if (impl_->thread.joinable()) impl_->thread.join();
}

SiteVoiceStats SiteVoice::stats() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->stats;
}

}  // namespace holo::voice
