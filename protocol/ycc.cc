#include "protocol/ycc.h"

#include <algorithm>
#include <cstring>

#include "common/cpu_features.h"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define HOLO_YCC_AVX2 1
#endif

namespace holo::protocol {
namespace {

inline uint8_t Clamp8(int v) { return static_cast<uint8_t>(std::min(std::max(v, 0), 255)); }

void RgbToYccRowScalar(const uint8_t* rgb, int n, uint8_t* y, uint8_t* cb, uint8_t* cr) {
  for (int x = 0; x < n; ++x) RgbToYccPixel(rgb + 3 * x, y + x, cb + x, cr + x);
}

void YccToRgbRowScalar(const uint8_t* y, const uint8_t* cb, const uint8_t* cr, int shift, int x0, int x1,
                       uint8_t* rgb) {
  for (int x = x0; x < x1; ++x) YccToRgbPixel(y[x], cb[x >> shift], cr[x >> shift], rgb + 3 * x);
}

#ifdef HOLO_YCC_AVX2
// Eight pixels at a time: the bytes are sorted into channels with byte
// shuffles, widened to 32 bits, multiplied and shifted exactly as the
// one-pixel functions do, and narrowed with saturation (which is their
// clamp).

__attribute__((target("avx2"))) inline __m128i Narrow(__m256i v) {
  const __m128i w = _mm_packs_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
  return _mm_packus_epi16(w, w);  // eight bytes, each clamped to 0..255
}

__attribute__((target("avx2"))) void RgbToYccRowAvx2(const uint8_t* rgb, int n, uint8_t* y, uint8_t* cb,
                                                     uint8_t* cr) {
  // Pixel i's R, G, B are bytes 3i, 3i+1, 3i+2 of 24: bytes 0..15 in `a`, 16..23 in `b`.
  const __m128i ra = _mm_setr_epi8(0, 3, 6, 9, 12, 15, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1);
  const __m128i rb = _mm_setr_epi8(-1, -1, -1, -1, -1, -1, 2, 5, -1, -1, -1, -1, -1, -1, -1, -1);
  const __m128i ga = _mm_setr_epi8(1, 4, 7, 10, 13, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1);
  const __m128i gb = _mm_setr_epi8(-1, -1, -1, -1, -1, 0, 3, 6, -1, -1, -1, -1, -1, -1, -1, -1);
  const __m128i ba = _mm_setr_epi8(2, 5, 8, 11, 14, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1);
  const __m128i bb = _mm_setr_epi8(-1, -1, -1, -1, -1, 1, 4, 7, -1, -1, -1, -1, -1, -1, -1, -1);
  const __m256i half = _mm256_set1_epi32(32768), c128 = _mm256_set1_epi32(128);
  const __m256i yr = _mm256_set1_epi32(19595), yg = _mm256_set1_epi32(38470), yb = _mm256_set1_epi32(7471);
  const __m256i ur = _mm256_set1_epi32(-11059), ug = _mm256_set1_epi32(-21709), ub = _mm256_set1_epi32(32768);
  const __m256i vr = _mm256_set1_epi32(32768), vg = _mm256_set1_epi32(-27439), vb = _mm256_set1_epi32(-5329);
  int x = 0;
  for (; x + 8 <= n; x += 8) {
    const uint8_t* s = rgb + 3 * x;
    const __m128i a = _mm_loadu_si128(reinterpret_cast<const __m128i*>(s));
    const __m128i b = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(s + 16));
    const __m256i r = _mm256_cvtepu8_epi32(_mm_or_si128(_mm_shuffle_epi8(a, ra), _mm_shuffle_epi8(b, rb)));
    const __m256i g = _mm256_cvtepu8_epi32(_mm_or_si128(_mm_shuffle_epi8(a, ga), _mm_shuffle_epi8(b, gb)));
    const __m256i bl = _mm256_cvtepu8_epi32(_mm_or_si128(_mm_shuffle_epi8(a, ba), _mm_shuffle_epi8(b, bb)));
    const auto dot = [&](__m256i kr, __m256i kg, __m256i kb) __attribute__((target("avx2"))) {
      const __m256i s3 = _mm256_add_epi32(_mm256_add_epi32(_mm256_mullo_epi32(r, kr), _mm256_mullo_epi32(g, kg)),
                                          _mm256_add_epi32(_mm256_mullo_epi32(bl, kb), half));
      return _mm256_srai_epi32(s3, 16);
    };
    _mm_storel_epi64(reinterpret_cast<__m128i*>(y + x), Narrow(dot(yr, yg, yb)));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(cb + x), Narrow(_mm256_add_epi32(dot(ur, ug, ub), c128)));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(cr + x), Narrow(_mm256_add_epi32(dot(vr, vg, vb), c128)));
  }
  RgbToYccRowScalar(rgb + 3 * x, n - x, y + x, cb + x, cr + x);
}

__attribute__((target("avx2"))) void YccToRgbRowAvx2(const uint8_t* y, const uint8_t* cb, const uint8_t* cr, int shift,
                                                     int x0, int x1, uint8_t* rgb) {
  int x = x0;
  if (shift && (x & 1) && x < x1) {  // 4:2:0 from an odd pixel: one alone, then pairs share their chroma
    YccToRgbPixel(y[x], cb[x >> 1], cr[x >> 1], rgb + 3 * x);
    ++x;
  }
  // Output bytes 0..15 and 16..23 of eight pixels from R and G (bytes 0..7
  // and 8..15 of `rg`) and B.
  const __m128i o0rg = _mm_setr_epi8(0, 8, -1, 1, 9, -1, 2, 10, -1, 3, 11, -1, 4, 12, -1, 5);
  const __m128i o0b = _mm_setr_epi8(-1, -1, 0, -1, -1, 1, -1, -1, 2, -1, -1, 3, -1, -1, 4, -1);
  const __m128i o1rg = _mm_setr_epi8(13, -1, 6, 14, -1, 7, 15, -1, -1, -1, -1, -1, -1, -1, -1, -1);
  const __m128i o1b = _mm_setr_epi8(-1, 5, -1, -1, 6, -1, -1, 7, -1, -1, -1, -1, -1, -1, -1, -1);
  const __m256i half = _mm256_set1_epi32(32768), c128 = _mm256_set1_epi32(128);
  const __m256i kr = _mm256_set1_epi32(91881), kgb = _mm256_set1_epi32(22554), kgr = _mm256_set1_epi32(46802);
  const __m256i kb = _mm256_set1_epi32(116130);
  for (; x + 8 <= x1; x += 8) {
    __m128i u8, v8;
    if (shift) {
      int32_t u4, v4;
      std::memcpy(&u4, cb + (x >> 1), 4);
      std::memcpy(&v4, cr + (x >> 1), 4);
      u8 = _mm_unpacklo_epi8(_mm_cvtsi32_si128(u4), _mm_cvtsi32_si128(u4));
      v8 = _mm_unpacklo_epi8(_mm_cvtsi32_si128(v4), _mm_cvtsi32_si128(v4));
    } else {
      u8 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(cb + x));
      v8 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(cr + x));
    }
    const __m256i yy = _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(y + x)));
    const __m256i u = _mm256_sub_epi32(_mm256_cvtepu8_epi32(u8), c128);
    const __m256i v = _mm256_sub_epi32(_mm256_cvtepu8_epi32(v8), c128);
    const __m256i r = _mm256_add_epi32(yy, _mm256_srai_epi32(_mm256_add_epi32(_mm256_mullo_epi32(v, kr), half), 16));
    const __m256i g = _mm256_sub_epi32(
        yy, _mm256_srai_epi32(
                _mm256_sub_epi32(_mm256_add_epi32(_mm256_mullo_epi32(u, kgb), _mm256_mullo_epi32(v, kgr)), half), 16));
    const __m256i b = _mm256_add_epi32(yy, _mm256_srai_epi32(_mm256_add_epi32(_mm256_mullo_epi32(u, kb), half), 16));
    const __m128i rg = _mm_unpacklo_epi64(Narrow(r), Narrow(g));
    const __m128i b8 = Narrow(b);
    uint8_t* d = rgb + 3 * x;
    _mm_storeu_si128(reinterpret_cast<__m128i*>(d),
                     _mm_or_si128(_mm_shuffle_epi8(rg, o0rg), _mm_shuffle_epi8(b8, o0b)));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(d + 16),
                     _mm_or_si128(_mm_shuffle_epi8(rg, o1rg), _mm_shuffle_epi8(b8, o1b)));
  }
  YccToRgbRowScalar(y, cb, cr, shift, x, x1, rgb);
}
#endif

}  // namespace

void RgbToYccPixel(const uint8_t* p, uint8_t* y, uint8_t* cb, uint8_t* cr) {
  const int r = p[0], g = p[1], b = p[2];
  *y = Clamp8((19595 * r + 38470 * g + 7471 * b + 32768) >> 16);
  *cb = Clamp8(((-11059 * r - 21709 * g + 32768 * b + 32768) >> 16) + 128);
  *cr = Clamp8(((32768 * r - 27439 * g - 5329 * b + 32768) >> 16) + 128);
}

void YccToRgbPixel(int y, int cb, int cr, uint8_t* p) {
  cb -= 128;
  cr -= 128;
  p[0] = Clamp8(y + ((91881 * cr + 32768) >> 16));
  p[1] = Clamp8(y - ((22554 * cb + 46802 * cr - 32768) >> 16));
  p[2] = Clamp8(y + ((116130 * cb + 32768) >> 16));
}

bool YccRowsUseAvx2() {
#ifdef HOLO_YCC_AVX2
  return CpuHasAvx2();
#else
  return false;
#endif
}

void RgbToYccRow(const uint8_t* rgb, int n, uint8_t* y, uint8_t* cb, uint8_t* cr) {
#ifdef HOLO_YCC_AVX2
  if (YccRowsUseAvx2()) return RgbToYccRowAvx2(rgb, n, y, cb, cr);
#endif
  RgbToYccRowScalar(rgb, n, y, cb, cr);
}

void YccToRgbRow(const uint8_t* y, const uint8_t* cb, const uint8_t* cr, int chroma_shift, int x0, int x1,
                 uint8_t* rgb) {
#ifdef HOLO_YCC_AVX2
  if (YccRowsUseAvx2()) return YccToRgbRowAvx2(y, cb, cr, chroma_shift, x0, x1, rgb);
#endif
  YccToRgbRowScalar(y, cb, cr, chroma_shift, x0, x1, rgb);
}

}  // namespace holo::protocol
