#include "audio/jitter_buffer.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace holo::audio {
namespace {
// Frames held at most (10 s): a flood of future sequence numbers cannot grow memory.
constexpr size_t kMaxPackets = 500;
// Underflows in a row after which the buffer stops and buffers again (200 ms).
constexpr int kMaxUnderflows = 10;
}  // namespace

Status JitterBufferOptions::Check() const {
  if (!(min_target_ms >= 0 && min_target_ms <= max_target_ms)) {
    return InvalidArgument("need 0 <= min_target_ms <= max_target_ms, got " + std::to_string(min_target_ms) + ", " +
                           std::to_string(max_target_ms));
  }
  if (!(initial_target_ms >= 0)) return InvalidArgument("initial_target_ms must be >= 0");
  if (window_packets < 10) return InvalidArgument("window_packets must be >= 10, got " + std::to_string(window_packets));
  if (!(max_stretch >= 0 && max_stretch <= 0.1)) return InvalidArgument("max_stretch must be in 0..0.1");
  if (!(stretch_per_ms >= 0)) return InvalidArgument("stretch_per_ms must be >= 0");
  if (!(stretch_integral_per_ms >= 0)) return InvalidArgument("stretch_integral_per_ms must be >= 0");
  if (!(delay_filter > 0 && delay_filter <= 1)) return InvalidArgument("delay_filter must be in (0, 1]");
  if (!(drop_above_ms > 0)) return InvalidArgument("drop_above_ms must be > 0");
  if (!(sync_jump_ms >= 20)) return InvalidArgument("sync_jump_ms must be >= 20 (one frame), got " + std::to_string(sync_jump_ms));
  if (!(sync_rebuffer_ms >= sync_jump_ms))
    return InvalidArgument("sync_rebuffer_ms must be >= sync_jump_ms, got " + std::to_string(sync_rebuffer_ms));
  return OkStatus();
}

StatusOr<std::unique_ptr<JitterBuffer>> JitterBuffer::Create(AudioCodec codec, Clock& clock,
                                                             const JitterBufferOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<JitterBuffer> jb(new JitterBuffer(clock, options));
  HOLO_ASSIGN_OR_RETURN(jb->decoder_, VoiceDecoder::Create(codec));
  jb->stats_.target_delay_ms = jb->stats_.jitter_target_ms = options.initial_target_ms;
  return jb;
}

Status JitterBuffer::Insert(AudioPose frame) {
  HOLO_RETURN_IF_ERROR(ValidateVoiceFrame(frame));
  // The classic and the lean layout carry the same Opus packets: one decoder plays both.
  if (IsOpus(frame.codec) != IsOpus(decoder_->codec())) return DataLoss("voice frame codec differs from the stream's");
  const int64_t now = clock_.NowUs();
  int64_t seq = 0;
  if (!started_) {
    seq = frame.sequence;
    next_seq_ = seq;
    last_seq32_ = seq;
    started_ = true;
  } else {
    seq = last_seq32_ + static_cast<int32_t>(frame.sequence - static_cast<uint32_t>(last_seq32_));
  }
  if (seq > next_seq_ + static_cast<int64_t>(kMaxPackets)) {
    // The sender restarted or jumped far ahead: start over from this frame.
    packets_.clear();
    carried_seq_ = carried_prev_seq_ = -1;
    fifo_.clear();
    frac_ = 0;
    transit_us_.clear();
    rel_delay_ms_.clear();
    next_seq_ = seq;
    max_seq_ = seq - 1;
    playing_ = false;
    delay_filter_init_ = false;
    integral_ = 0.0;
  }
  if (packets_.count(seq) != 0) {
    ++stats_.duplicates;
    return OkStatus();
  }
  last_seq32_ = std::max(last_seq32_, seq);
  if (seq >= max_seq_) {
    anchor_seq_ = seq;
    anchor_capture_us_ = frame.capture_time_us;
  }
  max_seq_ = std::max(max_seq_, seq);
  // Arrival delay relative to the sender's timeline, anchored on this frame.
  transit_us_.push_back(now - (anchor_capture_us_ + (seq - anchor_seq_) * kFrameUs));
  if (static_cast<int>(transit_us_.size()) > options_.window_packets) transit_us_.pop_front();
  const int64_t min_transit = *std::min_element(transit_us_.begin(), transit_us_.end());
  rel_delay_ms_.push_back(static_cast<double>(transit_us_.back() - min_transit) / 1000.0);
  if (static_cast<int>(rel_delay_ms_.size()) > options_.window_packets) rel_delay_ms_.pop_front();
  UpdateTarget();
  if (seq < next_seq_) {  // its turn has passed (it was concealed, or it is a duplicate of a played frame)
    ++stats_.late;
    return OkStatus();
  }
  packets_.emplace(seq, std::move(frame));
  while (packets_.size() > kMaxPackets) packets_.erase(packets_.begin());
  ++stats_.inserted;
  return OkStatus();
}

void JitterBuffer::UpdateTarget() {
  // Too few packets for a percentile: keep the initial target as a floor.
  std::vector<double> v(rel_delay_ms_.begin(), rel_delay_ms_.end());
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(0.97 * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  double target = v[k] + options_.margin_ms;
  if (v.size() < 50) target = std::max(target, options_.initial_target_ms);
  stats_.jitter_target_ms = std::clamp(target, options_.min_target_ms, options_.max_target_ms);
  stats_.transit_min_ms = static_cast<double>(*std::min_element(transit_us_.begin(), transit_us_.end())) / 1000.0;
  RefreshTarget();
}

void JitterBuffer::RefreshTarget() {
  // The controlled level is the delay of the first sample of the *next* pull
  // above the fastest packet; the sync delay is from capture to the pull that
  // plays a sample: level = sync − fastest transit − one frame.
  double target = stats_.jitter_target_ms;
  if (sync_delay_ms_ > 0 && !transit_us_.empty())
    target = std::max(target, sync_delay_ms_ - stats_.transit_min_ms - static_cast<double>(kFrameUs) / 1000.0);
  stats_.target_delay_ms = target;
}

double JitterBuffer::PlayCaptureUs() const {
  const double play_seq =
      static_cast<double>(next_seq_) - (static_cast<double>(fifo_.size()) - frac_) / kFrameSamples;
  return static_cast<double>(anchor_capture_us_) + (play_seq - static_cast<double>(anchor_seq_)) * kFrameUs;
}

double JitterBuffer::DelayMs(int64_t now_us) const {
  if (transit_us_.empty()) return 0.0;
  const int64_t min_transit = *std::min_element(transit_us_.begin(), transit_us_.end());
  return (static_cast<double>(now_us) - PlayCaptureUs() - static_cast<double>(min_transit)) / 1000.0;
}

void JitterBuffer::DecodeNext() {
  std::vector<float> pcm;
  auto it = packets_.find(next_seq_);
  bool ok = false;
  if (it != packets_.end()) {
    auto decoded = decoder_->Decode(it->second.audio);
    if (decoded.ok()) {
      pcm = std::move(decoded).value();
      if (it->second.has_pose) {
        pose_ = it->second.pose;
        carried_prev_pose_ = carried_pose_;
        carried_prev_seq_ = carried_seq_;
        carried_pose_ = pose_;
        carried_seq_ = next_seq_;
      } else {
        // A lean frame sent without its pose (every other frame): halfway
        // between the last pose and the next frame's when that is here, else
        // on from the last two poses (a head moves smoothly over 20 ms).
        auto next = packets_.find(next_seq_ + 1);
        const int64_t since = next_seq_ - carried_seq_;  // frames since the last pose (> 0)
        if (next != packets_.end() && next->second.has_pose && carried_seq_ >= 0 && since > 0 && since <= 3) {
          const float t = static_cast<float>(since) / static_cast<float>(since + 1);
          pose_ = protocol::LerpPose(carried_pose_, next->second.pose, t);
          ++stats_.poses_interpolated;
        } else if (carried_seq_ >= 0 && carried_prev_seq_ >= 0 && carried_seq_ > carried_prev_seq_ && since > 0 &&
                   since <= 2 && carried_seq_ - carried_prev_seq_ <= 4) {
          const float t = static_cast<float>(next_seq_ - carried_prev_seq_) /
                          static_cast<float>(carried_seq_ - carried_prev_seq_);
          pose_ = protocol::LerpPose(carried_prev_pose_, carried_pose_, t);
          ++stats_.poses_extrapolated;
        } else {
          ++stats_.poses_held;
        }
      }
      ++stats_.played;
      ok = true;
    }
    packets_.erase(it);
  }
  if (!ok) {
    auto next = packets_.find(next_seq_ + 1);
    bool used_fec = false;
    pcm = decoder_->Conceal(next != packets_.end() ? std::span<const uint8_t>(next->second.audio)
                                                   : std::span<const uint8_t>(),
                            &used_fec);
    ++stats_.concealed;
    if (used_fec) ++stats_.fec_recovered;
  }
  fifo_.insert(fifo_.end(), pcm.begin(), pcm.end());
  ++next_seq_;
}

std::vector<float> JitterBuffer::Pull() {
  std::vector<float> out(kFrameSamples, 0.0f);
  const int64_t now = clock_.NowUs();
  last_pull_capture_us_ = 0;
  if (!started_) return out;
  RefreshTarget();
  // Lip sync holds the delay above what the jitter needs.
  const bool sync = stats_.target_delay_ms > stats_.jitter_target_ms;
  const double frame_ms = static_cast<double>(kFrameUs) / 1000.0;
  if (!playing_) {
    if (packets_.empty()) return out;
    next_seq_ = std::max(next_seq_, packets_.begin()->first);
    fifo_.clear();
    frac_ = 0;
    // The first sample of this pull must be as late as the next pull's
    // would be at the target (the controller's level is one frame later).
    if (DelayMs(now) < stats_.target_delay_ms + (sync ? frame_ms : 0.0)) return out;
    playing_ = true;
    consecutive_underflows_ = 0;
  }
  double delay = DelayMs(now);
  if (sync && delay - frame_ms < stats_.target_delay_ms - options_.sync_rebuffer_ms) {
    // Far below the sync delay: stop and start again when the delay is there
    // (a silent gap; the frames wait in the buffer, none is skipped).
    playing_ = false;
    delay_filter_init_ = false;
    ++stats_.sync_rebuffers;
    stats_.current_delay_ms = 0;
    return out;
  }
  if (sync && delay - frame_ms < stats_.target_delay_ms - options_.sync_jump_ms) {
    // Below the sync delay: one concealment frame after what is decoded (the
    // decoder continues from its last frame), without consuming a packet.
    bool used_fec = false;
    const std::vector<float> pcm = decoder_->Conceal({}, &used_fec);
    fifo_.insert(fifo_.end(), pcm.begin(), pcm.end());
    ++stats_.sync_expands;
    delay = DelayMs(now);
  }
  // Far too much delay (a burst after a stall, or a lower sync delay): drop
  // whole frames. Under lip sync (a sync delay is set, even one the jitter
  // target exceeds) the delay follows the sync's moves by whole frames.
  const bool sync_set = sync_delay_ms_ > 0;
  const double drop_above = sync_set ? std::min(options_.drop_above_ms, options_.sync_jump_ms) : options_.drop_above_ms;
  while (delay - (sync_set ? frame_ms : 0.0) > stats_.target_delay_ms + drop_above && max_seq_ > next_seq_) {
    packets_.erase(next_seq_);
    ++next_seq_;
    ++stats_.dropped_frames;
    if (sync_set) ++stats_.sync_drops;
    delay = DelayMs(now);
  }
  // Drift controller. The controlled level is the delay of the first sample
  // the next pull will play (this pull's 20 ms already taken out), so it is
  // the audio actually held in reserve against late packets.
  const double level_ms = delay - static_cast<double>(kFrameUs) / 1000.0;
  if (!delay_filter_init_) {
    filtered_delay_ms_ = level_ms;
    delay_filter_init_ = true;
  } else {
    filtered_delay_ms_ += options_.delay_filter * (level_ms - filtered_delay_ms_);
  }
  const double error_ms = filtered_delay_ms_ - stats_.target_delay_ms;
  const double p = options_.stretch_per_ms * error_ms;
  // Anti-windup: the integral alone stays within the stretch range, and does
  // not integrate further while the output is saturated in that direction.
  const double next_integral = std::clamp(integral_ + options_.stretch_integral_per_ms * error_ms,
                                          -options_.max_stretch, options_.max_stretch);
  const double unclamped = p + next_integral;
  if (std::abs(unclamped) <= options_.max_stretch || std::abs(next_integral) < std::abs(integral_)) {
    integral_ = next_integral;
  }
  const double ratio = 1.0 + std::clamp(p + integral_, -options_.max_stretch, options_.max_stretch);
  const size_t need = static_cast<size_t>(frac_ + kFrameSamples * ratio) + 2;
  while (fifo_.size() < need) {
    if (packets_.count(next_seq_) != 0 || max_seq_ > next_seq_) {
      DecodeNext();
      consecutive_underflows_ = 0;
      continue;
    }
    // Nothing to play: stretch with concealment without consuming a frame.
    ++stats_.underflows;
    if (++consecutive_underflows_ > kMaxUnderflows) {
      playing_ = false;
      delay_filter_init_ = false;  // keep the integral: the clocks did not change
      fifo_.clear();
      frac_ = 0;
      stats_.current_delay_ms = 0;
      return out;
    }
    bool used_fec = false;
    const std::vector<float> pcm = decoder_->Conceal({}, &used_fec);
    fifo_.insert(fifo_.end(), pcm.begin(), pcm.end());
  }
  last_pull_capture_us_ = static_cast<int64_t>(std::llround(PlayCaptureUs()));
  double pos = frac_;
  for (int i = 0; i < kFrameSamples; ++i) {
    const auto k = static_cast<size_t>(pos);
    const float t = static_cast<float>(pos - static_cast<double>(k));
    out[i] = fifo_[k] * (1.0f - t) + fifo_[k + 1] * t;
    pos += ratio;
  }
  const auto consumed = static_cast<size_t>(pos);
  fifo_.erase(fifo_.begin(), fifo_.begin() + static_cast<std::ptrdiff_t>(consumed));
  frac_ = pos - static_cast<double>(consumed);
  stats_.stretch = ratio;
  stats_.drift_estimate = integral_;
  stats_.current_delay_ms = DelayMs(now);
  return out;
}

}  // namespace holo::audio
