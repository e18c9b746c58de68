#include "protocol/color_codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <memory>
#include <new>

#include <csetjmp>
#include <cstdio>
#include <cstdlib>

#include <jpeglib.h>
#include <jerror.h>
#include <lz4.h>
#include <turbojpeg.h>
#include <zstd.h>

#include "protocol/byte_io.h"

namespace holo::protocol {
namespace {

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

// Byte scans of mask rows, 32 then eight bytes at a time (masks are mostly long runs).
// Little-endian loads: the lowest address is the lowest byte.
int FirstSet(const uint8_t* p, int n) {
  int i = 0;
  for (; i + 32 <= n; i += 32) {  // long background runs: 32 bytes per test
    uint64_t v[4];
    std::memcpy(v, p + i, 32);
    if (v[0] | v[1] | v[2] | v[3]) break;
  }
  for (; i + 8 <= n; i += 8) {
    uint64_t v;
    std::memcpy(&v, p + i, 8);
    if (v) return i + (std::countr_zero(v) >> 3);
  }
  for (; i < n; ++i)
    if (p[i]) return i;
  return -1;
}
int FirstClear(const uint8_t* p, int n) {
  constexpr uint64_t kOnes = 0x0101010101010101ull, kHighs = 0x8080808080808080ull;
  auto zeros = [](uint64_t v) { return (v - kOnes) & ~v & kHighs; };
  int i = 0;
  for (; i + 32 <= n; i += 32) {  // long foreground runs: 32 bytes per test
    uint64_t v[4];
    std::memcpy(v, p + i, 32);
    if (zeros(v[0]) | zeros(v[1]) | zeros(v[2]) | zeros(v[3])) break;
  }
  for (; i + 8 <= n; i += 8) {
    uint64_t v;
    std::memcpy(&v, p + i, 8);
    // The lowest flagged byte is the first zero byte (flags above it may be false).
    const uint64_t z = zeros(v);
    if (z) return i + (std::countr_zero(z) >> 3);
  }
  for (; i < n; ++i)
    if (!p[i]) return i;
  return -1;
}
int LastSet(const uint8_t* p, int n) {
  int i = n;
  for (; i >= 32; i -= 32) {
    uint64_t v[4];
    std::memcpy(v, p + i - 32, 32);
    if (v[0] | v[1] | v[2] | v[3]) break;
  }
  for (; i >= 8; i -= 8) {
    uint64_t v;
    std::memcpy(&v, p + i - 8, 8);
    if (v) return i - 1 - (std::countl_zero(v) >> 3);
  }
  for (; i > 0; --i)
    if (p[i - 1]) return i - 1;
  return -1;
}

// The x positions in [0, n) where row `p` changes between background (0) and
// foreground (non-zero), starting from background: the C1 mask's transitions.
void RowTransitions(const uint8_t* p, int n, std::vector<uint32_t>* t) {
  t->clear();
  int x = 0;
  bool fg = false;
  while (x < n) {
    const int d = fg ? FirstClear(p + x, n - x) : FirstSet(p + x, n - x);
    if (d < 0) break;
    x += d;
    t->push_back(static_cast<uint32_t>(x));
    fg = !fg;
  }
}

// Fills the background pixels (`fg[i] == 0`) of one `B` × `B` block of RGB
// pixels (`rgb`, rows `stride` bytes apart) by push-pull: a pyramid of 2×2
// means of the foreground (push), then every background pixel takes the
// bilinear interpolation of the next coarser level (pull). The block's
// foreground continues smoothly into its background, so the block carries no
// artificial edge (no ringing into the foreground, fewer AC bits). The block
// has at least one foreground pixel.
template <int B>
void PushPullBlock(const uint8_t* fg, uint8_t* rgb, size_t stride) {
  constexpr int kLevels = std::bit_width(static_cast<unsigned>(B));  // B, B/2, ..., 1
  float c[kLevels][B * B * 3];
  uint8_t has[kLevels][B * B];
  // Only foreground values are read before the pull writes the rest.
  for (int y = 0; y < B; ++y)
    for (int x = 0; x < B; ++x) {
      const int i = y * B + x;
      has[0][i] = fg[i] != 0;
      if (has[0][i])
        for (int k = 0; k < 3; ++k) c[0][i * 3 + k] = rgb[y * stride + x * 3 + k];
    }
  for (int l = 1, s = B / 2; l < kLevels; ++l, s /= 2) {
    const int fs = 2 * s;
    for (int y = 0; y < s; ++y)
      for (int x = 0; x < s; ++x) {
        float sum[3] = {0, 0, 0};
        int n = 0;
        for (int dy = 0; dy < 2; ++dy)
          for (int dx = 0; dx < 2; ++dx) {
            const int fi = (2 * y + dy) * fs + 2 * x + dx;
            if (!has[l - 1][fi]) continue;
            for (int k = 0; k < 3; ++k) sum[k] += c[l - 1][fi * 3 + k];
            ++n;
          }
        const int ci = y * s + x;
        has[l][ci] = n > 0;
        for (int k = 0; k < 3; ++k) c[l][ci * 3 + k] = n ? sum[k] / static_cast<float>(n) : 0.0f;
      }
  }
  // Pull: the holes of each level take the bilinear interpolation of the
  // level above at the same point (cell centres: fine x ↔ coarse (x − ½) / 2),
  // computed separably: the coarse rows interpolated along x, then those
  // along y (the same products and sums as the 2-D formula).
  for (int l = kLevels - 1, cs = 1; l-- > 0; cs *= 2) {
    const int fs = 2 * cs;
    int i0[B], i1[B];
    float t[B];
    for (int x = 0; x < fs; ++x) {
      const float cx = std::clamp((static_cast<float>(x) - 0.5f) * 0.5f, 0.0f, static_cast<float>(cs - 1));
      i0[x] = static_cast<int>(cx);
      i1[x] = std::min(i0[x] + 1, cs - 1);
      t[x] = cx - static_cast<float>(i0[x]);
    }
    const float* up = c[l + 1];
    float h[B / 2 > 0 ? B / 2 : 1][B * 3];
    for (int j = 0; j < cs; ++j)
      for (int x = 0; x < fs; ++x)
        for (int k = 0; k < 3; ++k)
          h[j][x * 3 + k] = (1 - t[x]) * up[(j * cs + i0[x]) * 3 + k] + t[x] * up[(j * cs + i1[x]) * 3 + k];
    for (int y = 0; y < fs; ++y) {
      const float ty = t[y];
      const float* h0 = h[i0[y]];
      const float* h1 = h[i1[y]];
      for (int x = 0; x < fs; ++x) {
        const int fi = y * fs + x;
        if (has[l][fi]) continue;
        for (int k = 0; k < 3; ++k) c[l][fi * 3 + k] = (1 - ty) * h0[x * 3 + k] + ty * h1[x * 3 + k];
      }
    }
  }
  for (int y = 0; y < B; ++y)
    for (int x = 0; x < B; ++x) {
      const int i = y * B + x;
      if (fg[i]) continue;
      for (int k = 0; k < 3; ++k)
        rgb[y * stride + x * 3 + k] = static_cast<uint8_t>(std::clamp(c[0][i * 3 + k] + 0.5f, 0.0f, 255.0f));
    }
}

// 8 mask bytes (non-zero = foreground) to 8 bits, bit x = byte x.
inline uint32_t RowBits8(const uint8_t* p) {
  uint64_t v;
  std::memcpy(&v, p, 8);
  constexpr uint64_t kLow7 = 0x7F7F7F7F7F7F7F7Full;
  const uint64_t set = ((v & kLow7) + kLow7) | v;  // bit 7 of each non-zero byte (exact)
  return static_cast<uint32_t>((((set >> 7) & 0x0101010101010101ull) * 0x0102040810204080ull) >> 56);
}

// Eight 16-bit lanes (GCC and Clang vector extension; SSE2 on x86-64).
using U16x8 = uint16_t __attribute__((vector_size(16)));
// Mean of `n` (0–4) values summing to `sum`, rounded (0 when n = 0).
inline int32_t MeanOf(int32_t sum, int n) {
  static constexpr int32_t kRecip[5] = {0, 65536, 32768, 21846, 16384};
  return (sum * kRecip[n] + 32768) >> 16;
}
// PushPullBlock<8> in fixed point (1/16 steps): the default 4:4:4 blocks.
// The same pyramid and bilinear weights (quarters at these sizes), the 8 × 8
// level computed eight pixels at a time and written to the background pixels
// only; it differs from the float version by at most 1 in a few pixels and
// takes about half its time.
void PushPull8(const uint8_t* fg, uint8_t* rgb, size_t stride) {
  // Level 1 (4 × 4 cells of 2 × 2 pixels): means of the foreground, in 1/16.
  int32_t v1[3][16], v2[3][4], v3[3];
  uint8_t h1[16], h2[4];
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) {
      int32_t s[3] = {0, 0, 0};
      int n = 0;
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const int px = 2 * x + dx, py = 2 * y + dy;
          const int32_t on = fg[py * 8 + px] != 0;
          const uint8_t* p = rgb + py * stride + px * 3;
          for (int k = 0; k < 3; ++k) s[k] += on * p[k];
          n += on;
        }
      h1[y * 4 + x] = n > 0;
      for (int k = 0; k < 3; ++k) v1[k][y * 4 + x] = MeanOf(s[k] * 16, n);
    }
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 2; ++x) {
      const int a = (2 * y) * 4 + 2 * x, b = a + 1, c = a + 4, d = a + 5;
      const int n = h1[a] + h1[b] + h1[c] + h1[d];
      h2[y * 2 + x] = n > 0;
      for (int k = 0; k < 3; ++k) v2[k][y * 2 + x] = MeanOf(h1[a] * v1[k][a] + h1[b] * v1[k][b] + h1[c] * v1[k][c] + h1[d] * v1[k][d], n);
    }
  {
    const int n = h2[0] + h2[1] + h2[2] + h2[3];
    for (int k = 0; k < 3; ++k) v3[k] = MeanOf(h2[0] * v2[k][0] + h2[1] * v2[k][1] + h2[2] * v2[k][2] + h2[3] * v2[k][3], n);
  }
  // Pull: level 2's holes from level 3, level 1's from level 2 (bilinear).
  for (int i = 0; i < 4; ++i)
    if (!h2[i])
      for (int k = 0; k < 3; ++k) v2[k][i] = v3[k];
  static constexpr int kI0[4] = {0, 0, 0, 1}, kI1[4] = {0, 1, 1, 1}, kW0[4] = {4, 3, 1, 4}, kW1[4] = {0, 1, 3, 0};
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) {
      if (h1[y * 4 + x]) continue;
      for (int k = 0; k < 3; ++k) {
        const int32_t* c = v2[k];
        const int32_t top = kW0[x] * c[kI0[y] * 2 + kI0[x]] + kW1[x] * c[kI0[y] * 2 + kI1[x]];
        const int32_t bot = kW0[x] * c[kI1[y] * 2 + kI0[x]] + kW1[x] * c[kI1[y] * 2 + kI1[x]];
        v1[k][y * 4 + x] = (kW0[y] * top + kW1[y] * bot + 8) >> 4;
      }
    }
  // Level 0: every pixel's bilinear value from level 1, eight at a time
  // (16-bit lanes: 4080 × 16 fits), then written where the pixel is a hole.
  // Fine cell i's coarse neighbours kJ0[i], kJ1[i] and their weights (quarters),
  // the same along x (as lanes) and along y.
  static constexpr int kJ0[8] = {0, 0, 0, 1, 1, 2, 2, 3}, kJ1[8] = {0, 1, 1, 2, 2, 3, 3, 3};
  static constexpr uint16_t kV0[8] = {4, 3, 1, 3, 1, 3, 1, 4}, kV1[8] = {0, 1, 3, 1, 3, 1, 3, 0};
  U16x8 w0, w1;
  std::memcpy(&w0, kV0, sizeof w0);
  std::memcpy(&w1, kV1, sizeof w1);
  uint8_t out[3][64];
  for (int k = 0; k < 3; ++k) {
    U16x8 h[4];
    for (int j = 0; j < 4; ++j) {
      // The left and right level-1 neighbours of each of the 8 pixels.
      const uint16_t a = static_cast<uint16_t>(v1[k][j * 4]), b = static_cast<uint16_t>(v1[k][j * 4 + 1]),
                     c = static_cast<uint16_t>(v1[k][j * 4 + 2]), d = static_cast<uint16_t>(v1[k][j * 4 + 3]);
      const U16x8 left = {a, a, a, b, b, c, c, d}, right = {a, b, b, c, c, d, d, d};
      h[j] = left * w0 + right * w1;
    }
    for (int y = 0; y < 8; ++y) {
      const U16x8 v = (h[kJ0[y]] * kV0[y] + h[kJ1[y]] * kV1[y] + 128) >> 8;
      for (int x = 0; x < 8; ++x) out[k][y * 8 + x] = static_cast<uint8_t>(v[x]);
    }
  }
  uint64_t holes = 0;  // bit y * 8 + x: pixel (x, y) is background
  for (int y = 0; y < 8; ++y) holes |= uint64_t{~RowBits8(fg + y * 8) & 0xFFu} << (y * 8);
  while (holes) {
    const int i = std::countr_zero(holes);
    holes &= holes - 1;
    uint8_t* p = rgb + (i >> 3) * stride + (i & 7) * 3;
    p[0] = out[0][i];
    p[1] = out[1][i];
    p[2] = out[2][i];
  }
}

// Fills the background pixels (`fg[i] == 0`) of one `B` × `B` block (8 or
// 16) by repetitive padding, as MPEG-4 pads arbitrarily shaped objects:
// along each row, a background pixel takes the nearest foreground pixel of
// the row on each side (their mean when it lies between two); then each row
// without foreground takes the nearest filled row above and below (their
// mean between two). Half the time of PushPull8 for +1.4 % colour bytes at
// +0.03 dB on the studio (docs/codecs.md). The block has at least one
// foreground pixel.
template <int B>
void PadBlock(const uint8_t* fg, uint8_t* rgb, size_t stride) {
  static_assert(B == 8 || B == 16);
  constexpr uint32_t kFull = (1u << B) - 1;
  uint32_t bits[B];
  for (int y = 0; y < B; ++y) {
    bits[y] = RowBits8(fg + y * B);
    if constexpr (B == 16) bits[y] |= RowBits8(fg + y * B + 8) << 8;
  }
  for (int y = 0; y < B; ++y) {
    const uint32_t b = bits[y];
    if (b == 0 || b == kFull) continue;
    uint8_t* r = rgb + y * stride;
    int left[B], right[B];
    for (int x = 0, last = -1; x < B; ++x) left[x] = last = (b >> x & 1) ? x : last;
    for (int x = B - 1, next = -1; x >= 0; --x) right[x] = next = (b >> x & 1) ? x : next;
    for (int x = 0; x < B; ++x) {
      if (b >> x & 1) continue;
      const int l = left[x], n = right[x];
      if (l < 0 || n < 0) {
        std::memcpy(r + x * 3, r + (l < 0 ? n : l) * 3, 3);
      } else {
        for (int k = 0; k < 3; ++k) r[x * 3 + k] = static_cast<uint8_t>((r[l * 3 + k] + r[n * 3 + k] + 1) >> 1);
      }
    }
  }
  int above[B], below[B];
  for (int y = 0, last = -1; y < B; ++y) above[y] = last = bits[y] ? y : last;
  for (int y = B - 1, next = -1; y >= 0; --y) below[y] = next = bits[y] ? y : next;
  for (int y = 0; y < B; ++y) {
    if (bits[y]) continue;
    uint8_t* r = rgb + y * stride;
    const int a = above[y], n = below[y];
    if (a < 0 || n < 0) {
      std::memcpy(r, rgb + (a < 0 ? n : a) * stride, B * 3);
    } else {
      const uint8_t* pa = rgb + a * stride;
      const uint8_t* pn = rgb + n * stride;
      for (int i = 0; i < B * 3; ++i) r[i] = static_cast<uint8_t>((pa[i] + pn[i] + 1) >> 1);
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

// A libjpeg destination that appends the compressed bytes to a vector.
struct VectorDestination {
  jpeg_destination_mgr mgr;
  std::vector<uint8_t>* out;
  size_t start;
};
void DestInit(j_compress_ptr cinfo) {
  auto* d = reinterpret_cast<VectorDestination*>(cinfo->dest);
  d->out->resize(d->start + 16384);
  d->mgr.next_output_byte = d->out->data() + d->start;
  d->mgr.free_in_buffer = d->out->size() - d->start;
}
boolean DestGrow(j_compress_ptr cinfo) {
  auto* d = reinterpret_cast<VectorDestination*>(cinfo->dest);
  const size_t used = d->out->size();  // the whole buffer is full when libjpeg asks
  bool grown = true;
  try {
    d->out->resize(used * 2);
  } catch (const std::bad_alloc&) {
    grown = false;
  }
  if (!grown) {  // error_exit jumps: not from inside the handler
    cinfo->err->msg_code = JERR_OUT_OF_MEMORY;
    (*cinfo->err->error_exit)(reinterpret_cast<j_common_ptr>(cinfo));
  }
  d->mgr.next_output_byte = d->out->data() + used;
  d->mgr.free_in_buffer = d->out->size() - used;
  return TRUE;
}
void DestTerm(j_compress_ptr cinfo) {
  auto* d = reinterpret_cast<VectorDestination*>(cinfo->dest);
  d->out->resize(d->out->size() - d->mgr.free_in_buffer);
}

// One libjpeg compressor per thread, reused across images (creating one per
// image costs its allocations every time).
struct JpegCompressor {
  jpeg_compress_struct cinfo{};
  JpegError err{};
  bool created = false;
  // The Huffman tables in `cinfo` are an image's optimized ones: libjpeg-turbo's
  // jpeg_set_defaults keeps tables that exist, so the standard tables need a
  // fresh compressor.
  bool optimized_tables = false;
  JpegCompressor() = default;
  JpegCompressor(const JpegCompressor&) = delete;
  JpegCompressor& operator=(const JpegCompressor&) = delete;
  ~JpegCompressor() {
    if (created) jpeg_destroy_compress(&cinfo);
  }
};

// Huffman code lengths for the symbol frequencies `freq` (0 = absent) as
// JPEG Annex K.2 builds them: a Huffman tree with one reserved extra symbol
// (so that no code is all ones), lengths limited to 16 bits (K.3), the symbols
// listed by code length. Writes `bits` (bits[l] = codes of length l, l 1..16)
// and `values`.
void GenerateHuffman(const std::array<uint32_t, 256>& counts, uint8_t* bits, uint8_t* values) {
  constexpr int kMaxLen = 64;
  uint64_t freq[257];
  for (int i = 0; i < 256; ++i) freq[i] = counts[i];
  freq[256] = 1;
  int codesize[257] = {};
  int others[257];
  std::fill(std::begin(others), std::end(others), -1);
  for (;;) {
    int c1 = -1, c2 = -1;
    uint64_t v = UINT64_MAX;
    for (int i = 0; i <= 256; ++i)
      if (freq[i] && freq[i] <= v) v = freq[i], c1 = i;
    v = UINT64_MAX;
    for (int i = 0; i <= 256; ++i)
      if (freq[i] && freq[i] <= v && i != c1) v = freq[i], c2 = i;
    if (c2 < 0) break;
    freq[c1] += freq[c2];
    freq[c2] = 0;
    for (++codesize[c1]; others[c1] >= 0; ++codesize[c1]) c1 = others[c1];
    others[c1] = c2;
    for (++codesize[c2]; others[c2] >= 0; ++codesize[c2]) c2 = others[c2];
  }
  int count[kMaxLen + 1] = {};
  for (int i = 0; i <= 256; ++i)
    if (codesize[i]) count[std::min(codesize[i], kMaxLen)]++;
  for (int i = kMaxLen; i > 16; --i) {
    while (count[i] > 0) {
      int j = i - 2;
      while (count[j] == 0) --j;
      count[i] -= 2;
      count[i - 1]++;
      count[j + 1] += 2;
      count[j]--;
    }
  }
  int longest = 16;
  while (count[longest] == 0) --longest;
  count[longest]--;  // the reserved symbol's code
  bits[0] = 0;
  for (int l = 1; l <= 16; ++l) bits[l] = static_cast<uint8_t>(count[l]);
  int p = 0;
  for (int l = 1; l <= kMaxLen; ++l)
    for (int s = 0; s < 256; ++s)
      if (codesize[s] == l) values[p++] = static_cast<uint8_t>(s);
}

// A JPEG Huffman table (`bits` as in DHT, then the symbols) that codes every
// symbol a baseline 8-bit JPEG can hold — DC: sizes 0..11; AC: EOB, ZRL and
// every run 0..15 with size 1..10 — with the lengths of `t` (an optimized
// table that may lack symbols) for the symbols it has and long codes for the
// others: so that an image whose statistics differ a little still codes.
void CompleteTable(bool dc, const JHUFF_TBL& t, uint8_t* bits, uint8_t* values) {
  std::array<uint32_t, 256> counts{};
  for (int s = 0; s < 256; ++s) {
    const bool possible = dc ? s <= 11 : (s == 0x00 || s == 0xF0 || ((s & 15) >= 1 && (s & 15) <= 10));
    if (possible) counts[s] = 1;
  }
  int p = 0;
  for (int l = 1; l <= 16; ++l)
    for (int k = 0; k < t.bits[l] && p < 256; ++k, ++p) counts[t.huffval[p]] = 1u << (18 - l);
  GenerateHuffman(counts, bits, values);
}

// Baseline JPEG of `w` × `h` RGB8 pixels (rows `stride` bytes apart),
// quantization, subsampling, DCT and Huffman optimization from `o`, appended
// to `out` behind a u32 length (a blob32).
// Compresses a `w` × `h` RGB image given one MCU row (`mcu_h` pixel rows) at
// a time: `mcu_row(k)` returns row k's first pixel row, the others `stride`
// bytes apart (its buffer may be reused for the next row).
template <typename McuRow>
Status CompressJpeg(int w, int h, int mcu_h, size_t stride, McuRow&& mcu_row, const ColorEncodeOptions& o,
                    HuffmanTables* tables, std::vector<uint8_t>* out) {
  const bool use_tables = tables != nullptr && tables->valid && o.optimize_huffman;
  const bool optimize = o.optimize_huffman && !use_tables;
  thread_local JpegCompressor jc;
  jpeg_compress_struct& cinfo = jc.cinfo;
  ByteWriter bw(out);
  const size_t at = bw.ReserveU32();
  VectorDestination dest{{}, out, out->size()};
  dest.mgr.init_destination = DestInit;
  dest.mgr.empty_output_buffer = DestGrow;
  dest.mgr.term_destination = DestTerm;
  if (setjmp(jc.err.jump)) {
    // Start from a fresh compressor next time: the failed one may be mid-image.
    jpeg_destroy_compress(&cinfo);
    jc.created = false;
    out->resize(at);
    return Internal(std::string("libjpeg: ") + jc.err.message);
  }
  if (jc.created && jc.optimized_tables && !o.optimize_huffman) {  // back to the standard tables
    jpeg_destroy_compress(&cinfo);
    jc.created = false;
  }
  if (!jc.created) {
    jc.optimized_tables = false;
    cinfo.err = jpeg_std_error(&jc.err.mgr);
    jc.err.mgr.error_exit = JpegErrorExit;
    jc.err.mgr.emit_message = JpegSilence;
    jpeg_create_compress(&cinfo);
    jc.created = true;
  }
  cinfo.dest = &dest.mgr;
  cinfo.image_width = static_cast<JDIMENSION>(w);
  cinfo.image_height = static_cast<JDIMENSION>(h);
  cinfo.input_components = 3;
  cinfo.in_color_space = JCS_RGB;
  jpeg_set_defaults(&cinfo);
  cinfo.dct_method = o.accurate_dct ? JDCT_ISLOW : JDCT_IFAST;
  cinfo.optimize_coding = optimize ? TRUE : FALSE;
  jc.optimized_tables = jc.optimized_tables || o.optimize_huffman;
  if (use_tables) {
    // Luma DC, luma AC, chroma DC, chroma AC: the tables jpeg_set_defaults assigned.
    JHUFF_TBL* t[4] = {cinfo.dc_huff_tbl_ptrs[0], cinfo.ac_huff_tbl_ptrs[0], cinfo.dc_huff_tbl_ptrs[1],
                       cinfo.ac_huff_tbl_ptrs[1]};
    for (int i = 0; i < 4; ++i) {
      std::memcpy(t[i]->bits, tables->bits[i].data(), 17);
      std::memcpy(t[i]->huffval, tables->values[i].data(), 256);
      t[i]->sent_table = FALSE;
    }
  }
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
  JSAMPROW rows[16];
  for (int k = 0; cinfo.next_scanline < cinfo.image_height; ++k) {
    const uint8_t* first = mcu_row(k);
    const JDIMENSION start = cinfo.next_scanline;
    const JDIMENSION stop = std::min<JDIMENSION>(start + static_cast<JDIMENSION>(mcu_h), cinfo.image_height);
    for (JDIMENSION i = 0; i < stop - start; ++i) rows[i] = const_cast<JSAMPROW>(first + i * stride);
    while (cinfo.next_scanline < stop)
      jpeg_write_scanlines(&cinfo, rows + (cinfo.next_scanline - start), stop - cinfo.next_scanline);
  }
  jpeg_finish_compress(&cinfo);
  cinfo.dest = nullptr;
  if (tables != nullptr && optimize) {
    const JHUFF_TBL* t[4] = {cinfo.dc_huff_tbl_ptrs[0], cinfo.ac_huff_tbl_ptrs[0], cinfo.dc_huff_tbl_ptrs[1],
                             cinfo.ac_huff_tbl_ptrs[1]};
    for (int i = 0; i < 4; ++i) CompleteTable(i % 2 == 0, *t[i], tables->bits[i].data(), tables->values[i].data());
    tables->valid = true;
  }
  bw.PatchU32(at, static_cast<uint32_t>(out->size() - at - 4));
  return OkStatus();
}

// One libjpeg decompressor per thread, kept between images. Warnings (a
// truncated or corrupt but partly decodable JPEG) count as errors: no
// guessing on the wire.
struct JpegDecompressor {
  jpeg_decompress_struct cinfo{};
  JpegError err{};
  bool created = false;
  bool warned = false;
  JpegDecompressor() = default;
  JpegDecompressor(const JpegDecompressor&) = delete;
  JpegDecompressor& operator=(const JpegDecompressor&) = delete;
  ~JpegDecompressor() {
    if (created) jpeg_destroy_decompress(&cinfo);
  }
};
void JpegWarning(j_common_ptr cinfo, int level) {
  if (level >= 0) return;  // trace messages
  auto* d = static_cast<JpegDecompressor*>(cinfo->client_data);
  if (!d->warned) (*cinfo->err->format_message)(cinfo, d->err.message);
  d->warned = true;
}

// Decodes a `w` × `h` RGB JPEG whose MCU is `mcu_w` × `mcu_h` one MCU row at
// a time: `on_rows(pixels, stride, k)` gets MCU row k (its rows `stride`
// bytes apart, the last row possibly short) in one of two buffers that
// alternate, so row k − 1 is still readable. The rows stay in cache for the
// caller to scatter instead of a whole decoded image going through memory.
template <typename OnRows>
Status DecompressJpegRows(std::span<const uint8_t> jpeg, int w, int h, int mcu_w, int mcu_h,
                          std::vector<uint8_t>* ring, OnRows&& on_rows) {
  thread_local JpegDecompressor jd;
  jpeg_decompress_struct& cinfo = jd.cinfo;
  if (setjmp(jd.err.jump)) {
    // Start from a fresh decompressor next time: the failed one may be mid-image.
    jpeg_destroy_decompress(&cinfo);
    jd.created = false;
    return DataLoss(std::string("c1.jpeg: ") + jd.err.message);
  }
  if (!jd.created) {
    cinfo.err = jpeg_std_error(&jd.err.mgr);
    jd.err.mgr.error_exit = JpegErrorExit;
    jd.err.mgr.emit_message = JpegWarning;
    jpeg_create_decompress(&cinfo);
    cinfo.client_data = &jd;
    jd.created = true;
  }
  jd.warned = false;
  jpeg_mem_src(&cinfo, jpeg.data(), static_cast<unsigned long>(jpeg.size()));
  jpeg_read_header(&cinfo, TRUE);
  if (jd.warned || cinfo.num_components != 3 || static_cast<int>(cinfo.image_width) != w ||
      static_cast<int>(cinfo.image_height) != h || cinfo.max_h_samp_factor * DCTSIZE != mcu_w ||
      cinfo.max_v_samp_factor * DCTSIZE != mcu_h) {
    jpeg_abort_decompress(&cinfo);
    return DataLoss("c1.jpeg: the JPEG's header does not match its parsed size and sampling");
  }
  cinfo.out_color_space = JCS_RGB;
  cinfo.dct_method = JDCT_ISLOW;
  jpeg_start_decompress(&cinfo);
  const size_t stride = static_cast<size_t>(w) * 3;
  ring->resize(2 * stride * static_cast<size_t>(mcu_h));
  JSAMPROW rows[2][16];
  for (int b = 0; b < 2; ++b)
    for (int i = 0; i < mcu_h; ++i) rows[b][i] = ring->data() + (static_cast<size_t>(b) * mcu_h + i) * stride;
  for (int k = 0; cinfo.output_scanline < cinfo.output_height && !jd.warned; ++k) {
    const JDIMENSION start = cinfo.output_scanline;
    const JDIMENSION stop = std::min<JDIMENSION>(start + static_cast<JDIMENSION>(mcu_h), cinfo.output_height);
    while (cinfo.output_scanline < stop && !jd.warned)
      jpeg_read_scanlines(&cinfo, rows[k % 2] + (cinfo.output_scanline - start), stop - cinfo.output_scanline);
    if (!jd.warned) on_rows(rows[k % 2][0], stride, k);
  }
  if (jd.warned) {
    jpeg_abort_decompress(&cinfo);
    return DataLoss(std::string("c1.jpeg: ") + jd.err.message);
  }
  jpeg_finish_decompress(&cinfo);
  if (jd.warned) return DataLoss(std::string("c1.jpeg: ") + jd.err.message);
  return OkStatus();
}

// The C1 block grid of a `bw` × `bh` box: blocks of one JPEG MCU (`bx` × `by`
// pixels), `cols` × `rows` of them, and per block its slot in the JPEG image
// (-1: not coded). Box layout: every block is coded in place. Packed layout
// (flag kColorFlagPackedBlocks): only the blocks holding foreground, in
// raster order, `cols` per JPEG row — background-only blocks cost no pixels.
struct BlockGrid {
  int bx = 8, by = 8, cols = 0, rows = 0;
  std::vector<int32_t> slot;
  int coded = 0;  // blocks with a slot
  int jpeg_width(bool packed, int bw) const { return packed ? cols * bx : bw; }
  int jpeg_height(bool packed, int bh) const { return packed ? (coded + cols - 1) / cols * by : bh; }
  // Top-left pixel of block (c, r)'s slot in the JPEG image.
  int slot_x(int32_t s) const { return s % cols * bx; }
  int slot_y(int32_t s) const { return s / cols * by; }
};

// Marks the blocks that the transitions `t` of box row `y` touch with foreground.
void MarkRow(std::span<const uint32_t> t, uint32_t bw, int y, BlockGrid* g) {
  int32_t* row = &g->slot[static_cast<size_t>(y / g->by) * g->cols];
  for (size_t i = 0; i < t.size(); i += 2) {
    const uint32_t stop = i + 1 < t.size() ? t[i + 1] : bw;
    for (uint32_t c = t[i] / g->bx, last = (stop - 1) / g->bx; c <= last; ++c) row[c] = 1;
  }
}

// Assigns slots: every block (box layout) or the marked ones in raster order.
void AssignSlots(bool packed, BlockGrid* g) {
  g->coded = 0;
  for (int32_t& s : g->slot) s = (!packed || s > 0) ? g->coded++ : -1;
}

// Per-thread working buffers of the C1 encoder and decoder, kept between
// images (fresh pages per image cost more than the work at VGA). Reached
// through one reference per call: each thread_local access from a shared
// library may be a __tls_get_addr call.
struct C1Scratch {
  std::vector<uint8_t> ones, rle, canvas, block_mask, pixels;
  std::vector<uint32_t> prev, cur;
  std::vector<uint32_t> transitions, row_at;  // decoder: every box row's transitions
  std::vector<int32_t> occupied, block_of_slot, last_mcu_row;
};
C1Scratch& C1ThreadScratch() {
  thread_local C1Scratch s;
  return s;
}

Status EncodeC1(const ImageRgb8& image, const ImageGray8& mask, const ColorEncodeOptions& o, HuffmanTables* tables,
                std::vector<uint8_t>* out) {
  const int W = image.width(), H = image.height();
  C1Scratch& sc = C1ThreadScratch();
  std::vector<uint8_t>& ones = sc.ones;
  if (mask.empty()) ones.assign(static_cast<size_t>(W), 255);
  auto mask_row = [&](int y) { return mask.empty() ? ones.data() : mask.data() + static_cast<size_t>(y) * W; };
  int x0 = W, y0 = H, x1 = -1, y1 = -1;
  for (int y = 0; y < H; ++y) {
    const uint8_t* m = mask_row(y);
    const int first = FirstSet(m, W);
    if (first < 0) continue;
    x0 = std::min(x0, first);
    x1 = std::max(x1, LastSet(m, W));
    y0 = std::min(y0, y);
    y1 = y;
  }
  ByteWriter w(out);
  if (x1 < 0) {
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

  BlockGrid g;
  g.bx = g.by = o.chroma_420 ? 16 : 8;
  g.cols = (bw + g.bx - 1) / g.bx;
  g.rows = (bh + g.by - 1) / g.by;
  g.slot.assign(static_cast<size_t>(g.cols) * g.rows, 0);

  // Mask: per row of the box, the x positions where foreground starts or
  // ends ("transitions"), coded against the row above when it has as many
  // (silhouettes move by a pixel or two from row to row).
  std::vector<uint8_t>& rle = sc.rle;
  rle.clear();
  std::vector<uint32_t>& prev = sc.prev;
  std::vector<uint32_t>& cur = sc.cur;
  prev.clear();
  for (int y = 0; y < bh; ++y) {
    RowTransitions(mask_row(y0 + y) + x0, bw, &cur);
    MarkRow(cur, static_cast<uint32_t>(bw), y, &g);
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
  // One zstd context per thread: a fresh one per image costs its tables' allocation and page faults.
  thread_local std::unique_ptr<ZSTD_CCtx, size_t (*)(ZSTD_CCtx*)> zc(ZSTD_createCCtx(), ZSTD_freeCCtx);
  if (!zc) return Internal("zstd: cannot create a compression context");
  const size_t z = ZSTD_compressCCtx(zc.get(), out->data() + start, out->size() - start, rle.data(), rle.size(),
                                     o.mask_zstd_level);
  if (ZSTD_isError(z)) return Internal(std::string("zstd: ") + ZSTD_getErrorName(z));
  out->resize(start + z);
  w.PatchU32(at, static_cast<uint32_t>(z));

  // The JPEG image: every coded block's pixels at its slot. Background pixels
  // must cost JPEG as few bits as possible and must not ring into the
  // foreground: a block with background gets a push-pull fill (or the mean
  // foreground colour, kMean); a block without foreground (box layout) and
  // the padding after the last packed block one flat colour, the mean of the
  // coded block before it, so its DC difference costs almost nothing and it
  // has no AC at all.
  std::vector<int32_t>& occupied = sc.occupied;
  occupied = g.slot;  // 1: the block holds foreground
  AssignSlots(o.pack_blocks, &g);
  const int jw = g.jpeg_width(o.pack_blocks, bw), jh = g.jpeg_height(o.pack_blocks, bh);
  // The JPEG's rows are made one MCU row (one row of slots) at a time, just
  // before libjpeg reads them: the row buffer stays in cache.
  const int ch = o.pack_blocks ? jh : g.rows * g.by;
  const size_t stride = static_cast<size_t>(g.cols) * g.bx * 3;
  const int32_t slots = (ch / g.by) * g.cols;
  std::vector<uint8_t>& canvas = sc.canvas;
  std::vector<uint8_t>& block_mask = sc.block_mask;
  canvas.resize(stride * g.by);
  block_mask.resize(static_cast<size_t>(g.bx) * g.by);
  uint8_t mean_fill[3] = {128, 128, 128};
  if (o.fill == ColorEncodeOptions::Fill::kMean) {
    uint64_t sum[3] = {0, 0, 0}, count = 0;
    for (int y = y0; y <= y1; ++y) {
      const uint8_t* m = mask_row(y);
      const uint8_t* p = &image.at(0, y);
      for (int x = x0; x <= x1; ++x) {
        if (!m[x]) continue;
        for (int k = 0; k < 3; ++k) sum[k] += p[x * 3 + k];
        ++count;
      }
    }
    for (int k = 0; k < 3; ++k) mean_fill[k] = static_cast<uint8_t>(sum[k] / count);
  }
  // Per slot the block it holds (-1: a flat slot, no foreground).
  std::vector<int32_t>& block_of_slot = sc.block_of_slot;
  block_of_slot.assign(static_cast<size_t>(slots), -1);
  for (size_t bi = 0; bi < g.slot.size(); ++bi)
    if (g.slot[bi] >= 0 && occupied[bi]) block_of_slot[static_cast<size_t>(g.slot[bi])] = static_cast<int32_t>(bi);
  // Fills the background of the block at `dst` (its mask in block_mask).
  auto fill_background = [&](uint8_t* dst) {
    switch (o.fill) {
      case ColorEncodeOptions::Fill::kMean:
        for (int i = 0; i < g.bx * g.by; ++i)
          if (!block_mask[i]) std::memcpy(dst + (i / g.bx) * stride + (i % g.bx) * 3, mean_fill, 3);
        break;
      case ColorEncodeOptions::Fill::kPad:
        if (g.bx == 8)
          PadBlock<8>(block_mask.data(), dst, stride);
        else
          PadBlock<16>(block_mask.data(), dst, stride);
        break;
      case ColorEncodeOptions::Fill::kPushPull:
        if (g.bx == 8)
          PushPull8(block_mask.data(), dst, stride);
        else
          PushPullBlock<16>(block_mask.data(), dst, stride);
        break;
    }
  };
  // Block `bi`'s pixels into `dst` (rows `stride` apart), its background filled.
  auto make_block = [&](int32_t bi, uint8_t* dst) {
    const int r = bi / g.cols, c = bi % g.cols;
    const int px = x0 + c * g.bx, py = y0 + r * g.by;
    const int run = std::min(g.bx, x1 + 1 - px);  // pixels of the block row inside the box
    if (g.bx == 8 && run == 8 && py + 7 <= y1) {
      // The common case, an 8 × 8 block inside the box: fixed-size copies
      // (inlined moves, not a library call per row) and a word test per row.
      constexpr uint64_t kOnes = 0x0101010101010101ull, kHighs = 0x8080808080808080ull;
      uint64_t zeros = 0;  // high bit set in the bytes of background pixels
      for (int y = 0; y < 8; ++y) {
        std::memcpy(dst + y * stride, &image.at(px, py + y), 24);
        uint64_t v;
        std::memcpy(&v, mask_row(py + y) + px, 8);
        std::memcpy(&block_mask[static_cast<size_t>(y) * 8], &v, 8);
        zeros |= (v - kOnes) & ~v & kHighs;
      }
      if (zeros != 0) fill_background(dst);
      return;
    }
    bool full = run == g.bx;
    for (int y = 0; y < g.by; ++y) {
      uint8_t* bm = &block_mask[static_cast<size_t>(y) * g.bx];
      if (py + y > y1) {
        std::memset(bm, 0, g.bx);
        full = false;
        continue;
      }
      const uint8_t* m = mask_row(py + y) + px;
      std::memcpy(dst + y * stride, &image.at(px, py + y), static_cast<size_t>(run) * 3);
      std::memcpy(bm, m, run);
      std::memset(bm + run, 0, g.bx - run);
      full = full && FirstClear(m, run) < 0;
    }
    if (!full) fill_background(dst);
  };
  auto block_mean = [&](const uint8_t* p, size_t row_stride) {
    uint32_t sum[3] = {0, 0, 0};
    for (int y = 0; y < g.by; ++y)
      for (int x = 0; x < g.bx; ++x)
        for (int k = 0; k < 3; ++k) sum[k] += p[y * row_stride + x * 3 + k];
    const uint32_t n = static_cast<uint32_t>(g.bx * g.by);
    std::array<uint8_t, 3> m;
    for (int k = 0; k < 3; ++k) m[k] = static_cast<uint8_t>((sum[k] + n / 2) / n);
    return m;
  };
  // Flat slots (blocks without foreground, the padding slots) take the mean
  // colour of the last slot before them with foreground; leading ones the
  // first such slot's.
  std::array<uint8_t, 3> fill{128, 128, 128};
  if (slots > 0 && block_of_slot[0] < 0) {
    int32_t first = 0;
    while (first < slots && block_of_slot[first] < 0) ++first;
    if (first < slots) {  // made once more when its row comes
      make_block(block_of_slot[first], canvas.data());
      fill = block_mean(canvas.data(), stride);
    }
  }
  auto mcu_row = [&](int k) -> const uint8_t* {
    for (int32_t s = k * g.cols; s < (k + 1) * g.cols && s < slots; ++s) {
      uint8_t* dst = canvas.data() + static_cast<size_t>(s - k * g.cols) * g.bx * 3;
      const int32_t bi = block_of_slot[s];
      if (bi >= 0) {
        make_block(bi, dst);
        if (s + 1 < slots && block_of_slot[s + 1] < 0) fill = block_mean(dst, stride);
        continue;
      }
      for (int y = 0; y < g.by; ++y)
        for (int x = 0; x < g.bx; ++x) std::memcpy(dst + y * stride + x * 3, fill.data(), 3);
    }
    return canvas.data();
  };
  return CompressJpeg(jw, jh, g.by, stride, mcu_row, o, tables, out);
}

// `known`: when not null and the outputs already have the blob's size, the
// box the previous decode into them wrote (outside it they are zero).
// `written`: the box this decode wrote.
Status DecodeC1(ByteReader& r, uint32_t W, uint32_t H, bool packed, ImageRgb8* image, ImageGray8* mask,
                const ColorBox* known, ColorBox* written) {
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
  // Reused outputs (a receiver's per-pod images) are zeroed row by row right
  // before each row is written, while its cache lines are at hand: one pass
  // instead of a clear of everything and a second pass over the box. With a
  // `known` box only what it covers is cleared besides the new box.
  const bool fresh = image->width() != static_cast<int>(W) || image->height() != static_cast<int>(H) ||
                     mask->width() != static_cast<int>(W) || mask->height() != static_cast<int>(H);
  if (fresh) {
    image->Resize(static_cast<int>(W), static_cast<int>(H));
    mask->Resize(static_cast<int>(W), static_cast<int>(H));
  }
  const ColorBox dirty = fresh ? ColorBox{} : known ? *known : ColorBox{0, 0, W, H};
  // The span [first, second) of row `y` to zero before the box's part of it
  // is written: that part and the dirty box's.
  auto zero_span = [&](uint32_t y) {
    uint32_t a = x0, b = uint32_t{x0} + bw;
    if (y >= dirty.y0 && y < dirty.y0 + dirty.h && dirty.w > 0) {
      a = b > a ? std::min(a, dirty.x0) : dirty.x0;
      b = std::max(b, dirty.x0 + dirty.w);
    }
    return std::pair<uint32_t, uint32_t>(a, b);
  };
  const uint32_t box_y1 = empty_box ? 0 : uint32_t{y0} + bh;
  for (uint32_t y = dirty.y0; y < dirty.y0 + dirty.h; ++y) {
    if (!empty_box && y >= y0 && y < box_y1) continue;  // zeroed as it is written
    std::memset(image->row(static_cast<int>(y)) + size_t{dirty.x0} * 3, 0, size_t{dirty.w} * 3);
    std::memset(mask->row(static_cast<int>(y)) + dirty.x0, 0, dirty.w);
  }
  *written = empty_box ? ColorBox{} : ColorBox{x0, y0, bw, bh};
  if (empty_box) return OkStatus();

  // The JPEG's MCU is the block of the grid (packed layout: of the slots).
  int jw = 0, jh = 0, sub = 0, cs = 0;
  if (jpeg.size() > 0xFFFFFFFFu ||
      tjDecompressHeader3(Decompressor(), jpeg.data(), static_cast<unsigned long>(jpeg.size()), &jw, &jh, &sub, &cs) != 0 ||
      sub < 0 || sub >= TJ_NUMSAMP) {
    return DataLoss("c1.jpeg: not a JPEG image");
  }
  BlockGrid g;
  g.bx = tjMCUWidth[sub];
  g.by = tjMCUHeight[sub];
  g.cols = (bw + g.bx - 1) / g.bx;
  g.rows = (bh + g.by - 1) / g.by;
  g.slot.assign(static_cast<size_t>(g.cols) * g.rows, 0);
  // Mask rows: per row a header varint and at most bw transitions, each a varint of ≤ 3 bytes.
  const unsigned long long declared = ZSTD_getFrameContentSize(zmask.data(), zmask.size());
  const uint64_t bound = uint64_t{bh} * (uint64_t{bw} + 1) * 3;
  if (declared == ZSTD_CONTENTSIZE_ERROR || declared == ZSTD_CONTENTSIZE_UNKNOWN || declared > bound ||
      declared < bh) {
    return DataLoss("c1.mask: zstd frame size is missing or impossible for the box");
  }
  C1Scratch& sc = C1ThreadScratch();
  std::vector<uint8_t>& rle = sc.rle;
  rle.resize(declared);
  thread_local std::unique_ptr<ZSTD_DCtx, size_t (*)(ZSTD_DCtx*)> zd(ZSTD_createDCtx(), ZSTD_freeDCtx);
  if (!zd) return Internal("zstd: cannot create a decompression context");
  const size_t got = ZSTD_decompressDCtx(zd.get(), rle.data(), rle.size(), zmask.data(), zmask.size());
  if (ZSTD_isError(got) || got != declared) return DataLoss("c1.mask: zstd data is corrupt");
  const uint8_t* p = rle.data();
  const uint8_t* end = p + rle.size();
  // Every row's transitions, kept for the pixels: row y's are
  // transitions[row_at[y], row_at[y + 1]).
  std::vector<uint32_t>& transitions = sc.transitions;
  std::vector<uint32_t>& row_at = sc.row_at;
  transitions.clear();
  row_at.assign(static_cast<size_t>(bh) + 1, 0);
  for (int y = 0; y < bh; ++y) {
    uint32_t head = 0;
    if (!GetVarint(p, end, &head)) return DataLoss("c1.mask: row " + Str(y) + " ends early");
    const size_t first = transitions.size();
    if (head == 0) {  // as many transitions as the row above, each a signed delta to it
      for (size_t k = y > 0 ? row_at[static_cast<size_t>(y) - 1] : 0; k < first; ++k) {
        uint32_t z = 0;
        if (!GetVarint(p, end, &z)) return DataLoss("c1.mask: row " + Str(y) + " ends early");
        const uint32_t t = transitions[k] + static_cast<uint32_t>(UnZigZag32(z));  // wraps; range-checked below
        transitions.push_back(t);
      }
    } else {
      if (head - 1 > bw) return DataLoss("c1.mask: row " + Str(y) + " has more transitions than pixels");
      uint32_t next = 0;  // the smallest value the next transition may take
      for (uint32_t i = 0; i + 1 < head; ++i) {
        uint32_t gap = 0;
        if (!GetVarint(p, end, &gap)) return DataLoss("c1.mask: row " + Str(y) + " ends early");
        if (gap >= bw) return DataLoss("c1.mask: transition outside row " + Str(y));
        transitions.push_back(next + gap);
        next = next + gap + 1;
      }
    }
    const std::span<const uint32_t> cur(transitions.data() + first, transitions.size() - first);
    // Validate the whole row before filling: a fill needs its run's end too.
    for (size_t i = 0; i < cur.size(); ++i) {
      if (cur[i] >= bw || (i > 0 && cur[i] <= cur[i - 1])) {
        return DataLoss("c1.mask: transitions of row " + Str(y) + " out of order or outside the box");
      }
    }
    if (!fresh) {
      const auto [a, b] = zero_span(uint32_t{y0} + y);
      std::memset(mask->row(y0 + y) + a, 0, b - a);
    }
    uint8_t* row = &mask->at(x0, y0 + y);
    for (size_t i = 0; i < cur.size(); i += 2) {
      const uint32_t stop = i + 1 < cur.size() ? cur[i + 1] : bw;
      std::memset(row + cur[i], 255, stop - cur[i]);
    }
    if (packed) MarkRow(cur, bw, y, &g);
    row_at[static_cast<size_t>(y) + 1] = static_cast<uint32_t>(transitions.size());
  }
  if (p != end) return DataLoss("c1.mask: trailing run lengths");

  AssignSlots(packed, &g);
  if (packed && g.coded == 0) return DataLoss("c1.mask: a packed box must hold foreground");
  const int want_w = g.jpeg_width(packed, bw), want_h = g.jpeg_height(packed, bh);
  if (jw != want_w || jh != want_h) {
    return DataLoss("c1.jpeg: JPEG is " + Str(static_cast<uint32_t>(jw)) + "x" + Str(static_cast<uint32_t>(jh)) +
                    (packed ? ", the packed blocks need " : ", box is ") + Str(static_cast<uint32_t>(want_w)) +
                    "x" + Str(static_cast<uint32_t>(want_h)));
  }
  // Each box block row is written once the MCU rows holding its slots are
  // decoded (a block row's slots are consecutive: in at most two MCU rows).
  // Block rows without slots (packed: no foreground) are only zeroed.
  std::vector<int32_t>& last_mcu_row = sc.last_mcu_row;
  last_mcu_row.assign(static_cast<size_t>(g.rows), -1);
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c < g.cols; ++c) {
      const int32_t slot = g.slot[static_cast<size_t>(r) * g.cols + c];
      if (slot >= 0) last_mcu_row[r] = std::max(last_mcu_row[r], slot / g.cols);
    }
  int next_row = 0;  // the next block row to write
  const uint8_t* mcu_rows[2] = {nullptr, nullptr};
  size_t stride = 0;
  // Writes box block row `r` from the decoded MCU rows: per pixel row, its
  // foreground runs (the mask's transitions), each cut at the block edges
  // and copied from the blocks' slots — a fixed-size copy for a whole block
  // row (most of a silhouette's inside). Every block a run touches has a
  // slot (packed: MarkRow marked it).
  auto write_block_row = [&](int r) {
    const int32_t* slots = &g.slot[static_cast<size_t>(r) * g.cols];
    for (int y = r * g.by; y < std::min<int>(bh, (r + 1) * g.by); ++y) {
      if (!fresh) {
        const auto [a, b] = zero_span(uint32_t{y0} + y);
        std::memset(image->row(y0 + y) + size_t{a} * 3, 0, size_t{b - a} * 3);
      }
      uint8_t* d = &image->at(x0, y0 + y);
      const size_t in_block_y = static_cast<size_t>(y - r * g.by) * stride;
      const uint32_t* t = transitions.data() + row_at[static_cast<size_t>(y)];
      const uint32_t nt = row_at[static_cast<size_t>(y) + 1] - row_at[static_cast<size_t>(y)];
      for (uint32_t i = 0; i < nt; i += 2) {
        const uint32_t start = t[i], stop = i + 1 < nt ? t[i + 1] : bw;
        for (uint32_t x = start; x < stop;) {
          const uint32_t c = x / static_cast<uint32_t>(g.bx), bx0 = c * static_cast<uint32_t>(g.bx);
          const uint32_t end = std::min(stop, bx0 + static_cast<uint32_t>(g.bx));
          const int32_t slot = slots[c];
          if (slot >= 0) {
            const uint8_t* src = mcu_rows[(slot / g.cols) % 2] + in_block_y +
                                 (static_cast<size_t>(g.slot_x(slot)) + (x - bx0)) * 3;
            if (end - x == static_cast<uint32_t>(g.bx) && g.bx == 8)
              std::memcpy(d + size_t{x} * 3, src, 24);
            else
              std::memcpy(d + size_t{x} * 3, src, size_t{end - x} * 3);
          }
          x = end;
        }
      }
    }
  };
  HOLO_RETURN_IF_ERROR(DecompressJpegRows(jpeg, jw, jh, g.bx, g.by, &sc.pixels,
                                          [&](const uint8_t* rows, size_t row_stride, int k) {
                                            mcu_rows[k % 2] = rows;
                                            stride = row_stride;
                                            while (next_row < g.rows && last_mcu_row[next_row] <= k)
                                              write_block_row(next_row++);
                                          }));
  while (next_row < g.rows) {
    if (last_mcu_row[next_row] >= 0) return DataLoss("c1.jpeg: fewer MCU rows than the blocks need");
    write_block_row(next_row++);
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
  if (huffman_refresh < 1) {
    return InvalidArgument("huffman_refresh must be >= 1, got " + std::to_string(huffman_refresh));
  }
  if (mask_zstd_level < 1 || mask_zstd_level > 19) {
    return InvalidArgument("mask_zstd_level must be in [1, 19], got " + std::to_string(mask_zstd_level));
  }
  return OkStatus();
}

namespace {

Status Encode(const ImageRgb8& image, const ImageGray8& mask, const ColorEncodeOptions& options,
              HuffmanTables* tables, std::vector<uint8_t>* out) {
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
  w.U8(options.codec == ColorCodec::kC1 && options.pack_blocks ? kColorFlagPackedBlocks : 0);
  w.U16(static_cast<uint16_t>(image.width()));
  w.U16(static_cast<uint16_t>(image.height()));
  if (options.codec == ColorCodec::kC0) return EncodeC0(image, mask, out);
  return EncodeC1(image, mask, options, tables, out);
}

}  // namespace

Status EncodeColor(const ImageRgb8& image, const ImageGray8& mask, const ColorEncodeOptions& options,
                   std::vector<uint8_t>* out) {
  return Encode(image, mask, options, nullptr, out);
}

ColorEncoder::ColorEncoder(ColorEncodeOptions options) : options_(options) {}

Status ColorEncoder::Encode(const ImageRgb8& image, const ImageGray8& mask, std::vector<uint8_t>* out) {
  if (since_refresh_ >= options_.huffman_refresh) tables_.valid = false;
  const bool refresh = !tables_.valid;
  const Status s = holo::protocol::Encode(image, mask, options_, &tables_, out);
  if (!s.ok()) {
    tables_.valid = false;
    return s;
  }
  if (refresh && tables_.valid) {
    since_refresh_ = 0;
    ++optimized_images_;
  }
  ++since_refresh_;
  return OkStatus();
}

namespace {

// DecodeColor, and for a ColorDecoder with `box` (in: what the previous decode
// into these images wrote; out: what this one wrote).
Status DecodeColorInto(std::span<const uint8_t> blob, ImageRgb8* image, ImageGray8* mask, const Limits& limits,
                       ColorBox* box) {
  ByteReader r(blob);
  uint8_t codec = 0, flags = 0;
  uint16_t w = 0, h = 0;
  HOLO_RETURN_IF_ERROR(r.U8("color.codec", &codec));
  HOLO_RETURN_IF_ERROR(r.U8("color.flags", &flags));
  HOLO_RETURN_IF_ERROR(r.U16("color.width", &w));
  HOLO_RETURN_IF_ERROR(r.U16("color.height", &h));
  if (flags & ~kColorFlagPackedBlocks) return DataLoss("color.flags: unknown flag bits set");
  if ((flags & kColorFlagPackedBlocks) && codec != static_cast<uint8_t>(ColorCodec::kC1)) {
    return DataLoss("color.flags: packed blocks (bit 0) is a C1 flag, the codec is " + Str(codec));
  }
  HOLO_RETURN_IF_ERROR(CheckSize("color.width", w, h, limits));
  Status s;
  ColorBox written;
  switch (codec) {
    case static_cast<uint8_t>(ColorCodec::kC0):
      s = DecodeC0(r, w, h, image, mask);
      written = ColorBox{0, 0, w, h};
      break;
    case static_cast<uint8_t>(ColorCodec::kC1):
      s = DecodeC1(r, w, h, (flags & kColorFlagPackedBlocks) != 0, image, mask, box, &written);
      break;
    case static_cast<uint8_t>(ColorCodec::kH264):
      s = UnsupportedVersion("color.codec: H.264 (codec 3) is reserved and not implemented in this build");
      break;
    default: s = DataLoss("color.codec: unknown color codec " + Str(codec));
  }
  if (!s.ok()) {
    *image = ImageRgb8();
    *mask = ImageGray8();
    written = ColorBox{};
  }
  if (box != nullptr) *box = written;
  return s;
}

}  // namespace

Status DecodeColor(std::span<const uint8_t> blob, ImageRgb8* image, ImageGray8* mask, const Limits& limits) {
  return DecodeColorInto(blob, image, mask, limits, nullptr);
}

Status ColorDecoder::Decode(std::span<const uint8_t> blob, const Limits& limits) {
  return DecodeColorInto(blob, &image_, &mask_, limits, &box_);
}

}  // namespace holo::protocol
