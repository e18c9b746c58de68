// Reads a recording (recording_format.h) from an untrusted file. Every length
// is checked against the file and the protocol limits before anything is
// allocated; every record's CRC is checked when it is read.
//
// A cleanly closed file is opened from its index (the last 32 bytes point to
// it). A file that was never closed (recorder killed, disk full) is scanned
// once: every complete record up to the end is kept, a torn last record (the
// file ends inside it, or the rest of the file is zeros) is ignored and
// reported, and the index is rebuilt. Damage with valid-looking bytes after
// it is an error unless `salvage` is set.
//
// The reader is immutable after Open; ReadAt is thread-safe (pread), so many
// replays can share one reader.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/rig.h"
#include "common/status.h"
#include "protocol/messages.h"
#include "server/record/recording_format.h"

namespace holo::record {

struct RecordingReaderOptions {
  uint32_t max_message_bytes = 64u << 20;
  // Largest index (entries) accepted or rebuilt: 4 Mi entries ≈ 38 h at 30 fps.
  uint64_t max_index_entries = 4u << 20;
  // Accept an unclosed file whose damage is followed by more bytes, keeping
  // what comes before the damage.
  bool salvage = false;
};

struct RecordedMessage {
  uint64_t offset = 0;       // of the record
  uint64_t next_offset = 0;  // of the record after it
  int64_t time_us = 0;       // media time
  protocol::Header header;   // decoded from the first 32 bytes of `bytes`
  // The protocol frame exactly as recorded (header + payload).
  std::shared_ptr<const std::vector<uint8_t>> bytes;
};

struct RecordingSummary {
  FileHeader file;
  uint64_t file_bytes = 0;
  uint64_t data_begin = kFileHeaderSize;  // first message record (the Rig)
  uint64_t data_end = 0;                  // end of the last complete message record
  bool clean = false;                     // closed with an index (else the index was rebuilt by scanning)
  uint64_t ignored_tail_bytes = 0;        // bytes after data_end that are not a valid footer
  std::string tail_note;                  // why they were ignored
  uint64_t num_messages = 0;
  int64_t duration_us = 0;                // media time of the last message
  std::vector<IndexEntry> index;          // every MeshFrame key frame
};

class RecordingReader {
 public:
  static StatusOr<std::unique_ptr<RecordingReader>> Open(const std::string& path,
                                                         RecordingReaderOptions options = {});
  ~RecordingReader();
  RecordingReader(const RecordingReader&) = delete;
  RecordingReader& operator=(const RecordingReader&) = delete;

  const RecordingSummary& summary() const { return summary_; }
  const std::string& path() const { return path_; }
  // The Rig of the first record.
  const Rig& rig() const { return rig_; }

  // Reads and validates the message record at `offset` (a record start:
  // data_begin, an index offset, or a previous message's next_offset, below
  // data_end). DataLoss naming the offset on any damage.
  StatusOr<RecordedMessage> ReadAt(uint64_t offset) const;
  // The last index entry with time ≤ `time_us` (nullptr if none).
  const IndexEntry* KeyFrameAtOrBefore(int64_t time_us) const;

 private:
  RecordingReader() = default;
  Status ReadExact(uint64_t offset, uint8_t* out, size_t size) const;
  // Validates the record header at `offset` and reads its body into `body`.
  Status ReadRecord(uint64_t offset, uint64_t limit, RecordHeader* header, uint8_t raw_header[kRecordHeaderSize],
                    std::vector<uint8_t>* body) const;
  Status OpenFromFooter(bool* used);
  Status Scan();
  Status CheckMessage(uint64_t offset, const RecordHeader& rh, const std::vector<uint8_t>& body,
                      protocol::Header* out) const;

  int fd_ = -1;
  std::string path_;
  RecordingReaderOptions options_;
  protocol::Limits limits_;
  RecordingSummary summary_;
  Rig rig_;
};

// "12.345 s" style.
std::string FormatSeconds(int64_t us);

}  // namespace holo::record
