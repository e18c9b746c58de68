// Parsing the live broadcast's parts (docs/broadcast.md §2): a part is message
// records back to back (24-byte record header + one whole protocol frame),
// exactly the bytes the segment file holds after its file header. Safe on
// untrusted input: every length is checked against the bytes that remain and
// the limit before anything is copied, every CRC and protocol header checked.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "common/status.h"
#include "protocol/messages.h"

namespace holo::record {

struct LiveRecord {
  int64_t time_us = 0;          // broadcast time (µs since the availability start)
  protocol::Header header;      // the frame's protocol header
  std::span<const uint8_t> frame;  // the whole frame (header + payload), borrowed from the input
};

// Splits `bytes` into message records. DataLoss naming the record index and
// byte offset for: a bad magic, kind other than message, reserved bytes, a
// body shorter than a frame header or over `max_message_bytes` + 32, a body
// past the end (a truncated part), a CRC mismatch, a protocol header that does
// not decode, says MORE_FRAGMENTS or disagrees with the body length, or a
// time that goes back. An empty input is DataLoss too (a part holds ≥ 1
// record). The spans borrow `bytes`.
StatusOr<std::vector<LiveRecord>> ParseLiveRecords(std::span<const uint8_t> bytes,
                                                   uint32_t max_message_bytes = 64u << 20);

}  // namespace holo::record
