// The viewer side of a site's voices and picture in sync (audio/av_sync.h
// has the rules, docs/live.md the figures):
//  * RemoteVoices: one jitter buffer per voice stream of a site, pulled every
//    20 ms; it reports each stream's playout to an AvSync and holds the delay
//    the AvSync asks for. No thread, injected clock (tests drive it in
//    simulated time); holo::net::Participant and SiteAvSync run it.
//  * SiteAvSync: a SiteClient's voices played on a thread of its own and its
//    pictures handed to the render loop when they are due (NextFrame), so
//    that both stay in sync; with the measured offsets in stats().
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "audio/av_sync.h"
#include "audio/jitter_buffer.h"
#include "common/clock.h"
#include "common/status.h"
#include "net/site_client.h"
#include "protocol/messages.h"

namespace holo::net {

struct VoicePlayoutOptions {
  audio::JitterBufferOptions jitter;
  // Time from a pull to the moment its first sample is heard, ms: the 20 ms
  // block queued in OpenAL Soft (a sound card adds its own buffer).
  double output_latency_ms = 20.0;
  // Test hook: every voice frame waits this long after it arrived before it
  // reaches the jitter buffer, ms (a slower voice path).
  double inject_delay_ms = 0.0;
  Status Check() const;
};

struct RemoteVoicesStats {
  int64_t frames = 0;        // voice frames received
  int64_t speakers = 0;      // voice streams heard
  int64_t concealed = 0, late = 0, underflows = 0;
  int64_t sync_expands = 0, sync_drops = 0, sync_rebuffers = 0;
  double jitter_target_ms = 0;  // of the last stream pulled
};

class RemoteVoices {
 public:
  // `clock` (arrival and playout times; the clock the AvSync gets) and
  // `sync` (may be null: no lip sync) are borrowed for the object's life.
  RemoteVoices(Clock& clock, VoicePlayoutOptions options, audio::AvSync* sync);
  RemoteVoices(const RemoteVoices&) = delete;
  RemoteVoices& operator=(const RemoteVoices&) = delete;

  // A voice frame of stream `stream` that arrived now (validated by the
  // jitter buffer; an invalid one is counted and ignored).
  void Insert(uint32_t stream, protocol::AudioPose frame);

  struct Block {
    uint32_t stream = 0;
    std::vector<float> pcm;      // 20 ms, 48 kHz mono (silence while buffering)
    bool playing = false;
    bool new_speaker = false;    // the first block of this stream
    protocol::HeadPose pose;     // the speaker's head while this was captured
    int64_t capture_us = 0;      // capture time (site clock) of pcm[0] (playing only)
    int64_t playout_us = 0;      // when pcm[0] is heard (this clock)
    double buffer_delay_ms = 0;  // the jitter buffer's playout delay above its fastest packet
  };
  // One 20 ms step of every voice: call every 20 ms of the clock.
  std::vector<Block> Pull();
  RemoteVoicesStats stats() const { return stats_; }

 private:
  struct Speaker {
    std::unique_ptr<audio::JitterBuffer> jb;
    int codec_delay_us = 0;
    bool announced = false;
  };
  void Deliver(uint32_t stream, protocol::AudioPose frame);
  void Release(int64_t now_us);

  Clock& clock_;
  VoicePlayoutOptions options_;
  audio::AvSync* sync_;
  std::map<uint32_t, Speaker> speakers_;
  std::deque<std::pair<int64_t, std::pair<uint32_t, protocol::AudioPose>>> delayed_;  // inject_delay_ms
  RemoteVoicesStats stats_;
};

struct SiteAvSyncOptions {
  audio::AvSyncOptions sync;
  VoicePlayoutOptions voice;
  // Play the client's voices (off: the caller plays them and reports to
  // sync(), as a call participant does) ...
  bool play_voice = true;
  // ... on a thread of its own, every 20 ms (off: the caller calls
  // TickVoice() every 20 ms of the clock; tests in simulated time).
  bool voice_thread = true;
  // Clock of arrivals, playout and display (borrowed; null: WallClock, the
  // clock capture times are stamped with). NextFrame's timeout sleeps in
  // real time whatever the clock.
  Clock* clock = nullptr;
  // Test hook: every picture waits this long after it was decoded, ms (a
  // slower picture path).
  double inject_picture_delay_ms = 0.0;
  // Pictures held for their voice at most (a memory bound); beyond it the
  // oldest is shown at once.
  size_t max_held_pictures = 64;
  // Every 20 ms block of every voice, on the playout thread.
  std::function<void(const RemoteVoices::Block&)> on_voice;
  Status Check() const;
};

class SiteAvSync {
 public:
  // `client` (and `external_sync` if given: the AvSync a call participant's
  // voice playout reports to) are borrowed and must outlive this object.
  static StatusOr<std::unique_ptr<SiteAvSync>> Start(SiteClient* client, SiteAvSyncOptions options,
                                                     audio::AvSync* external_sync = nullptr);
  ~SiteAvSync();  // Stop()
  SiteAvSync(const SiteAvSync&) = delete;
  SiteAvSync& operator=(const SiteAvSync&) = delete;
  void Stop();

  // The newest received picture that is due now (older due ones are
  // dropped), waiting up to `timeout_s` for one; false if none.
  // `ready_us` (optional): when it was taken from the client, decoded (the
  // clock's time; it may have been held since).
  bool NextFrame(ReceivedFrame* out, double timeout_s = 0.0, int64_t* ready_us = nullptr);
  // `frame` (from NextFrame) is visible from `display_us` (the clock's
  // time); rendering it started at `render_start_us`.
  void Displayed(const ReceivedFrame& frame, int64_t render_start_us, int64_t display_us);
  // Pictures dropped because a newer one was due too.
  int64_t pictures_skipped() const;

  // One 20 ms voice step: takes the client's voice frames and plays 20 ms
  // of each voice (what the voice thread does; for voice_thread = false).
  void TickVoice();

  audio::AvSync& sync() { return *sync_; }
  const audio::AvSync& sync() const { return *sync_; }
  audio::AvSyncStats stats() const { return sync_->stats(); }
  RemoteVoicesStats voice_stats() const;

 private:
  SiteAvSync() = default;
  void VoiceLoop();
  // Takes the client's waiting pictures (Hold: one of them, decoded now).
  void PollPictures();
  void Hold(ReceivedFrame frame);

  SiteClient* client_ = nullptr;
  SiteAvSyncOptions options_;
  Clock* clock_ = nullptr;
  std::unique_ptr<audio::AvSync> own_sync_;
  audio::AvSync* sync_ = nullptr;
  std::unique_ptr<RemoteVoices> voices_;
  std::thread voice_thread_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mu_;  // held_, skipped_, voice stats
  struct Held {
    ReceivedFrame frame;
    int64_t ready_us = 0;
    int64_t show_us = 0;
    bool scheduled = false;
  };
  std::deque<Held> held_;
  int64_t skipped_ = 0;
  RemoteVoicesStats voice_stats_;
};

}  // namespace holo::net
