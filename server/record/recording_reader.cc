#include "server/record/recording_reader.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "server/record/recording_writer.h"

namespace holo::record {
namespace {

std::string At(uint64_t offset) { return "offset " + std::to_string(offset) + ": "; }

}  // namespace

std::string FormatSeconds(int64_t us) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.3f s", static_cast<double>(us) * 1e-6);
  return buf;
}

RecordingReader::~RecordingReader() {
  if (fd_ >= 0) ::close(fd_);
}

Status RecordingReader::ReadExact(uint64_t offset, uint8_t* out, size_t size) const {
  size_t done = 0;
  while (done < size) {
    const ssize_t n = ::pread(fd_, out + done, size - done, static_cast<off_t>(offset + done));
    if (n < 0) {
      if (errno == EINTR) continue;
      return Unavailable(path_ + ": read failed at " + At(offset) + std::strerror(errno));
    }
    if (n == 0) return DataLoss(path_ + ": " + At(offset) + "file ended early (was it truncated while open?)");
    done += static_cast<size_t>(n);
  }
  return OkStatus();
}

StatusOr<std::unique_ptr<RecordingReader>> RecordingReader::Open(const std::string& path,
                                                                 RecordingReaderOptions options) {
  if (options.max_message_bytes < 64 || options.max_message_bytes > (64u << 20))
    return InvalidArgument("max_message_bytes must be in [64, 64 MiB]");
  std::unique_ptr<RecordingReader> r(new RecordingReader());
  r->path_ = path;
  r->options_ = options;
  r->limits_.max_message_bytes = options.max_message_bytes;
  r->limits_.max_frame_payload = options.max_message_bytes;
  r->fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (r->fd_ < 0) {
    const int e = errno;
    if (e == ENOENT) return NotFound(path + ": no such recording");
    return Unavailable(path + ": cannot open: " + std::strerror(e));
  }
  struct stat st;
  if (::fstat(r->fd_, &st) != 0) return Unavailable(path + ": fstat: " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) return InvalidArgument(path + ": not a regular file");
  RecordingSummary& s = r->summary_;
  s.file_bytes = static_cast<uint64_t>(st.st_size);
  uint8_t fh[kFileHeaderSize];
  if (s.file_bytes < kFileHeaderSize)
    return DataLoss(path + ": " + std::to_string(s.file_bytes) + " bytes, too short for a recording header (" +
                    std::to_string(kFileHeaderSize) + ")");
  HOLO_RETURN_IF_ERROR(r->ReadExact(0, fh, sizeof(fh)));
  auto header = DecodeFileHeader(fh);
  if (!header.ok()) return header.status().WithContext(path);
  s.file = *header;

  bool used_footer = false;
  HOLO_RETURN_IF_ERROR(r->OpenFromFooter(&used_footer));
  if (!used_footer) HOLO_RETURN_IF_ERROR(r->Scan());
  if (s.num_messages == 0)
    return DataLoss(path + ": the recording holds no complete message (not even the Rig)" +
                    (s.tail_note.empty() ? std::string() : "; " + s.tail_note));
  // The first message must be the Rig; keep it.
  HOLO_ASSIGN_OR_RETURN(RecordedMessage first, r->ReadAt(s.data_begin));
  if (first.header.type != protocol::MessageType::kRig)
    return DataLoss(path + ": the first message is " + protocol::MessageTypeName(first.header.type) +
                    ", a recording starts with the Rig");
  auto payload = protocol::DecodePayload(protocol::MessageType::kRig,
                                         std::span<const uint8_t>(*first.bytes).subspan(protocol::kHeaderSize),
                                         r->limits_);
  if (!payload.ok()) return payload.status().WithContext(path + ": rig");
  r->rig_ = std::get<protocol::RigMessage>(*payload).rig;
  return r;
}

Status RecordingReader::ReadRecord(uint64_t offset, uint64_t limit, RecordHeader* header,
                                   uint8_t raw[kRecordHeaderSize], std::vector<uint8_t>* body) const {
  if (offset < kFileHeaderSize || offset > limit || limit - offset < kRecordHeaderSize)
    return DataLoss(path_ + ": " + At(offset) + "no record fits there");
  HOLO_RETURN_IF_ERROR(ReadExact(offset, raw, kRecordHeaderSize));
  auto h = DecodeRecordHeader(std::span<const uint8_t>(raw, kRecordHeaderSize));
  if (!h.ok()) return h.status().WithContext(path_ + ": " + At(offset));
  const uint64_t room = limit - offset - kRecordHeaderSize;
  if (h->body_length > room)
    return DataLoss(path_ + ": " + At(offset) + "record of " + std::to_string(h->body_length) + " bytes, only " +
                    std::to_string(room) + " remain");
  switch (h->kind) {
    case RecordKind::kMessage:
      if (h->body_length < protocol::kHeaderSize || h->body_length > options_.max_message_bytes + protocol::kHeaderSize)
        return DataLoss(path_ + ": " + At(offset) + "message record of " + std::to_string(h->body_length) +
                        " bytes is outside [32, max message + 32]");
      break;
    case RecordKind::kIndex:
      if (h->body_length > kIndexFixedSize + options_.max_index_entries * kIndexEntrySize)
        return DataLoss(path_ + ": " + At(offset) + "index of " + std::to_string(h->body_length) +
                        " bytes is over the limit");
      break;
    case RecordKind::kEnd:
      if (h->body_length != 8) return DataLoss(path_ + ": " + At(offset) + "end record must have 8 bytes");
      break;
  }
  body->resize(h->body_length);
  HOLO_RETURN_IF_ERROR(ReadExact(offset + kRecordHeaderSize, body->data(), body->size()));
  if (!RecordCrcMatches(std::span<const uint8_t>(raw, kRecordHeaderSize), *body))
    return DataLoss(path_ + ": " + At(offset) + "record checksum mismatch (corrupt)");
  *header = *h;
  return OkStatus();
}

Status RecordingReader::CheckMessage(uint64_t offset, const RecordHeader& rh, const std::vector<uint8_t>& body,
                                     protocol::Header* out) const {
  auto ph = protocol::DecodeHeader(body.data(), body.size(), limits_);
  if (!ph.ok()) return ph.status().WithContext(path_ + ": " + At(offset) + "message header");
  if (ph->payload_length != body.size() - protocol::kHeaderSize)
    return DataLoss(path_ + ": " + At(offset) + "message header says " + std::to_string(ph->payload_length) +
                    " payload bytes, the record holds " + std::to_string(body.size() - protocol::kHeaderSize));
  if (ph->flags & protocol::kFlagMoreFragments)
    return DataLoss(path_ + ": " + At(offset) + "a fragment in a recording (messages are stored whole)");
  if (!IsRecordable(ph->type))
    return DataLoss(path_ + ": " + At(offset) + "message type " + protocol::MessageTypeName(ph->type) +
                    " does not belong in a recording");
  (void)rh;
  *out = *ph;
  return OkStatus();
}

Status RecordingReader::OpenFromFooter(bool* used) {
  *used = false;
  RecordingSummary& s = summary_;
  if (s.file_bytes < kFileHeaderSize + FooterBytes(0)) return OkStatus();
  const uint64_t end_offset = s.file_bytes - kEndRecordSize;
  uint8_t raw[kRecordHeaderSize];
  RecordHeader eh;
  std::vector<uint8_t> body;
  // No valid end record: the file was not closed; scan it.
  if (!ReadRecord(end_offset, s.file_bytes, &eh, raw, &body).ok() || eh.kind != RecordKind::kEnd) return OkStatus();
  uint64_t index_offset = 0;
  std::memcpy(&index_offset, body.data(), 8);
  // From here on the end record is genuine: a bad index is damage, not a torn tail.
  if (index_offset < kFileHeaderSize || index_offset > end_offset)
    return DataLoss(path_ + ": end record points to an index at " + std::to_string(index_offset) +
                    ", outside the file");
  RecordHeader ih;
  HOLO_RETURN_IF_ERROR(ReadRecord(index_offset, end_offset, &ih, raw, &body));
  if (ih.kind != RecordKind::kIndex) return DataLoss(path_ + ": " + At(index_offset) + "expected the index record");
  if (index_offset + kRecordHeaderSize + body.size() != end_offset)
    return DataLoss(path_ + ": " + At(index_offset) + "bytes between the index and the end record");
  auto index = DecodeIndexBody(body, kFileHeaderSize, index_offset);
  if (!index.ok()) return index.status().WithContext(path_);
  if (index->entries.size() > options_.max_index_entries) return DataLoss(path_ + ": index over the entry limit");
  if (index->num_messages == 0) return DataLoss(path_ + ": index says the recording holds no message");
  if (ih.time_us != index->duration_us) return DataLoss(path_ + ": index duration does not match its record time");
  s.clean = true;
  s.data_end = index_offset;
  s.num_messages = index->num_messages;
  s.duration_us = index->duration_us;
  s.index = std::move(index->entries);
  *used = true;
  return OkStatus();
}

Status RecordingReader::Scan() {
  RecordingSummary& s = summary_;
  const uint64_t size = s.file_bytes;
  uint64_t offset = kFileHeaderSize;
  uint64_t rig_offset = 0;
  int64_t last_time = 0;
  bool have_rig = false;
  std::vector<uint8_t> body;
  std::string damage;
  bool torn = false;
  while (offset < size) {
    uint8_t raw[kRecordHeaderSize];
    const uint64_t remain = size - offset;
    if (remain < kRecordHeaderSize) {
      torn = true;
      damage = "the last record's header is cut off";
      break;
    }
    HOLO_RETURN_IF_ERROR(ReadExact(offset, raw, kRecordHeaderSize));
    auto rh = DecodeRecordHeader(std::span<const uint8_t>(raw, kRecordHeaderSize));
    if (!rh.ok()) {
      damage = rh.status().message();
      break;
    }
    if (rh->body_length > remain - kRecordHeaderSize) {
      torn = true;
      damage = "the last record is cut off (" + std::to_string(remain - kRecordHeaderSize) + " of " +
               std::to_string(rh->body_length) + " bytes)";
      break;
    }
    RecordHeader h;
    Status st = ReadRecord(offset, size, &h, raw, &body);
    if (!st.ok()) {
      damage = st.message();
      break;
    }
    if (h.kind != RecordKind::kMessage) {
      // An index (and end record) that did not validate as a footer: the
      // data ends here.
      damage = "an incomplete index after the last message";
      torn = true;
      break;
    }
    protocol::Header ph;
    st = CheckMessage(offset, h, body, &ph);
    if (st.ok() && !have_rig && ph.type != protocol::MessageType::kRig)
      st = DataLoss(path_ + ": " + At(offset) + "the first message is not the Rig");
    if (st.ok() && h.time_us < last_time)
      st = DataLoss(path_ + ": " + At(offset) + "message time goes back");
    if (!st.ok()) {
      damage = st.message();
      break;
    }
    last_time = h.time_us;
    if (ph.type == protocol::MessageType::kRig) {
      rig_offset = offset;
      have_rig = true;
    }
    if (ph.type == protocol::MessageType::kMeshFrame && (ph.flags & protocol::kFlagKeyFrame)) {
      if (s.index.size() >= options_.max_index_entries)
        return DataLoss(path_ + ": more than " + std::to_string(options_.max_index_entries) + " key frames");
      s.index.push_back({h.time_us, offset, rig_offset});
    }
    s.num_messages += 1;
    s.duration_us = h.time_us;
    offset += kRecordHeaderSize + body.size();
  }
  s.data_end = offset;
  s.clean = false;
  if (offset < size) {
    s.ignored_tail_bytes = size - offset;
    if (!torn) {
      // Zeros to the end (a crash after the file grew) count as a torn tail.
      bool zeros = true;
      std::vector<uint8_t> chunk(64 * 1024);
      for (uint64_t at = offset; at < size && zeros;) {
        const size_t n = static_cast<size_t>(std::min<uint64_t>(chunk.size(), size - at));
        HOLO_RETURN_IF_ERROR(ReadExact(at, chunk.data(), n));
        zeros = std::all_of(chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(n),
                            [](uint8_t b) { return b == 0; });
        at += n;
      }
      torn = zeros;
      if (zeros) damage = "zero bytes after the last message";
    }
    if (!torn && !options_.salvage)
      return DataLoss(path_ + ": damaged at " + At(offset) + damage + "; " + std::to_string(size - offset) +
                      " bytes follow; " + std::to_string(s.num_messages) +
                      " messages before it are intact (open with salvage / --salvage to read them)");
    s.tail_note = "not closed cleanly; ignored " + std::to_string(size - offset) + " bytes at " + At(offset) + damage;
  } else {
    s.tail_note = "not closed cleanly (no index); index rebuilt by scanning";
  }
  return OkStatus();
}

StatusOr<RecordedMessage> RecordingReader::ReadAt(uint64_t offset) const {
  if (offset < summary_.data_begin || offset >= summary_.data_end)
    return OutOfRange(path_ + ": " + At(offset) + "outside the recorded messages [" +
                      std::to_string(summary_.data_begin) + ", " + std::to_string(summary_.data_end) + ")");
  RecordHeader h;
  uint8_t raw[kRecordHeaderSize];
  auto body = std::make_shared<std::vector<uint8_t>>();
  HOLO_RETURN_IF_ERROR(ReadRecord(offset, summary_.data_end, &h, raw, body.get()));
  if (h.kind != RecordKind::kMessage) return DataLoss(path_ + ": " + At(offset) + "expected a message record");
  RecordedMessage m;
  HOLO_RETURN_IF_ERROR(CheckMessage(offset, h, *body, &m.header));
  m.offset = offset;
  m.next_offset = offset + kRecordHeaderSize + body->size();
  m.time_us = h.time_us;
  m.bytes = std::move(body);
  return m;
}

const IndexEntry* RecordingReader::KeyFrameAtOrBefore(int64_t time_us) const {
  const auto& idx = summary_.index;
  auto it = std::upper_bound(idx.begin(), idx.end(), time_us,
                             [](int64_t t, const IndexEntry& e) { return t < e.time_us; });
  if (it == idx.begin()) return nullptr;
  return &*(it - 1);
}

}  // namespace holo::record
