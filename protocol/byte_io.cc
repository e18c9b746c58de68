#include "protocol/byte_io.h"

#include <cmath>

namespace holo::protocol {

void ByteWriter::String16(std::string_view s) {
  HOLO_CHECK_MSG(s.size() <= 0xFFFF, "string too long for a u16 length");
  U16(static_cast<uint16_t>(s.size()));
  Raw(s.data(), s.size());
}

void ByteWriter::String8(std::string_view s) {
  HOLO_CHECK_MSG(s.size() <= 0xFF, "string too long for a u8 length");
  U8(static_cast<uint8_t>(s.size()));
  Raw(s.data(), s.size());
}

void ByteWriter::Blob32(std::span<const uint8_t> b) {
  HOLO_CHECK_MSG(b.size() <= 0xFFFFFFFFull, "blob too long for a u32 length");
  U32(static_cast<uint32_t>(b.size()));
  Bytes(b);
}

Status ByteReader::Raw(const char* field, void* v, size_t n) {
  if (remaining() < n) {
    return DataLoss(std::string(field) + ": needs " + std::to_string(n) + " bytes, " + std::to_string(remaining()) +
                    " remain");
  }
  std::memcpy(v, data_ + pos_, n);
  pos_ += n;
  return OkStatus();
}

Status ByteReader::F32(const char* field, float* v) {
  HOLO_RETURN_IF_ERROR(Raw(field, v, 4));
  if (!std::isfinite(*v)) return DataLoss(std::string(field) + ": not a finite number");
  return OkStatus();
}

Status ByteReader::F64(const char* field, double* v) {
  HOLO_RETURN_IF_ERROR(Raw(field, v, 8));
  if (!std::isfinite(*v)) return DataLoss(std::string(field) + ": not a finite number");
  return OkStatus();
}

Status ByteReader::View(const char* field, size_t n, std::span<const uint8_t>* b) {
  if (remaining() < n) {
    return DataLoss(std::string(field) + ": needs " + std::to_string(n) + " bytes, " + std::to_string(remaining()) +
                    " remain");
  }
  *b = std::span<const uint8_t>(data_ + pos_, n);
  pos_ += n;
  return OkStatus();
}

Status ByteReader::String16(const char* field, size_t max_len, std::string* s) {
  uint16_t n = 0;
  HOLO_RETURN_IF_ERROR(U16(field, &n));
  if (n > max_len) {
    return DataLoss(std::string(field) + ": length " + std::to_string(n) + " exceeds limit " + std::to_string(max_len));
  }
  std::span<const uint8_t> b;
  HOLO_RETURN_IF_ERROR(View(field, n, &b));
  s->assign(reinterpret_cast<const char*>(b.data()), b.size());
  return OkStatus();
}

Status ByteReader::String8(const char* field, std::string* s) {
  uint8_t n = 0;
  HOLO_RETURN_IF_ERROR(U8(field, &n));
  std::span<const uint8_t> b;
  HOLO_RETURN_IF_ERROR(View(field, n, &b));
  s->assign(reinterpret_cast<const char*>(b.data()), b.size());
  return OkStatus();
}

Status ByteReader::Blob32(const char* field, size_t max_len, std::span<const uint8_t>* b) {
  uint32_t n = 0;
  HOLO_RETURN_IF_ERROR(U32(field, &n));
  if (n > max_len) {
    return DataLoss(std::string(field) + ": length " + std::to_string(n) + " exceeds limit " + std::to_string(max_len));
  }
  return View(field, n, b);
}

Status ByteReader::CheckCount(const char* field, uint64_t count, size_t element_size) const {
  if (element_size != 0 && count > remaining() / element_size) {
    return DataLoss(std::string(field) + ": count " + std::to_string(count) + " of " + std::to_string(element_size) +
                    "-byte elements exceeds the " + std::to_string(remaining()) + " bytes that remain");
  }
  return OkStatus();
}

Status ByteReader::ExpectEnd(const char* what) const {
  if (remaining() != 0) {
    return DataLoss(std::string(what) + ": " + std::to_string(remaining()) + " trailing bytes");
  }
  return OkStatus();
}

uint16_t FloatToHalf(float f) {
  const uint32_t x = std::bit_cast<uint32_t>(f);
  const uint32_t sign = (x >> 16) & 0x8000u;
  const uint32_t abs = x & 0x7FFFFFFFu;
  if (abs >= 0x7F800000u) {  // inf or NaN
    return static_cast<uint16_t>(sign | 0x7C00u | (abs > 0x7F800000u ? 0x200u : 0u));
  }
  if (abs >= 0x477FF000u) return static_cast<uint16_t>(sign | 0x7C00u);  // rounds to >= 65520: inf
  if (abs < 0x38800000u) {  // subnormal half (or zero)
    if (abs < 0x33000000u) return static_cast<uint16_t>(sign);  // < half of the smallest subnormal
    const uint32_t mant = (abs & 0x007FFFFFu) | 0x00800000u;
    // value = mant * 2^(e-150) and the half subnormal unit is 2^-24, so h = mant >> (126 - e), 14..24.
    const int s = 126 - static_cast<int>(abs >> 23);
    uint32_t h = mant >> s;
    const uint32_t rem = mant & ((1u << s) - 1);
    const uint32_t half = 1u << (s - 1);
    if (rem > half || (rem == half && (h & 1u))) ++h;
    return static_cast<uint16_t>(sign | h);
  }
  uint32_t h = ((abs - 0x38000000u) >> 13);
  const uint32_t rem = abs & 0x1FFFu;
  if (rem > 0x1000u || (rem == 0x1000u && (h & 1u))) ++h;
  return static_cast<uint16_t>(sign | h);
}

float HalfToFloat(uint16_t h) {
  const uint32_t sign = static_cast<uint32_t>(h & 0x8000u) << 16;
  const uint32_t exp = (h >> 10) & 0x1Fu;
  const uint32_t mant = h & 0x3FFu;
  if (exp == 0) {
    const float v = std::ldexp(static_cast<float>(mant), -24);
    return sign ? -v : v;
  }
  if (exp == 31) return std::bit_cast<float>(sign | 0x7F800000u | (mant << 13));
  return std::bit_cast<float>(sign | ((exp + 112) << 23) | (mant << 13));
}

}  // namespace holo::protocol
