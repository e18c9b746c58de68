#include "server/stereo/patchmatch.h"

#include <algorithm>
#include <cmath>
#include <vector>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define HOLO_PM_X86 1
#endif

#include <opencv2/imgproc.hpp>

#include "common/worker_pool.h"

namespace holo {

Status PatchMatchOptions::Check() const {
  if (!(std::isfinite(min_disparity) && std::isfinite(max_disparity) && min_disparity >= 0.0f &&
        max_disparity > min_disparity + 1.0f && max_disparity <= 4096.0f))
    return InvalidArgument("disparity range must satisfy 0 <= min_disparity < max_disparity - 1 <= 4095, got [" +
                           FormatNumber(min_disparity) + ", " + FormatNumber(max_disparity) + "]");
  if (window_rows < 1 || window_rows > 31 || window_rows % 2 == 0)
    return InvalidArgument("window_rows must be odd and in [1, 31], got " + FormatNumber(window_rows));
  if (window_step < 1 || window_step > 4)
    return InvalidArgument("window_step must be in [1, 4], got " + FormatNumber(window_step));
  if (iterations < 1 || iterations > 16)
    return InvalidArgument("iterations must be in [1, 16], got " + FormatNumber(iterations));
  if (coarse_levels < 0 || coarse_levels > 4)
    return InvalidArgument("coarse_levels must be in [0, 4], got " + FormatNumber(coarse_levels));
  if (fine_iterations < 1 || fine_iterations > 16)
    return InvalidArgument("fine_iterations must be in [1, 16], got " + FormatNumber(fine_iterations));
  if (fine_refine_start < 0 || fine_refine_start > 20)
    return InvalidArgument("fine_refine_start must be in [0, 20], got " + FormatNumber(fine_refine_start));
  if (refine_per_sweep < 0 || refine_per_sweep > 8)
    return InvalidArgument("refine_per_sweep must be in [0, 8], got " + FormatNumber(refine_per_sweep));
  if (!(alpha >= 0.0f && alpha <= 1.0f)) return InvalidArgument("alpha must be in [0, 1], got " + FormatNumber(alpha));
  if (!(tau_color > 0.0f && tau_grad > 0.0f && gamma > 0.0f && std::isfinite(tau_color) && std::isfinite(tau_grad) &&
        std::isfinite(gamma)))
    return InvalidArgument("tau_color, tau_grad and gamma must be finite and > 0");
  if (!(min_normal_z > 0.05f && min_normal_z <= 1.0f))
    return InvalidArgument("min_normal_z must be in (0.05, 1], got " + FormatNumber(min_normal_z));
  if (!std::isfinite(lr_max_diff)) return InvalidArgument("lr_max_diff must be finite");
  if (edge_shift_px < 0 || edge_shift_px > 8 || edge_probe_px < 1 || edge_probe_px > 32)
    return InvalidArgument("edge_shift_px must be in [0, 8] and edge_probe_px in [1, 32], got " +
                           FormatNumber(edge_shift_px) + " and " + FormatNumber(edge_probe_px));
  if (!(edge_min_jump > 0.0f && edge_min_jump < 1.0f))
    return InvalidArgument("edge_min_jump must be in (0, 1), got " + FormatNumber(edge_min_jump));
  if (!(edge_margin >= 0.0f && edge_margin < 1.0f))
    return InvalidArgument("edge_margin must be in [0, 1), got " + FormatNumber(edge_margin));
  if (final_window_step < 0 || final_window_step > 4)
    return InvalidArgument("final_window_step must be in [0, 4], got " + FormatNumber(final_window_step));
  if (!(final_step_px >= 1.0f / 32.0f && final_step_px <= 4.0f))
    return InvalidArgument("final_step_px must be in [1/32, 4], got " + FormatNumber(final_step_px));
  if (threads < 0 || threads > 256) return InvalidArgument("threads must be in [0, 256], got " + FormatNumber(threads));
  if (temporal_iterations < 1 || temporal_iterations > 16)
    return InvalidArgument("temporal_iterations must be in [1, 16], got " + FormatNumber(temporal_iterations));
  if (temporal_refine_start < 0 || temporal_refine_start > 20)
    return InvalidArgument("temporal_refine_start must be in [0, 20], got " + FormatNumber(temporal_refine_start));
  if (!(temporal_still >= 0.0f && temporal_still <= 100.0f))
    return InvalidArgument("temporal_still must be in [0, 100], got " + FormatNumber(temporal_still));
  if (temporal_refine_per_sweep < 0 || temporal_refine_per_sweep > 8)
    return InvalidArgument("temporal_refine_per_sweep must be in [0, 8], got " +
                           FormatNumber(temporal_refine_per_sweep));
  if (!(temporal_min_overlap > 0.0f && temporal_min_overlap <= 1.0f))
    return InvalidArgument("temporal_min_overlap must be in (0, 1], got " + FormatNumber(temporal_min_overlap));
  return OkStatus();
}

ImageRect ImageRect::Clipped(int width, int height) const {
  ImageRect r{std::max(x0, 0), std::max(y0, 0), std::min(x1, width), std::min(y1, height)};
  if (r.empty()) r = ImageRect{};
  return r;
}

RowSpans RowSpans::FromRect(const ImageRect& rect, int width, int height) {
  const ImageRect r = rect.Clipped(width, height);
  RowSpans s;
  s.x0.assign(static_cast<size_t>(std::max(height, 0)), 0);
  s.x1.assign(s.x0.size(), 0);
  for (int y = r.y0; y < r.y1; ++y) {
    s.x0[static_cast<size_t>(y)] = r.x0;
    s.x1[static_cast<size_t>(y)] = r.x1;
  }
  return s;
}

ImageRect RowSpans::Bounds() const {
  ImageRect b;
  bool any = false;
  for (int y = 0; y < rows(); ++y) {
    const int a = x0[static_cast<size_t>(y)], e = x1[static_cast<size_t>(y)];
    if (e <= a) continue;
    if (!any) b = ImageRect{a, y, e, y + 1};
    any = true;
    b.x0 = std::min(b.x0, a);
    b.x1 = std::max(b.x1, e);
    b.y1 = y + 1;
  }
  return b;
}

int64_t RowSpans::area() const {
  int64_t n = 0;
  for (int y = 0; y < rows(); ++y) n += std::max(0, x1[static_cast<size_t>(y)] - x0[static_cast<size_t>(y)]);
  return n;
}

bool RowSpans::IsFull(int width) const {
  if (rows() == 0) return false;
  for (int y = 0; y < rows(); ++y)
    if (x0[static_cast<size_t>(y)] > 0 || x1[static_cast<size_t>(y)] < width) return false;
  return true;
}

namespace {

struct Plane {
  float a = 0, b = 0, c = 0;
  float At(float x, float y) const { return a * x + b * y + c; }
};
inline bool SamePlane(const Plane& p, const Plane& q) { return p.a == q.a && p.b == q.b && p.c == q.c; }

inline uint64_t Mix(uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}
// Uniform in [-1, 1) from 21 bits of `h` starting at `shift`.
inline float Sym(uint64_t h, int shift) {
  return static_cast<float>((h >> shift) & 0x1fffff) * (2.0f / 2097152.0f) - 1.0f;
}

// One view's images and state. Image rows are padded by kPad replicated
// pixels on each side, so a window's columns can be loaded without clamping.
constexpr int kPad = 16;
constexpr int kTail = 32;
struct View {
  int W = 0, H = 0, stride = 0;
  float sign = -1.0f;       // the matching pixel in the other view is at x + sign·d
  ImageRect region;         // the bounds of the pixels whose planes this Compute works on
  RowSpans spans;            // ... and those pixels, row by row (an empty row: x0 == x1 == 0)
  std::vector<float> I, G;  // intensity and x gradient, padded rows
  // The same padded rows packed for the AVX2 path's reads of the other
  // view: per position x, int16 {I(x), I(x+1)} in `pair_i` and
  // {2·G(x), 2·G(x+1)} in `pair_g` (both exact: I is 8-bit, G a half
  // integer), so one 32-bit element holds both interpolation ends. Each
  // array has kTail elements after the last row (whole vectors are loaded
  // there; lanes never select them).
  std::vector<uint32_t> pair_i, pair_g;
  std::vector<float> wtot;  // per pixel: total support weight of its window
  std::vector<Plane> plane;
  std::vector<float> cost;
  std::vector<Plane> proposal;
  std::vector<uint8_t> has_proposal;
  // PatchMatchOptions::temporal_still: the last Compute's intensities (the
  // same padded rows as I), per pixel the change of its cost's inputs (the
  // largest |I − last_I| over its window and its match's, averaged), and the
  // pixels left alone in this Compute.
  std::vector<float> last_I;
  std::vector<float> change;
  std::vector<uint8_t> settled;

  const float* IRow(int y) const { return I.data() + static_cast<size_t>(y) * stride + kPad; }
  const float* GRow(int y) const { return G.data() + static_cast<size_t>(y) * stride + kPad; }
  const uint32_t* PairIRow(int y) const { return pair_i.data() + static_cast<size_t>(y) * stride + kPad; }
  const uint32_t* PairGRow(int y) const { return pair_g.data() + static_cast<size_t>(y) * stride + kPad; }

  void Load(const ImageGray8& img, float s) {
    W = img.width();
    H = img.height();
    stride = W + 2 * kPad;
    sign = s;
    const size_t n = static_cast<size_t>(W) * H;
    last_I.swap(I);  // the last Compute's intensities (PatchMatchOptions::temporal_still)
    I.resize(static_cast<size_t>(stride) * H + 8);
    G.resize(I.size());
    pair_i.resize(I.size() + kTail);
    pair_g.resize(I.size() + kTail);
    for (int y = 0; y < H; ++y) {
      const uint8_t* src = img.row(y);
      float* r = I.data() + static_cast<size_t>(y) * stride;
      float* g = G.data() + static_cast<size_t>(y) * stride;
      for (int x = -kPad; x < W + kPad; ++x) r[x + kPad] = src[std::clamp(x, 0, W - 1)];
      for (int x = -kPad; x < W + kPad; ++x) {
        const int xc = std::clamp(x, 0, W - 1);
        g[x + kPad] = 0.5f * (r[std::min(xc + 1, W - 1) + kPad] - r[std::max(xc - 1, 0) + kPad]);
      }
      uint32_t* qi = pair_i.data() + static_cast<size_t>(y) * stride;
      uint32_t* qg = pair_g.data() + static_cast<size_t>(y) * stride;
      for (int j = 0; j < stride; ++j) {
        const int j1 = std::min(j + 1, stride - 1);
        const auto i16 = [](float v) { return static_cast<uint32_t>(static_cast<uint16_t>(static_cast<int16_t>(v))); };
        qi[j] = i16(r[j]) | i16(r[j1]) << 16;
        qg[j] = i16(2.0f * g[j]) | i16(2.0f * g[j1]) << 16;
      }
    }
    wtot.resize(n);
    plane.resize(n);
    cost.resize(n);
    proposal.resize(n);
    has_proposal.resize(n);
    settled.assign(n, 0);
    change.resize(n);
  }
};

struct CostParams {
  int rows = 5, step = 2;
  float alpha = 0.5f, tau_c = 20, tau_g = 6, inv_gamma2 = 1.0f / 144.0f;
  float penalty = 0;  // cost of a sample that falls outside the other image
};

// The 8 column offsets of the window.
inline int ColumnOffset(int lane, int step) { return step * lane - (7 * step) / 2; }

inline float SupportWeight(float dI, float inv_gamma2) { return 1.0f / (1.0f + dI * dI * inv_gamma2); }

// Total support weight of the window at (x, y) (depends on the view only).
// `centre`: the intensity the weights compare with (the edge pass's shifted
// windows weigh by the pixel's own; otherwise the window's centre).
float WindowWeight(const View& v, int x, int y, const CostParams& cp, float centre) {
  float w = 0;
  for (int r = 0; r < cp.rows; ++r) {
    const float* si = v.IRow(std::clamp(y + (r - cp.rows / 2) * cp.step, 0, v.H - 1));
    for (int l = 0; l < 8; ++l) w += SupportWeight(si[x + ColumnOffset(l, cp.step)] - centre, cp.inv_gamma2);
  }
  return w;
}

float WindowWeight(const View& v, int x, int y, const CostParams& cp) {
  return WindowWeight(v, x, y, cp, v.IRow(y)[x]);
}

// The largest |I − last_I| over the window at (x, y) (PatchMatchOptions::temporal_still).
float WindowChange(const View& v, int x, int y, const CostParams& cp) {
  float c = 0;
  for (int r = 0; r < cp.rows; ++r) {
    const size_t ro = static_cast<size_t>(std::clamp(y + (r - cp.rows / 2) * cp.step, 0, v.H - 1)) * v.stride + kPad;
    for (int l = 0; l < 8; ++l) {
      const size_t j = ro + static_cast<size_t>(x + ColumnOffset(l, cp.step));
      c = std::max(c, std::abs(v.I[j] - v.last_I[j]));
    }
  }
  return c;
}

// Mean weighted cost of plane `p` in the window at (x, y), or a value ≥
// `bound` as soon as the partial sum shows it cannot beat `bound`. Weights
// compare with `centre`; `wt` is their total. Window columns beyond the
// image read the replicated border.
float CostScalar(const View& self, const View& other, int x, int y, const Plane& p, const CostParams& cp, float bound,
                 float centre, float wt) {
  const int H = self.H;
  const float max_x = static_cast<float>(self.W - 1) - 1e-3f;
  const float limit = bound * wt;
  float sum = 0;
  for (int r = 0; r < cp.rows; ++r) {
    const int yy = std::clamp(y + (r - cp.rows / 2) * cp.step, 0, H - 1);
    const float* si = self.IRow(yy);
    const float* sg = self.GRow(yy);
    const float* oi = other.IRow(yy);
    const float* og = other.GRow(yy);
    const float row_d = p.b * static_cast<float>(yy) + p.c;
    for (int l = 0; l < 8; ++l) {
      const int xx = x + ColumnOffset(l, cp.step);
      const float xf = static_cast<float>(xx);
      const float d = p.a * xf + row_d;
      float xs = xf + self.sign * d;
      const bool inside = xs >= 0.0f && xs <= max_x;
      xs = std::clamp(xs, 0.0f, max_x);
      const int i0 = static_cast<int>(xs);
      const float f = xs - static_cast<float>(i0);
      const float ov = oi[i0] + f * (oi[i0 + 1] - oi[i0]);
      float rho = (1.0f - cp.alpha) * std::min(std::abs(si[xx] - ov), cp.tau_c);
      if (cp.alpha > 0.0f) {
        const float og_v = og[i0] + f * (og[i0 + 1] - og[i0]);
        rho += cp.alpha * std::min(std::abs(sg[xx] - og_v), cp.tau_g);
      }
      if (!inside) rho = cp.penalty;
      sum += SupportWeight(si[xx] - centre, cp.inv_gamma2) * rho;
    }
    if (sum >= limit) return bound;
  }
  return sum / wt;
}

// What a pixel's window contributes from its own view — its samples'
// intensity and gradient and their support weights, 8 columns per row —
// computed once when a sweep visits the pixel and shared by the 3–4 planes
// it tries there (the AVX2 path; the scalar path reads the rows directly).
constexpr int kMaxWindowRows = 31;
struct SelfWindow {
  alignas(32) float sv[kMaxWindowRows * 8];
  alignas(32) float sg[kMaxWindowRows * 8];
  alignas(32) float w[kMaxWindowRows * 8];
};

#ifdef HOLO_PM_X86
// The 8 window columns x + step·l − (7·step)/2 of a padded row.
__attribute__((target("avx2,fma"))) inline __m256 LoadColumns(const float* row, int x, int step, __m256i idx) {
  if (step == 1) return _mm256_loadu_ps(row + x - 3);
  if (step == 2) {
    // Even elements of row[x-7 .. x+8]: shuffle two loads, then restore lane order.
    const __m256 v0 = _mm256_loadu_ps(row + x - 7), v1 = _mm256_loadu_ps(row + x + 1);
    const __m256 e = _mm256_shuffle_ps(v0, v1, _MM_SHUFFLE(2, 0, 2, 0));
    return _mm256_castpd_ps(_mm256_permute4x64_pd(_mm256_castps_pd(e), _MM_SHUFFLE(3, 1, 2, 0)));
  }
  return _mm256_i32gather_ps(row, idx, 4);
}

__attribute__((target("avx2,fma"))) inline float HorizontalSum(__m256 v) {
  const __m128 h = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
  const __m128 h2 = _mm_add_ps(h, _mm_movehl_ps(h, h));
  return _mm_cvtss_f32(_mm_add_ss(h2, _mm_shuffle_ps(h2, h2, 1)));
}

// `centre_value`: the intensity the support weights compare with (the
// window's centre, or for the edge pass's shifted windows the pixel's own).
__attribute__((target("avx2,fma"))) void PrepareWindowAvx2(const View& self, int x, int y, const CostParams& cp,
                                                             float centre_value, SelfWindow* sw) {
  const __m256 centre = _mm256_set1_ps(centre_value);
  const __m256i lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i xx = _mm256_add_epi32(_mm256_mullo_epi32(lanes, _mm256_set1_epi32(cp.step)),
                                      _mm256_set1_epi32(x - (7 * cp.step) / 2));
  const __m256 one = _mm256_set1_ps(1.0f), inv_g2 = _mm256_set1_ps(cp.inv_gamma2);
  for (int r = 0; r < cp.rows; ++r) {
    const int yy = std::clamp(y + (r - cp.rows / 2) * cp.step, 0, self.H - 1);
    const __m256 sv = LoadColumns(self.IRow(yy), x, cp.step, xx);
    _mm256_store_ps(sw->sv + 8 * r, sv);
    _mm256_store_ps(sw->sg + 8 * r, LoadColumns(self.GRow(yy), x, cp.step, xx));
    const __m256 dI = _mm256_sub_ps(sv, centre);
    _mm256_store_ps(sw->w + 8 * r, _mm256_div_ps(one, _mm256_fmadd_ps(_mm256_mul_ps(dI, dI), inv_g2, one)));
  }
}

// The total of a prepared window's support weights.
__attribute__((target("avx2,fma"))) float WindowTotalAvx2(const CostParams& cp, const SelfWindow& sw) {
  __m256 total = _mm256_setzero_ps();
  for (int r = 0; r < cp.rows; ++r) total = _mm256_add_ps(total, _mm256_load_ps(sw.w + 8 * r));
  return HorizontalSum(total);
}

// The largest |I − last_I| over the window at (x, y) of view `v` (x in [0, W)).
__attribute__((target("avx2,fma"))) float WindowChangeAvx2(const View& v, int x, int y, const CostParams& cp) {
  const __m256i lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i xx = _mm256_add_epi32(_mm256_mullo_epi32(lanes, _mm256_set1_epi32(cp.step)),
                                      _mm256_set1_epi32(x - (7 * cp.step) / 2));
  const __m256 sign = _mm256_set1_ps(-0.0f);
  __m256 total = _mm256_setzero_ps();
  for (int r = 0; r < cp.rows; ++r) {
    const size_t ro = static_cast<size_t>(std::clamp(y + (r - cp.rows / 2) * cp.step, 0, v.H - 1)) * v.stride + kPad;
    const __m256 now = LoadColumns(v.I.data() + ro, x, cp.step, xx);
    const __m256 last = LoadColumns(v.last_I.data() + ro, x, cp.step, xx);
    total = _mm256_max_ps(total, _mm256_andnot_ps(sign, _mm256_sub_ps(now, last)));
  }
  alignas(32) float t[8];
  _mm256_store_ps(t, total);
  return *std::max_element(t, t + 8);
}

// Lanes idx (0 ≤ idx < 8·regs) of the 8·regs consecutive elements at `p`:
// `regs` loads and in-register permutes (cheaper than a gather).
__attribute__((target("avx2,fma"))) inline __m256i SelectLanes(const uint32_t* p, __m256i idx, int regs) {
  __m256i r = _mm256_permutevar8x32_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p)), idx);
  if (regs > 1) {
    const __m256i r1 = _mm256_permutevar8x32_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p + 8)), idx);
    r = _mm256_blendv_epi8(r, r1, _mm256_cmpgt_epi32(idx, _mm256_set1_epi32(7)));
  }
  if (regs > 2) {
    const __m256i r2 = _mm256_permutevar8x32_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p + 16)), idx);
    r = _mm256_blendv_epi8(r, r2, _mm256_cmpgt_epi32(idx, _mm256_set1_epi32(15)));
  }
  return r;
}

template <bool kGradient>
__attribute__((target("avx2,fma"))) float CostAvx2(const View& self, const View& other, int x, int y, const Plane& p,
                                                    const CostParams& cp, const SelfWindow& sw, float bound, float wt) {
  const int W = self.W, H = self.H;
  const __m256i lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i xx = _mm256_add_epi32(_mm256_mullo_epi32(lanes, _mm256_set1_epi32(cp.step)),
                                      _mm256_set1_epi32(x - (7 * cp.step) / 2));
  const __m256 xf = _mm256_cvtepi32_ps(xx);
  const __m256 a = _mm256_set1_ps(p.a), sign = _mm256_set1_ps(self.sign);
  const __m256 zero = _mm256_setzero_ps(), max_x = _mm256_set1_ps(static_cast<float>(W - 1) - 1e-3f);
  const __m256 wc = _mm256_set1_ps(1.0f - cp.alpha), wg = _mm256_set1_ps(cp.alpha);
  const __m256 tau_c = _mm256_set1_ps(cp.tau_c), tau_g = _mm256_set1_ps(cp.tau_g);
  const __m256 penalty = _mm256_set1_ps(cp.penalty);
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256i lo16 = _mm256_set1_epi32(0xffff);
  const __m256 half = _mm256_set1_ps(0.5f);
  const float limit = bound * wt;
  // x + sign·a·x: the part of the sample position that does not change with the row.
  const __m256 xs_base = _mm256_fmadd_ps(sign, _mm256_mul_ps(a, xf), xf);
  // The window's samples of a row of the other view lie within
  // |x_7 − x_0| + 1 pixels, one to four vectors for the usual planes: up to
  // three, the row's elements are loaded and permuted into the lanes (lane
  // index relative to `base`, a pixel left of the lowest lane's; a check
  // falls back to gathers if rounding ever put a lane outside).
  alignas(32) float xb[8];
  _mm256_store_ps(xb, xs_base);
  const float lo_base = std::min(xb[0], xb[7]);
  const int regs = (static_cast<int>(std::abs(xb[7] - xb[0]) + 0.51f) + 9) / 8;
  const __m256i max_idx = _mm256_set1_epi32(8 * regs - 1);
  const float max_xs = static_cast<float>(W - 1) - 1e-3f;
  __m256 sum = zero;
  for (int r = 0; r < cp.rows; ++r) {
    const int yy = std::clamp(y + (r - cp.rows / 2) * cp.step, 0, H - 1);
    const __m256 row_d = _mm256_set1_ps(self.sign * (p.b * static_cast<float>(yy) + p.c));
    __m256 xs = _mm256_add_ps(xs_base, row_d);
    const __m256 inside = _mm256_and_ps(_mm256_cmp_ps(xs, zero, _CMP_GE_OQ), _mm256_cmp_ps(xs, max_x, _CMP_LE_OQ));
    xs = _mm256_min_ps(_mm256_max_ps(xs, zero), max_x);
    const __m256i i0 = _mm256_cvttps_epi32(xs);
    const __m256 f = _mm256_sub_ps(xs, _mm256_cvtepi32_ps(i0));
    // Both interpolation ends (and their gradients) from one 32-bit element each.
    const uint32_t* irow = other.PairIRow(yy);
    const uint32_t* grow = other.PairGRow(yy);
    __m256i ip, gp;
    bool selected = false;
    if (regs <= 3) {
      const int base = static_cast<int>(std::clamp(lo_base + self.sign * (p.b * static_cast<float>(yy) + p.c) - 0.5f,
                                                   0.0f, max_xs));
      const __m256i idx = _mm256_sub_epi32(i0, _mm256_set1_epi32(base));
      const __m256i out = _mm256_or_si256(_mm256_cmpgt_epi32(idx, max_idx),
                                          _mm256_cmpgt_epi32(_mm256_setzero_si256(), idx));
      if (_mm256_testz_si256(out, out)) {
        ip = SelectLanes(irow + base, idx, regs);
        if constexpr (kGradient) gp = SelectLanes(grow + base, idx, regs);
        selected = true;
      }
    }
    if (!selected) {
      ip = _mm256_i32gather_epi32(reinterpret_cast<const int*>(irow), i0, 4);
      if constexpr (kGradient) gp = _mm256_i32gather_epi32(reinterpret_cast<const int*>(grow), i0, 4);
    }
    const __m256 o0 = _mm256_cvtepi32_ps(_mm256_and_si256(ip, lo16));
    const __m256 o1 = _mm256_cvtepi32_ps(_mm256_srli_epi32(ip, 16));
    const __m256 sv = _mm256_load_ps(sw.sv + 8 * r);
    const __m256 ov = _mm256_fmadd_ps(f, _mm256_sub_ps(o1, o0), o0);
    __m256 rho = _mm256_mul_ps(wc, _mm256_min_ps(_mm256_and_ps(_mm256_sub_ps(sv, ov), abs_mask), tau_c));
    if constexpr (kGradient) {
      const __m256 g0 = _mm256_mul_ps(half, _mm256_cvtepi32_ps(_mm256_srai_epi32(_mm256_slli_epi32(gp, 16), 16)));
      const __m256 g1 = _mm256_mul_ps(half, _mm256_cvtepi32_ps(_mm256_srai_epi32(gp, 16)));
      const __m256 sgv = _mm256_load_ps(sw.sg + 8 * r);
      const __m256 ogv = _mm256_fmadd_ps(f, _mm256_sub_ps(g1, g0), g0);
      const __m256 eg = _mm256_min_ps(_mm256_and_ps(_mm256_sub_ps(sgv, ogv), abs_mask), tau_g);
      rho = _mm256_fmadd_ps(wg, eg, rho);
    }
    rho = _mm256_blendv_ps(penalty, rho, inside);
    sum = _mm256_fmadd_ps(_mm256_load_ps(sw.w + 8 * r), rho, sum);
    // Halfway, stop when this plane cannot win any more (a horizontal sum
    // costs about a row's arithmetic, so only once).
    if (r == cp.rows / 2 && r + 1 < cp.rows && HorizontalSum(sum) >= limit) return bound;
  }
  const float total = HorizontalSum(sum);
  return total / wt;
}
#endif

}  // namespace

struct PatchMatchStereo::Impl {
  explicit Impl(int threads) : pool(threads) {}
  WorkerPool pool;
  View left, right;
  ImageFloat right_disparity;
  bool avx2 = false;
  // The half-resolution level (coarse_levels > 0) and its pair.
  std::unique_ptr<PatchMatchStereo> coarse;
  ImageGray8 coarse_left, coarse_right;
  ImageFloat coarse_disparity;
  // The last Compute's regions and image size (its planes stay in left and
  // right: PatchMatchOptions::temporal starts from them).
  bool have_last = false;
  int last_w = 0, last_h = 0;
  ImageRect last_left, last_right;    // their bounds
  RowSpans last_lspans, last_rspans;  // and their spans
  uint64_t temporal_calls = 0;
  // PatchMatchOptions::temporal_still: each view's noise level, and scratch.
  float still_level[2] = {0, 0};
  std::vector<float> change_scratch;  // varies the refinement's random numbers from frame to frame
  bool last_temporal = false;
  std::vector<Plane> edge_planes;  // the edge pass's copy of the left planes
};

namespace {
// 2×2 box average (OpenCV's area resampling at exactly half size); an odd
// last row or column is left out.
void HalveImage(const ImageGray8& in, ImageGray8* out) {
  const int w = in.width() / 2, h = in.height() / 2;
  if (out->width() != w || out->height() != h) out->Resize(w, h);
  const cv::Mat src(in.height(), in.width(), CV_8UC1, const_cast<uint8_t*>(in.data()));
  cv::Mat dst(h, w, CV_8UC1, out->data());
  cv::resize(src(cv::Rect(0, 0, 2 * w, 2 * h)), dst, dst.size(), 0, 0, cv::INTER_AREA);
}
}  // namespace

PatchMatchStereo::PatchMatchStereo(PatchMatchOptions options) : options_(options) {
  const Status s = options_.Check();
  HOLO_CHECK_MSG(s.ok(), s.ToString());
  impl_ = std::make_unique<Impl>(options_.threads);
#ifdef HOLO_PM_X86
  impl_->avx2 = !options_.force_scalar && __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#endif
}

PatchMatchStereo::~PatchMatchStereo() = default;

StatusOr<std::unique_ptr<PatchMatchStereo>> PatchMatchStereo::Create(PatchMatchOptions options) {
  HOLO_RETURN_IF_ERROR(options.Check().WithContext("patchmatch options"));
  return std::make_unique<PatchMatchStereo>(options);
}

const ImageFloat& PatchMatchStereo::right_disparity() const { return impl_->right_disparity; }
bool PatchMatchStereo::uses_avx2() const { return impl_->avx2; }
bool PatchMatchStereo::last_was_temporal() const { return impl_->last_temporal; }
void PatchMatchStereo::ForgetLast() { impl_->have_last = false; }

ImageRect PatchMatchStereo::RightRegion(const ImageRect& left_region, int width, int height,
                                        float max_disparity) const {
  if (max_disparity < 0.0f) max_disparity = options_.max_disparity;
  const ImageRect l = left_region.Clipped(width, height);
  if (l.empty()) return l;
  // Not narrowed on the right by min_disparity (a few pixels): the whole
  // image then gives the full run's right region, and its result bit for bit.
  return ImageRect{l.x0 - static_cast<int>(std::ceil(max_disparity)), l.y0, l.x1, l.y1}.Clipped(width, height);
}

Status PatchMatchStereo::Compute(const ImageGray8& left, const ImageGray8& right, ImageFloat* disparity) {
  return Compute(left, right, ImageRect::Full(left.width(), left.height()), disparity);
}

Status PatchMatchStereo::Compute(const ImageGray8& left, const ImageGray8& right, const ImageRect& region,
                                 ImageFloat* disparity) {
  return Compute(left, right, region, options_.max_disparity, disparity);
}

Status PatchMatchStereo::Compute(const ImageGray8& left, const ImageGray8& right, const ImageRect& region,
                                 float max_disparity, ImageFloat* disparity) {
  return Compute(left, right, RowSpans::FromRect(region, left.width(), left.height()), max_disparity, disparity);
}

Status PatchMatchStereo::Compute(const ImageGray8& left, const ImageGray8& right, const RowSpans& spans,
                                 float max_disparity, ImageFloat* disparity) {
  if (std::isnan(max_disparity)) return InvalidArgument("max_disparity is NaN");
  if (left.width() != right.width() || left.height() != right.height())
    return InvalidArgument("stereo pair sizes differ: left " + std::to_string(left.width()) + "x" +
                           std::to_string(left.height()) + ", right " + std::to_string(right.width()) + "x" +
                           std::to_string(right.height()));
  if (left.width() < 16 || left.height() < 8)
    return InvalidArgument("stereo pair too small: " + std::to_string(left.width()) + "x" +
                           std::to_string(left.height()) + " (at least 16x8)");
  const PatchMatchOptions& o = options_;
  Impl& im = *impl_;
  View& L = im.left;
  View& R = im.right;
  const int W = left.width(), H = left.height();
  if (spans.rows() != H)
    return InvalidArgument("row spans: " + std::to_string(spans.rows()) + " rows for a " + std::to_string(H) +
                           "-row image");
  // The left view's spans, clipped to the image.
  L.spans.x0.assign(static_cast<size_t>(H), 0);
  L.spans.x1.assign(static_cast<size_t>(H), 0);
  for (int y = 0; y < H; ++y) {
    const int a = std::max(spans.x0[static_cast<size_t>(y)], 0), e = std::min(spans.x1[static_cast<size_t>(y)], W);
    if (e > a) {
      L.spans.x0[static_cast<size_t>(y)] = a;
      L.spans.x1[static_cast<size_t>(y)] = e;
    }
  }
  const ImageRect lreg = L.spans.Bounds();
  if (disparity->width() != W || disparity->height() != H) disparity->Resize(W, H);
  if (im.right_disparity.width() != W || im.right_disparity.height() != H) im.right_disparity.Resize(W, H);
  if (lreg.empty()) {
    im.last_temporal = false;
    disparity->Fill(0.0f);
    im.right_disparity.Fill(0.0f);
    return OkStatus();
  }
  L.Load(left, -1.0f);
  R.Load(right, +1.0f);
  L.region = lreg;
  // This call's search range: [min_disparity, dmax].
  const float dmax = std::clamp(max_disparity, std::min(o.min_disparity + 2.0f, o.max_disparity), o.max_disparity);
  // The right view's spans: each left span widened to the left by the range
  // (as RightRegion does for a rectangle).
  R.spans.x0.assign(static_cast<size_t>(H), 0);
  R.spans.x1.assign(static_cast<size_t>(H), 0);
  for (int y = 0; y < H; ++y) {
    const size_t r = static_cast<size_t>(y);
    if (L.spans.x1[r] <= L.spans.x0[r]) continue;
    R.spans.x0[r] = std::max(0, L.spans.x0[r] - static_cast<int>(std::ceil(dmax)));
    R.spans.x1[r] = L.spans.x1[r];
  }
  R.region = R.spans.Bounds();
  CostParams cp;
  cp.rows = o.window_rows;
  cp.step = o.window_step;
  cp.alpha = o.alpha;
  cp.tau_c = o.tau_color;
  cp.tau_g = o.tau_grad;
  cp.inv_gamma2 = 1.0f / (o.gamma * o.gamma);
  cp.penalty = (1.0f - o.alpha) * o.tau_color + o.alpha * o.tau_grad;
  const bool avx2 = im.avx2;
  const bool gradient = o.alpha > 0.0f;
  // Call before the costs of a pixel: fills `sw` where the AVX2 path reads it.
  // Both with the window `w` (the sweeps' `cp`, or the dense last pass's).
  auto prepare_with = [&](const CostParams& w, const View& self, int x, int y, SelfWindow* sw) {
#ifdef HOLO_PM_X86
    if (avx2) PrepareWindowAvx2(self, x, y, w, self.IRow(y)[x], sw);
#endif
    (void)w, (void)self, (void)x, (void)y, (void)sw;
  };
  // The cost with the weights compared with `centre` and totalling `wt`
  // (prepared with the same centre on the AVX2 path).
  auto cost_weighted = [&](const CostParams& w, const View& self, const View& other, int x, int y, const Plane& p,
                           const SelfWindow& sw, float bound, float centre, float wt) {
#ifdef HOLO_PM_X86
    if (avx2) return gradient ? CostAvx2<true>(self, other, x, y, p, w, sw, bound, wt)
                              : CostAvx2<false>(self, other, x, y, p, w, sw, bound, wt);
#endif
    (void)sw;
    return CostScalar(self, other, x, y, p, w, bound, centre, wt);
  };
  auto cost_with = [&](const CostParams& w, const View& self, const View& other, int x, int y, const Plane& p,
                       const SelfWindow& sw, float bound) {
    return cost_weighted(w, self, other, x, y, p, sw, bound, self.IRow(y)[x],
                         self.wtot[static_cast<size_t>(y) * W + x]);
  };
  auto prepare = [&](const View& self, int x, int y, SelfWindow* sw) { prepare_with(cp, self, x, y, sw); };
  // prepare_with, and the pixel's total support weight (wtot) in window `w`:
  // from the prepared weights on the AVX2 path.
  auto prepare_total = [&](const CostParams& w, View& v, int x, int y, SelfWindow* sw) {
    const size_t i = static_cast<size_t>(y) * W + x;
#ifdef HOLO_PM_X86
    if (avx2) {
      PrepareWindowAvx2(v, x, y, w, v.IRow(y)[x], sw);
      v.wtot[i] = WindowTotalAvx2(w, *sw);
      return;
    }
#endif
    (void)sw;
    v.wtot[i] = WindowWeight(v, x, y, w);
  };
  auto cost = [&](const View& self, const View& other, int x, int y, const Plane& p, const SelfWindow& sw,
                  float bound) { return cost_with(cp, self, other, x, y, p, sw, bound); };
  constexpr float kNoBound = 3.0e38f;
  const float dmin = o.min_disparity, range = dmax - dmin;
  const float min_nz = o.min_normal_z;
  // Plane through disparity `d` at (x, y) with unit normal n (nz ≥ min_nz).
  auto make_plane = [&](float x, float y, float d, float nx, float ny, float nz) {
    nz = std::max(nz, min_nz);
    Plane p;
    p.a = -nx / nz;
    p.b = -ny / nz;
    p.c = d - p.a * x - p.b * y;
    return p;
  };
  auto normal_of = [](const Plane& p, float* nx, float* ny, float* nz) {
    const float inv = 1.0f / std::sqrt(p.a * p.a + p.b * p.b + 1.0f);
    *nx = -p.a * inv;
    *ny = -p.b * inv;
    *nz = inv;
  };
  auto valid_at = [&](const Plane& p, float x, float y) {
    const float d = p.At(x, y);
    return d >= dmin && d <= dmax;
  };
  // Start from the last Compute's planes (PatchMatchOptions::temporal)?
  // (The pixels of this call's spans inside the last call's.)
  const auto overlap = [&](const RowSpans& last) {
    int64_t n = 0;
    for (int y = 0; y < H; ++y) {
      const size_t r = static_cast<size_t>(y);
      n += std::max(0, std::min(L.spans.x1[r], last.x1[r]) - std::max(L.spans.x0[r], last.x0[r]));
    }
    return n;
  };
  const int64_t larea = L.spans.area();
  const bool temporal = o.temporal && im.have_last && im.last_w == W && im.last_h == H &&
                        larea < static_cast<int64_t>(W) * H &&
                        static_cast<double>(overlap(im.last_lspans)) >=
                            o.temporal_min_overlap * static_cast<double>(larea);
  // A temporal start varies the refinement's random numbers from call to
  // call (the same perturbations every frame would retry the same planes);
  // any other call gives a fresh matcher's result bit for bit.
  const uint64_t seed = Mix(o.seed + 0x7f4a7c15ULL + (temporal ? Mix(++im.temporal_calls) : 0));
  auto rng = [&](uint64_t pass, int x, int y, uint64_t k) {
    return Mix(seed ^ Mix((pass << 40) ^ (k << 32) ^ (static_cast<uint64_t>(y) << 16) ^ static_cast<uint64_t>(x)));
  };

  // PatchMatchOptions::temporal_still: leave alone the pixels whose window
  // has not changed since the last Compute.
  const bool still = temporal && o.temporal_still > 0.0f;

  // Random initialisation.
  auto init = [&](View& v, const View& other, uint64_t tag) {
    const ImageRect& g = v.region;
    im.pool.Run(g.height(), [&](int row, int) {
      const int y = g.y0 + row;
      SelfWindow sw;
      for (int x = v.spans.x0[static_cast<size_t>(y)]; x < v.spans.x1[static_cast<size_t>(y)]; ++x) {
        const uint64_t h = rng(tag, x, y, 0);
        const float d = dmin + range * 0.5f * (Sym(h, 0) + 1.0f);
        float nx = 0.5f * Sym(h, 21), ny = 0.5f * Sym(h, 42);
        float nz = std::sqrt(std::max(0.0f, 1.0f - nx * nx - ny * ny));
        const size_t i = static_cast<size_t>(y) * W + x;
        v.plane[i] = make_plane(static_cast<float>(x), static_cast<float>(y), d, nx, ny, nz);
        prepare_total(cp, v, x, y, &sw);
        v.cost[i] = cost(v, other, x, y, v.plane[i], sw, kNoBound);
      }
    });
  };

  auto try_plane = [&](View& v, const View& other, int x, int y, const Plane& p, const SelfWindow& sw) {
    const size_t i = static_cast<size_t>(y) * W + x;
    // Propagation copies planes exactly, so a neighbour's (or the other
    // view's) plane is often the pixel's own: its cost is the one stored.
    if (SamePlane(p, v.plane[i])) return;
    if (!valid_at(p, static_cast<float>(x), static_cast<float>(y))) return;
    const float c = cost(v, other, x, y, p, sw, v.cost[i]);
    if (c < v.cost[i]) {
      v.cost[i] = c;
      v.plane[i] = p;
    }
  };
  // Start from the half-resolution level's planes where there is one: a
  // plane d = a·x + b·y + c at half resolution is d' = a·x' + b·y' + 2c −
  // (a + b)/2 at full resolution (pixel centres x = (x' + ½)/2 − ½).
  // (Offering each pixel its coarse neighbours' planes as well changed
  // bad-2px by < 0.1 point on the studio pairs for 10 % more time.)
  const bool from_coarse = o.coarse_levels > 0 && W / 2 >= 16 && H / 2 >= 8;
  auto init_from_coarse = [&](View& v, const View& other, const View& cv) {
    const int cw = cv.W;
    const ImageRect& g = v.region;
    // The coarse spans contain every (x / 2, y / 2) of v's (they are one
    // coarse pixel wider).
    const ImageRect& cg = cv.region;
    auto upsample = [&](const Plane& q) { return Plane{q.a, q.b, 2.0f * q.c - 0.5f * (q.a + q.b)}; };
    im.pool.Run(g.height(), [&](int row, int) {
      const int y = g.y0 + row;
      SelfWindow sw;
      const int cy = std::clamp(y / 2, cg.y0, cg.y1 - 1);
      const bool has_span = cv.spans.x1[static_cast<size_t>(cy)] > cv.spans.x0[static_cast<size_t>(cy)];
      const int cx0 = has_span ? cv.spans.x0[static_cast<size_t>(cy)] : cg.x0;
      const int cx1 = has_span ? cv.spans.x1[static_cast<size_t>(cy)] : cg.x1;
      for (int x = v.spans.x0[static_cast<size_t>(y)]; x < v.spans.x1[static_cast<size_t>(y)]; ++x) {
        const size_t i = static_cast<size_t>(y) * W + x;
        const int cx = std::clamp(x / 2, cx0, cx1 - 1);
        prepare_total(cp, v, x, y, &sw);
        v.plane[i] = upsample(cv.plane[static_cast<size_t>(cy) * cw + cx]);
        if (!valid_at(v.plane[i], static_cast<float>(x), static_cast<float>(y))) {
          const float d = std::clamp(v.plane[i].At(static_cast<float>(x), static_cast<float>(y)), dmin, dmax);
          v.plane[i] = Plane{0.0f, 0.0f, d};
        }
        v.cost[i] = cost(v, other, x, y, v.plane[i], sw, kNoBound);
      }
    });
  };
  // The last Compute's planes (PatchMatchOptions::temporal): kept where the
  // last spans had them, else the nearest pixel's of them (on the nearest
  // row with a span). Two passes, so that no row reads a plane another row
  // is changing. `last` has at least one span.
  std::vector<int> near_row(static_cast<size_t>(H));
  auto init_from_last = [&](View& v, const View& other, const RowSpans& last) {
    const ImageRect& g = v.region;
    for (int y = 0, prev = -1; y < H; ++y) {  // the nearest row with a span, per row
      if (last.x1[static_cast<size_t>(y)] > last.x0[static_cast<size_t>(y)]) prev = y;
      near_row[static_cast<size_t>(y)] = prev;
    }
    for (int y = H - 1, next = -1; y >= 0; --y) {
      if (last.x1[static_cast<size_t>(y)] > last.x0[static_cast<size_t>(y)]) next = y;
      const int prev = near_row[static_cast<size_t>(y)];
      near_row[static_cast<size_t>(y)] = prev < 0 || (next >= 0 && next - y < y - prev) ? next : prev;
    }
    im.pool.Run(g.height(), [&](int row, int) {
      const int y = g.y0 + row;
      const int ly = near_row[static_cast<size_t>(y)];
      const Plane* from = v.plane.data() + static_cast<size_t>(ly) * W;
      const int lx0 = last.x0[static_cast<size_t>(ly)], lx1 = last.x1[static_cast<size_t>(ly)];
      for (int x = v.spans.x0[static_cast<size_t>(y)]; x < v.spans.x1[static_cast<size_t>(y)]; ++x) {
        if (!last.Contains(x, y)) v.plane[static_cast<size_t>(y) * W + x] = from[std::clamp(x, lx0, lx1 - 1)];
      }
    });
    im.pool.Run(g.height(), [&](int row, int) {
      const int y = g.y0 + row;
      SelfWindow sw;
      for (int x = v.spans.x0[static_cast<size_t>(y)]; x < v.spans.x1[static_cast<size_t>(y)]; ++x) {
        const size_t i = static_cast<size_t>(y) * W + x;
        if (!valid_at(v.plane[i], static_cast<float>(x), static_cast<float>(y))) {
          const float d = std::clamp(v.plane[i].At(static_cast<float>(x), static_cast<float>(y)), dmin, dmax);
          v.plane[i] = Plane{0.0f, 0.0f, d};
        }
        prepare_total(cp, v, x, y, &sw);
        v.cost[i] = cost(v, other, x, y, v.plane[i], sw, kNoBound);
        if (!still) continue;
        if (!last.Contains(x, y)) {
          v.change[i] = 3.0e38f;  // new to the region: always visited
          continue;
        }
        // The pixel's window and its match's in the other view (the cost's
        // inputs): both unchanged, so is the best plane. Each window's
        // largest change of a sample, not the mean: an edge moving a pixel
        // changes a few samples a lot (with means, 1.1 lost the site's
        // masks 0.016 of IoU; docs/stereo.md). The two averaged.
        const int xo = std::clamp(
            static_cast<int>(std::lround(static_cast<float>(x) + v.sign * v.plane[i].At(static_cast<float>(x), static_cast<float>(y)))),
            0, W - 1);
#ifdef HOLO_PM_X86
        if (avx2) {
          v.change[i] = 0.5f * (WindowChangeAvx2(v, x, y, cp) + WindowChangeAvx2(other, xo, y, cp));
          continue;
        }
#endif
        v.change[i] = 0.5f * (WindowChange(v, x, y, cp) + WindowChange(other, xo, y, cp));
      }
    });
    if (!still) return;
    // The view's noise level: the median change of its pixels outside the
    // region's bounds (every 4th of every 4th row: what is not the person
    // has not moved). It starts at 0 and rises by at most 20 % + 0.25 grey
    // levels per Compute (reaching a camera's noise in ~10 frames), so that
    // a view that moves as a whole (from the start, or a light switched on)
    // does not lift the threshold with it. Too little outside (under 1/16
    // of the image): nothing is left alone.
    std::vector<float>& cs = im.change_scratch;
    cs.clear();
    for (int y = 2; y < H; y += 4)
      for (int x = 2; x < W; x += 4)
        if (!g.Contains(x, y)) cs.push_back(WindowChange(v, x, y, cp));
    if (cs.size() * 16 < static_cast<size_t>(W / 4) * static_cast<size_t>(H / 4)) return;
    std::nth_element(cs.begin(), cs.begin() + static_cast<std::ptrdiff_t>(cs.size() / 2), cs.end());
    float& level = im.still_level[v.sign < 0 ? 0 : 1];
    level = std::min(cs[cs.size() / 2], 1.2f * level + 0.25f);
    const float below = o.temporal_still * level;
    for (int y = g.y0; y < g.y1; ++y)
      for (int x = v.spans.x0[static_cast<size_t>(y)]; x < v.spans.x1[static_cast<size_t>(y)]; ++x) {
        const size_t i = static_cast<size_t>(y) * W + x;
        v.settled[i] = v.change[i] <= below;
      }
  };
  int iterations = o.iterations;
  int step_index = 0;
  const int refine_per_sweep = temporal ? o.temporal_refine_per_sweep : o.refine_per_sweep;
  // PatchMatchOptions::light_right_view: set below where the planes start
  // from the coarse level's or the last Compute's.
  bool light_right = false;
  if (temporal) {
    init_from_last(L, R, im.last_lspans);
    if (!im.last_right.empty()) {
      init_from_last(R, L, im.last_rspans);
    } else {
      init(R, L, 2);
    }
    iterations = o.temporal_iterations;
    step_index = o.temporal_refine_start;
    light_right = o.light_right_view;
  } else if (from_coarse) {
    if (!im.coarse) {
      PatchMatchOptions co = o;
      co.coarse_levels = o.coarse_levels - 1;
      co.min_disparity = o.min_disparity * 0.5f;
      co.max_disparity = std::max(o.max_disparity * 0.5f, co.min_disparity + 2.0f);
      co.lr_max_diff = -1.0f;  // the full-resolution level checks
      co.temporal = false;     // it runs only when the full resolution does not start from its last planes
      co.final_window_step = 0;  // the full resolution's last pass follows
      HOLO_ASSIGN_OR_RETURN(im.coarse, PatchMatchStereo::Create(co));
    }
    HalveImage(left, &im.coarse_left);
    HalveImage(right, &im.coarse_right);
    // The halved region, one coarse pixel wider on each side, so that every
    // full-resolution pixel of both views finds its coarse pixel inside the
    // coarse views' regions.
    const int cw = im.coarse_left.width(), ch = im.coarse_left.height();
    RowSpans creg;  // coarse row cy: the full rows 2·cy − 2 … 2·cy + 3, halved, one coarse pixel wider
    creg.x0.assign(static_cast<size_t>(ch), 0);
    creg.x1.assign(static_cast<size_t>(ch), 0);
    for (int cy = 0; cy < ch; ++cy) {
      int a = cw, e = 0;
      for (int y = std::max(0, 2 * cy - 2); y <= std::min(H - 1, 2 * cy + 3); ++y) {
        if (L.spans.x1[static_cast<size_t>(y)] <= L.spans.x0[static_cast<size_t>(y)]) continue;
        a = std::min(a, std::max(0, L.spans.x0[static_cast<size_t>(y)] / 2 - 1));
        e = std::max(e, std::min(cw, (L.spans.x1[static_cast<size_t>(y)] + 1) / 2 + 1));
      }
      if (e > a) {
        creg.x0[static_cast<size_t>(cy)] = a;
        creg.x1[static_cast<size_t>(cy)] = e;
      }
    }
    const PatchMatchOptions& co = im.coarse->options();
    const float cmax = dmax >= o.max_disparity ? co.max_disparity : std::max(dmax * 0.5f, co.min_disparity + 2.0f);
    HOLO_RETURN_IF_ERROR(im.coarse->Compute(im.coarse_left, im.coarse_right, creg, cmax, &im.coarse_disparity));
    init_from_coarse(L, R, im.coarse->impl_->left);
    init_from_coarse(R, L, im.coarse->impl_->right);
    iterations = o.fine_iterations;
    step_index = o.fine_refine_start;
    light_right = o.light_right_view;
  } else {
    init(L, R, 1);
    init(R, L, 2);
  }

  auto refine = [&](View& v, const View& other, int x, int y, uint64_t pass, float scale, const SelfWindow& sw) {
    const size_t i = static_cast<size_t>(y) * W + x;
    for (int k = 0; k < refine_per_sweep; ++k) {
      const uint64_t h = rng(pass, x, y, static_cast<uint64_t>(k) + 1);
      const float s = scale * std::ldexp(1.0f, -k);
      const Plane& cur = v.plane[i];
      const float xf = static_cast<float>(x), yf = static_cast<float>(y);
      const float d = std::clamp(cur.At(xf, yf) + Sym(h, 0) * 0.25f * range * s, dmin, dmax);
      float nx, ny, nz;
      normal_of(cur, &nx, &ny, &nz);
      nx += Sym(h, 21) * s;
      ny += Sym(h, 42) * s;
      nz += Sym(Mix(h), 0) * s;
      const float inv = 1.0f / std::sqrt(nx * nx + ny * ny + nz * nz + 1e-12f);
      try_plane(v, other, x, y, make_plane(xf, yf, d, nx * inv, ny * inv, nz * inv), sw);
    }
  };
  // The other view's planes, converted and offered to the pixels they land on
  // (rows are independent in a rectified pair: parallel over rows).
  auto scatter = [&](View& v, const View& other) {
    const ImageRect& g = v.region;  // the other view's spans are on the same rows
    im.pool.Run(g.height(), [&](int row, int) {
      const int y = g.y0 + row;
      const size_t ro = static_cast<size_t>(y) * W;
      const int x0 = v.spans.x0[static_cast<size_t>(y)], x1 = v.spans.x1[static_cast<size_t>(y)];
      std::fill(v.has_proposal.begin() + ro + x0, v.has_proposal.begin() + ro + x1, 0);
      for (int x = other.spans.x0[static_cast<size_t>(y)]; x < other.spans.x1[static_cast<size_t>(y)]; ++x) {
        const Plane& p = other.plane[ro + x];
        const float d = p.At(static_cast<float>(x), static_cast<float>(y));
        const int tx = static_cast<int>(std::lround(static_cast<float>(x) + other.sign * d));
        if (tx < x0 || tx >= x1) continue;
        const float den = 1.0f + other.sign * p.a;
        if (std::abs(den) < 1e-3f) continue;
        const Plane q{p.a / den, p.b / den, p.c / den};
        // Several pixels may land on one: the nearest surface (largest disparity) wins.
        if (v.has_proposal[ro + tx] &&
            v.proposal[ro + tx].At(static_cast<float>(tx), static_cast<float>(y)) >= d)
          continue;
        v.proposal[ro + tx] = q;
        v.has_proposal[ro + tx] = 1;
      }
    });
  };

  constexpr int kColumnBlock = 16;
  for (int it = 0; it < iterations; ++it) {
    const bool forward = it % 2 == 0;
    for (int vi = 0; vi < 2; ++vi) {
      View& v = vi == 0 ? L : R;
      const View& other = vi == 0 ? R : L;
      const ImageRect& g = v.region;
      const int gh = g.height();
      const int column_blocks = (g.width() + kColumnBlock - 1) / kColumnBlock;
      const uint64_t pass = static_cast<uint64_t>(it) * 8 + static_cast<uint64_t>(vi) * 4 + 16;
      scatter(v, other);
      const int per_sweep = std::max(1, refine_per_sweep);
      const float scale_h = std::ldexp(1.0f, -step_index);
      const float scale_v = std::ldexp(1.0f, -(step_index + per_sweep));
      // Horizontal sweep: view proposal, left (or right) neighbour, refinement
      // (none in a light right view).
      const bool light = light_right && vi == 1;
      im.pool.Run(gh, [&](int row, int) {
        const int y = g.y0 + row;
        const size_t ro = static_cast<size_t>(y) * W;
        const int x0 = v.spans.x0[static_cast<size_t>(y)], x1 = v.spans.x1[static_cast<size_t>(y)];
        SelfWindow sw;
        for (int k = 0; k < x1 - x0; ++k) {
          const int x = forward ? x0 + k : x1 - 1 - k;
          if (v.settled[ro + x]) continue;
          prepare(v, x, y, &sw);
          if (v.has_proposal[ro + x]) try_plane(v, other, x, y, v.proposal[ro + x], sw);
          if (k > 0) try_plane(v, other, x, y, v.plane[ro + (forward ? x - 1 : x + 1)], sw);
          if (!light) refine(v, other, x, y, pass, scale_h, sw);
        }
      });
      if (light) continue;
      // Vertical sweep over blocks of columns.
      im.pool.Run(column_blocks, [&](int blk, int) {
        const int x0 = g.x0 + blk * kColumnBlock, x1 = std::min(g.x1, x0 + kColumnBlock);
        SelfWindow sw;
        for (int k = 1; k < gh; ++k) {
          const int y = forward ? g.y0 + k : g.y1 - 1 - k;
          const int yn = forward ? y - 1 : y + 1;
          const int xa = std::max(x0, v.spans.x0[static_cast<size_t>(y)]), xe = std::min(x1, v.spans.x1[static_cast<size_t>(y)]);
          for (int x = xa; x < xe; ++x) {
            if (v.settled[static_cast<size_t>(y) * W + x]) continue;
            prepare(v, x, y, &sw);
            if (v.spans.Contains(x, yn)) try_plane(v, other, x, y, v.plane[static_cast<size_t>(yn) * W + x], sw);
            refine(v, other, x, y, pass + 1, scale_v, sw);
          }
        }
      });
    }
    step_index += 2 * std::max(1, refine_per_sweep);
  }

  // The dense last pass (PatchMatchOptions::final_window_step): each left
  // pixel's plane moved along d only, to the minimum of a V through its costs
  // in the denser window at d and d ± final_step_px; the best of the four
  // planes is kept.
  if (o.final_window_step > 0) {
    CostParams fcp = cp;
    fcp.step = o.final_window_step;
    const ImageRect& g = L.region;
    im.pool.Run(g.height(), [&](int row, int) {
      const int y = g.y0 + row;
      SelfWindow sw;
      for (int x = L.spans.x0[static_cast<size_t>(y)]; x < L.spans.x1[static_cast<size_t>(y)]; ++x) {
        const size_t i = static_cast<size_t>(y) * W + x;
        if (L.settled[i]) continue;  // its plane had the dense pass last time
        prepare_total(fcp, L, x, y, &sw);  // (the next Compute recomputes wtot for its window)
        auto fcost = [&](const Plane& p, float bound) { return cost_with(fcp, L, R, x, y, p, sw, bound); };
        const float xf = static_cast<float>(x), yf = static_cast<float>(y);
        const float h = o.final_step_px;
        const Plane centre = L.plane[i];
        Plane best = centre;
        const float centre_cost = fcost(centre, kNoBound);
        float best_cost = centre_cost;
        // Costs at d − h and d + h (an invalid side: no parabola).
        float side[2] = {kNoBound, kNoBound};
        for (int k = 0; k < 2; ++k) {
          Plane q = centre;
          q.c += k == 0 ? -h : h;
          if (!valid_at(q, xf, yf)) continue;
          side[k] = fcost(q, kNoBound);
          if (side[k] < best_cost) {
            best_cost = side[k];
            best = q;
          }
        }
        // The minimum of a V through the three costs (equiangular fit: exact
        // for a cost linear in |d − d*| near the minimum, as absolute
        // differences are; a parabola's vertex would move half as far).
        const float rise = std::max(side[0], side[1]) - centre_cost;
        if (side[0] < kNoBound && side[1] < kNoBound && centre_cost <= std::min(side[0], side[1]) && rise > 1e-6f) {
          Plane q = centre;
          q.c += std::clamp(0.5f * h * (side[0] - side[1]) / rise, -h, h);
          if (valid_at(q, xf, yf)) {
            const float c = fcost(q, best_cost);
            if (c < best_cost) {
              best_cost = c;
              best = q;
            }
          }
        }
        L.plane[i] = best;
        L.cost[i] = best_cost;
      }
    });
  }

  // The edge pass (PatchMatchOptions::edge_shift_px): planes read from a
  // copy, so rows in parallel see the planes before the pass.
  if (o.edge_shift_px > 0 && o.final_window_step > 0) {
    CostParams fcp = cp;
    fcp.step = o.final_window_step;
    const ImageRect& g = L.region;
    im.edge_planes.assign(L.plane.begin(), L.plane.end());
    const std::vector<Plane>& before = im.edge_planes;
    const int r = o.edge_probe_px, sh = o.edge_shift_px;
    im.pool.Run(g.height(), [&](int row, int) {
      const int y = g.y0 + row;
      SelfWindow sw;
      const float yf = static_cast<float>(y);
      for (int x = L.spans.x0[static_cast<size_t>(y)]; x < L.spans.x1[static_cast<size_t>(y)]; ++x) {
        const size_t i = static_cast<size_t>(y) * W + x;
        const float xf = static_cast<float>(x);
        // The pixel's own plane, then the probes: the planes r pixels away
        // (inside the spans).
        Plane cand[5] = {before[i]};
        int nc = 1;
        float dlo = before[i].At(xf, yf), dhi = dlo;
        auto probe = [&](int px, int py) {
          if (!L.spans.Contains(px, py)) return;
          const Plane& q = before[static_cast<size_t>(py) * W + px];
          const float d = q.At(static_cast<float>(px), static_cast<float>(py));
          dlo = std::min(dlo, d);
          dhi = std::max(dhi, d);
          cand[nc++] = q;
        };
        probe(x - r, y);
        probe(x + r, y);
        probe(x, y - r / 2);
        probe(x, y + r / 2);
        if (!(dhi - dlo > o.edge_min_jump * dhi)) continue;
        // Another plane must beat the own plane's best window by the margin.
        float own_cost = kNoBound, best_cost = kNoBound;
        Plane best_other = before[i];
        const float own = L.IRow(y)[x];  // the shifted windows weigh by the pixel's own intensity
        for (int s = -sh; s <= sh; s += sh) {
          const int xs = std::clamp(x + s, 0, W - 1);
          float wt;
#ifdef HOLO_PM_X86
          if (avx2) {
            PrepareWindowAvx2(L, xs, y, fcp, own, &sw);
            wt = WindowTotalAvx2(fcp, sw);
          } else
#endif
          {
            wt = WindowWeight(L, xs, y, fcp, own);
          }
          own_cost = std::min(own_cost, cost_weighted(fcp, L, R, xs, y, cand[0], sw, kNoBound, own, wt));
          for (int k = 1; k < nc; ++k) {
            if (!valid_at(cand[k], xf, yf)) continue;
            const float c = cost_weighted(fcp, L, R, xs, y, cand[k], sw, best_cost, own, wt);
            if (c < best_cost) {
              best_cost = c;
              best_other = cand[k];
            }
          }
        }
        if (best_cost < (1.0f - o.edge_margin) * own_cost) L.plane[i] = best_other;
      }
    });
  }

  // Disparities and the left-right check (0 outside the spans).
  im.pool.Run(H, [&](int y, int) {
    const size_t ro = static_cast<size_t>(y) * W;
    float* rd = im.right_disparity.row(y);
    float* out = disparity->row(y);
    std::fill(rd, rd + W, 0.0f);
    std::fill(out, out + W, 0.0f);
    for (int x = R.spans.x0[static_cast<size_t>(y)]; x < R.spans.x1[static_cast<size_t>(y)]; ++x)
      rd[x] = R.plane[ro + x].At(static_cast<float>(x), static_cast<float>(y));
    for (int x = L.spans.x0[static_cast<size_t>(y)]; x < L.spans.x1[static_cast<size_t>(y)]; ++x) {
      const float d = L.plane[ro + x].At(static_cast<float>(x), static_cast<float>(y));
      bool ok = d >= dmin && d <= dmax && d > 0.0f;
      if (ok && o.lr_max_diff >= 0.0f) {
        const int xr = static_cast<int>(std::lround(static_cast<float>(x) - d));
        ok = R.spans.Contains(xr, y) && std::abs(rd[xr] - d) <= o.lr_max_diff;
      }
      out[x] = ok ? d : 0.0f;
    }
  });
  im.have_last = true;
  im.last_temporal = temporal;
  if (im.last_w != W || im.last_h != H) im.still_level[0] = im.still_level[1] = 0.0f;  // another camera
  im.last_w = W;
  im.last_h = H;
  im.last_left = lreg;
  im.last_right = R.region;
  im.last_lspans = L.spans;
  im.last_rspans = R.spans;
  return OkStatus();
}

}  // namespace holo
