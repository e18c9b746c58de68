#include "protocol/recording_format.h"

#include <algorithm>
#include <array>
#include <cstring>

#include "protocol/byte_io.h"

namespace holo::record {
namespace {

using Tables = std::array<std::array<uint32_t, 256>, 8>;

constexpr Tables MakeTables() {
  Tables t{};
  constexpr uint32_t kPoly = 0x82F63B78u;  // CRC-32C, reflected
  for (uint32_t i = 0; i < 256; ++i) {
    uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1) ? (c >> 1) ^ kPoly : c >> 1;
    t[0][i] = c;
  }
  for (uint32_t i = 0; i < 256; ++i)
    for (size_t s = 1; s < 8; ++s) t[s][i] = (t[s - 1][i] >> 8) ^ t[0][t[s - 1][i] & 0xFF];
  return t;
}
constexpr Tables kTables = MakeTables();

void PutU16(uint8_t* p, uint16_t v) { std::memcpy(p, &v, 2); }
void PutU32(uint8_t* p, uint32_t v) { std::memcpy(p, &v, 4); }
void PutI64(uint8_t* p, int64_t v) { std::memcpy(p, &v, 8); }
uint16_t GetU16(const uint8_t* p) { uint16_t v; std::memcpy(&v, p, 2); return v; }
uint32_t GetU32(const uint8_t* p) { uint32_t v; std::memcpy(&v, p, 4); return v; }
int64_t GetI64(const uint8_t* p) { int64_t v; std::memcpy(&v, p, 8); return v; }

uint32_t HeaderCrc(const uint8_t* header, std::span<const uint8_t> body) {
  // The CRC covers the record header without its CRC field, then the body.
  uint32_t c = Crc32c(0, header, 12);
  c = Crc32c(c, header + 16, 8);
  return Crc32c(c, body.data(), body.size());
}

}  // namespace

uint32_t Crc32c(uint32_t crc, const uint8_t* data, size_t size) {
  uint32_t c = ~crc;
  while (size >= 8) {
    uint32_t lo, hi;
    std::memcpy(&lo, data, 4);
    std::memcpy(&hi, data + 4, 4);
    lo ^= c;
    c = kTables[7][lo & 0xFF] ^ kTables[6][(lo >> 8) & 0xFF] ^ kTables[5][(lo >> 16) & 0xFF] ^
        kTables[4][lo >> 24] ^ kTables[3][hi & 0xFF] ^ kTables[2][(hi >> 8) & 0xFF] ^
        kTables[1][(hi >> 16) & 0xFF] ^ kTables[0][hi >> 24];
    data += 8;
    size -= 8;
  }
  while (size--) c = (c >> 8) ^ kTables[0][(c ^ *data++) & 0xFF];
  return ~c;
}

void EncodeFileHeader(const FileHeader& h, uint8_t out[kFileHeaderSize]) {
  std::memset(out, 0, kFileHeaderSize);
  PutU32(out + 0, kFileMagic);
  PutU16(out + 4, h.format_version);
  PutU16(out + 6, static_cast<uint16_t>(kFileHeaderSize));
  PutU16(out + 8, h.protocol_version);
  PutU16(out + 10, h.flags);
  PutI64(out + 16, h.created_unix_us);
  const size_t n = std::min(h.source.size(), kSourceNameBytes - 1);
  std::memcpy(out + 24, h.source.data(), n);
  PutU32(out + 60, Crc32c(0, out, 60));
}

StatusOr<FileHeader> DecodeFileHeader(std::span<const uint8_t> b) {
  if (b.size() < kFileHeaderSize)
    return DataLoss("recording header: file is " + std::to_string(b.size()) + " bytes, shorter than the " +
                    std::to_string(kFileHeaderSize) + "-byte header");
  const uint8_t* p = b.data();
  if (GetU32(p) != kFileMagic) return DataLoss("recording header: bad magic (not a Holoport recording)");
  if (GetU32(p + 60) != Crc32c(0, p, 60)) return DataLoss("recording header: checksum mismatch");
  FileHeader h;
  h.format_version = GetU16(p + 4);
  if (h.format_version != kFormatVersion)
    return UnsupportedVersion("recording format version " + std::to_string(h.format_version) +
                              ", this build reads version " + std::to_string(kFormatVersion));
  if (GetU16(p + 6) != kFileHeaderSize) return DataLoss("recording header: header_size must be 64");
  h.protocol_version = GetU16(p + 8);
  if (h.protocol_version != 1)
    return UnsupportedVersion("recording holds protocol version " + std::to_string(h.protocol_version) +
                              ", this build speaks 1");
  h.flags = GetU16(p + 10);
  if ((h.flags & ~kFileFlagSegment) != 0) return DataLoss("recording header: unknown flags");
  if (GetU32(p + 12) != 0 || GetU32(p + 56) != 0) return DataLoss("recording header: reserved bytes not 0");
  h.created_unix_us = GetI64(p + 16);
  const char* s = reinterpret_cast<const char*>(p + 24);
  const size_t len = strnlen(s, kSourceNameBytes);
  if (len == kSourceNameBytes) return DataLoss("recording header: source name not terminated");
  for (size_t i = len; i < kSourceNameBytes; ++i)
    if (s[i] != 0) return DataLoss("recording header: source name padding not 0");
  h.source.assign(s, len);
  return h;
}

void EncodeRecordHeader(RecordKind kind, int64_t time_us, std::span<const uint8_t> body,
                        uint8_t out[kRecordHeaderSize]) {
  std::memset(out, 0, kRecordHeaderSize);
  PutU32(out + 0, kRecordMagic);
  out[4] = static_cast<uint8_t>(kind);
  PutU32(out + 8, static_cast<uint32_t>(body.size()));
  PutI64(out + 16, time_us);
  PutU32(out + 12, HeaderCrc(out, body));
}

StatusOr<RecordHeader> DecodeRecordHeader(std::span<const uint8_t> b) {
  if (b.size() < kRecordHeaderSize) return DataLoss("record header truncated");
  const uint8_t* p = b.data();
  if (GetU32(p) != kRecordMagic) return DataLoss("record header: bad magic");
  if (p[4] < 1 || p[4] > 3) return DataLoss("record header: unknown kind " + std::to_string(p[4]));
  if (p[5] != 0 || GetU16(p + 6) != 0) return DataLoss("record header: reserved bytes not 0");
  RecordHeader h;
  h.kind = static_cast<RecordKind>(p[4]);
  h.body_length = GetU32(p + 8);
  h.crc = GetU32(p + 12);
  h.time_us = GetI64(p + 16);
  if (h.time_us < 0) return DataLoss("record header: negative time " + std::to_string(h.time_us));
  return h;
}

bool RecordCrcMatches(std::span<const uint8_t> header_bytes, std::span<const uint8_t> body) {
  if (header_bytes.size() < kRecordHeaderSize) return false;
  return GetU32(header_bytes.data() + 12) == HeaderCrc(header_bytes.data(), body);
}

std::vector<uint8_t> EncodeIndexBody(const IndexBody& index) {
  std::vector<uint8_t> out(kIndexFixedSize + index.entries.size() * kIndexEntrySize);
  uint8_t* p = out.data();
  std::memcpy(p, &index.num_messages, 8);
  PutI64(p + 8, index.duration_us);
  PutU32(p + 16, static_cast<uint32_t>(index.entries.size()));
  p += kIndexFixedSize;
  for (const IndexEntry& e : index.entries) {
    PutI64(p, e.time_us);
    std::memcpy(p + 8, &e.offset, 8);
    std::memcpy(p + 16, &e.rig_offset, 8);
    p += kIndexEntrySize;
  }
  return out;
}

StatusOr<IndexBody> DecodeIndexBody(std::span<const uint8_t> body, uint64_t data_begin, uint64_t data_end) {
  protocol::ByteReader r(body);
  IndexBody index;
  uint32_t count = 0;
  HOLO_RETURN_IF_ERROR(r.U64("index.num_messages", &index.num_messages));
  HOLO_RETURN_IF_ERROR(r.I64("index.duration_us", &index.duration_us));
  HOLO_RETURN_IF_ERROR(r.U32("index.count", &count));
  if (index.duration_us < 0) return DataLoss("index.duration_us: negative");
  if (r.remaining() != static_cast<uint64_t>(count) * kIndexEntrySize)
    return DataLoss("index.count: " + std::to_string(count) + " entries need " +
                    std::to_string(static_cast<uint64_t>(count) * kIndexEntrySize) + " bytes, " +
                    std::to_string(r.remaining()) + " remain");
  // Every message record takes at least header + protocol header bytes.
  if (index.num_messages > (data_end - data_begin) / (kRecordHeaderSize + 32))
    return DataLoss("index.num_messages: " + std::to_string(index.num_messages) + " cannot fit in the file");
  index.entries.resize(count);
  for (uint32_t i = 0; i < count; ++i) {
    IndexEntry& e = index.entries[i];
    HOLO_RETURN_IF_ERROR(r.I64("index.time_us", &e.time_us));
    HOLO_RETURN_IF_ERROR(r.U64("index.offset", &e.offset));
    HOLO_RETURN_IF_ERROR(r.U64("index.rig_offset", &e.rig_offset));
    const std::string at = "index entry " + std::to_string(i) + ": ";
    if (e.offset < data_begin || e.offset >= data_end) return DataLoss(at + "offset outside the data");
    if (e.rig_offset < data_begin || e.rig_offset > e.offset) return DataLoss(at + "rig offset out of range");
    if (e.time_us < 0 || e.time_us > index.duration_us) return DataLoss(at + "time out of range");
    if (i > 0) {
      const IndexEntry& p = index.entries[i - 1];
      if (e.offset <= p.offset) return DataLoss(at + "offsets not increasing");
      if (e.time_us < p.time_us) return DataLoss(at + "times decreasing");
      if (e.rig_offset < p.rig_offset) return DataLoss(at + "rig offsets decreasing");
    }
  }
  return index;
}

}  // namespace holo::record
