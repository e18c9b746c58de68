#include "server/record/recording_writer.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <iterator>

#include "common/log.h"

namespace holo::record {
namespace {

std::string Errno(int e) { return std::strerror(e); }

class PosixRecordingFile final : public RecordingFile {
 public:
  PosixRecordingFile(int fd, std::string path) : fd_(fd), path_(std::move(path)) {}
  ~PosixRecordingFile() override {
    if (fd_ >= 0) ::close(fd_);
  }

  Status WriteAll(const iovec* iov_in, int count, bool* enospc) override {
    *enospc = false;
    std::vector<iovec> iov(iov_in, iov_in + count);
    size_t i = 0;
    while (i < iov.size()) {
      if (iov[i].iov_len == 0) {
        ++i;
        continue;
      }
      const ssize_t n = ::writev(fd_, iov.data() + i, static_cast<int>(iov.size() - i));
      if (n < 0) {
        if (errno == EINTR) continue;
        const int e = errno;
        *enospc = (e == ENOSPC || e == EDQUOT || e == EFBIG);
        return Unavailable(path_ + ": write failed: " + Errno(e));
      }
      if (n == 0) {
        *enospc = true;
        return Unavailable(path_ + ": write made no progress");
      }
      size_t left = static_cast<size_t>(n);
      while (left > 0 && i < iov.size()) {
        const size_t take = std::min(left, iov[i].iov_len);
        iov[i].iov_base = static_cast<uint8_t*>(iov[i].iov_base) + take;
        iov[i].iov_len -= take;
        left -= take;
        if (iov[i].iov_len == 0) ++i;
      }
    }
    return OkStatus();
  }
  Status Truncate(uint64_t size) override {
    if (::ftruncate(fd_, static_cast<off_t>(size)) != 0) return Unavailable(path_ + ": ftruncate: " + Errno(errno));
    if (::lseek(fd_, static_cast<off_t>(size), SEEK_SET) < 0) return Unavailable(path_ + ": lseek: " + Errno(errno));
    return OkStatus();
  }
  Status Sync() override {
    if (::fdatasync(fd_) != 0) return Unavailable(path_ + ": fdatasync: " + Errno(errno));
    return OkStatus();
  }
  Status Close() override {
    if (fd_ < 0) return OkStatus();
    const int r = ::close(fd_);
    fd_ = -1;
    if (r != 0) return Unavailable(path_ + ": close: " + Errno(errno));
    return OkStatus();
  }

 private:
  int fd_;
  std::string path_;
};

std::string Seconds(int64_t us) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3f s", static_cast<double>(us) * 1e-6);
  return buf;
}

}  // namespace

StatusOr<std::unique_ptr<RecordingFile>> OpenPosixRecordingFile(const std::string& path, bool overwrite) {
  const int flags = O_WRONLY | O_CREAT | O_CLOEXEC | (overwrite ? O_TRUNC : O_EXCL);
  const int fd = ::open(path.c_str(), flags, 0644);
  if (fd < 0) {
    const int e = errno;
    if (e == EEXIST)
      return InvalidArgument(path + ": exists; refusing to overwrite a recording (choose another name or pass --overwrite)");
    return Unavailable(path + ": cannot create: " + Errno(e));
  }
  return std::unique_ptr<RecordingFile>(new PosixRecordingFile(fd, path));
}

Status RecordingWriterOptions::Check() const {
  if (max_message_bytes < 64 || max_message_bytes > (64u << 20))
    return InvalidArgument("max_message_bytes must be in [64, 64 MiB], got " + std::to_string(max_message_bytes));
  if (max_bytes != 0 && max_bytes < kFileHeaderSize + FooterBytes(1) + 1024)
    return InvalidArgument("max_bytes " + std::to_string(max_bytes) + " is too small for a recording (at least " +
                           std::to_string(kFileHeaderSize + FooterBytes(1) + 1024) + ")");
  return OkStatus();
}

StatusOr<std::unique_ptr<RecordingWriter>> RecordingWriter::Create(const std::string& path,
                                                                   RecordingWriterOptions options, bool overwrite) {
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_ASSIGN_OR_RETURN(auto file, OpenPosixRecordingFile(path, overwrite));
  return Create(std::move(file), std::move(options), path);
}

StatusOr<std::unique_ptr<RecordingWriter>> RecordingWriter::Create(std::unique_ptr<RecordingFile> file,
                                                                   RecordingWriterOptions options, std::string name) {
  HOLO_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<RecordingWriter> w(new RecordingWriter(std::move(file), std::move(options), std::move(name)));
  FileHeader h;
  h.flags = w->options_.file_flags;
  h.source = w->options_.source;
  h.created_unix_us = std::chrono::duration_cast<std::chrono::microseconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  uint8_t bytes[kFileHeaderSize];
  EncodeFileHeader(h, bytes);
  iovec iov{bytes, sizeof(bytes)};
  bool enospc = false;
  Status s = w->file_->WriteAll(&iov, 1, &enospc);
  if (!s.ok()) {
    (void)w->file_->Close();
    w->closed_ = true;
    return enospc ? Unavailable(w->name_ + ": disk full: cannot even write the recording header (" + s.message() + ")")
                  : s;
  }
  w->stats_.bytes = kFileHeaderSize;
  return w;
}

RecordingWriter::RecordingWriter(std::unique_ptr<RecordingFile> file, RecordingWriterOptions options,
                                 std::string name)
    : file_(std::move(file)), options_(std::move(options)), name_(std::move(name)) {
  limits_.max_message_bytes = options_.max_message_bytes;
  // A recorded message is one unfragmented frame: its payload may be a whole message.
  limits_.max_frame_payload = options_.max_message_bytes;
}

RecordingWriter::~RecordingWriter() {
  Status s = Close();
  if (!s.ok()) spdlog::error("{}: closing the recording: {}", name_, s.message());
}

Status RecordingWriter::Fail(Status s) {
  failed_ = s;
  return s;
}

Status RecordingWriter::WriteFooter() {
  IndexBody index;
  index.num_messages = stats_.messages;
  index.duration_us = stats_.duration_us;
  index.entries = index_;
  const std::vector<uint8_t> body = EncodeIndexBody(index);
  uint8_t index_header[kRecordHeaderSize];
  EncodeRecordHeader(RecordKind::kIndex, stats_.duration_us, body, index_header);
  uint8_t end[kEndRecordSize];
  const uint64_t index_offset = stats_.bytes;
  std::memcpy(end + kRecordHeaderSize, &index_offset, 8);
  EncodeRecordHeader(RecordKind::kEnd, stats_.duration_us, std::span<const uint8_t>(end + kRecordHeaderSize, 8), end);
  iovec iov[3] = {{index_header, sizeof(index_header)},
                  {const_cast<uint8_t*>(body.data()), body.size()},
                  {end, sizeof(end)}};
  bool enospc = false;
  Status s = file_->WriteAll(iov, 3, &enospc);
  if (!s.ok()) {
    // Leave a file a reader can scan: no partial index.
    (void)file_->Truncate(stats_.bytes);
    return s;
  }
  return file_->Sync();
}

Status RecordingWriter::WriteMessage(int64_t time_us, std::span<const uint8_t> frame) {
  if (!failed_.ok()) return failed_;
  if (closed_) return InvalidArgument(name_ + ": the recording is closed");
  // Validate the message (nothing is written for a bad one).
  if (frame.size() < protocol::kHeaderSize)
    return InvalidArgument("message of " + std::to_string(frame.size()) + " bytes is shorter than a frame header");
  auto header = protocol::DecodeHeader(frame.data(), frame.size(), limits_);
  if (!header.ok()) return InvalidArgument("message header: " + header.status().message());
  if (header->payload_length != frame.size() - protocol::kHeaderSize)
    return InvalidArgument("message header says " + std::to_string(header->payload_length) + " payload bytes, " +
                           std::to_string(frame.size() - protocol::kHeaderSize) + " given");
  if (header->flags & protocol::kFlagMoreFragments)
    return InvalidArgument("a fragment cannot be recorded: reassemble the message first");
  if (!IsRecordable(header->type))
    return InvalidArgument(std::string("message type ") + protocol::MessageTypeName(header->type) +
                           " is not recorded (only Rig, MeshFrame, ColorFrame, AudioPose, Stats)");
  if (!have_rig_ && header->type != protocol::MessageType::kRig)
    return InvalidArgument("a recording starts with the Rig message; got " +
                           std::string(protocol::MessageTypeName(header->type)) + " first");
  if (time_us < 0 || time_us < stats_.duration_us)
    return InvalidArgument("message time " + std::to_string(time_us) + " µs goes back (last " +
                           std::to_string(stats_.duration_us) + " µs)");
  if (options_.validate_payloads) {
    auto payload = protocol::DecodePayload(*header, frame.subspan(protocol::kHeaderSize), limits_);
    if (!payload.ok()) return InvalidArgument("message payload: " + payload.status().message());
  }
  const bool key = header->type == protocol::MessageType::kMeshFrame && (header->flags & protocol::kFlagKeyFrame);

  const uint64_t offset = stats_.bytes;
  const uint64_t record_bytes = kRecordHeaderSize + frame.size();
  if (options_.max_bytes != 0 &&
      offset + record_bytes + FooterBytes(index_.size() + (key ? 1 : 0)) > options_.max_bytes) {
    Status s = WriteFooter();
    closed_ = true;
    (void)file_->Close();
    const std::string kept = std::to_string(stats_.messages) + " messages, " + Seconds(stats_.duration_us);
    if (!s.ok())
      return Fail(Unavailable(name_ + ": size limit of " + std::to_string(options_.max_bytes) +
                              " bytes reached, and writing the index failed (" + s.message() + "); the " + kept +
                              " before are kept and a reader rebuilds the index"));
    return Fail(OutOfRange(name_ + ": size limit of " + std::to_string(options_.max_bytes) +
                           " bytes reached; recording stopped and closed with " + kept));
  }

  uint8_t rh[kRecordHeaderSize];
  EncodeRecordHeader(RecordKind::kMessage, time_us, frame, rh);
  iovec iov[2] = {{rh, sizeof(rh)}, {const_cast<uint8_t*>(frame.data()), frame.size()}};
  bool enospc = false;
  Status s = file_->WriteAll(iov, 2, &enospc);
  if (!s.ok()) {
    // Drop the partial record, then try to leave an index behind.
    Status t = file_->Truncate(offset);
    Status f = t.ok() ? WriteFooter() : t;
    closed_ = true;
    (void)file_->Close();
    const std::string kept = "the " + std::to_string(stats_.messages) + " messages (" + Seconds(stats_.duration_us) +
                             ", " + std::to_string(offset) + " bytes) written before are kept" +
                             (f.ok() ? " and indexed" : " (no index: a reader rebuilds it by scanning)");
    return Fail(Unavailable(name_ + (enospc ? ": disk full" : ": write failed") + " (" + s.message() +
                            "); recording stopped; " + kept));
  }
  stats_.bytes += record_bytes;
  stats_.messages += 1;
  stats_.duration_us = time_us;
  const auto type_index = static_cast<uint16_t>(header->type);
  HOLO_CHECK(type_index < std::size(stats_.messages_by_type));
  stats_.messages_by_type[type_index] += 1;
  if (header->type == protocol::MessageType::kRig) {
    rig_offset_ = offset;
    have_rig_ = true;
  }
  if (key) {
    index_.push_back({time_us, offset, rig_offset_});
    stats_.key_frames += 1;
  }
  unsynced_ += record_bytes;
  if (options_.sync_every_bytes != 0 && unsynced_ >= options_.sync_every_bytes) {
    unsynced_ = 0;
    Status y = file_->Sync();
    if (!y.ok()) {
      closed_ = true;
      (void)file_->Close();
      return Fail(Unavailable(name_ + ": " + y.message() + "; recording stopped; " +
                              std::to_string(stats_.messages) + " messages written (no index: a reader rebuilds it)"));
    }
  }
  return OkStatus();
}

Status RecordingWriter::Close() {
  if (closed_) return OkStatus();
  closed_ = true;
  Status s = WriteFooter();
  Status c = file_->Close();
  if (!s.ok())
    return Fail(Unavailable(name_ + ": writing the index failed (" + s.message() + "); the " +
                            std::to_string(stats_.messages) + " messages are kept and a reader rebuilds the index"));
  if (!c.ok()) return Fail(c);
  return OkStatus();
}

}  // namespace holo::record
