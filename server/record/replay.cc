#include "server/record/replay.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace holo::record {
namespace {

constexpr int64_t kNever = std::numeric_limits<int64_t>::max();
constexpr int64_t kRunSliceUs = 20000;

bool ValidSpeed(double s) { return std::isfinite(s) && s >= kMinReplaySpeed && s <= kMaxReplaySpeed; }

std::string SpeedError(double s) {
  return "replay speed must be in [0.25, 4], got " + std::to_string(s);
}

}  // namespace

Status ReplayOptions::Check() const {
  if (!ValidSpeed(speed)) return InvalidArgument(SpeedError(speed));
  if (start_us < 0) return InvalidArgument("replay start time must be ≥ 0");
  return OkStatus();
}

ReplaySource::ReplaySource(std::shared_ptr<const RecordingReader> reader, Clock* clock, ReplayOptions options)
    : reader_(std::move(reader)), clock_(clock) {
  speed_ = options.speed;
  loop_ = options.loop;
  paused_ = options.start_paused;
  cursor_ = reader_->summary().data_begin;
  anchor_clock_us_ = clock_->NowUs();
  anchor_media_us_ = 0;
  const auto& idx = reader_->summary().index;
  if (idx.size() >= 2) {
    const int64_t span = idx.back().time_us - idx.front().time_us;
    loop_gap_us_ = std::clamp<int64_t>(span / static_cast<int64_t>(idx.size() - 1), 1000, 1000000);
  }
}

StatusOr<std::unique_ptr<ReplaySource>> ReplaySource::Create(std::shared_ptr<const RecordingReader> reader,
                                                             Clock* clock, ReplayOptions options) {
  if (reader == nullptr || clock == nullptr) return InvalidArgument("replay needs a reader and a clock");
  HOLO_RETURN_IF_ERROR(options.Check());
  if (options.start_us > reader->summary().duration_us)
    return OutOfRange("replay start " + FormatSeconds(options.start_us) + " is past the end (" +
                      FormatSeconds(reader->summary().duration_us) + ")");
  // Media time starts at the first message (a segment starts late).
  HOLO_ASSIGN_OR_RETURN(RecordedMessage first, reader->ReadAt(reader->summary().data_begin));
  std::unique_ptr<ReplaySource> r(new ReplaySource(std::move(reader), clock, options));
  r->first_time_us_ = first.time_us;
  r->anchor_media_us_ = first.time_us;
  if (options.start_us > first.time_us) {
    std::lock_guard<std::mutex> lock(r->mu_);
    HOLO_RETURN_IF_ERROR(r->SeekLocked(options.start_us, clock->NowUs()));
    r->counters_.generation = 0;
  }
  return r;
}

int64_t ReplaySource::MediaNowLocked(int64_t now) const {
  if (paused_) return anchor_media_us_;
  return anchor_media_us_ + static_cast<int64_t>(std::floor(static_cast<double>(now - anchor_clock_us_) * speed_));
}

int64_t ReplaySource::DueClockLocked(int64_t media_us) const {
  return anchor_clock_us_ + static_cast<int64_t>(std::ceil(static_cast<double>(media_us - anchor_media_us_) / speed_));
}

Status ReplaySource::LoadPendingLocked() {
  if (pending_ || cursor_ >= reader_->summary().data_end) return OkStatus();
  auto m = reader_->ReadAt(cursor_);
  if (!m.ok()) return m.status();
  if (m->time_us < last_time_us_)
    return DataLoss(reader_->path() + ": offset " + std::to_string(m->offset) + ": message time goes back");
  last_time_us_ = m->time_us;
  pending_ = std::move(*m);
  return OkStatus();
}

StatusOr<size_t> ReplaySource::Pump(const ReplayCallback& sink, size_t max_messages) {
  std::vector<std::pair<std::shared_ptr<const std::vector<uint8_t>>, protocol::Header>> out;
  Status error;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!failed_.ok()) return failed_;
    const int64_t now = clock_->NowUs();
    const RecordingSummary& sum = reader_->summary();
    while (out.size() < max_messages && !ended_) {
      if (pending_rig_) {
        auto rig = reader_->ReadAt(*pending_rig_);
        pending_rig_.reset();
        if (!rig.ok()) {
          error = rig.status();
          break;
        }
        out.emplace_back(rig->bytes, rig->header);
        continue;
      }
      error = LoadPendingLocked();
      if (!error.ok()) break;
      if (!pending_) {  // the end
        if (!loop_) {
          ended_ = true;
          break;
        }
        const int64_t restart_media = sum.duration_us + loop_gap_us_;
        if (MediaNowLocked(now) < restart_media) break;
        // Seamless laps; after a long stall (the caller did not pump for more
        // than a second) restart now instead of replaying the missed laps.
        const int64_t wrap_clock = DueClockLocked(restart_media);
        anchor_clock_us_ = now - wrap_clock > 1000000 ? now : wrap_clock;
        cursor_ = sum.data_begin;
        last_time_us_ = 0;
        fast_forward_until_us_ = -1;
        counters_.generation += 1;
        error = LoadPendingLocked();
        if (!error.ok()) break;
        anchor_media_us_ = pending_ ? pending_->time_us : first_time_us_;
        continue;
      }
      if (pending_->time_us > MediaNowLocked(now)) break;
      RecordedMessage m = std::move(*pending_);
      pending_.reset();
      cursor_ = m.next_offset;
      if (fast_forward_until_us_ >= 0) {
        if (m.time_us < fast_forward_until_us_) {
          const auto t = m.header.type;
          if (t == protocol::MessageType::kAudioPose || t == protocol::MessageType::kStats ||
              t == protocol::MessageType::kRegions) {
            counters_.skipped += 1;
            continue;
          }
        } else {
          fast_forward_until_us_ = -1;
        }
      }
      out.emplace_back(std::move(m.bytes), m.header);
    }
    counters_.emitted += out.size();
    if (!error.ok()) {
      failed_ = error;
      ended_ = true;
    }
  }
  for (auto& [bytes, header] : out) sink(std::move(bytes), header);
  if (!error.ok()) return error;
  return out.size();
}

int64_t ReplaySource::NextDueUs() {
  std::lock_guard<std::mutex> lock(mu_);
  const int64_t now = clock_->NowUs();
  if (!failed_.ok() || ended_) return kNever;
  if (pending_rig_) return now;
  if (!LoadPendingLocked().ok()) return now;  // Pump reports the error
  if (!pending_) {
    if (!loop_) return now;  // Pump marks the end
    if (paused_) return kNever;
    return DueClockLocked(reader_->summary().duration_us + loop_gap_us_);
  }
  if (paused_) return pending_->time_us <= anchor_media_us_ ? now : kNever;
  return DueClockLocked(pending_->time_us);
}

Status ReplaySource::Run(const ReplayCallback& sink) {
  while (!stop_) {
    auto n = Pump(sink);
    if (!n.ok()) return n.status();
    const int64_t due = NextDueUs();
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (ended_ && !loop_) return OkStatus();
    }
    const int64_t now = clock_->NowUs();
    if (due <= now) continue;
    clock_->SleepUntilUs(due == kNever ? now + kRunSliceUs : std::min(due, now + kRunSliceUs));
  }
  return OkStatus();
}

void ReplaySource::Pause() {
  std::lock_guard<std::mutex> lock(mu_);
  if (paused_) return;
  anchor_media_us_ = MediaNowLocked(clock_->NowUs());
  paused_ = true;
}

void ReplaySource::Resume() {
  std::lock_guard<std::mutex> lock(mu_);
  if (!paused_) return;
  anchor_clock_us_ = clock_->NowUs();
  paused_ = false;
}

Status ReplaySource::SeekLocked(int64_t time_us, int64_t now) {
  const RecordingSummary& sum = reader_->summary();
  if (time_us < 0 || time_us > sum.duration_us)
    return OutOfRange("seek to " + FormatSeconds(time_us) + " is outside the recording [0, " +
                      FormatSeconds(sum.duration_us) + "]");
  time_us = std::max(time_us, first_time_us_);
  const IndexEntry* key = reader_->KeyFrameAtOrBefore(time_us);
  pending_.reset();
  pending_rig_.reset();
  if (key != nullptr) {
    cursor_ = key->offset;
    pending_rig_ = key->rig_offset;
    last_time_us_ = key->time_us;
  } else {
    cursor_ = sum.data_begin;  // before the first key frame: from the Rig
    last_time_us_ = 0;
  }
  anchor_media_us_ = time_us;
  anchor_clock_us_ = now;
  fast_forward_until_us_ = time_us;
  ended_ = false;
  failed_ = OkStatus();
  counters_.generation += 1;
  return OkStatus();
}

Status ReplaySource::Seek(int64_t time_us) {
  std::lock_guard<std::mutex> lock(mu_);
  return SeekLocked(time_us, clock_->NowUs());
}

Status ReplaySource::SetSpeed(double speed) {
  if (!ValidSpeed(speed)) return InvalidArgument(SpeedError(speed));
  std::lock_guard<std::mutex> lock(mu_);
  const int64_t now = clock_->NowUs();
  anchor_media_us_ = MediaNowLocked(now);
  anchor_clock_us_ = now;
  speed_ = speed;
  return OkStatus();
}

void ReplaySource::SetLoop(bool loop) {
  std::lock_guard<std::mutex> lock(mu_);
  loop_ = loop;
  if (loop && ended_ && failed_.ok()) ended_ = false;
}

Status ReplaySource::ApplyControl(const protocol::Control& c) {
  using protocol::ControlCommand;
  switch (c.command) {
    case ControlCommand::kPause: Pause(); return OkStatus();
    case ControlCommand::kResume: Resume(); return OkStatus();
    case ControlCommand::kSeek: return Seek(c.value);
    case ControlCommand::kSetSpeed: return SetSpeed(static_cast<double>(c.speed));
    case ControlCommand::kSetLoop: SetLoop(c.value != 0); return OkStatus();
    case ControlCommand::kRequestKeyFrame: {
      std::lock_guard<std::mutex> lock(mu_);
      const int64_t now = clock_->NowUs();
      const int64_t pos = std::clamp<int64_t>(MediaNowLocked(now), 0, reader_->summary().duration_us);
      return SeekLocked(pos, now);
    }
    default:
      return InvalidArgument("control command " + std::to_string(static_cast<int>(c.command)) +
                             " is not a replay command (pause 4, resume 5, seek 6, speed 7, key frame 8, loop 9)");
  }
}

ReplayState ReplaySource::state() {
  std::lock_guard<std::mutex> lock(mu_);
  ReplayState s = counters_;
  const int64_t now = clock_->NowUs();
  s.duration_us = reader_->summary().duration_us;
  s.position_us = std::clamp<int64_t>(MediaNowLocked(now), 0, s.duration_us);
  s.speed = speed_;
  s.paused = paused_;
  s.loop = loop_;
  s.ended = ended_;
  return s;
}

}  // namespace holo::record
