#include "protocol/depth_codec.h"

#include <zstd.h>

#include <algorithm>
#include <cstring>
#include <string>

#include "protocol/byte_io.h"
#include "protocol/rans_coder.h"

namespace holo::protocol {
namespace {

constexpr uint8_t kD1 = 1;
constexpr uint8_t kD2 = 2;
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
  if (codec != DepthCodec::kD1 && codec != DepthCodec::kD2)
    return InvalidArgument("depth codec must be D1 or D2, got " + std::to_string(static_cast<int>(codec)));
  if (zstd_level < 1 || zstd_level > 19) return InvalidArgument("zstd_level must be in 1..19, got " + std::to_string(zstd_level));
  if (noise_at_1m_um < 1 || noise_at_1m_um > 0xFFFF)
    return InvalidArgument("noise_at_1m_um must be in 1..65535, got " + std::to_string(noise_at_1m_um));
  return OkStatus();
}

namespace {

// ------------------------------------------------------------------ D2
//
// The model both sides run per pixel, in row-major order (PROTOCOL.md §8.2),
// on the fill plane F (the depth, with every invalid pixel replaced by its
// prediction) and the magnitude plane M (|residual| of valid pixels, 0 for
// invalid ones). What depends only on the rows above is computed for a whole
// row first (PrepareRow: no dependency between pixels, so it pipelines); the
// serial per-pixel part (At) adds the current row's left neighbours.

constexpr uint32_t kD2Contexts = 16;
constexpr uint32_t kInvalidToken = 40;  // one past the largest token of a 16-bit value
constexpr int32_t kInvalidResidual = INT32_MIN;
// The least-squares plane through the causal neighbours (dx, dy) = (−1,0)
// (−2,0) (−3,0) | (−2,−1) (−1,−1) (0,−1) (1,−1) (2,−1) (3,−1) | (−1,−2)
// (0,−2) (1,−2), evaluated at (0, 0), in 1/4096: exact weights 59/226,
// 49/226, 39/226, 2/339, 17/339, 32/339, 47/339, 62/339, 77/339, −109/678,
// −79/678, −49/678, rounded, summing to 4096. The residual variance of a
// noisy plane is ~1.31 σ² (MED: ~2 σ²).
constexpr int32_t kW0[3] = {1069, 888, 707};                  // row y: x−1, x−2, x−3
constexpr int32_t kW1[6] = {24, 205, 387, 568, 749, 930};     // row y−1: x−2 .. x+3
constexpr int32_t kW2[3] = {-658, -477, -296};                // row y−2: x−1 .. x+1
static_assert(kW0[0] + kW0[1] + kW0[2] + kW1[0] + kW1[1] + kW1[2] + kW1[3] + kW1[4] + kW1[5] + kW2[0] + kW2[1] +
                  kW2[2] ==
              4096);

struct D2Pixel {
  int pred;
  uint32_t ctx;
};

class D2Model {
 public:
  explicit D2Model(int w, uint64_t noise_um) : w_(w), noise_(noise_um) {
    thr_.resize(static_cast<size_t>(w));
    for (auto* v : {&sum_, &lo_, &hi_}) v->resize(static_cast<size_t>(w));
    ctx_up_.resize(static_cast<size_t>(w));
  }

  // Before row y: `f`, `m` are row y of F and M (rows above at −w, −2w);
  // `dup` is row y − 1 of the depth (null on row 0).
  void PrepareRow(const uint16_t* f, const uint16_t* m, const uint16_t* dup, int y) {
    y_ = y;
    if (y == 0) return;
    const int w = w_;
    const uint16_t* f1 = f - w;
    const uint16_t* m1 = m - w;
    // Pixel x of the row above with its left and right neighbours' residual
    // and validity (0 and valid outside the image).
    auto prepare = [&](int x, uint32_t rc, uint32_t rd, bool invalid_side) {
      // S = noise × b², b = F(x, y−1): the noise level σ = S / 10^9 mm.
      const uint64_t b = f1[x];
      const uint64_t s = noise_ * b * b;
      const uint64_t e = 2u * m1[x] + rc + rd + (rc + rd) / 2 + s / 100000000u + 6u;
      ctx_up_[x] = static_cast<uint8_t>(Context(e, invalid_side || dup[x] == 0));
      thr_[x] = static_cast<uint32_t>(std::min<uint64_t>(s * 8 / 1000000000u + 4, UINT32_MAX));
    };
    if (w == 1) {
      prepare(0, 0, 0, false);
    } else {
      prepare(0, 0, m1[1], dup[1] == 0);
      for (int x = 1; x + 1 < w; ++x) prepare(x, m1[x - 1], m1[x + 1], (dup[x - 1] == 0) | (dup[x + 1] == 0));
      prepare(w - 1, m1[w - 2], 0, dup[w - 2] == 0);
    }
    if (y < 2) return;
    const uint16_t* f2 = f - 2 * w;
    for (int x = 3; x + 3 < w; ++x) {
      const int v[9] = {f1[x - 2], f1[x - 1], f1[x], f1[x + 1], f1[x + 2], f1[x + 3], f2[x - 1], f2[x], f2[x + 1]};
      int lo = v[0], hi = v[0];
      int32_t sum = 0;
      for (int k = 0; k < 9; ++k) {
        lo = std::min(lo, v[k]);
        hi = std::max(hi, v[k]);
        sum += (k < 6 ? kW1[k] : kW2[k - 6]) * v[k];
      }
      sum_[x] = sum;
      lo_[x] = lo;
      hi_[x] = hi;
    }
  }

  // Pixel x of the prepared row: `f` as for PrepareRow (pixels before x of
  // row y already set), `d` row y of the depth. kInterior: the caller
  // guarantees y ≥ 2 and 3 ≤ x < width − 3 (InteriorBegin/End), so no
  // border checks.
  template <bool kInterior>
  D2Pixel At(const uint16_t* f, const uint16_t* d, int x) const {
    const bool invalid_left = (kInterior || x > 0) && d[x - 1] == 0;
    if (!kInterior && y_ == 0) {  // a = b = c = the left neighbour; no residuals above
      const uint64_t a = x > 0 ? f[x - 1] : 0;
      return {static_cast<int>(a), Context(noise_ * a * a / 100000000u + 6u, invalid_left)};
    }
    const int w = w_;
    const int b = f[x - w];
    const int a = kInterior || x > 0 ? f[x - 1] : b, c = kInterior || x > 0 ? f[x - w - 1] : b;
    int pred = c >= std::max(a, b) ? std::min(a, b) : c <= std::min(a, b) ? std::max(a, b) : a + b - c;
    if (kInterior || (y_ >= 2 && x >= 3 && x + 3 < w)) {
      const int v0 = f[x - 1], v1 = f[x - 2], v2 = f[x - 3];
      const int lo = std::min({lo_[x], v0, v1, v2}), hi = std::max({hi_[x], v0, v1, v2});
      const int plane = std::clamp((sum_[x] + kW0[0] * v0 + kW0[1] * v1 + kW0[2] * v2 + 2048) >> 12, 0, 0xFFFF);
      // The window is one surface when its spread is within 8 σ + 4 mm.
      pred = static_cast<uint32_t>(hi - lo) <= thr_[x] ? plane : pred;
    }
    return {pred, ctx_up_[x] | (invalid_left ? 8u : 0u)};
  }
  // The context of pixel x (row ≥ 1) but for an invalid left neighbour (+8).
  uint32_t ContextAbove(int x) const { return ctx_up_[x]; }
  // The interior pixels of the prepared row: [InteriorBegin, InteriorEnd).
  int InteriorBegin() const { return y_ >= 2 && w_ > 6 ? 3 : w_; }
  int InteriorEnd() const { return y_ >= 2 && w_ > 6 ? w_ - 3 : w_; }

 private:
  // E ≈ 12 × the expected |residual| (the residuals above and 10 σ), in
  // octaves, × whether a neighbour is invalid. (Finer classes, or classes by
  // predictor or by 2+ invalid neighbours, cost more in frequency tables than
  // they save; the left neighbour's residual saves 0.01 % and would put the
  // raw bits on the decoder's critical path: measured on the studio's pods.)
  static uint32_t Context(uint64_t e, bool invalid) {
    const int q = std::clamp(static_cast<int>(std::bit_width(e)) - 4, 0, 7);
    return static_cast<uint32_t>(q) + (invalid ? 8u : 0u);
  }

  int w_;
  uint64_t noise_;
  int y_ = 0;
  std::vector<uint32_t> thr_;
  std::vector<int32_t> sum_, lo_, hi_;
  std::vector<uint8_t> ctx_up_;  // the context but for an invalid left neighbour
};

Status EncodeD2(const ImageDepth16& depth, const DepthEncodeOptions& options, std::vector<uint8_t>* out) {
  const int w = depth.width(), h = depth.height();
  const size_t n = static_cast<size_t>(w) * h;
  thread_local std::vector<uint16_t> fill, mag, syms;
  fill.resize(n);
  mag.resize(n);
  const uint64_t noise = static_cast<uint64_t>(options.noise_at_1m_um);
  rans::TokenWriter tw(kD2Contexts, n, &syms);
  D2Model model(w, noise);
  for (int y = 0; y < h; ++y) {
    const uint16_t* row = depth.row(y);
    const uint16_t* up = y > 0 ? depth.row(y - 1) : nullptr;
    uint16_t* f = fill.data() + static_cast<size_t>(y) * w;
    uint16_t* m = mag.data() + static_cast<size_t>(y) * w;
    model.PrepareRow(f, m, up, y);
    auto code = [&](int x, const D2Pixel& px) {
      const uint16_t v = row[x];
      if (v == 0) {
        tw.Put(px.ctx, kInvalidToken);
        f[x] = static_cast<uint16_t>(px.pred);
        m[x] = 0;
      } else {
        const auto r = static_cast<int16_t>(static_cast<uint16_t>(v - px.pred));
        tw.PutValue16(px.ctx, rans::ZigZag(r));
        f[x] = v;
        m[x] = static_cast<uint16_t>(r < 0 ? -r : r);
      }
    };
    const int x0 = model.InteriorBegin(), x1 = model.InteriorEnd();
    for (int x = 0; x < x0; ++x) code(x, model.At<false>(f, row, x));
    for (int x = x0; x < x1; ++x) code(x, model.At<true>(f, row, x));
    for (int x = x1; x < w; ++x) code(x, model.At<false>(f, row, x));
  }
  ByteWriter bw(out);
  bw.U8(kD2);
  bw.U16(static_cast<uint16_t>(w));
  bw.U16(static_cast<uint16_t>(h));
  bw.U16(static_cast<uint16_t>(options.noise_at_1m_um));
  const size_t size_at = bw.ReserveU32();
  const size_t start = out->size();
  tw.Finish(out);
  bw.PatchU32(size_at, static_cast<uint32_t>(out->size() - start));
  return OkStatus();
}

Status DecodeD2(ByteReader& r, std::span<const uint8_t> blob, int w, int h, ImageDepth16* depth) {
  uint16_t noise16 = 0;
  HOLO_RETURN_IF_ERROR(r.U16("depth.d2.noise", &noise16));
  std::span<const uint8_t> coded;
  HOLO_RETURN_IF_ERROR(r.Blob32("depth.d2.stream", blob.size(), &coded));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd("depth"));
  thread_local rans::TokenReader tr;  // its tables and buffers kept between frames
  HOLO_RETURN_IF_ERROR(tr.Init(coded, kD2Contexts, "depth.d2"));
  const size_t n = static_cast<size_t>(w) * h;
  if (n > tr.MaxSymbols())
    return DataLoss("depth.d2: " + std::to_string(n) + " pixels cannot fit in " + std::to_string(coded.size()) +
                    " coded bytes");
  if (depth->width() != w || depth->height() != h) depth->Resize(w, h);
  thread_local std::vector<uint16_t> fill, mag;
  fill.resize(n);
  mag.resize(n);
  D2Model model(w, noise16);
  std::string error;
  thread_local std::vector<int32_t> res;  // one row's residuals (kInvalidResidual: invalid)
  res.resize(static_cast<size_t>(w));
  for (int y = 0; y < h; ++y) {
    uint16_t* row = depth->row(y);
    const uint16_t* up = y > 0 ? depth->row(y - 1) : nullptr;
    uint16_t* f = fill.data() + static_cast<size_t>(y) * w;
    uint16_t* m = mag.data() + static_cast<size_t>(y) * w;
    model.PrepareRow(f, m, up, y);
    // false on a token or residual no encoder writes (`error` says which).
    auto decode = [&](int x, const D2Pixel& px) {
      const uint32_t tok = tr.Get(px.ctx);
      if (tok == kInvalidToken) {
        row[x] = 0;
        f[x] = static_cast<uint16_t>(px.pred);
        m[x] = 0;
        return true;
      }
      if (tok > kInvalidToken) {
        error = "token " + std::to_string(tok) + " is not a 16-bit residual";
        return false;
      }
      const int32_t res = rans::UnZigZag(tr.ValueOfToken16(tok));
      const auto v = static_cast<uint16_t>(px.pred + res);
      if (v == 0) {
        error = "a residual decodes to depth 0 (invalid pixels have their own token)";
        return false;
      }
      row[x] = v;
      f[x] = v;
      m[x] = static_cast<uint16_t>(res < 0 ? -res : res);
      return true;
    };
    const int x0 = model.InteriorBegin(), x1 = model.InteriorEnd();
    bool ok = true;
    if (y == 0) {  // the contexts of row 0 depend on the decoded depth to the left
      for (int x = 0; ok && x < w; ++x) ok = decode(x, model.At<false>(f, row, x));
    } else {
      // Below row 0 a context depends only on the rows above and on whether
      // the left pixel is invalid: all of the row's tokens first (the rANS
      // chain alone), then its pixels (the prediction chain alone).
      bool left_invalid = false;
      for (int x = 0; x < w; ++x) {
        const uint32_t tok = tr.Get(model.ContextAbove(x) | (left_invalid ? 8u : 0u));
        left_invalid = tok == kInvalidToken;
        if (left_invalid) {
          res[x] = kInvalidResidual;
          continue;
        }
        if (tok > kInvalidToken) {
          error = "token " + std::to_string(tok) + " is not a 16-bit residual";
          ok = false;
          break;
        }
        res[x] = rans::UnZigZag(tr.ValueOfToken16(tok));
      }
      auto place = [&](int x, int pred) {
        const int32_t r = res[x];
        if (r == kInvalidResidual) {
          row[x] = 0;
          f[x] = static_cast<uint16_t>(pred);
          m[x] = 0;
          return true;
        }
        const auto v = static_cast<uint16_t>(pred + r);
        row[x] = v;
        f[x] = v;
        m[x] = static_cast<uint16_t>(r < 0 ? -r : r);
        return v != 0;
      };
      if (ok) {
        for (int x = 0; ok && x < x0; ++x) ok = place(x, model.At<false>(f, row, x).pred);
        for (int x = x0; ok && x < x1; ++x) ok = place(x, model.At<true>(f, row, x).pred);
        for (int x = x1; ok && x < w; ++x) ok = place(x, model.At<false>(f, row, x).pred);
        if (!ok) error = "a residual decodes to depth 0 (invalid pixels have their own token)";
      }
    }
    if (!ok) return tr.ok() ? DataLoss("depth.d2: " + error) : tr.Finish();
    if (!tr.ok()) return tr.Finish();
  }
  return tr.Finish();
}

}  // namespace

Status EncodeDepth(const ImageDepth16& depth, const DepthEncodeOptions& options, std::vector<uint8_t>* out) {
  HOLO_RETURN_IF_ERROR(options.Check());
  const int w = depth.width(), h = depth.height();
  if (w <= 0 || h <= 0 || w > 0xFFFF || h > 0xFFFF)
    return InvalidArgument("EncodeDepth: image size " + std::to_string(w) + "x" + std::to_string(h) + " outside 1..65535");
  if (options.codec == DepthCodec::kD2) return EncodeD2(depth, options, out);
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
// The blob's codec byte (D1 or D2), width and height.
Status ReadDepthHeader(ByteReader& r, uint8_t* codec, uint16_t* w, uint16_t* h) {
  HOLO_RETURN_IF_ERROR(r.U8("depth.codec", codec));
  if (*codec != kD1 && *codec != kD2) return DataLoss("depth.codec: unknown depth codec " + std::to_string(*codec));
  HOLO_RETURN_IF_ERROR(r.U16("depth.width", w));
  return r.U16("depth.height", h);
}
}  // namespace

StatusOr<DepthCodec> PeekDepthCodec(std::span<const uint8_t> blob) {
  if (blob.empty()) return DataLoss("depth.codec: empty blob");
  if (blob[0] != kD1 && blob[0] != kD2) return DataLoss("depth.codec: unknown depth codec " + std::to_string(blob[0]));
  return static_cast<DepthCodec>(blob[0]);
}

Status PeekDepthSize(std::span<const uint8_t> blob, int* width, int* height) {
  ByteReader r(blob);
  uint8_t codec = 0;
  uint16_t w = 0, h = 0;
  HOLO_RETURN_IF_ERROR(ReadDepthHeader(r, &codec, &w, &h));
  *width = w;
  *height = h;
  return OkStatus();
}

Status DecodeDepth(std::span<const uint8_t> blob, ImageDepth16* depth, const Limits& limits) {
  ByteReader r(blob);
  uint8_t codec = 0;
  uint16_t w = 0, h = 0;
  HOLO_RETURN_IF_ERROR(ReadDepthHeader(r, &codec, &w, &h));
  if (w == 0 || h == 0 || w > limits.max_image_dim || h > limits.max_image_dim)
    return DataLoss("depth.width: image size " + std::to_string(w) + "x" + std::to_string(h) + " outside 1.." +
                    std::to_string(limits.max_image_dim));
  const uint64_t pixels = uint64_t{w} * h;
  if (pixels > limits.max_image_pixels)
    return DataLoss("depth.width: " + std::to_string(pixels) + " pixels exceed limit " + std::to_string(limits.max_image_pixels));
  if (codec == kD2) return DecodeD2(r, blob, w, h, depth);
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
