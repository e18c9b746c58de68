// The recorder's side of a connection: takes the frames a recorder client
// receives (fragments of several messages interleaved, as on the wire),
// reassembles each message's exact bytes, and appends content messages to a
// RecordingWriter with media time = receive time since the first Rig. This is
// the small interface the network client plugs into (holoport-record
// --connect, when the client library exists):
//
//   RecordingSink sink(writer.get());
//   on every frame received:  Status s = sink.AddFrame(frame, clock.NowUs());
//   s not OK → DataLoss: the stream is malformed (close the connection);
//              OutOfRange / Unavailable: the recording ended (size limit, disk full).
#pragma once

#include <cstdint>
#include <map>
#include <utility>
#include <vector>

#include "common/status.h"
#include "protocol/messages.h"
#include "server/record/recording_writer.h"

namespace holo::record {

struct RecordingSinkStats {
  uint64_t frames = 0;
  uint64_t recorded = 0;            // messages written
  uint64_t ignored_types = 0;       // session messages (Welcome, Ping, …) not recorded
  uint64_t before_rig = 0;          // content dropped because no Rig had arrived yet
  uint64_t rejected = 0;            // messages the writer refused as invalid
};

class RecordingSink {
 public:
  // `writer` must outlive the sink. `max_in_progress`: messages being
  // reassembled at once (PROTOCOL.md §2: 16).
  explicit RecordingSink(RecordingWriter* writer, uint32_t max_message_bytes = 64u << 20, size_t max_in_progress = 16);

  // One frame as cut from the byte stream (protocol::FrameParser) and the
  // receive time (any monotonic µs clock).
  Status AddFrame(const protocol::Frame& frame, int64_t receive_time_us);

  const RecordingSinkStats& stats() const { return stats_; }

 private:
  Status Write(const protocol::Header& first, const std::vector<uint8_t>& payload, int64_t receive_time_us);

  struct Partial {
    protocol::Header first;
    std::vector<uint8_t> payload;
  };
  RecordingWriter* writer_;
  uint32_t max_message_bytes_;
  size_t max_in_progress_;
  std::map<std::pair<uint32_t, uint16_t>, Partial> partial_;
  bool have_rig_ = false;
  int64_t origin_us_ = 0;
  int64_t last_time_us_ = 0;
  std::vector<uint8_t> scratch_;
  RecordingSinkStats stats_;
};

}  // namespace holo::record
