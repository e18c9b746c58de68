// Cutting a recording into independently playable segments for an HTTP
// cache tier (docs/recording.md): each segment is itself a recording file
// (flag "segment" in its header) that starts with the Rig in effect and a
// MeshFrame key frame, so a viewer can start at any segment; a JSON manifest
// lists them with their media time range.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/status.h"
#include "server/record/recording_reader.h"

namespace holo::record {

struct SegmentInfo {
  std::string file;        // name inside the output directory
  int64_t start_us = 0;    // media time of its first key frame
  int64_t end_us = 0;      // media time of its last message
  uint64_t bytes = 0;
  uint64_t messages = 0;
};

// Writes seg_NNNNN.hrec files of about `target_us` of media each (cut at the
// first key frame at or after the target) and `manifest.json` into `dir`.
StatusOr<std::vector<SegmentInfo>> CutSegments(const RecordingReader& reader, int64_t target_us,
                                               const std::string& dir);

}  // namespace holo::record
