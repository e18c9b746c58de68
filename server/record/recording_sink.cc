#include "server/record/recording_sink.h"

#include <algorithm>

namespace holo::record {

RecordingSink::RecordingSink(RecordingWriter* writer, uint32_t max_message_bytes, size_t max_in_progress)
    : writer_(writer), max_message_bytes_(max_message_bytes), max_in_progress_(max_in_progress) {}

Status RecordingSink::AddFrame(const protocol::Frame& frame, int64_t receive_time_us) {
  stats_.frames += 1;
  const protocol::Header& h = frame.header;
  if (frame.payload.size() != h.payload_length)
    return DataLoss("recording sink: frame payload of " + std::to_string(frame.payload.size()) +
                    " bytes, header says " + std::to_string(h.payload_length));
  const auto key = std::make_pair(h.stream_id, static_cast<uint16_t>(h.type));
  auto it = partial_.find(key);
  const bool more = (h.flags & protocol::kFlagMoreFragments) != 0;
  if (it == partial_.end() && !more) {
    if (!IsRecordable(h.type)) {
      stats_.ignored_types += 1;
      return OkStatus();
    }
    return Write(h, frame.payload, receive_time_us);
  }
  if (it == partial_.end()) {
    if (partial_.size() >= max_in_progress_)
      return DataLoss("recording sink: more than " + std::to_string(max_in_progress_) + " messages in progress");
    it = partial_.emplace(key, Partial{h, {}}).first;
  } else if (it->second.first.sequence != h.sequence || it->second.first.capture_time_us != h.capture_time_us) {
    return DataLoss("recording sink: fragment of " + std::string(protocol::MessageTypeName(h.type)) + " stream " +
                    std::to_string(h.stream_id) + " does not match the message in progress");
  }
  Partial& p = it->second;
  if (p.payload.size() + frame.payload.size() > max_message_bytes_)
    return DataLoss("recording sink: reassembled " + std::string(protocol::MessageTypeName(h.type)) + " over " +
                    std::to_string(max_message_bytes_) + " bytes");
  p.payload.insert(p.payload.end(), frame.payload.begin(), frame.payload.end());
  if (more) return OkStatus();
  Partial done = std::move(p);
  partial_.erase(it);
  if (!IsRecordable(h.type)) {
    stats_.ignored_types += 1;
    return OkStatus();
  }
  // The whole message keeps the first fragment's flags, without MORE_FRAGMENTS.
  return Write(done.first, done.payload, receive_time_us);
}

Status RecordingSink::Write(const protocol::Header& first, const std::vector<uint8_t>& payload,
                            int64_t receive_time_us) {
  if (!have_rig_) {
    if (first.type != protocol::MessageType::kRig) {
      stats_.before_rig += 1;
      return OkStatus();
    }
    have_rig_ = true;
    origin_us_ = receive_time_us;
  }
  protocol::Header h = first;
  h.flags = static_cast<uint16_t>(h.flags & ~protocol::kFlagMoreFragments);
  h.payload_length = static_cast<uint32_t>(payload.size());
  scratch_.resize(protocol::kHeaderSize + payload.size());
  protocol::EncodeHeader(h, scratch_.data());
  std::copy(payload.begin(), payload.end(), scratch_.begin() + protocol::kHeaderSize);
  const int64_t t = std::max(last_time_us_, receive_time_us - origin_us_);
  Status s = writer_->WriteMessage(t, scratch_);
  if (s.code() == StatusCode::kInvalidArgument) {
    stats_.rejected += 1;  // a bad message is not recorded; the recording goes on
    return OkStatus();
  }
  if (!s.ok()) return s;
  last_time_us_ = t;
  stats_.recorded += 1;
  return OkStatus();
}

}  // namespace holo::record
