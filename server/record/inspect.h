// Full validation and statistics of a recording (holoport-record --info).
#pragma once

#include <cstdint>
#include <string>

#include "common/status.h"
#include "server/record/recording_reader.h"

namespace holo::record {

struct RecordingInspection {
  uint64_t messages = 0;
  uint64_t by_type[16] = {};  // indexed by message type (1..15)
  uint64_t payload_bytes_by_type[16] = {};
  uint64_t mesh_frames = 0;
  uint64_t key_frames = 0;
  int64_t first_frame_index = -1, last_frame_index = -1;
  int64_t max_key_gap_us = 0;       // longest media time between consecutive key frames
  int64_t max_message_gap_us = 0;   // longest media time between consecutive messages
  uint64_t rigs = 0;
  uint64_t decoded_meshes = 0;      // deep: geometry blobs decoded
};

// Reads every message (record CRC, protocol header, payload decode); with
// `deep` also decodes every geometry blob. Fails at the first bad message
// with an error naming its offset.
StatusOr<RecordingInspection> InspectRecording(const RecordingReader& reader, bool deep);

// A human-readable report (several lines) and a JSON object of the same.
std::string InspectionText(const RecordingReader& reader, const RecordingInspection& in);
std::string InspectionJson(const RecordingReader& reader, const RecordingInspection& in);

}  // namespace holo::record
