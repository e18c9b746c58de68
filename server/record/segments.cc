#include "server/record/segments.h"

#include <cstdio>
#include <filesystem>
#include <memory>

#include <nlohmann/json.hpp>

#include "common/file_util.h"
#include "server/record/recording_writer.h"

namespace holo::record {

StatusOr<std::vector<SegmentInfo>> CutSegments(const RecordingReader& reader, int64_t target_us,
                                               const std::string& dir) {
  if (target_us < 100000) return InvalidArgument("segment length must be ≥ 0.1 s");
  HOLO_RETURN_IF_ERROR(MakeDirs(dir));
  const RecordingSummary& sum = reader.summary();
  std::vector<SegmentInfo> segments;
  std::unique_ptr<RecordingWriter> writer;
  uint64_t rig_offset = sum.data_begin;
  int64_t segment_start = 0;

  auto finish = [&]() -> Status {
    if (!writer) return OkStatus();
    HOLO_RETURN_IF_ERROR(writer->Close());
    SegmentInfo& s = segments.back();
    s.messages = writer->stats().messages;
    s.end_us = writer->stats().duration_us;
    s.bytes = std::filesystem::file_size(dir + "/" + s.file);
    writer.reset();
    return OkStatus();
  };
  auto start = [&](int64_t time_us) -> Status {
    HOLO_RETURN_IF_ERROR(finish());
    char name[32];
    std::snprintf(name, sizeof(name), "seg_%05zu.hrec", segments.size());
    RecordingWriterOptions o;
    o.source = sum.file.source;
    o.file_flags = kFileFlagSegment;
    o.sync_every_bytes = 0;
    HOLO_ASSIGN_OR_RETURN(writer, RecordingWriter::Create(dir + "/" + name, o, /*overwrite=*/true));
    segments.push_back({name, time_us, time_us, 0, 0});
    segment_start = time_us;
    // The Rig in effect opens every segment, stamped with the segment's start.
    HOLO_ASSIGN_OR_RETURN(RecordedMessage rig, reader.ReadAt(rig_offset));
    return writer->WriteMessage(time_us, *rig.bytes);
  };

  uint64_t at = sum.data_begin;
  bool first = true;
  while (at < sum.data_end) {
    HOLO_ASSIGN_OR_RETURN(RecordedMessage m, reader.ReadAt(at));
    at = m.next_offset;
    const bool key = m.header.type == protocol::MessageType::kMeshFrame && (m.header.flags & protocol::kFlagKeyFrame);
    if (m.header.type == protocol::MessageType::kRig) {
      rig_offset = m.offset;
      if (first) {  // the first segment starts at the recording's start, with its Rig
        first = false;
        HOLO_RETURN_IF_ERROR(start(m.time_us));
        continue;
      }
    }
    if (key && m.time_us - segment_start >= target_us) HOLO_RETURN_IF_ERROR(start(m.time_us));
    HOLO_RETURN_IF_ERROR(writer->WriteMessage(m.time_us, *m.bytes));
  }
  HOLO_RETURN_IF_ERROR(finish());

  nlohmann::json j;
  j["source"] = sum.file.source;
  j["duration_us"] = sum.duration_us;
  j["target_segment_us"] = target_us;
  j["segments"] = nlohmann::json::array();
  for (const SegmentInfo& s : segments)
    j["segments"].push_back(
        {{"file", s.file}, {"start_us", s.start_us}, {"end_us", s.end_us}, {"bytes", s.bytes}, {"messages", s.messages}});
  HOLO_RETURN_IF_ERROR(WriteStringToFile(dir + "/manifest.json", j.dump(2) + "\n"));
  return segments;
}

}  // namespace holo::record
