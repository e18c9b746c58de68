// Writes a recording (recording_format.h, docs/recording.md) crash-safely:
// every message goes to the kernel in one write as soon as it arrives (a
// kill -9 loses nothing already written), data is fdatasync'ed periodically,
// and the index is written when the recording is closed (a reader rebuilds it
// by scanning a file that was never closed). A size limit and write failures
// (a full disk) end the recording with a clear error and leave every message
// written before intact and readable.
#pragma once

#include <sys/uio.h>

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/status.h"
#include "protocol/messages.h"
#include "server/record/recording_format.h"

namespace holo::record {

// The message types a recording keeps; the others (Hello, Control, Ping…)
// belong to a live session.
inline bool IsRecordable(protocol::MessageType t) {
  using protocol::MessageType;
  return t == MessageType::kRig || t == MessageType::kMeshFrame || t == MessageType::kColorFrame ||
         t == MessageType::kAudioPose || t == MessageType::kStats || t == MessageType::kRegions;
}

// Where the bytes go; a seam for failure injection in tests.
class RecordingFile {
 public:
  virtual ~RecordingFile() = default;
  // Writes all of the buffers (retrying short writes) or fails naming errno;
  // `*enospc` is set when the failure is a full disk or quota.
  virtual Status WriteAll(const iovec* iov, int count, bool* enospc) = 0;
  // Cuts the file to `size` bytes (drops a partial record after a failure).
  virtual Status Truncate(uint64_t size) = 0;
  virtual Status Sync() = 0;
  virtual Status Close() = 0;
};

// A regular file. Fails if `path` exists unless `overwrite`.
StatusOr<std::unique_ptr<RecordingFile>> OpenPosixRecordingFile(const std::string& path, bool overwrite);

struct RecordingWriterOptions {
  // Largest file size, bytes, index included (0 = unlimited). When the next
  // message would not fit, the recording is closed (index written) and
  // WriteMessage returns OutOfRange.
  uint64_t max_bytes = 0;
  // fdatasync after this many bytes (0 = only at Close).
  uint64_t sync_every_bytes = 8u << 20;
  // Decode every payload before writing it (a recording holds only valid
  // messages).
  bool validate_payloads = true;
  // Largest message; also bounded by the protocol's hard limit.
  uint32_t max_message_bytes = 64u << 20;
  std::string source;  // stored in the file header (≤ 31 bytes are kept)
  uint16_t file_flags = 0;
  Status Check() const;
};

struct RecordingWriterStats {
  uint64_t messages = 0;
  uint64_t key_frames = 0;
  uint64_t bytes = 0;        // file size so far (without the index)
  int64_t duration_us = 0;   // media time of the last message
  uint64_t messages_by_type[16] = {};  // indexed by message type (1..15)
};

class RecordingWriter {
 public:
  // Writes the file header. `path` must not exist unless `overwrite`.
  static StatusOr<std::unique_ptr<RecordingWriter>> Create(const std::string& path, RecordingWriterOptions options,
                                                           bool overwrite = false);
  // Same on any RecordingFile (tests inject failures here).
  static StatusOr<std::unique_ptr<RecordingWriter>> Create(std::unique_ptr<RecordingFile> file,
                                                           RecordingWriterOptions options,
                                                           std::string name = "recording");
  ~RecordingWriter();  // Close()s, logging an error (spdlog)
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;

  // Appends one message: `frame` is a whole protocol frame (32-byte header +
  // payload, not a fragment) exactly as received; `time_us` its media time
  // (µs since the recording started, non-decreasing). The first message must
  // be the Rig. Only content is recorded: Rig, MeshFrame, ColorFrame,
  // AudioPose, Stats, Regions (InvalidArgument for other types).
  // Errors: InvalidArgument (bad message; nothing written, the recording
  // goes on), OutOfRange (size limit: the recording is now closed),
  // Unavailable (disk full / write failure: the recording is closed with
  // everything before this message kept). After OutOfRange or Unavailable
  // every call returns that error again.
  Status WriteMessage(int64_t time_us, std::span<const uint8_t> frame);
  // Writes the index and end record, syncs and closes. Idempotent.
  Status Close();

  const RecordingWriterStats& stats() const { return stats_; }
  // The error that ended the recording (OK while it is open or after Close).
  const Status& final_status() const { return failed_; }

 private:
  RecordingWriter(std::unique_ptr<RecordingFile> file, RecordingWriterOptions options, std::string name);
  Status Fail(Status s);
  Status WriteFooter();

  std::unique_ptr<RecordingFile> file_;
  RecordingWriterOptions options_;
  std::string name_;
  protocol::Limits limits_;
  RecordingWriterStats stats_;
  std::vector<IndexEntry> index_;
  uint64_t rig_offset_ = 0;
  uint64_t unsynced_ = 0;
  bool have_rig_ = false;
  bool closed_ = false;
  Status failed_;
};

}  // namespace holo::record
