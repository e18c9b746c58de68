// Bounds-checked little-endian byte writer and reader: the only way protocol
// code touches wire bytes. No struct is ever cast onto a buffer.
//
// ByteReader is safe on untrusted input: every read checks the bytes that
// remain, and the count helpers check `count * element_size` against them
// *before* the caller allocates. Errors are DataLoss statuses that name the
// field ("mesh.num_triangles: needs 1200000 bytes, 37 remain").
#pragma once

#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/status.h"

static_assert(std::endian::native == std::endian::little, "holo_protocol assumes a little-endian host");

namespace holo::protocol {

// Decimal text of a count, size or field value, for error messages.
inline std::string Str(uint64_t v) { return std::to_string(v); }

// Appends little-endian scalars to a growing byte vector it borrows (the
// vector must outlive the writer).
class ByteWriter {
 public:
  explicit ByteWriter(std::vector<uint8_t>* out) : out_(out) {}

  void U8(uint8_t v) { out_->push_back(v); }
  void U16(uint16_t v) { Raw(&v, 2); }
  void U32(uint32_t v) { Raw(&v, 4); }
  void U64(uint64_t v) { Raw(&v, 8); }
  void I32(int32_t v) { Raw(&v, 4); }
  void I64(int64_t v) { Raw(&v, 8); }
  void F32(float v) { Raw(&v, 4); }
  void F64(double v) { Raw(&v, 8); }
  void Bytes(std::span<const uint8_t> b) { out_->insert(out_->end(), b.begin(), b.end()); }
  // u16 length + bytes. HOLO_CHECKs that the string fits (callers validate first).
  void String16(std::string_view s);
  // u8 length + bytes.
  void String8(std::string_view s);
  // u32 length + bytes.
  void Blob32(std::span<const uint8_t> b);

  // Reserves a u32 to be filled later by PatchU32 (e.g. a length prefix).
  size_t ReserveU32() {
    const size_t at = out_->size();
    U32(0);
    return at;
  }
  void PatchU32(size_t at, uint32_t v) {
    HOLO_CHECK(at + 4 <= out_->size());
    std::memcpy(out_->data() + at, &v, 4);
  }
  size_t size() const { return out_->size(); }

 private:
  void Raw(const void* p, size_t n) {
    const auto* b = static_cast<const uint8_t*>(p);
    out_->insert(out_->end(), b, b + n);
  }
  std::vector<uint8_t>* out_;
};

// Reads little-endian scalars from a borrowed byte range (valid for the
// reader's lifetime). Safe on untrusted input.
class ByteReader {
 public:
  ByteReader(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  explicit ByteReader(std::span<const uint8_t> s) : data_(s.data()), size_(s.size()) {}

  size_t remaining() const { return size_ - pos_; }
  size_t position() const { return pos_; }
  bool empty() const { return pos_ == size_; }

  Status U8(const char* field, uint8_t* v) { return Raw(field, v, 1); }
  Status U16(const char* field, uint16_t* v) { return Raw(field, v, 2); }
  Status U32(const char* field, uint32_t* v) { return Raw(field, v, 4); }
  Status U64(const char* field, uint64_t* v) { return Raw(field, v, 8); }
  Status I32(const char* field, int32_t* v) { return Raw(field, v, 4); }
  Status I64(const char* field, int64_t* v) { return Raw(field, v, 8); }
  // Floats must be finite (NaN/inf are refused: they poison geometry and timing).
  Status F32(const char* field, float* v);
  Status F64(const char* field, double* v);

  // A u16-length string of at most `max_len` bytes.
  Status String16(const char* field, size_t max_len, std::string* s);
  Status String8(const char* field, std::string* s);
  // A u32-length byte run of at most `max_len` bytes, returned as a view into
  // the reader's buffer (borrowed: valid as long as the buffer).
  Status Blob32(const char* field, size_t max_len, std::span<const uint8_t>* b);
  // `n` raw bytes as a borrowed view.
  Status View(const char* field, size_t n, std::span<const uint8_t>* b);
  // Checks that `count` elements of `element_size` bytes each fit into the
  // remaining bytes, without overflow. Call before allocating for `count`.
  Status CheckCount(const char* field, uint64_t count, size_t element_size) const;
  // OK if every byte was consumed; DataLoss naming `what` otherwise.
  Status ExpectEnd(const char* what) const;

 private:
  Status Raw(const char* field, void* v, size_t n);
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

// IEEE 754 binary16 conversion (round to nearest even; overflow → ±inf).
uint16_t FloatToHalf(float f);
float HalfToFloat(uint16_t h);

}  // namespace holo::protocol
