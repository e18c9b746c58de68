#include "server/record/live_packager.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <utility>

#include <nlohmann/json.hpp>

#include "common/file_util.h"
#include "protocol/messages.h"
#include "protocol/recording_format.h"

namespace holo::record {
namespace {

bool Packaged(protocol::MessageType t) {
  using protocol::MessageType;
  return t == MessageType::kRig || t == MessageType::kMeshFrame || t == MessageType::kColorFrame ||
         t == MessageType::kAudioPose || t == MessageType::kStats;
}

// Writes `data` to dir/.name.tmp, then renames it to dir/name: a reader (the
// origin) sees the whole file or none.
Status WriteAtomically(const std::string& dir, const std::string& name, std::span<const uint8_t> data) {
  const std::string tmp = dir + "/." + name + ".tmp";
  const std::string path = dir + "/" + name;
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return Unavailable("cannot create " + tmp + ": " + std::strerror(errno));
  size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = std::strerror(errno);
      ::close(fd);
      ::unlink(tmp.c_str());
      return Unavailable("writing " + tmp + " failed: " + why);
    }
    done += static_cast<size_t>(n);
  }
  if (::close(fd) != 0) return Unavailable("closing " + tmp + " failed: " + std::strerror(errno));
  if (::rename(tmp.c_str(), path.c_str()) != 0)
    return Unavailable("renaming " + tmp + " to " + path + " failed: " + std::strerror(errno));
  return OkStatus();
}

// "seg_00042.p3" / "seg_00042.hrec" → 42; false for any other name.
bool SegmentNumberOf(const std::string& name, uint64_t* number) {
  if (name.rfind("seg_", 0) != 0) return false;
  size_t i = 4;
  uint64_t v = 0;
  while (i < name.size() && name[i] >= '0' && name[i] <= '9') {
    if (i - 4 >= 15) return false;
    v = v * 10 + static_cast<uint64_t>(name[i] - '0');
    ++i;
  }
  if (i == 4 || i >= name.size() || name[i] != '.') return false;
  *number = v;
  return true;
}

}  // namespace

std::string LiveSegmentFileName(uint64_t number) {
  char b[40];
  std::snprintf(b, sizeof(b), "seg_%05llu.hrec", static_cast<unsigned long long>(number));
  return b;
}

std::string LivePartName(uint64_t number, uint64_t part) {
  char b[48];
  std::snprintf(b, sizeof(b), "seg_%05llu.p%llu", static_cast<unsigned long long>(number),
                static_cast<unsigned long long>(part));
  return b;
}

Status LivePackagerOptions::Check() const {
  if (dir.empty()) return InvalidArgument("live packager: the output directory is empty");
  if (segment_us < 200000 || segment_us > 60000000)
    return InvalidArgument("live packager: segment length must be 0.2..60 s, got " + std::to_string(segment_us) +
                           " µs");
  if (part_us < 20000 || part_us > segment_us)
    return InvalidArgument("live packager: part length must be 20 ms .. the segment length, got " +
                           std::to_string(part_us) + " µs");
  if (window_segments < 1 || window_segments > 10000)
    return InvalidArgument("live packager: window must be 1..10000 segments, got " +
                           std::to_string(window_segments));
  if (keep_extra_segments < 0 || keep_extra_segments > 10000)
    return InvalidArgument("live packager: keep_extra_segments must be 0..10000, got " +
                           std::to_string(keep_extra_segments));
  if (max_age_ms < 0) return InvalidArgument("live packager: max_age_ms must be ≥ 0");
  if (cache_bucket_ms < 0 || cache_bucket_ms > 60000)
    return InvalidArgument("live packager: cache_bucket_ms must be 0..60000, got " + std::to_string(cache_bucket_ms));
  return OkStatus();
}

LivePackager::LivePackager(LivePackagerOptions options) : options_(std::move(options)) {}

LivePackager::~LivePackager() {
  if (writer_) (void)writer_->Close();  // leaves the temporary file; a restart numbers past it
}

StatusOr<std::unique_ptr<LivePackager>> LivePackager::Open(LivePackagerOptions options, int64_t now_unix_us) {
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_RETURN_IF_ERROR(MakeDirs(options.dir));
  std::unique_ptr<LivePackager> p(new LivePackager(std::move(options)));
  HOLO_RETURN_IF_ERROR(p->Load(now_unix_us));
  return p;
}

Status LivePackager::Load(int64_t now_unix_us) {
  availability_start_ = now_unix_us;
  bool found_any = false;
  uint64_t max_number = 0;
  uint64_t next_floor = 0;  // live.json's next_segment
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(options_.dir, ec)) {
    std::string name = e.path().filename().string();
    if (!name.empty() && name[0] == '.') name = name.substr(1);  // temporaries count too
    uint64_t n = 0;
    if (SegmentNumberOf(name, &n)) {
      found_any = true;
      max_number = std::max(max_number, n);
    }
  }
  if (ec) return Unavailable("cannot list " + options_.dir + ": " + ec.message());

  const std::string manifest = options_.dir + "/live.json";
  if (FileExists(manifest)) {
    HOLO_ASSIGN_OR_RETURN(std::string text, ReadFileToString(manifest));
    nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
    auto bad = [&](const std::string& what) { return DataLoss(manifest + ": " + what); };
    if (!j.is_object()) return bad("not a JSON object");
    if (j.value("format", std::string()) != "holoport-live") return bad("format is not \"holoport-live\"");
    if (!j.contains("version") || !j["version"].is_number_integer() || j["version"].get<int64_t>() != 1)
      return bad("version is not 1");
    if (!j.contains("availability_start_unix_us") || !j["availability_start_unix_us"].is_number_integer())
      return bad("availability_start_unix_us missing");
    availability_start_ = j["availability_start_unix_us"].get<int64_t>();
    if (availability_start_ <= 0 || availability_start_ > now_unix_us)
      return bad("availability_start_unix_us " + std::to_string(availability_start_) + " is not in the past");
    if (j.contains("next_segment") && j["next_segment"].is_number_unsigned()) {
      found_any = true;
      next_floor = j["next_segment"].get<uint64_t>();
    }
    if (!j.contains("segments") || !j["segments"].is_array()) return bad("segments is not an array");
    for (const auto& s : j["segments"]) {
      try {
        LiveSegmentInfo seg;
        seg.number = s.at("number").get<uint64_t>();
        seg.complete = s.at("complete").get<bool>();
        seg.discontinuity = s.at("discontinuity").get<bool>();
        seg.start_us = s.at("start_us").get<int64_t>();
        seg.end_us = s.at("end_us").get<int64_t>();
        seg.bytes = s.at("bytes").get<uint64_t>();
        for (const auto& pj : s.at("parts")) {
          LivePartInfo part;
          part.name = pj.at("name").get<std::string>();
          part.start_us = pj.at("start_us").get<int64_t>();
          part.end_us = pj.at("end_us").get<int64_t>();
          part.bytes = pj.at("bytes").get<uint64_t>();
          part.messages = pj.at("messages").get<uint64_t>();
          part.available_unix_us = pj.at("available_unix_us").get<int64_t>();
          if (part.name != LivePartName(seg.number, seg.parts.size())) return bad("part name " + part.name);
          seg.parts.push_back(std::move(part));
        }
        found_any = true;
        max_number = std::max(max_number, seg.number);
        last_time_ = std::max(last_time_, seg.end_us);
        if (seg.complete && (window_.empty() || seg.number > window_.back().number)) {
          window_.push_back(std::move(seg));
        } else {
          // Never closed (the packager was killed): not listed again; its files
          // go with the next pruning.
          pruned_pending_.push_back(seg.number);
        }
      } catch (const nlohmann::json::exception& e) {
        return bad(std::string("a segment entry: ") + e.what());
      }
    }
  }
  next_segment_ = found_any ? std::max(max_number + 1, next_floor) : 0;
  next_discontinuity_ = found_any;
  last_time_ = std::max(last_time_, now_unix_us - availability_start_);
  return OkStatus();
}

int64_t LivePackager::MediaTime(int64_t unix_us) {
  last_time_ = std::max(last_time_, unix_us - availability_start_);
  return last_time_;
}

Status LivePackager::AddMessage(std::span<const uint8_t> frame, int64_t receive_unix_us) {
  protocol::Limits limits;
  limits.max_frame_payload = limits.max_message_bytes;  // whole messages, not fragments
  if (frame.size() < protocol::kHeaderSize)
    return InvalidArgument("live packager: message of " + std::to_string(frame.size()) + " bytes");
  auto header = protocol::DecodeHeader(frame.data(), frame.size(), limits);
  auto reject = [&](const std::string& why) {
    stats_.rejected += 1;
    return InvalidArgument("live packager: " + why);
  };
  if (!header.ok()) return reject("message header: " + header.status().message());
  if (header->payload_length != frame.size() - protocol::kHeaderSize) return reject("payload length mismatch");
  if (header->flags & protocol::kFlagMoreFragments) return reject("a fragment (reassemble first)");
  if (!Packaged(header->type)) {  // session messages (Ping, Pong, Control, ...): not part of a broadcast
    stats_.ignored_types += 1;
    return OkStatus();
  }
  auto payload = protocol::DecodePayload(*header, frame.subspan(protocol::kHeaderSize), limits);
  if (!payload.ok()) return reject("message payload: " + payload.status().message());

  const int64_t t = MediaTime(receive_unix_us);
  const bool key = header->type == protocol::MessageType::kMeshFrame && (header->flags & protocol::kFlagKeyFrame);
  if (header->type == protocol::MessageType::kRig) rig_.assign(frame.begin(), frame.end());
  if (!open_) {
    if (!key || rig_.empty()) {
      if (header->type != protocol::MessageType::kRig) stats_.dropped_before_key += 1;
      return OkStatus();
    }
    HOLO_RETURN_IF_ERROR(StartSegment(t));
  } else if (key && t - window_.back().start_us >= options_.segment_us) {
    HOLO_RETURN_IF_ERROR(CloseSegment(receive_unix_us));
    HOLO_RETURN_IF_ERROR(StartSegment(t));
  } else if (part_messages_ > 0 && t - part_start_ >= options_.part_us) {
    HOLO_RETURN_IF_ERROR(PublishPart(receive_unix_us));
  }
  HOLO_RETURN_IF_ERROR(writer_->WriteMessage(t, frame));
  uint8_t rh[kRecordHeaderSize];
  EncodeRecordHeader(RecordKind::kMessage, t, frame, rh);
  if (part_messages_ == 0) part_start_ = t;
  part_.insert(part_.end(), rh, rh + kRecordHeaderSize);
  part_.insert(part_.end(), frame.begin(), frame.end());
  part_messages_ += 1;
  part_end_ = t;
  stats_.messages += 1;
  return OkStatus();
}

Status LivePackager::StartSegment(int64_t t) {
  const uint64_t number = next_segment_++;
  RecordingWriterOptions o;
  o.source = options_.source;
  o.file_flags = kFileFlagSegment;
  o.sync_every_bytes = 0;
  o.validate_payloads = false;  // AddMessage decoded it already
  HOLO_ASSIGN_OR_RETURN(writer_, RecordingWriter::Create(options_.dir + "/." + LiveSegmentFileName(number) + ".tmp",
                                                         o, /*overwrite=*/true));
  LiveSegmentInfo seg;
  seg.number = number;
  seg.discontinuity = next_discontinuity_;
  seg.start_us = t;
  seg.end_us = t;
  next_discontinuity_ = false;
  window_.push_back(std::move(seg));
  open_ = true;
  // The Rig in effect opens every segment, stamped with the segment's start.
  HOLO_RETURN_IF_ERROR(writer_->WriteMessage(t, rig_));
  uint8_t rh[kRecordHeaderSize];
  EncodeRecordHeader(RecordKind::kMessage, t, rig_, rh);
  part_.assign(rh, rh + kRecordHeaderSize);
  part_.insert(part_.end(), rig_.begin(), rig_.end());
  part_messages_ = 1;
  part_start_ = part_end_ = t;
  stats_.messages += 1;
  return OkStatus();
}

Status LivePackager::Tick(int64_t now_unix_us) {
  if (!open_ || part_messages_ == 0) return OkStatus();
  if (now_unix_us - availability_start_ - part_start_ < options_.part_us) return OkStatus();
  return PublishPart(now_unix_us);
}

bool LivePackager::WantsKeyFrame(int64_t now_unix_us) {
  if (last_keyframe_request_ != INT64_MIN && now_unix_us - last_keyframe_request_ < options_.part_us) return false;
  const bool due = !open_ || now_unix_us - availability_start_ - window_.back().start_us >= options_.segment_us;
  if (!due) return false;
  last_keyframe_request_ = now_unix_us;
  stats_.keyframe_requests += 1;
  return true;
}

Status LivePackager::PublishPart(int64_t now_unix_us) {
  if (!open_ || part_messages_ == 0) return OkStatus();
  LiveSegmentInfo& seg = window_.back();
  LivePartInfo part;
  part.name = LivePartName(seg.number, seg.parts.size());
  part.start_us = part_start_;
  part.end_us = part_end_;
  part.bytes = part_.size();
  part.messages = part_messages_;
  HOLO_RETURN_IF_ERROR(WriteAtomically(options_.dir, part.name, part_));
  part.available_unix_us = now_unix_us;
  seg.end_us = part_end_;
  seg.bytes += part.bytes;
  seg.parts.push_back(std::move(part));
  part_.clear();
  part_messages_ = 0;
  stats_.parts += 1;
  return WriteManifest(now_unix_us, false);
}

Status LivePackager::CloseSegment(int64_t now_unix_us) {
  if (!open_) return OkStatus();
  HOLO_RETURN_IF_ERROR(PublishPart(now_unix_us));
  LiveSegmentInfo& seg = window_.back();
  HOLO_RETURN_IF_ERROR(writer_->Close());
  writer_.reset();
  const std::string name = LiveSegmentFileName(seg.number);
  const std::string tmp = options_.dir + "/." + name + ".tmp";
  if (::rename(tmp.c_str(), (options_.dir + "/" + name).c_str()) != 0)
    return Unavailable("renaming " + tmp + " failed: " + std::strerror(errno));
  seg.complete = true;
  open_ = false;
  stats_.segments += 1;
  HOLO_RETURN_IF_ERROR(Prune());
  return WriteManifest(now_unix_us, false);
}

Status LivePackager::Prune() {
  while (window_.size() > static_cast<size_t>(options_.window_segments) && window_.front().complete) {
    pruned_pending_.push_back(window_.front().number);
    window_.pop_front();
  }
  while (pruned_pending_.size() > static_cast<size_t>(options_.keep_extra_segments)) {
    const uint64_t n = pruned_pending_.front();
    pruned_pending_.pop_front();
    // Every file of segment n: its parts, the segment file and a temporary left by a killed run.
    std::error_code ec;
    const std::string prefix = LiveSegmentFileName(n).substr(0, LiveSegmentFileName(n).size() - 4);  // "seg_NNNNN."
    std::vector<std::filesystem::path> doomed;
    for (const auto& e : std::filesystem::directory_iterator(options_.dir, ec)) {
      const std::string name = e.path().filename().string();
      if (name.rfind(prefix, 0) == 0 || name.rfind("." + prefix, 0) == 0) doomed.push_back(e.path());
    }
    for (const auto& path : doomed) std::filesystem::remove(path, ec);
    stats_.pruned_segments += 1;
  }
  return OkStatus();
}

Status LivePackager::Discontinuity(int64_t now_unix_us) {
  HOLO_RETURN_IF_ERROR(CloseSegment(now_unix_us));
  next_discontinuity_ = true;
  rig_.clear();  // wait for the new stream's Rig
  return OkStatus();
}

Status LivePackager::Finish(int64_t now_unix_us) {
  HOLO_RETURN_IF_ERROR(CloseSegment(now_unix_us));
  return WriteManifest(now_unix_us, true);
}

Status LivePackager::WriteManifest(int64_t now_unix_us, bool ended) {
  nlohmann::json j;
  j["format"] = "holoport-live";
  j["version"] = 1;
  j["source"] = options_.source;
  j["availability_start_unix_us"] = availability_start_;
  j["published_unix_us"] = now_unix_us;
  j["target_segment_us"] = options_.segment_us;
  j["target_part_us"] = options_.part_us;
  j["update_interval_ms"] = options_.part_us / 1000;
  j["max_age_ms"] = std::max(options_.max_age_ms, options_.cache_bucket_ms);
  j["cache_bucket_ms"] = options_.cache_bucket_ms;
  j["window_segments"] = options_.window_segments;
  j["keep_extra_segments"] = options_.keep_extra_segments;
  j["ended"] = ended;
  j["next_segment"] = next_segment_;
  nlohmann::json segs = nlohmann::json::array();
  for (const LiveSegmentInfo& s : window_) {
    if (s.parts.empty()) continue;  // an open segment is listed once its part 0 exists
    nlohmann::json parts = nlohmann::json::array();
    for (const LivePartInfo& p : s.parts)
      parts.push_back({{"name", p.name},
                       {"start_us", p.start_us},
                       {"end_us", p.end_us},
                       {"bytes", p.bytes},
                       {"messages", p.messages},
                       {"available_unix_us", p.available_unix_us}});
    nlohmann::json sj;
    sj["number"] = s.number;
    sj["file"] = s.complete ? nlohmann::json(LiveSegmentFileName(s.number)) : nlohmann::json(nullptr);
    sj["complete"] = s.complete;
    sj["discontinuity"] = s.discontinuity;
    sj["start_us"] = s.start_us;
    sj["end_us"] = s.end_us;
    sj["bytes"] = s.bytes;
    sj["parts"] = std::move(parts);
    segs.push_back(std::move(sj));
  }
  j["segments"] = std::move(segs);
  const std::string text = j.dump(1) + "\n";
  return WriteAtomically(options_.dir, "live.json",
                         std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
}

}  // namespace holo::record
