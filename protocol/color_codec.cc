#include "protocol/color_codec.h"

#include <algorithm>
#include <cstring>
#include <memory>

#include <lz4.h>
#include <turbojpeg.h>
#include <zstd.h>

#include "protocol/byte_io.h"

namespace holo::protocol {
namespace {

std::string Str(uint64_t v) { return std::to_string(v); }

struct TjDeleter {
  void operator()(void* h) const {
    if (h) tjDestroy(h);
  }
};
using TjHandle = std::unique_ptr<void, TjDeleter>;

// One compressor and one decompressor per thread: creating them per image costs more than small images.
tjhandle Compressor() {
  thread_local TjHandle h(tjInitCompress());
  return h.get();
}
tjhandle Decompressor() {
  thread_local TjHandle h(tjInitDecompress());
  return h.get();
}

void PutVarint(std::vector<uint8_t>* out, uint32_t v) {
  while (v >= 0x80) {
    out->push_back(static_cast<uint8_t>(v | 0x80));
    v >>= 7;
  }
  out->push_back(static_cast<uint8_t>(v));
}

bool GetVarint(const uint8_t*& p, const uint8_t* end, uint32_t* v) {
  uint32_t r = 0;
  for (int shift = 0; shift <= 28; shift += 7) {
    if (p == end) return false;
    const uint8_t b = *p++;
    r |= static_cast<uint32_t>(b & 0x7F) << shift;
    if (!(b & 0x80)) {
      *v = r;
      return true;
    }
  }
  return false;
}

Status CheckSize(const char* field, uint32_t w, uint32_t h, const Limits& limits) {
  if (w == 0 || h == 0 || w > limits.max_image_dim || h > limits.max_image_dim ||
      uint64_t{w} * h > limits.max_image_pixels) {
    return DataLoss(std::string(field) + ": image size " + Str(w) + "x" + Str(h) + " outside the limits");
  }
  return OkStatus();
}

bool IsFg(const ImageGray8& mask, int x, int y) { return mask.empty() || mask.at(x, y) != 0; }

// ------------------------------------------------------------------ C0

Status EncodeC0(const ImageRgb8& image, const ImageGray8& mask, std::vector<uint8_t>* out) {
  std::vector<uint8_t> keyed(image.storage());
  const size_t n = image.num_pixels();
  for (size_t i = 0; i < n; ++i) {
    uint8_t* p = &keyed[i * 3];
    if (!mask.empty() && mask.data()[i] == 0) {
      p[0] = p[1] = p[2] = 0;
    } else if (p[0] == 0 && p[1] == 0 && p[2] == 0) {
      p[2] = 1;  // keep foreground distinguishable from the key colour
    }
  }
  ByteWriter w(out);
  const size_t at = w.ReserveU32();
  const size_t start = out->size();
  out->resize(start + static_cast<size_t>(LZ4_compressBound(static_cast<int>(keyed.size()))));
  const int lz = LZ4_compress_default(reinterpret_cast<const char*>(keyed.data()),
                                      reinterpret_cast<char*>(out->data() + start), static_cast<int>(keyed.size()),
                                      static_cast<int>(out->size() - start));
  if (lz <= 0) return Internal("LZ4 compression of the image failed");
  out->resize(start + static_cast<size_t>(lz));
  w.PatchU32(at, static_cast<uint32_t>(lz));
  return OkStatus();
}

Status DecodeC0(ByteReader& r, uint32_t w, uint32_t h, ImageRgb8* image, ImageGray8* mask) {
  std::span<const uint8_t> lz;
  HOLO_RETURN_IF_ERROR(r.Blob32("c0.pixels", r.remaining(), &lz));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd("c0"));
  const uint64_t want = uint64_t{w} * h * 3;
  if (want > uint64_t{lz.size()} * 255 + 16) {
    return DataLoss("c0.pixels: " + Str(want) + " bytes cannot come from " + Str(lz.size()) + " LZ4 bytes");
  }
  image->Resize(static_cast<int>(w), static_cast<int>(h));
  const int got = LZ4_decompress_safe(reinterpret_cast<const char*>(lz.data()), reinterpret_cast<char*>(image->data()),
                                      static_cast<int>(lz.size()), static_cast<int>(want));
  if (got != static_cast<int>(want)) return DataLoss("c0.pixels: LZ4 data is corrupt or has the wrong size");
  mask->Resize(static_cast<int>(w), static_cast<int>(h));
  const uint8_t* p = image->data();
  uint8_t* m = mask->data();
  for (size_t i = 0, n = image->num_pixels(); i < n; ++i) m[i] = (p[i * 3] | p[i * 3 + 1] | p[i * 3 + 2]) ? 255 : 0;
  return OkStatus();
}

// ------------------------------------------------------------------ C1

Status EncodeC1(const ImageRgb8& image, const ImageGray8& mask, const ColorEncodeOptions& o,
                std::vector<uint8_t>* out) {
  const int W = image.width(), H = image.height();
  int x0 = W, y0 = H, x1 = -1, y1 = -1;
  uint64_t sum[3] = {0, 0, 0}, count = 0;
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      if (!IsFg(mask, x, y)) continue;
      x0 = std::min(x0, x);
      x1 = std::max(x1, x);
      y0 = std::min(y0, y);
      y1 = std::max(y1, y);
      for (int c = 0; c < 3; ++c) sum[c] += image.at(x, y, c);
      ++count;
    }
  }
  ByteWriter w(out);
  if (count == 0) {
    for (int i = 0; i < 4; ++i) w.U16(0);
    w.U32(0);
    w.U32(0);
    return OkStatus();
  }
  const int bw = x1 - x0 + 1, bh = y1 - y0 + 1;
  w.U16(static_cast<uint16_t>(x0));
  w.U16(static_cast<uint16_t>(y0));
  w.U16(static_cast<uint16_t>(bw));
  w.U16(static_cast<uint16_t>(bh));

  // Mask: per row of the box, alternating run lengths starting with background.
  std::vector<uint8_t> rle;
  rle.reserve(static_cast<size_t>(bh) * 8);
  for (int y = y0; y <= y1; ++y) {
    bool fg = false;
    uint32_t run = 0;
    for (int x = x0; x <= x1; ++x) {
      if (IsFg(mask, x, y) != fg) {
        PutVarint(&rle, run);
        fg = !fg;
        run = 0;
      }
      ++run;
    }
    PutVarint(&rle, run);
  }
  const size_t at = w.ReserveU32();
  size_t start = out->size();
  out->resize(start + ZSTD_compressBound(rle.size()));
  const size_t z = ZSTD_compress(out->data() + start, out->size() - start, rle.data(), rle.size(), 3);
  if (ZSTD_isError(z)) return Internal(std::string("zstd: ") + ZSTD_getErrorName(z));
  out->resize(start + z);
  w.PatchU32(at, static_cast<uint32_t>(z));

  // Box pixels; background inside the box gets the mean foreground colour so
  // that JPEG does not ring at the silhouette.
  const uint8_t fill[3] = {static_cast<uint8_t>(sum[0] / count), static_cast<uint8_t>(sum[1] / count),
                           static_cast<uint8_t>(sum[2] / count)};
  std::vector<uint8_t> box(static_cast<size_t>(bw) * bh * 3);
  for (int y = 0; y < bh; ++y) {
    for (int x = 0; x < bw; ++x) {
      uint8_t* d = &box[(static_cast<size_t>(y) * bw + x) * 3];
      if (IsFg(mask, x0 + x, y0 + y)) {
        std::memcpy(d, &image.at(x0 + x, y0 + y), 3);
      } else {
        std::memcpy(d, fill, 3);
      }
    }
  }
  unsigned char* jpeg = nullptr;
  unsigned long jpeg_size = 0;
  if (tjCompress2(Compressor(), box.data(), bw, 0, bh, TJPF_RGB, &jpeg, &jpeg_size, o.chroma_420 ? TJSAMP_420 : TJSAMP_444,
                  o.jpeg_quality, TJFLAG_FASTDCT) != 0) {
    if (jpeg) tjFree(jpeg);
    return Internal(std::string("turbojpeg: ") + tjGetErrorStr2(Compressor()));
  }
  w.Blob32(std::span<const uint8_t>(jpeg, jpeg_size));
  tjFree(jpeg);
  return OkStatus();
}

Status DecodeC1(ByteReader& r, uint32_t W, uint32_t H, ImageRgb8* image, ImageGray8* mask) {
  uint16_t x0 = 0, y0 = 0, bw = 0, bh = 0;
  HOLO_RETURN_IF_ERROR(r.U16("c1.box_x", &x0));
  HOLO_RETURN_IF_ERROR(r.U16("c1.box_y", &y0));
  HOLO_RETURN_IF_ERROR(r.U16("c1.box_width", &bw));
  HOLO_RETURN_IF_ERROR(r.U16("c1.box_height", &bh));
  std::span<const uint8_t> zmask, jpeg;
  HOLO_RETURN_IF_ERROR(r.Blob32("c1.mask", r.remaining(), &zmask));
  HOLO_RETURN_IF_ERROR(r.Blob32("c1.jpeg", r.remaining(), &jpeg));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd("c1"));
  const bool empty_box = bw == 0 || bh == 0;
  if (empty_box && (bw != 0 || bh != 0 || x0 != 0 || y0 != 0 || !zmask.empty() || !jpeg.empty())) {
    return DataLoss("c1.box: an empty box must be all zero with no mask or JPEG bytes");
  }
  if (!empty_box && (uint32_t{x0} + bw > W || uint32_t{y0} + bh > H)) {
    return DataLoss("c1.box: box " + Str(x0) + "," + Str(y0) + " " + Str(bw) + "x" + Str(bh) + " leaves the " +
                    Str(W) + "x" + Str(H) + " image");
  }
  image->Resize(static_cast<int>(W), static_cast<int>(H));
  mask->Resize(static_cast<int>(W), static_cast<int>(H));
  if (empty_box) return OkStatus();

  // Mask run lengths: at most bw + 1 runs of ≤ 2-byte varints per row.
  const unsigned long long declared = ZSTD_getFrameContentSize(zmask.data(), zmask.size());
  const uint64_t bound = uint64_t{bh} * (uint64_t{bw} + 1) * 3;
  if (declared == ZSTD_CONTENTSIZE_ERROR || declared == ZSTD_CONTENTSIZE_UNKNOWN || declared > bound ||
      declared < bh) {
    return DataLoss("c1.mask: zstd frame size is missing or impossible for the box");
  }
  std::vector<uint8_t> rle(declared);
  const size_t got = ZSTD_decompress(rle.data(), rle.size(), zmask.data(), zmask.size());
  if (ZSTD_isError(got) || got != declared) return DataLoss("c1.mask: zstd data is corrupt");
  const uint8_t* p = rle.data();
  const uint8_t* end = p + rle.size();
  for (int y = 0; y < bh; ++y) {
    uint8_t* row = &mask->at(x0, y0 + y);
    uint32_t x = 0;
    bool fg = false;
    while (true) {
      uint32_t run = 0;
      if (!GetVarint(p, end, &run)) return DataLoss("c1.mask: run lengths end early in row " + Str(y));
      if (run > bw - x) return DataLoss("c1.mask: runs overflow row " + Str(y));
      if (fg) std::memset(row + x, 255, run);
      x += run;
      fg = !fg;
      if (x == bw) break;
    }
  }
  if (p != end) return DataLoss("c1.mask: trailing run lengths");

  int jw = 0, jh = 0, sub = 0, cs = 0;
  if (jpeg.size() > 0xFFFFFFFFu ||
      tjDecompressHeader3(Decompressor(), jpeg.data(), static_cast<unsigned long>(jpeg.size()), &jw, &jh, &sub, &cs) != 0) {
    return DataLoss("c1.jpeg: not a JPEG image");
  }
  if (jw != bw || jh != bh) {
    return DataLoss("c1.jpeg: JPEG is " + Str(static_cast<uint32_t>(jw)) + "x" + Str(static_cast<uint32_t>(jh)) +
                    ", box is " + Str(bw) + "x" + Str(bh));
  }
  std::vector<uint8_t> box(static_cast<size_t>(bw) * bh * 3);
  if (tjDecompress2(Decompressor(), jpeg.data(), static_cast<unsigned long>(jpeg.size()), box.data(), bw, 0, bh,
                    TJPF_RGB, TJFLAG_FASTDCT) != 0) {
    // Warnings (e.g. a truncated but partly decodable JPEG) are errors here: no guessing on the wire.
    return DataLoss(std::string("c1.jpeg: ") + tjGetErrorStr2(Decompressor()));
  }
  for (int y = 0; y < bh; ++y) {
    const uint8_t* m = &mask->at(x0, y0 + y);
    uint8_t* d = &image->at(x0, y0 + y);
    const uint8_t* s = &box[static_cast<size_t>(y) * bw * 3];
    for (int x = 0; x < bw; ++x) {
      if (m[x]) std::memcpy(d + x * 3, s + x * 3, 3);
    }
  }
  return OkStatus();
}

}  // namespace

Status ColorEncodeOptions::Check() const {
  if (codec != ColorCodec::kC0 && codec != ColorCodec::kC1) {
    return InvalidArgument("codec must be C0 or C1 (H.264 is reserved, not implemented)");
  }
  if (jpeg_quality < 1 || jpeg_quality > 100) {
    return InvalidArgument("jpeg_quality must be in [1, 100], got " + std::to_string(jpeg_quality));
  }
  return OkStatus();
}

Status EncodeColor(const ImageRgb8& image, const ImageGray8& mask, const ColorEncodeOptions& options,
                   std::vector<uint8_t>* out) {
  HOLO_RETURN_IF_ERROR(options.Check());
  const Limits limits;
  if (image.empty()) return InvalidArgument("image is empty");
  if (!mask.empty() && (mask.width() != image.width() || mask.height() != image.height())) {
    return InvalidArgument("mask is " + Str(mask.width()) + "x" + Str(mask.height()) + ", image is " +
                           Str(image.width()) + "x" + Str(image.height()));
  }
  const Status size_ok = CheckSize("image", image.width(), image.height(), limits);
  if (!size_ok.ok()) return InvalidArgument(size_ok.message());
  ByteWriter w(out);
  w.U8(static_cast<uint8_t>(options.codec));
  w.U8(0);
  w.U16(static_cast<uint16_t>(image.width()));
  w.U16(static_cast<uint16_t>(image.height()));
  if (options.codec == ColorCodec::kC0) return EncodeC0(image, mask, out);
  return EncodeC1(image, mask, options, out);
}

Status DecodeColor(std::span<const uint8_t> blob, ImageRgb8* image, ImageGray8* mask, const Limits& limits) {
  ByteReader r(blob);
  uint8_t codec = 0, flags = 0;
  uint16_t w = 0, h = 0;
  HOLO_RETURN_IF_ERROR(r.U8("color.codec", &codec));
  HOLO_RETURN_IF_ERROR(r.U8("color.flags", &flags));
  HOLO_RETURN_IF_ERROR(r.U16("color.width", &w));
  HOLO_RETURN_IF_ERROR(r.U16("color.height", &h));
  if (flags != 0) return DataLoss("color.flags: unknown flag bits set");
  HOLO_RETURN_IF_ERROR(CheckSize("color.width", w, h, limits));
  Status s;
  switch (codec) {
    case static_cast<uint8_t>(ColorCodec::kC0): s = DecodeC0(r, w, h, image, mask); break;
    case static_cast<uint8_t>(ColorCodec::kC1): s = DecodeC1(r, w, h, image, mask); break;
    case static_cast<uint8_t>(ColorCodec::kH264):
      s = UnsupportedVersion("color.codec: H.264 (codec 3) is reserved and not implemented in this build");
      break;
    default: s = DataLoss("color.codec: unknown color codec " + Str(codec));
  }
  if (!s.ok()) {
    *image = ImageRgb8();
    *mask = ImageGray8();
  }
  return s;
}

}  // namespace holo::protocol
