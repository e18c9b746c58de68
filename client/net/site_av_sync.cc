#include "client/net/site_av_sync.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "audio/voice_codec.h"

namespace holo::net {

Status VoicePlayoutOptions::Check() const {
  HOLO_RETURN_IF_ERROR(jitter.Check());
  if (!(output_latency_ms >= 0 && output_latency_ms <= 1000))
    return InvalidArgument("output_latency_ms must be in 0..1000, got " + std::to_string(output_latency_ms));
  if (!(inject_delay_ms >= 0 && inject_delay_ms <= 10000))
    return InvalidArgument("voice inject_delay_ms must be in 0..10000, got " + std::to_string(inject_delay_ms));
  return OkStatus();
}

Status SiteAvSyncOptions::Check() const {
  HOLO_RETURN_IF_ERROR(sync.Check());
  HOLO_RETURN_IF_ERROR(voice.Check());
  if (!(inject_picture_delay_ms >= 0 && inject_picture_delay_ms <= 10000))
    return InvalidArgument("inject_picture_delay_ms must be in 0..10000, got " + std::to_string(inject_picture_delay_ms));
  if (max_held_pictures < 1) return InvalidArgument("max_held_pictures must be >= 1");
  return OkStatus();
}

RemoteVoices::RemoteVoices(Clock& clock, VoicePlayoutOptions options, audio::AvSync* sync)
    : clock_(clock), options_(std::move(options)), sync_(sync) {}

void RemoteVoices::Insert(uint32_t stream, protocol::AudioPose frame) {
  ++stats_.frames;
  if (options_.inject_delay_ms > 0) {
    const auto release = clock_.NowUs() + static_cast<int64_t>(std::llround(options_.inject_delay_ms * 1000.0));
    delayed_.push_back({release, {stream, std::move(frame)}});
    return;
  }
  Deliver(stream, std::move(frame));
}

void RemoteVoices::Deliver(uint32_t stream, protocol::AudioPose frame) {
  Speaker& sp = speakers_[stream];
  if (!sp.jb) {
    auto jb = audio::JitterBuffer::Create(frame.codec, clock_, options_.jitter);
    if (!jb.ok()) {  // an unknown codec: nothing to play it with
      speakers_.erase(stream);
      return;
    }
    sp.jb = std::move(*jb);
    sp.codec_delay_us = audio::CodecDelaySamples(frame.codec) * 1000000 / audio::kSampleRate;
  }
  (void)sp.jb->Insert(std::move(frame));  // invalid frames are refused there (and not played)
}

void RemoteVoices::Release(int64_t now_us) {
  while (!delayed_.empty() && delayed_.front().first <= now_us) {
    auto [stream, frame] = std::move(delayed_.front().second);
    delayed_.pop_front();
    Deliver(stream, std::move(frame));
  }
}

std::vector<RemoteVoices::Block> RemoteVoices::Pull() {
  const int64_t now = clock_.NowUs();
  Release(now);
  const double target_ms = sync_ ? sync_->VoiceTargetMs(now) : 0.0;
  const auto output_us = static_cast<int64_t>(std::llround(options_.output_latency_ms * 1000.0));
  std::vector<Block> out;
  out.reserve(speakers_.size());
  RemoteVoicesStats s;
  s.frames = stats_.frames;
  for (auto& [stream, sp] : speakers_) {
    const double codec_ms = sp.codec_delay_us / 1000.0;
    // The AvSync's target is capture → heard; the buffer holds capture → pull.
    sp.jb->SetSyncDelayMs(target_ms > 0 ? target_ms - options_.output_latency_ms - codec_ms : 0.0);
    Block b;
    b.stream = stream;
    b.pcm = sp.jb->Pull();
    b.playing = sp.jb->playing() && sp.jb->last_pull_capture_us() != 0;
    b.new_speaker = !sp.announced;
    sp.announced = true;
    b.pose = sp.jb->pose();
    b.playout_us = now + output_us;
    const audio::JitterBufferStats& js = sp.jb->stats();
    b.buffer_delay_ms = js.current_delay_ms;
    if (b.playing) {
      // The decoder's output lags its input by the codec delay.
      b.capture_us = sp.jb->last_pull_capture_us() - sp.codec_delay_us;
      // Without sync: capture → pull is the jitter target + one frame + the
      // fastest packet's transit; then the output and the codec add theirs.
      const double natural = js.jitter_target_ms + static_cast<double>(audio::kFrameUs) / 1000.0 + js.transit_min_ms +
                             options_.output_latency_ms + codec_ms;
      if (sync_) sync_->VoicePlayout(stream, b.capture_us, b.playout_us, natural);
    }
    s.concealed += js.concealed;
    s.late += js.late;
    s.underflows += js.underflows;
    s.sync_expands += js.sync_expands;
    s.sync_drops += js.sync_drops;
    s.sync_rebuffers += js.sync_rebuffers;
    s.jitter_target_ms = js.jitter_target_ms;
    out.push_back(std::move(b));
  }
  s.speakers = static_cast<int64_t>(speakers_.size());
  stats_ = s;
  return out;
}

StatusOr<std::unique_ptr<SiteAvSync>> SiteAvSync::Start(SiteClient* client, SiteAvSyncOptions options,
                                                        audio::AvSync* external_sync) {
  if (client == nullptr) return InvalidArgument("SiteAvSync needs a client");
  HOLO_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<SiteAvSync> s(new SiteAvSync());
  s->client_ = client;
  s->options_ = std::move(options);
  if (external_sync != nullptr) {
    s->sync_ = external_sync;
  } else {
    s->own_sync_ = std::make_unique<audio::AvSync>(s->options_.sync);
    s->sync_ = s->own_sync_.get();
  }
  s->clock_ = s->options_.clock != nullptr ? s->options_.clock : &WallClock::Instance();
  if (s->options_.play_voice) {
    s->voices_ = std::make_unique<RemoteVoices>(*s->clock_, s->options_.voice, s->sync_);
    if (s->options_.voice_thread) {
      SiteAvSync* self = s.get();
      s->voice_thread_ = std::thread([self] { self->VoiceLoop(); });
    }
  }
  return s;
}

SiteAvSync::~SiteAvSync() { Stop(); }

void SiteAvSync::Stop() {
  stop_ = true;
  if (voice_thread_.joinable()) voice_thread_.join();
}

void SiteAvSync::VoiceLoop() {
  Clock& clock = *clock_;
  int64_t next = clock.NowUs();
  while (!stop_) {
    clock.SleepUntilUs(next + audio::kFrameUs);
    if (stop_) break;
    next += audio::kFrameUs;
    TickVoice();
    // Behind by more than two steps (a loaded machine did not run this
    // thread): the audio of that time is lost as on a sound card that ran
    // dry; carry on from now instead of pulling a burst of steps back to
    // back (each would see a wrong delay and drop or conceal frames).
    if (clock.NowUs() - next > 2 * audio::kFrameUs) next = clock.NowUs();
  }
}

void SiteAvSync::TickVoice() {
  if (!voices_) return;
  protocol::AudioPose a;
  uint32_t stream = 0;
  while (client_->PollAudio(&a, &stream)) voices_->Insert(stream, std::move(a));
  const std::vector<RemoteVoices::Block> blocks = voices_->Pull();
  if (options_.on_voice)
    for (const auto& b : blocks) options_.on_voice(b);
  std::lock_guard<std::mutex> l(mu_);
  voice_stats_ = voices_->stats();
}

void SiteAvSync::Hold(ReceivedFrame frame) {
  Held h;
  h.ready_us = clock_->NowUs() + static_cast<int64_t>(std::llround(options_.inject_picture_delay_ms * 1000.0));
  h.frame = std::move(frame);
  std::lock_guard<std::mutex> l(mu_);
  held_.push_back(std::move(h));
}

void SiteAvSync::PollPictures() {
  ReceivedFrame f;
  while (client_->PollFrame(&f)) Hold(std::move(f));
}

bool SiteAvSync::NextFrame(ReceivedFrame* out, double timeout_s, int64_t* ready_us) {
  const auto real_deadline =
      std::chrono::steady_clock::now() + std::chrono::microseconds(static_cast<int64_t>(std::llround(timeout_s * 1e6)));
  for (;;) {
    PollPictures();
    const int64_t now = clock_->NowUs();
    int64_t next_event = now + 5000;
    {
      std::lock_guard<std::mutex> l(mu_);
      for (Held& h : held_) {
        if (!h.scheduled && now >= h.ready_us) {
          h.show_us = sync_->PictureReady(h.frame.capture_time_us, h.ready_us);
          h.scheduled = true;
        }
      }
      // Memory bound: the oldest held pictures are shown at once.
      for (size_t i = 0; held_.size() > options_.max_held_pictures && i < held_.size() - options_.max_held_pictures; ++i) {
        if (held_[i].scheduled) held_[i].show_us = std::min(held_[i].show_us, now);
      }
      int due = -1;
      for (size_t i = 0; i < held_.size(); ++i) {
        const Held& h = held_[i];
        if (h.scheduled && h.show_us <= now) {
          due = static_cast<int>(i);
        } else {
          next_event = std::min(next_event, h.scheduled ? h.show_us : h.ready_us);
        }
      }
      if (due >= 0) {
        skipped_ += due;
        if (ready_us != nullptr) *ready_us = held_[static_cast<size_t>(due)].ready_us;
        *out = std::move(held_[static_cast<size_t>(due)].frame);
        held_.erase(held_.begin(), held_.begin() + due + 1);
        return true;
      }
    }
    const auto left = real_deadline - std::chrono::steady_clock::now();
    if (left <= std::chrono::steady_clock::duration::zero()) return false;
    // Until the next held picture is due or a new one arrives, whichever is first.
    const auto wait = std::min<std::chrono::steady_clock::duration>(
        std::chrono::microseconds(std::clamp<int64_t>(next_event - now, 500, 5000)), left);
    ReceivedFrame f;
    if (client_->WaitFrame(&f, std::chrono::duration<double>(wait).count())) Hold(std::move(f));
  }
}

void SiteAvSync::Displayed(const ReceivedFrame& frame, int64_t render_start_us, int64_t display_us) {
  sync_->PictureDisplayed(frame.capture_time_us, render_start_us, display_us);
}

int64_t SiteAvSync::pictures_skipped() const {
  std::lock_guard<std::mutex> l(mu_);
  return skipped_;
}

RemoteVoicesStats SiteAvSync::voice_stats() const {
  std::lock_guard<std::mutex> l(mu_);
  return voice_stats_;
}

}  // namespace holo::net
