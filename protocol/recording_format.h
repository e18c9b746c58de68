// The recording container (docs/recording.md, PROTOCOL.md §10): a file
// header, then records. Every record is a 24-byte record header (magic, kind,
// body length, CRC-32C, media time) and a body:
//   kind 1 (message): one protocol frame, exactly the bytes of the message as
//                     received (32-byte protocol header + payload,
//                     unfragmented);
//   kind 2 (index):   the seek index (written when the recording is closed);
//   kind 3 (end):     the offset of the index record; always the last 32
//                     bytes of a cleanly closed file.
// A recording that was never closed (the recorder was killed) has no index
// and no end record: the reader rebuilds the index by scanning and ignores a
// torn last record.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/status.h"

namespace holo::record {

inline constexpr uint32_t kFileMagic = 0x43524C48;    // bytes "HLRC"
inline constexpr uint32_t kRecordMagic = 0x4D524C48;  // bytes "HLRM"
inline constexpr uint16_t kFormatVersion = 1;
inline constexpr size_t kFileHeaderSize = 64;
inline constexpr size_t kRecordHeaderSize = 24;
inline constexpr size_t kIndexEntrySize = 24;
inline constexpr size_t kIndexFixedSize = 20;  // u64 messages, i64 duration, u32 count
inline constexpr size_t kEndRecordSize = kRecordHeaderSize + 8;
inline constexpr size_t kSourceNameBytes = 32;
// File header flag: this file is a segment cut from a longer recording.
inline constexpr uint16_t kFileFlagSegment = 1u << 0;

enum class RecordKind : uint8_t { kMessage = 1, kIndex = 2, kEnd = 3 };

// CRC-32C (Castagnoli), slicing by 8. `crc` is the running value (0 to start).
// Our own: Debian packages no CRC-32C library for C++ (zlib has only CRC-32),
// and the browser player (web/src/bytes.js) checks the same sums.
uint32_t Crc32c(uint32_t crc, const uint8_t* data, size_t size);

struct FileHeader {
  uint16_t format_version = kFormatVersion;
  uint16_t protocol_version = 1;
  uint16_t flags = 0;
  int64_t created_unix_us = 0;
  std::string source;  // ≤ 31 bytes of UTF-8 ("synthetic:S8-QVGA", "tcp:host:port")
};
void EncodeFileHeader(const FileHeader& h, uint8_t out[kFileHeaderSize]);
// DataLoss / UnsupportedVersion naming the field.
StatusOr<FileHeader> DecodeFileHeader(std::span<const uint8_t> bytes);

struct RecordHeader {
  RecordKind kind = RecordKind::kMessage;
  uint32_t body_length = 0;
  uint32_t crc = 0;
  int64_t time_us = 0;  // media time since the start of the recording
};
// Fills the header bytes including the CRC over the header and `body`.
void EncodeRecordHeader(RecordKind kind, int64_t time_us, std::span<const uint8_t> body,
                        uint8_t out[kRecordHeaderSize]);
// Checks magic, kind and reserved bytes (not the CRC, which needs the body).
StatusOr<RecordHeader> DecodeRecordHeader(std::span<const uint8_t> bytes);
// OK if the CRC in `header_bytes` matches header + body.
bool RecordCrcMatches(std::span<const uint8_t> header_bytes, std::span<const uint8_t> body);

// One seekable point: a MeshFrame key frame and the Rig in effect there.
struct IndexEntry {
  int64_t time_us = 0;       // media time of the key frame
  uint64_t offset = 0;       // file offset of the key frame's record
  uint64_t rig_offset = 0;   // file offset of the Rig message record in effect
  bool operator==(const IndexEntry&) const = default;
};
struct IndexBody {
  uint64_t num_messages = 0;
  int64_t duration_us = 0;  // media time of the last message
  std::vector<IndexEntry> entries;
};
std::vector<uint8_t> EncodeIndexBody(const IndexBody& index);
// Validates counts against the bytes, times non-decreasing, offsets increasing
// and inside [data_begin, data_end), rig offsets ≤ offsets.
StatusOr<IndexBody> DecodeIndexBody(std::span<const uint8_t> body, uint64_t data_begin, uint64_t data_end);

// Bytes an index record + end record with `entries` entries take.
inline uint64_t FooterBytes(size_t entries) {
  return kRecordHeaderSize + kIndexFixedSize + entries * kIndexEntrySize + kEndRecordSize;
}

}  // namespace holo::record
