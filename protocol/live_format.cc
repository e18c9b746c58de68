#include "protocol/live_format.h"

#include <string>

#include "protocol/recording_format.h"

namespace holo::record {

StatusOr<std::vector<LiveRecord>> ParseLiveRecords(std::span<const uint8_t> bytes, uint32_t max_message_bytes) {
  if (bytes.empty()) return DataLoss("live part: empty");
  std::vector<LiveRecord> out;
  protocol::Limits limits;
  size_t at = 0;
  int64_t last = 0;
  while (at < bytes.size()) {
    const std::string where = "live part: record " + std::to_string(out.size()) + " at byte " + std::to_string(at);
    if (bytes.size() - at < kRecordHeaderSize) return DataLoss(where + ": truncated record header");
    auto rh = DecodeRecordHeader(bytes.subspan(at, kRecordHeaderSize));
    if (!rh.ok()) return DataLoss(where + ": " + rh.status().message());
    if (rh->kind != RecordKind::kMessage) return DataLoss(where + ": not a message record");
    if (rh->body_length < protocol::kHeaderSize ||
        rh->body_length - protocol::kHeaderSize > static_cast<uint64_t>(max_message_bytes))
      return DataLoss(where + ": body length " + std::to_string(rh->body_length) + " out of range");
    if (rh->body_length > bytes.size() - at - kRecordHeaderSize)
      return DataLoss(where + ": body of " + std::to_string(rh->body_length) + " bytes runs past the end");
    const auto header_bytes = bytes.subspan(at, kRecordHeaderSize);
    const auto body = bytes.subspan(at + kRecordHeaderSize, rh->body_length);
    if (!RecordCrcMatches(header_bytes, body)) return DataLoss(where + ": CRC mismatch");
    if (rh->time_us < 0 || rh->time_us < last) return DataLoss(where + ": time goes back");
    limits.max_frame_payload = max_message_bytes;  // recorded messages are whole, not fragments
    auto h = protocol::DecodeHeader(body.data(), body.size(), limits);
    if (!h.ok()) return DataLoss(where + ": protocol header: " + h.status().message());
    if (h->flags & protocol::kFlagMoreFragments) return DataLoss(where + ": a fragment");
    if (h->payload_length != body.size() - protocol::kHeaderSize)
      return DataLoss(where + ": protocol header says " + std::to_string(h->payload_length) + " payload bytes");
    out.push_back({rh->time_us, *h, body});
    last = rh->time_us;
    at += kRecordHeaderSize + rh->body_length;
  }
  return out;
}

}  // namespace holo::record
