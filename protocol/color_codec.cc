#include "protocol/color_codec.h"

#include <algorithm>
#include <cstring>
#include <memory>

#include <csetjmp>
#include <cstdio>
#include <cstdlib>

#include <jpeglib.h>
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

// One decompressor per thread: creating it per image costs more than small images.
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

size_t VarintBytes(uint32_t v) {
  size_t n = 1;
  while (v >= 0x80) {
    v >>= 7;
    ++n;
  }
  return n;
}
uint32_t ZigZag32(int32_t v) { return (static_cast<uint32_t>(v) << 1) ^ static_cast<uint32_t>(v >> 31); }
int32_t UnZigZag32(uint32_t z) { return static_cast<int32_t>(z >> 1) ^ -static_cast<int32_t>(z & 1u); }

bool GetVarint(const uint8_t*& p, const uint8_t* end, uint32_t* v) {
  uint32_t r = 0;
  for (int shift = 0; shift <= 28; shift += 7) {
    if (p == end) return false;
    const uint8_t b = *p++;
    if (shift == 28 && (b & 0x70)) return false;  // the value would not fit 32 bits
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

// Fills the background pixels (`fg[i] == 0`) of the `w` × `h` RGB image `rgb`
// by push-pull: a pyramid of 2×2 means of the foreground (push), then every
// background pixel takes its value from the coarsest-needed level, bilinearly
// interpolated from the next coarser level (pull). The result continues the
// foreground smoothly across the silhouette, so that the JPEG blocks that
// straddle it carry no artificial edge (no ringing into the foreground, fewer
// AC bits) and blocks of pure background are nearly flat (DC only).
void PushPullFill(int w, int h, const uint8_t* fg, uint8_t* rgb) {
  struct Level {
    int w, h;
    std::vector<float> c;   // 3 per pixel: mean colour of the foreground below it
    std::vector<uint8_t> has;  // any foreground below it
  };
  std::vector<Level> lv;
  lv.push_back({w, h, std::vector<float>(static_cast<size_t>(w) * h * 3), std::vector<uint8_t>(fg, fg + size_t{1} * w * h)});
  for (size_t i = 0; i < lv[0].c.size(); ++i) lv[0].c[i] = rgb[i];
  while (lv.back().w > 1 || lv.back().h > 1) {
    const Level& f = lv.back();
    Level c{(f.w + 1) / 2, (f.h + 1) / 2, {}, {}};
    c.c.assign(static_cast<size_t>(c.w) * c.h * 3, 0.0f);
    c.has.assign(static_cast<size_t>(c.w) * c.h, 0);
    for (int y = 0; y < c.h; ++y)
      for (int x = 0; x < c.w; ++x) {
        float s[3] = {0, 0, 0};
        int n = 0;
        for (int dy = 0; dy < 2; ++dy)
          for (int dx = 0; dx < 2; ++dx) {
            const int fx = 2 * x + dx, fy = 2 * y + dy;
            if (fx >= f.w || fy >= f.h) continue;
            const size_t fi = static_cast<size_t>(fy) * f.w + fx;
            if (!f.has[fi]) continue;
            for (int k = 0; k < 3; ++k) s[k] += f.c[fi * 3 + k];
            ++n;
          }
        const size_t ci = static_cast<size_t>(y) * c.w + x;
        if (n) {
          c.has[ci] = 1;
          for (int k = 0; k < 3; ++k) c.c[ci * 3 + k] = s[k] / static_cast<float>(n);
        }
      }
    lv.push_back(std::move(c));
  }
  // Pull: coarse to fine, holes take the bilinear interpolation of the level above.
  for (size_t l = lv.size() - 1; l-- > 0;) {
    Level& f = lv[l];
    const Level& c = lv[l + 1];
    for (int y = 0; y < f.h; ++y) {
      const float cy = std::clamp((static_cast<float>(y) - 0.5f) * 0.5f, 0.0f, static_cast<float>(c.h - 1));
      const int y0 = static_cast<int>(cy), y1 = std::min(y0 + 1, c.h - 1);
      const float ty = cy - static_cast<float>(y0);
      for (int x = 0; x < f.w; ++x) {
        const size_t fi = static_cast<size_t>(y) * f.w + x;
        if (f.has[fi]) continue;
        const float cx = std::clamp((static_cast<float>(x) - 0.5f) * 0.5f, 0.0f, static_cast<float>(c.w - 1));
        const int x0 = static_cast<int>(cx), x1 = std::min(x0 + 1, c.w - 1);
        const float tx = cx - static_cast<float>(x0);
        const float* a = &c.c[(static_cast<size_t>(y0) * c.w + x0) * 3];
        const float* b = &c.c[(static_cast<size_t>(y0) * c.w + x1) * 3];
        const float* d = &c.c[(static_cast<size_t>(y1) * c.w + x0) * 3];
        const float* e = &c.c[(static_cast<size_t>(y1) * c.w + x1) * 3];
        for (int k = 0; k < 3; ++k) {
          f.c[fi * 3 + k] = (1 - ty) * ((1 - tx) * a[k] + tx * b[k]) + ty * ((1 - tx) * d[k] + tx * e[k]);
        }
      }
    }
  }
  for (size_t i = 0, n = static_cast<size_t>(w) * h; i < n; ++i) {
    if (fg[i]) continue;
    for (int k = 0; k < 3; ++k) rgb[i * 3 + k] = static_cast<uint8_t>(std::clamp(lv[0].c[i * 3 + k] + 0.5f, 0.0f, 255.0f));
  }
}


// Fills background pixels block by block on JPEG's MCU grid (`block` = 16
// for 4:2:0, 8 for 4:4:4): a block with foreground gets a push-pull fill of
// its own pixels (a smooth continuation of its foreground), a block without
// gets one flat colour, the mean of the block before it in the row (so its DC
// difference costs almost nothing and it has no AC at all). A global smooth
// fill would put gentle gradients into every empty block, which costs AC
// coefficients everywhere: measured +8% bytes against a flat mean fill.
void BlockwiseFill(int w, int h, int block, const uint8_t* fg, uint8_t* rgb) {
  std::vector<uint8_t> bm(static_cast<size_t>(block) * block), bc(bm.size() * 3);
  float global[3] = {0, 0, 0};
  size_t nfg = 0;
  for (size_t i = 0, n = static_cast<size_t>(w) * h; i < n; ++i) {
    if (!fg[i]) continue;
    for (int k = 0; k < 3; ++k) global[k] += rgb[i * 3 + k];
    ++nfg;
  }
  for (int k = 0; k < 3; ++k) global[k] = nfg ? global[k] / static_cast<float>(nfg) : 128.0f;
  for (int by = 0; by < h; by += block) {
    uint8_t prev[3] = {static_cast<uint8_t>(global[0] + 0.5f), static_cast<uint8_t>(global[1] + 0.5f),
                       static_cast<uint8_t>(global[2] + 0.5f)};
    for (int bx = 0; bx < w; bx += block) {
      const int cw = std::min(block, w - bx), ch = std::min(block, h - by);
      int n = 0;
      for (int y = 0; y < ch; ++y)
        for (int x = 0; x < cw; ++x) n += fg[static_cast<size_t>(by + y) * w + bx + x] != 0;
      if (n == 0) {
        for (int y = 0; y < ch; ++y)
          for (int x = 0; x < cw; ++x) std::memcpy(&rgb[(static_cast<size_t>(by + y) * w + bx + x) * 3], prev, 3);
        continue;
      }
      if (n < cw * ch) {
        for (int y = 0; y < ch; ++y) {
          std::memcpy(&bm[static_cast<size_t>(y) * cw], &fg[static_cast<size_t>(by + y) * w + bx], cw);
          std::memcpy(&bc[static_cast<size_t>(y) * cw * 3], &rgb[(static_cast<size_t>(by + y) * w + bx) * 3], cw * 3);
        }
        PushPullFill(cw, ch, bm.data(), bc.data());
        for (int y = 0; y < ch; ++y)
          std::memcpy(&rgb[(static_cast<size_t>(by + y) * w + bx) * 3], &bc[static_cast<size_t>(y) * cw * 3], cw * 3);
      }
      uint32_t s[3] = {0, 0, 0};
      for (int y = 0; y < ch; ++y)
        for (int x = 0; x < cw; ++x)
          for (int k = 0; k < 3; ++k) s[k] += rgb[(static_cast<size_t>(by + y) * w + bx + x) * 3 + k];
      for (int k = 0; k < 3; ++k) prev[k] = static_cast<uint8_t>((s[k] + cw * ch / 2) / (cw * ch));
    }
  }
}

// libjpeg reports errors through a callback that must not return: jump back.
struct JpegError {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};
[[noreturn]] void JpegErrorExit(j_common_ptr cinfo) {
  auto* e = reinterpret_cast<JpegError*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, e->message);
  std::longjmp(e->jump, 1);
}
void JpegSilence(j_common_ptr, int) {}

// The 64 quantization steps of one table in natural (row-major) order.
// kStandard: the luminance or chrominance table of JPEG Annex K scaled by
// `quality` as libjpeg does. kFlat: one step for every frequency, 16 scaled
// the same way (q85 → 5, q90 → 3, q95 → 2): the MSE-optimal choice at high
// rates, where the Annex K tables (made for the eye) spend too few bits on
// high frequencies and on chroma for a PSNR in RGB.
void QuantTable(ColorEncodeOptions::Quant quant, bool chroma, int quality, unsigned int* table) {
  static constexpr unsigned int kLuma[64] = {
      16, 11, 10, 16, 24,  40,  51,  61,  12, 12, 14, 19, 26,  58,  60,  55,  14, 13, 16, 24, 40,  57,
      69, 56, 14, 17, 22,  29,  51,  87,  80, 62, 18, 22, 37, 56,  68,  109, 103, 77, 24, 35, 55, 64,
      81, 104, 113, 92, 49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99};
  static constexpr unsigned int kChroma[64] = {
      17, 18, 24, 47, 99, 99, 99, 99, 18, 21, 26, 66, 99, 99, 99, 99, 24, 26, 56, 99, 99, 99,
      99, 99, 47, 66, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99,
      99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99};
  const long scale = quality < 50 ? 5000 / quality : 200 - 2 * quality;
  for (int i = 0; i < 64; ++i) {
    const unsigned int base = quant == ColorEncodeOptions::Quant::kFlat ? 16u : (chroma ? kChroma[i] : kLuma[i]);
    table[i] = static_cast<unsigned int>(std::clamp<long>((base * scale + 50) / 100, 1, 255));
  }
}

// Baseline JPEG of the `w` × `h` RGB8 pixels: accurate DCT, Huffman tables
// optimized for this image, quantization and subsampling from `o`.
Status CompressJpeg(const uint8_t* rgb, int w, int h, const ColorEncodeOptions& o, std::vector<uint8_t>* out) {
  jpeg_compress_struct cinfo;
  JpegError err;
  cinfo.err = jpeg_std_error(&err.mgr);
  err.mgr.error_exit = JpegErrorExit;
  err.mgr.emit_message = JpegSilence;
  unsigned char* buf = nullptr;
  unsigned long size = 0;
  if (setjmp(err.jump)) {
    jpeg_destroy_compress(&cinfo);
    std::free(buf);
    return Internal(std::string("libjpeg: ") + err.message);
  }
  jpeg_create_compress(&cinfo);
  jpeg_mem_dest(&cinfo, &buf, &size);
  cinfo.image_width = static_cast<JDIMENSION>(w);
  cinfo.image_height = static_cast<JDIMENSION>(h);
  cinfo.input_components = 3;
  cinfo.in_color_space = JCS_RGB;
  jpeg_set_defaults(&cinfo);
  cinfo.dct_method = o.accurate_dct ? JDCT_ISLOW : JDCT_IFAST;
  cinfo.optimize_coding = o.optimize_huffman ? TRUE : FALSE;
  unsigned int table[64];
  QuantTable(o.quant, false, o.jpeg_quality, table);
  jpeg_add_quant_table(&cinfo, 0, table, 100, TRUE);
  QuantTable(o.quant, true, o.jpeg_quality, table);
  jpeg_add_quant_table(&cinfo, 1, table, 100, TRUE);
  // Flat tables are the same for all channels: one table in the file.
  if (o.quant == ColorEncodeOptions::Quant::kFlat)
    for (int c = 0; c < 3; ++c) cinfo.comp_info[c].quant_tbl_no = 0;
  const int luma_sampling = o.chroma_420 ? 2 : 1;
  cinfo.comp_info[0].h_samp_factor = cinfo.comp_info[0].v_samp_factor = luma_sampling;
  for (int c = 1; c < 3; ++c) cinfo.comp_info[c].h_samp_factor = cinfo.comp_info[c].v_samp_factor = 1;
  jpeg_start_compress(&cinfo, TRUE);
  while (cinfo.next_scanline < cinfo.image_height) {
    JSAMPROW row = const_cast<JSAMPROW>(rgb + static_cast<size_t>(cinfo.next_scanline) * w * 3);
    jpeg_write_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_compress(&cinfo);
  jpeg_destroy_compress(&cinfo);
  out->assign(buf, buf + size);
  std::free(buf);
  return OkStatus();
}

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

  // Mask: per row of the box, the x positions where foreground starts or
  // ends ("transitions"), coded against the row above when it has as many
  // (silhouettes move by a pixel or two from row to row).
  std::vector<uint8_t> rle;
  rle.reserve(static_cast<size_t>(bh) * 8);
  std::vector<uint32_t> prev, cur;
  for (int y = y0; y <= y1; ++y) {
    cur.clear();
    bool fg = false;
    for (int x = x0; x <= x1; ++x) {
      if (IsFg(mask, x, y) != fg) {
        cur.push_back(static_cast<uint32_t>(x - x0));
        fg = !fg;
      }
    }
    size_t delta_bytes = SIZE_MAX, explicit_bytes = VarintBytes(static_cast<uint32_t>(cur.size() + 1));
    for (size_t i = 0; i < cur.size(); ++i) explicit_bytes += VarintBytes(cur[i] - (i ? cur[i - 1] + 1 : 0));
    if (cur.size() == prev.size()) {
      delta_bytes = 1;
      for (size_t i = 0; i < cur.size(); ++i) delta_bytes += VarintBytes(ZigZag32(int32_t(cur[i] - prev[i])));
    }
    if (delta_bytes <= explicit_bytes) {
      PutVarint(&rle, 0);
      for (size_t i = 0; i < cur.size(); ++i) PutVarint(&rle, ZigZag32(int32_t(cur[i] - prev[i])));
    } else {
      PutVarint(&rle, static_cast<uint32_t>(cur.size() + 1));
      for (size_t i = 0; i < cur.size(); ++i) PutVarint(&rle, cur[i] - (i ? cur[i - 1] + 1 : 0));
    }
    prev.swap(cur);
  }
  const size_t at = w.ReserveU32();
  size_t start = out->size();
  out->resize(start + ZSTD_compressBound(rle.size()));
  const size_t z = ZSTD_compress(out->data() + start, out->size() - start, rle.data(), rle.size(), 9);
  if (ZSTD_isError(z)) return Internal(std::string("zstd: ") + ZSTD_getErrorName(z));
  out->resize(start + z);
  w.PatchU32(at, static_cast<uint32_t>(z));

  // Box pixels. Background inside the box must cost JPEG as few bits as
  // possible and must not ring into the foreground: see FillBackground.
  std::vector<uint8_t> box(static_cast<size_t>(bw) * bh * 3);
  std::vector<uint8_t> box_mask(static_cast<size_t>(bw) * bh);
  for (int y = 0; y < bh; ++y) {
    for (int x = 0; x < bw; ++x) {
      const size_t i = static_cast<size_t>(y) * bw + x;
      box_mask[i] = IsFg(mask, x0 + x, y0 + y) ? 1 : 0;
      if (box_mask[i]) std::memcpy(&box[i * 3], &image.at(x0 + x, y0 + y), 3);
    }
  }
  if (o.fill == ColorEncodeOptions::Fill::kMean) {
    const uint8_t fill[3] = {static_cast<uint8_t>(sum[0] / count), static_cast<uint8_t>(sum[1] / count),
                             static_cast<uint8_t>(sum[2] / count)};
    for (size_t i = 0; i < box_mask.size(); ++i)
      if (!box_mask[i]) std::memcpy(&box[i * 3], fill, 3);
  } else {
    BlockwiseFill(bw, bh, o.chroma_420 ? 16 : 8, box_mask.data(), box.data());
  }
  std::vector<uint8_t> jpeg;
  HOLO_RETURN_IF_ERROR(CompressJpeg(box.data(), bw, bh, o, &jpeg));
  w.Blob32(jpeg);
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

  // Mask rows: per row a header varint and at most bw transitions, each a varint of ≤ 3 bytes.
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
  std::vector<uint32_t> prev, cur;
  for (int y = 0; y < bh; ++y) {
    uint32_t head = 0;
    if (!GetVarint(p, end, &head)) return DataLoss("c1.mask: row " + Str(y) + " ends early");
    cur.clear();
    if (head == 0) {  // as many transitions as the row above, each a signed delta to it
      for (uint32_t t : prev) {
        uint32_t z = 0;
        if (!GetVarint(p, end, &z)) return DataLoss("c1.mask: row " + Str(y) + " ends early");
        cur.push_back(t + static_cast<uint32_t>(UnZigZag32(z)));  // wraps; range-checked below
      }
    } else {
      if (head - 1 > bw) return DataLoss("c1.mask: row " + Str(y) + " has more transitions than pixels");
      uint32_t next = 0;  // the smallest value the next transition may take
      for (uint32_t i = 0; i + 1 < head; ++i) {
        uint32_t gap = 0;
        if (!GetVarint(p, end, &gap)) return DataLoss("c1.mask: row " + Str(y) + " ends early");
        if (gap >= bw) return DataLoss("c1.mask: transition outside row " + Str(y));
        cur.push_back(next + gap);
        next = next + gap + 1;
      }
    }
    // Validate the whole row before filling: a fill needs its run's end too.
    for (size_t i = 0; i < cur.size(); ++i) {
      if (cur[i] >= bw || (i > 0 && cur[i] <= cur[i - 1])) {
        return DataLoss("c1.mask: transitions of row " + Str(y) + " out of order or outside the box");
      }
    }
    uint8_t* row = &mask->at(x0, y0 + y);
    for (size_t i = 0; i < cur.size(); i += 2) {
      const uint32_t stop = i + 1 < cur.size() ? cur[i + 1] : bw;
      std::memset(row + cur[i], 255, stop - cur[i]);
    }
    prev.swap(cur);
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
                    TJPF_RGB, TJFLAG_ACCURATEDCT) != 0) {
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
