#include "protocol/depth_codec.h"

#include <zstd.h>

#include <cstring>
#include <string>

#include "protocol/byte_io.h"

namespace holo::protocol {
namespace {

constexpr uint8_t kD1 = 1;
constexpr size_t kBlobHeader = 1 + 2 + 2 + 4;

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
  // Row deltas, little endian (the host is little endian: checked by byte_io).
  thread_local std::vector<uint16_t> delta;
  delta.resize(static_cast<size_t>(w) * h);
  for (int y = 0; y < h; ++y) {
    const uint16_t* src = depth.row(y);
    uint16_t* dst = delta.data() + static_cast<size_t>(y) * w;
    dst[0] = src[0];
    for (int x = 1; x < w; ++x) dst[x] = static_cast<uint16_t>(src[x] - src[x - 1]);
  }
  const size_t raw = delta.size() * 2;
  const size_t bound = ZSTD_compressBound(raw);
  const size_t start = out->size();
  out->resize(start + kBlobHeader + bound);
  uint8_t* p = out->data() + start;
  p[0] = kD1;
  const auto w16 = static_cast<uint16_t>(w), h16 = static_cast<uint16_t>(h);
  std::memcpy(p + 1, &w16, 2);
  std::memcpy(p + 3, &h16, 2);
  const size_t n = ZSTD_compress(p + kBlobHeader, bound, delta.data(), raw, options.zstd_level);
  if (ZSTD_isError(n)) {
    out->resize(start);
    return Internal(std::string("EncodeDepth: zstd: ") + ZSTD_getErrorName(n));
  }
  const auto n32 = static_cast<uint32_t>(n);
  std::memcpy(p + 5, &n32, 4);
  out->resize(start + kBlobHeader + n);
  return OkStatus();
}

Status PeekDepthSize(std::span<const uint8_t> blob, int* width, int* height) {
  ByteReader r(blob);
  uint8_t codec = 0;
  uint16_t w = 0, h = 0;
  HOLO_RETURN_IF_ERROR(r.U8("depth.codec", &codec));
  if (codec != kD1) return DataLoss("depth.codec: unknown depth codec " + std::to_string(codec));
  HOLO_RETURN_IF_ERROR(r.U16("depth.width", &w));
  HOLO_RETURN_IF_ERROR(r.U16("depth.height", &h));
  *width = w;
  *height = h;
  return OkStatus();
}

Status DecodeDepth(std::span<const uint8_t> blob, ImageDepth16* depth, const Limits& limits) {
  ByteReader r(blob);
  uint8_t codec = 0;
  uint16_t w = 0, h = 0;
  HOLO_RETURN_IF_ERROR(r.U8("depth.codec", &codec));
  if (codec != kD1) return DataLoss("depth.codec: unknown depth codec " + std::to_string(codec));
  HOLO_RETURN_IF_ERROR(r.U16("depth.width", &w));
  HOLO_RETURN_IF_ERROR(r.U16("depth.height", &h));
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
  if (depth->width() != w || depth->height() != h) depth->Resize(w, h);
  const size_t n = ZSTD_decompress(depth->data(), pixels * 2, z.data(), z.size());
  if (ZSTD_isError(n)) return DataLoss(std::string("depth.zstd: ") + ZSTD_getErrorName(n));
  if (n != pixels * 2) return DataLoss("depth.zstd: decoded " + std::to_string(n) + " bytes, expected " + std::to_string(pixels * 2));
  for (int y = 0; y < h; ++y) {
    uint16_t* row = depth->row(y);
    for (int x = 1; x < w; ++x) row[x] = static_cast<uint16_t>(row[x] + row[x - 1]);
  }
  return OkStatus();
}

}  // namespace holo::protocol
