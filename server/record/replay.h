// Replay of a recording as a live source: emits the recorded protocol frames
// (byte-identical) at their original pacing on an injected Clock, with pause,
// resume, seek, speed (0.25×–4×) and loop. Control API: docs/recording.md.
//
// Two ways to drive it:
//  * pull — the network server calls Pump() from its own loop (e.g. an Asio
//    timer set to NextDueUs()); Pump emits every message that is due now;
//  * push — Run() on a thread of its own sleeps on the clock between
//    messages and calls the callback; Stop() ends it.
// Controls (Pause, Resume, Seek, SetSpeed, SetLoop, ApplyControl) may come
// from any thread; the callback is never called with the lock held, so it may
// call controls itself.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include "common/clock.h"
#include "common/status.h"
#include "protocol/messages.h"
#include "server/record/recording_reader.h"

namespace holo::record {

// One recorded protocol frame (header + payload, exactly as recorded) and its
// decoded header. The bytes are shared: fan it out without copying.
using ReplayCallback =
    std::function<void(std::shared_ptr<const std::vector<uint8_t>> message_bytes, protocol::Header header)>;

inline constexpr double kMinReplaySpeed = 0.25;
inline constexpr double kMaxReplaySpeed = 4.0;

struct ReplayOptions {
  double speed = 1.0;       // 0.25 .. 4
  bool loop = false;        // start again at the end
  int64_t start_us = 0;     // media time to start at (a seek before the first message)
  bool start_paused = false;
  Status Check() const;
};

struct ReplayState {
  int64_t position_us = 0;  // media time now
  int64_t duration_us = 0;
  double speed = 1.0;
  bool paused = false;
  bool loop = false;
  bool ended = false;       // reached the end (never true while looping)
  uint64_t generation = 0;  // +1 on every seek and loop: sequence numbers and capture times jump
  uint64_t emitted = 0;     // messages emitted
  uint64_t skipped = 0;     // audio/stats skipped while fast-forwarding after a seek
};

class ReplaySource {
 public:
  static StatusOr<std::unique_ptr<ReplaySource>> Create(std::shared_ptr<const RecordingReader> reader, Clock* clock,
                                                        ReplayOptions options = {});

  // Pull: emits, in file order, every message due at the clock's now (at
  // most `max_messages`). Returns how many were emitted; DataLoss if the file
  // is damaged where it was read (the replay then ends).
  StatusOr<size_t> Pump(const ReplayCallback& sink, size_t max_messages = SIZE_MAX);
  // Clock time (µs) at which the next message is due: ≤ now if one is due,
  // INT64_MAX when paused with nothing due, or at the end.
  int64_t NextDueUs();
  // Push: pumps and sleeps on the clock (in slices of ≤ 20 ms, to notice
  // controls and Stop) until Stop() or the end (never, with loop).
  Status Run(const ReplayCallback& sink);
  void Stop() { stop_ = true; }

  // --- controls (thread-safe) ---
  // Freezes media time; nothing more is emitted until Resume or Seek.
  void Pause();
  void Resume();
  // Jumps to media time `time_us` (0 ≤ t ≤ duration, else OutOfRange): the
  // Rig in effect and the last key frame at or before t are emitted at once,
  // then the video frames up to t (fast-forward; audio and stats before t are
  // skipped), then pacing continues from t. Keeps paused/playing; a seek while
  // paused shows the frame at t.
  Status Seek(int64_t time_us);
  // 0.25 ≤ speed ≤ 4 (InvalidArgument otherwise); keeps the position.
  Status SetSpeed(double speed);
  void SetLoop(bool loop);
  // A viewer's Control message: kPause, kResume, kSeek (value = media µs),
  // kSetSpeed (speed), kRequestKeyFrame (= seek to the position now).
  // InvalidArgument for other commands (they are not replay commands).
  Status ApplyControl(const protocol::Control& control);

  ReplayState state();
  const RecordingReader& reader() const { return *reader_; }

 private:
  ReplaySource(std::shared_ptr<const RecordingReader> reader, Clock* clock, ReplayOptions options);
  int64_t MediaNowLocked(int64_t now) const;
  int64_t DueClockLocked(int64_t media_us) const;
  Status SeekLocked(int64_t time_us, int64_t now);
  Status LoadPendingLocked();

  std::shared_ptr<const RecordingReader> reader_;
  Clock* clock_;
  std::mutex mu_;
  std::atomic<bool> stop_{false};
  // Media time anchor_media_us_ corresponds to clock time anchor_clock_us_.
  int64_t anchor_clock_us_ = 0;
  int64_t anchor_media_us_ = 0;
  double speed_ = 1.0;
  bool paused_ = false;
  bool loop_ = false;
  bool ended_ = false;
  uint64_t cursor_ = 0;                      // next record to read
  std::optional<RecordedMessage> pending_;   // next message (read ahead)
  std::optional<uint64_t> pending_rig_;      // Rig to emit before it (after a seek)
  int64_t fast_forward_until_us_ = -1;       // skip audio/stats before this media time
  int64_t last_time_us_ = 0;                 // time of the last message read (must not go back)
  int64_t loop_gap_us_ = 33333;
  int64_t first_time_us_ = 0;                // media time of the first message              // media time between the end and the restart
  ReplayState counters_;
  Status failed_;
};

}  // namespace holo::record
