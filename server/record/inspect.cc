#include "server/record/inspect.h"

#include <cstdio>
#include <iterator>

#include <nlohmann/json.hpp>

#include "common/mesh.h"
#include "protocol/geometry_codec.h"

namespace holo::record {

StatusOr<RecordingInspection> InspectRecording(const RecordingReader& reader, bool deep) {
  RecordingInspection in;
  const RecordingSummary& sum = reader.summary();
  uint64_t at = sum.data_begin;
  int64_t last_key = -1, last_time = -1;
  Mesh mesh;
  while (at < sum.data_end) {
    HOLO_ASSIGN_OR_RETURN(RecordedMessage m, reader.ReadAt(at));
    at = m.next_offset;
    const auto type = static_cast<uint16_t>(m.header.type);
    auto payload = protocol::DecodePayload(m.header,
                                           std::span<const uint8_t>(*m.bytes).subspan(protocol::kHeaderSize));
    if (!payload.ok())
      return payload.status().WithContext(reader.path() + ": offset " + std::to_string(m.offset) + ": " +
                                          protocol::MessageTypeName(m.header.type));
    in.messages += 1;
    HOLO_CHECK(type < std::size(in.by_type));  // the reader passes recordable types only
    in.by_type[type] += 1;
    in.payload_bytes_by_type[type] += m.header.payload_length;
    if (last_time >= 0) in.max_message_gap_us = std::max(in.max_message_gap_us, m.time_us - last_time);
    last_time = m.time_us;
    if (m.header.type == protocol::MessageType::kRig) in.rigs += 1;
    if (m.header.type == protocol::MessageType::kMeshFrame) {
      const auto& mf = std::get<protocol::MeshFrame>(*payload);
      in.mesh_frames += 1;
      if (in.first_frame_index < 0) in.first_frame_index = mf.frame_index;
      in.last_frame_index = mf.frame_index;
      if (m.header.flags & protocol::kFlagKeyFrame) {
        in.key_frames += 1;
        if (last_key >= 0) in.max_key_gap_us = std::max(in.max_key_gap_us, m.time_us - last_key);
        last_key = m.time_us;
      }
      if (deep) {
        Status s = protocol::DecodeGeometry(mf.data, &mesh);
        if (!s.ok())
          return s.WithContext(reader.path() + ": offset " + std::to_string(m.offset) + ": frame " +
                               std::to_string(mf.frame_index));
        in.decoded_meshes += 1;
      }
    }
  }
  if (in.messages != sum.num_messages)
    return DataLoss(reader.path() + ": the index says " + std::to_string(sum.num_messages) + " messages, the file holds " +
                    std::to_string(in.messages));
  if (in.key_frames != sum.index.size())
    return DataLoss(reader.path() + ": the index lists " + std::to_string(sum.index.size()) +
                    " key frames, the file holds " + std::to_string(in.key_frames));
  return in;
}

namespace {

double Mb(uint64_t b) { return static_cast<double>(b) / 1e6; }

double BytesPerMinute(const RecordingSummary& s) {
  if (s.duration_us <= 0) return 0;
  return static_cast<double>(s.data_end) * 60e6 / static_cast<double>(s.duration_us);
}

}  // namespace

std::string InspectionText(const RecordingReader& reader, const RecordingInspection& in) {
  const RecordingSummary& s = reader.summary();
  std::string out;
  char line[512];
  auto add = [&](const char* fmt, auto... args) {
    std::snprintf(line, sizeof(line), fmt, args...);
    out += line;
  };
  add("%s: Holoport recording v%u%s, source '%s'\n", reader.path().c_str(), s.file.format_version,
      (s.file.flags & kFileFlagSegment) ? " (segment)" : "", s.file.source.c_str());
  add("  state      %s\n", s.clean ? "closed cleanly (index read from the footer)" : s.tail_note.c_str());
  add("  duration   %s\n", FormatSeconds(s.duration_us).c_str());
  add("  size       %.3f MB (%llu bytes; %.2f MB per minute)\n", Mb(s.file_bytes),
      static_cast<unsigned long long>(s.file_bytes), Mb(static_cast<uint64_t>(BytesPerMinute(s))));
  add("  messages   %llu: rig %llu, mesh %llu (key %llu, frames %lld..%lld), colour %llu, audio+pose %llu, stats %llu, "
      "regions %llu\n",
      static_cast<unsigned long long>(in.messages), static_cast<unsigned long long>(in.rigs),
      static_cast<unsigned long long>(in.mesh_frames), static_cast<unsigned long long>(in.key_frames),
      static_cast<long long>(in.first_frame_index), static_cast<long long>(in.last_frame_index),
      static_cast<unsigned long long>(in.by_type[6]), static_cast<unsigned long long>(in.by_type[7]),
      static_cast<unsigned long long>(in.by_type[13]), static_cast<unsigned long long>(in.by_type[15]));
  if (in.mesh_frames > 0 && s.duration_us > 0)
    add("  video      %.2f fps, %.1f kB per mesh frame, %.3f Mbit/s geometry\n",
        static_cast<double>(in.mesh_frames > 1 ? in.mesh_frames - 1 : 0) * 1e6 / static_cast<double>(s.duration_us),
        static_cast<double>(in.payload_bytes_by_type[5]) / 1e3 / static_cast<double>(in.mesh_frames),
        static_cast<double>(in.payload_bytes_by_type[5]) * 8 / static_cast<double>(s.duration_us));
  if (!s.index.empty())
    add("  index      %zu key frames, %s .. %s, longest gap %s\n", s.index.size(),
        FormatSeconds(s.index.front().time_us).c_str(), FormatSeconds(s.index.back().time_us).c_str(),
        FormatSeconds(in.max_key_gap_us).c_str());
  else
    out += "  index      empty (no key frame: seeking restarts from the beginning)\n";
  if (in.decoded_meshes > 0) add("  geometry   %llu blobs decoded\n", static_cast<unsigned long long>(in.decoded_meshes));
  out += "  valid      yes (every record checksum, header and payload checked)\n";
  return out;
}

std::string InspectionJson(const RecordingReader& reader, const RecordingInspection& in) {
  const RecordingSummary& s = reader.summary();
  nlohmann::json j;
  j["file"] = reader.path();
  j["source"] = s.file.source;
  j["segment"] = (s.file.flags & kFileFlagSegment) != 0;
  j["clean"] = s.clean;
  j["tail_note"] = s.tail_note;
  j["ignored_tail_bytes"] = s.ignored_tail_bytes;
  j["duration_us"] = s.duration_us;
  j["file_bytes"] = s.file_bytes;
  j["bytes_per_minute"] = BytesPerMinute(s);
  j["messages"] = in.messages;
  j["mesh_frames"] = in.mesh_frames;
  j["key_frames"] = in.key_frames;
  j["audio_pose"] = in.by_type[7];
  j["color_frames"] = in.by_type[6];
  j["regions"] = in.by_type[15];
  j["rigs"] = in.rigs;
  j["index_entries"] = s.index.size();
  j["max_key_gap_us"] = in.max_key_gap_us;
  j["decoded_meshes"] = in.decoded_meshes;
  j["valid"] = true;
  return j.dump();
}

}  // namespace holo::record
