#include "protocol/depth_codec.h"

#include <zstd.h>

#include <algorithm>
#include <cstring>
#include <string>

#include "protocol/byte_io.h"

namespace holo::protocol {
namespace {

constexpr uint8_t kD1 = 1;
constexpr size_t kBlobHeader = 1 + 2 + 2 + 4;

// LOCO-I's median edge detector from the left (a), upper (b) and upper-left
// (c) neighbours; the first row predicts from the left, the first column from above.
inline int PredictMed(const uint16_t* row, const uint16_t* up, int x) {
  if (!up) return x > 0 ? row[x - 1] : 0;
  if (x == 0) return up[0];
  const int a = row[x - 1], b = up[x], c = up[x - 1];
  if (c >= std::max(a, b)) return std::min(a, b);
  if (c <= std::min(a, b)) return std::max(a, b);
  return a + b - c;
}

inline uint16_t ZigZag(int16_t v) {
  return static_cast<uint16_t>((static_cast<uint16_t>(v) << 1) ^ static_cast<uint16_t>(v >> 15));
}
inline int16_t UnZigZag(uint16_t z) { return static_cast<int16_t>((z >> 1) ^ (~(z & 1) + 1)); }

}  // namespace

Status DepthEncodeOptions::Check() const {
  if (zstd_level < 1 || zstd_level > 19) return InvalidArgument("zstd_level must be in 1..19, got " + std::to_string(zstd_level));
  return OkStatus();
}

Status EncodeDepth(const ImageDepth16& depth, const DepthEncodeOptions& options, std::vector<uint8_t>* out) {
  HOLO_RETURN_IF_ERROR(options.Check());
  const int w = depth.width(), h = depth.height();
  if (w <= 0 || h <= 0 || w > 0xFFFF || h > 0xFFFF)
    return InvalidArgument("EncodeDepth: image size " + std::to_string(w) + "x" + std::to_string(h) + " outside 1..65535");
  // MED-predicted residuals, zigzag coded, split into a plane of high bytes
  // then a plane of low bytes (mostly zeros, then small numbers: what zstd's
  // entropy stage codes well).
  thread_local std::vector<uint8_t> planes;
  const size_t n = static_cast<size_t>(w) * h;
  planes.resize(2 * n);
  for (int y = 0; y < h; ++y) {
    const uint16_t* row = depth.row(y);
    const uint16_t* up = y > 0 ? depth.row(y - 1) : nullptr;
    for (int x = 0; x < w; ++x) {
      const int pred = PredictMed(row, up, x);
      const uint16_t z = ZigZag(static_cast<int16_t>(static_cast<uint16_t>(row[x] - pred)));
      const size_t i = static_cast<size_t>(y) * w + x;
      planes[i] = static_cast<uint8_t>(z >> 8);
      planes[n + i] = static_cast<uint8_t>(z & 0xFF);
    }
  }
  const size_t raw = planes.size();
  const size_t bound = ZSTD_compressBound(raw);
  const size_t start = out->size();
  out->resize(start + kBlobHeader + bound);
  uint8_t* p = out->data() + start;
  p[0] = kD1;
  const auto w16 = static_cast<uint16_t>(w), h16 = static_cast<uint16_t>(h);
  std::memcpy(p + 1, &w16, 2);
  std::memcpy(p + 3, &h16, 2);
  const size_t zn = ZSTD_compress(p + kBlobHeader, bound, planes.data(), raw, options.zstd_level);
  if (ZSTD_isError(zn)) {
    out->resize(start);
    return Internal(std::string("EncodeDepth: zstd: ") + ZSTD_getErrorName(zn));
  }
  const auto n32 = static_cast<uint32_t>(zn);
  std::memcpy(p + 5, &n32, 4);
  out->resize(start + kBlobHeader + zn);
  return OkStatus();
}

namespace {
// The blob's codec byte (must be D1), width and height.
Status ReadDepthHeader(ByteReader& r, uint16_t* w, uint16_t* h) {
  uint8_t codec = 0;
  HOLO_RETURN_IF_ERROR(r.U8("depth.codec", &codec));
  if (codec != kD1) return DataLoss("depth.codec: unknown depth codec " + std::to_string(codec));
  HOLO_RETURN_IF_ERROR(r.U16("depth.width", w));
  return r.U16("depth.height", h);
}
}  // namespace

Status PeekDepthSize(std::span<const uint8_t> blob, int* width, int* height) {
  ByteReader r(blob);
  uint16_t w = 0, h = 0;
  HOLO_RETURN_IF_ERROR(ReadDepthHeader(r, &w, &h));
  *width = w;
  *height = h;
  return OkStatus();
}

Status DecodeDepth(std::span<const uint8_t> blob, ImageDepth16* depth, const Limits& limits) {
  ByteReader r(blob);
  uint16_t w = 0, h = 0;
  HOLO_RETURN_IF_ERROR(ReadDepthHeader(r, &w, &h));
  if (w == 0 || h == 0 || w > limits.max_image_dim || h > limits.max_image_dim)
    return DataLoss("depth.width: image size " + std::to_string(w) + "x" + std::to_string(h) + " outside 1.." +
                    std::to_string(limits.max_image_dim));
  const uint64_t pixels = uint64_t{w} * h;
  if (pixels > limits.max_image_pixels)
    return DataLoss("depth.width: " + std::to_string(pixels) + " pixels exceed limit " + std::to_string(limits.max_image_pixels));
  std::span<const uint8_t> z;
  HOLO_RETURN_IF_ERROR(r.Blob32("depth.zstd", blob.size(), &z));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd("depth"));
  const unsigned long long declared = ZSTD_getFrameContentSize(z.data(), z.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR) return DataLoss("depth.zstd: not a zstd frame");
  if (declared == ZSTD_CONTENTSIZE_UNKNOWN) return DataLoss("depth.zstd: frame does not declare its size");
  if (declared != pixels * 2)
    return DataLoss("depth.zstd: frame holds " + std::to_string(declared) + " bytes, a " + std::to_string(w) + "x" +
                    std::to_string(h) + " image needs " + std::to_string(pixels * 2));
  // Exactly one frame, nothing after it.
  const size_t frame_size = ZSTD_findFrameCompressedSize(z.data(), z.size());
  if (ZSTD_isError(frame_size) || frame_size != z.size()) return DataLoss("depth.zstd: corrupt or trailing bytes");
  thread_local std::vector<uint8_t> planes;
  planes.resize(pixels * 2);
  const size_t n = ZSTD_decompress(planes.data(), planes.size(), z.data(), z.size());
  if (ZSTD_isError(n)) return DataLoss(std::string("depth.zstd: ") + ZSTD_getErrorName(n));
  if (n != pixels * 2) return DataLoss("depth.zstd: decoded " + std::to_string(n) + " bytes, expected " + std::to_string(pixels * 2));
  if (depth->width() != w || depth->height() != h) depth->Resize(w, h);
  for (int y = 0; y < h; ++y) {
    uint16_t* row = depth->row(y);
    const uint16_t* up = y > 0 ? depth->row(y - 1) : nullptr;
    for (int x = 0; x < w; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      const auto zz = static_cast<uint16_t>((planes[i] << 8) | planes[pixels + i]);
      row[x] = static_cast<uint16_t>(PredictMed(row, up, x) + UnZigZag(zz));
    }
  }
  return OkStatus();
}

}  // namespace holo::protocol
