#include "server/segment/segmenter.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>

#include <Eigen/Core>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define HOLO_SEGMENT_AVX2 1
#endif

#include "common/cpu_features.h"
#include "common/worker_pool.h"

namespace holo {
namespace {

std::string SizeString(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

Status CheckPositive(const char* name, float v) {
  if (!(v > 0.0f) || !std::isfinite(v)) return InvalidArgument(std::string(name) + " must be > 0, got " + std::to_string(v));
  return OkStatus();
}
Status CheckNonNegative(const char* name, float v) {
  if (!(v >= 0.0f) || !std::isfinite(v))
    return InvalidArgument(std::string(name) + " must be >= 0, got " + std::to_string(v));
  return OkStatus();
}

// HSV of an 8-bit RGB pixel as (a, b, v): the hexcone chroma vector
// (R − (G+B)/2, √3/2·(G − B)) — angle ≈ hue, length ≈ max − min — divided
// by max + dark_level, which is the saturation S·(cos H, sin H) for bright
// pixels and shrinks towards grey where the hue of dark pixels is noise;
// v = max / 255. Scaling R, G, B together (shading, shadow) keeps a and b.
struct Hsv {
  float a, b, v;
};
// `inv_table[m]` = 1 / (m + dark_level).
inline Hsv ToHsv(int r, int g, int b, const float* inv_table) {
  const int m = std::max(r, std::max(g, b));
  const float inv = inv_table[m];
  Hsv h;
  h.a = (static_cast<float>(r) - 0.5f * static_cast<float>(g + b)) * inv;
  h.b = 0.8660254f * static_cast<float>(g - b) * inv;
  h.v = static_cast<float>(m) * (1.0f / 255.0f);
  return h;
}

inline uint8_t Luma(int r, int g, int b) { return static_cast<uint8_t>((77 * r + 150 * g + 29 * b) >> 8); }

// Logistic function through a fast 2^x (Schraudolph-style exponent bits
// plus a cubic for the fraction; relative error of exp < 3e-4), several times faster
// than std::exp and plenty for mean-field probabilities.
inline float FastExp2(float x) {
  x = std::clamp(x, -60.0f, 60.0f);
  const float fl = std::floor(x);
  const float f = x - fl;
  const float p = 1.0f + f * (0.6951786f + f * (0.2261487f + f * 0.0781455f));
  const int32_t bits = (static_cast<int32_t>(fl) + 127) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof(scale));
  return scale * p;
}
inline float Sigmoid(float x) { return 1.0f / (1.0f + FastExp2(-1.4426950f * x)); }

// Background model of a pod's pixels, prepared for the unary term; one
// array per field so that eight pixels load as one vector.
struct BgModel {
  // Background depth minus the margin τ, metres; negative when the empty
  // room had no depth here.
  std::vector<float> depth_offset_m;
  std::vector<float> a, b, v;
  std::vector<float> inv_var_ab, inv_var_v;

  void Resize(size_t n) {
    for (auto* f : {&depth_offset_m, &a, &b, &v, &inv_var_ab, &inv_var_v}) f->resize(n);
  }
};

}  // namespace

Status SegmenterOptions::Check() const {
  HOLO_RETURN_IF_ERROR(CheckPositive("depth_sigma_m", depth_sigma_m));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("depth_margin_min_m", depth_margin_min_m));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("depth_margin_stddevs", depth_margin_stddevs));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("depth_max_logodds", depth_max_logodds));
  HOLO_RETURN_IF_ERROR(CheckPositive("depth_edge_m", depth_edge_m));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("depth_edge_max_logodds", depth_edge_max_logodds));
  if (depth_edge_band_px < 0 || depth_edge_band_px > 32)
    return InvalidArgument("depth_edge_band_px must be in [0, 32], got " + std::to_string(depth_edge_band_px));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("depth_noise_at_1m_m", depth_noise_at_1m_m));
  HOLO_RETURN_IF_ERROR(CheckPositive("chroma_sigma", chroma_sigma));
  HOLO_RETURN_IF_ERROR(CheckPositive("value_sigma", value_sigma));
  HOLO_RETURN_IF_ERROR(CheckPositive("dark_level", dark_level));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("colour_threshold", colour_threshold));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("colour_scale", colour_scale));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("colour_max_logodds", colour_max_logodds));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("colour_bg_max_logodds", colour_bg_max_logodds));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("depth_weight", depth_weight));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("colour_weight", colour_weight));
  if (!std::isfinite(prior_logodds) || !std::isfinite(depth_appeared_logodds))
    return InvalidArgument("prior_logodds and depth_appeared_logodds must be finite");
  if (crf_iterations < 0 || crf_iterations > 20)
    return InvalidArgument("crf_iterations must be in 0..20, got " + std::to_string(crf_iterations));
  if (downsample != 1 && downsample != 2 && downsample != 4)
    return InvalidArgument("downsample must be 1, 2 or 4, got " + std::to_string(downsample));
  if (!(grid_spatial_px >= 1.0f && grid_spatial_px <= 256.0f))
    return InvalidArgument("grid_spatial_px must be in [1, 256], got " + std::to_string(grid_spatial_px));
  if (!(grid_range >= 1.0f && grid_range <= 256.0f))
    return InvalidArgument("grid_range must be in [1, 256], got " + std::to_string(grid_range));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("crf_weight", crf_weight));
  if (threads < 0 || threads > 256) return InvalidArgument("threads must be in 0..256, got " + std::to_string(threads));
  return OkStatus();
}

// ---------------------------------------------------------------------------
// Per pod state: background sums, model and every per-frame buffer.

namespace {

struct PodState {
  PodCalibration calib;
  bool registered = true;
  int w = 0, h = 0;  // depth camera

  // Background sums.
  std::vector<uint16_t> depth_count;
  std::vector<double> depth_sum, depth_sum2;  // metres
  std::vector<float> col_sum;                 // a, b, v, a²+b², v² per pixel
  BgModel model;
  std::vector<float> bg_depth_m;  // mean background depth (0 = none), for colour registration

  // Non-registered pods: unit-depth rays of the depth camera, and colour
  // sampled into the depth camera.
  std::vector<Eigen::Vector3f> rays;
  ImageRgb8 colour_in_depth;

  // Per frame buffers.
  ImageFloat unary;
  std::vector<uint8_t> band, band_tmp, band_row;  // SegmenterOptions::depth_edge_band_px
  std::vector<uint8_t> luma;
  // CRF at the downsampled resolution.
  int dw = 0, dh = 0;
  std::vector<float> unary_ds, q_ds;
  std::vector<uint8_t> luma_ds;
  std::vector<int32_t> splat_cell;  // nearest grid cell of each downsampled pixel
  // Bilateral grid: (Σq, Σ1) per cell, x fastest, 1-cell zero pad on every side.
  int gx = 0, gy = 0, gz = 0;
  std::vector<float> grid, grid_tmp;
  // Slice tables: grid column/row (with pad) and fraction per image column/row.
  std::vector<int32_t> col_cell_ds, row_cell_ds, col_cell, row_cell;
  std::vector<float> col_frac_ds, row_frac_ds, col_frac, row_frac;
};

// Colour of `frame` seen from the depth camera of `pod`: per depth pixel the
// colour (bilinear) where its 3-D point projects in the colour camera. The
// point's depth is the current one, or the background's where the current
// one is invalid or within `near_bg_m` of the background — then the
// background samples the same colour pixels every frame despite depth noise.
void RegisterColour(PodState* s, const RgbdFrame& frame, float near_bg_m) {
  if (s->colour_in_depth.width() != s->w || s->colour_in_depth.height() != s->h) s->colour_in_depth.Resize(s->w, s->h);
  const CameraModel colour_cam{s->calib.color, Pose::Identity()};
  const Pose& c_from_d = s->calib.color_from_depth;
  const ImageRgb8& src = frame.color;
  const bool have_bg = !s->bg_depth_m.empty();
  for (int y = 0; y < s->h; ++y) {
    for (int x = 0; x < s->w; ++x) {
      const size_t i = static_cast<size_t>(y) * s->w + x;
      float z = frame.depth.at(x, y) * 0.001f;
      const float bg = have_bg ? s->bg_depth_m[i] : 0.0f;
      if (bg > 0 && (z <= 0 || std::abs(z - bg) < near_bg_m)) z = bg;
      if (z <= 0) z = 2.0f;
      const Eigen::Vector3f p = c_from_d * (s->rays[i] * z);
      Eigen::Vector2f px;
      uint8_t* out = &s->colour_in_depth.at(x, y, 0);
      out[0] = out[1] = out[2] = 0;
      if (!colour_cam.ProjectCamera(p, &px)) continue;
      const int x0 = static_cast<int>(std::floor(px.x())), y0 = static_cast<int>(std::floor(px.y()));
      if (x0 < 0 || y0 < 0 || x0 + 1 >= src.width() || y0 + 1 >= src.height()) continue;
      const float fx = px.x() - x0, fy = px.y() - y0;
      const uint8_t* c00 = &src.at(x0, y0, 0);
      const uint8_t* c10 = c00 + 3;
      const uint8_t* c01 = &src.at(x0, y0 + 1, 0);
      const uint8_t* c11 = c01 + 3;
      for (int c = 0; c < 3; ++c) {
        const float v = (1 - fy) * ((1 - fx) * c00[c] + fx * c10[c]) + fy * ((1 - fx) * c01[c] + fx * c11[c]);
        out[c] = static_cast<uint8_t>(v + 0.5f);
      }
    }
  }
}

void BlurLines(float* data, int num_lines, int line_stride, int n, int elem_stride, int elem_size, float* tmp) {
  // [1 2 1]/4 along lines of `n` elements (first and last are the zero pad
  // and stay untouched). `tmp` holds one element of `elem_size` floats.
  for (int l = 0; l < num_lines; ++l) {
    float* line = data + static_cast<size_t>(l) * line_stride;
    std::copy(line, line + elem_size, tmp);  // previous (original) element
    for (int i = 1; i < n - 1; ++i) {
      float* cur = line + static_cast<size_t>(i) * elem_stride;
      const float* next = cur + elem_stride;
      for (int k = 0; k < elem_size; ++k) {
        const float c = cur[k];
        cur[k] = 0.25f * tmp[k] + 0.5f * c + 0.25f * next[k];
        tmp[k] = c;
      }
    }
  }
}

}  // namespace

struct Segmenter::Impl {
  explicit Impl(int threads) : pool(threads) {}
  WorkerPool pool;
  std::array<float, 256> inv_table;  // 1 / (m + dark_level)
  std::vector<PodState> pods;
  int background_frames = 0;
  bool has_model = false;
  std::vector<SegmentDebug>* debug = nullptr;

  Status CheckFrames(const RgbdFrameSet& frames, const char* what) const;
  void Accumulate(PodState* s, const RgbdFrame& f);
  void Finish(PodState* s, const SegmenterOptions& o);
  void SegmentPod(PodState* s, RgbdFrame* f, const SegmenterOptions& o, SegmentDebug* dbg);
  void SetupGrid(PodState* s, const SegmenterOptions& o);
  void SplatBlur(PodState* s);
};

Segmenter::Segmenter(const Rig& rig, SegmenterOptions options)
    : options_(options), impl_(std::make_unique<Impl>(options.threads)) {
  const Status st = options_.Check();
  HOLO_CHECK_MSG(st.ok(), st.ToString());
  for (int m = 0; m < 256; ++m) impl_->inv_table[m] = 1.0f / (static_cast<float>(m) + options_.dark_level);
  impl_->pods.resize(rig.pods.size());
  for (size_t i = 0; i < rig.pods.size(); ++i) {
    PodState& s = impl_->pods[i];
    s.calib = rig.pods[i];
    s.registered = s.calib.IsRegistered();
    s.w = s.calib.depth.width;
    s.h = s.calib.depth.height;
    const size_t n = static_cast<size_t>(s.w) * s.h;
    if (!s.registered) {
      const CameraModel depth_cam{s.calib.depth, Pose::Identity()};
      s.rays.resize(n);
      for (int y = 0; y < s.h; ++y)
        for (int x = 0; x < s.w; ++x)
          s.rays[static_cast<size_t>(y) * s.w + x] =
              depth_cam.UnprojectCamera(Eigen::Vector2f(static_cast<float>(x), static_cast<float>(y)), 1.0f);
    }
    s.unary.Resize(s.w, s.h);
    s.luma.resize(n);
    impl_->SetupGrid(&s, options_);
  }
}

Segmenter::~Segmenter() = default;

bool Segmenter::has_background() const { return impl_->has_model; }

Status Segmenter::Impl::CheckFrames(const RgbdFrameSet& frames, const char* what) const {
  if (frames.frames.size() != pods.size())
    return InvalidArgument(std::string(what) + ": frame set has " + std::to_string(frames.frames.size()) +
                           " pods, the rig has " + std::to_string(pods.size()));
  for (size_t i = 0; i < pods.size(); ++i) {
    const RgbdFrame& f = frames.frames[i];
    const PodState& s = pods[i];
    if (f.depth.width() != s.w || f.depth.height() != s.h)
      return InvalidArgument(std::string(what) + ": pod " + std::to_string(i) + " depth is " +
                             SizeString(f.depth.width(), f.depth.height()) + ", the rig says " + SizeString(s.w, s.h));
    if (f.color.width() != s.calib.color.width || f.color.height() != s.calib.color.height)
      return InvalidArgument(std::string(what) + ": pod " + std::to_string(i) + " colour is " +
                             SizeString(f.color.width(), f.color.height()) + ", the rig says " +
                             SizeString(s.calib.color.width, s.calib.color.height));
  }
  return OkStatus();
}

Status Segmenter::AddBackgroundFrame(const RgbdFrameSet& frames) {
  HOLO_RETURN_IF_ERROR(impl_->CheckFrames(frames, "AddBackgroundFrame"));
  Impl* impl = impl_.get();
  const RgbdFrameSet* in = &frames;
  impl->pool.ParallelFor(static_cast<int>(impl->pods.size()),
                         [&](int i) { impl->Accumulate(&impl->pods[i], in->frames[i]); });
  ++impl->background_frames;
  return OkStatus();
}

void Segmenter::Impl::Accumulate(PodState* s, const RgbdFrame& f) {
  const size_t n = static_cast<size_t>(s->w) * s->h;
  if (s->depth_count.size() != n) {
    s->depth_count.assign(n, 0);
    s->depth_sum.assign(n, 0.0);
    s->depth_sum2.assign(n, 0.0);
    s->col_sum.assign(n * 5, 0.0f);
  }
  const uint8_t* rgb = f.color.data();
  if (!s->registered) {
    RegisterColour(s, f, 0.0f);
    rgb = s->colour_in_depth.data();
  }
  const uint16_t* d = f.depth.data();
  for (size_t i = 0; i < n; ++i) {
    if (d[i] > 0) {
      const double z = d[i] * 0.001;
      ++s->depth_count[i];
      s->depth_sum[i] += z;
      s->depth_sum2[i] += z * z;
    }
    const Hsv c = ToHsv(rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2], inv_table.data());
    float* cs = &s->col_sum[5 * i];
    cs[0] += c.a;
    cs[1] += c.b;
    cs[2] += c.v;
    cs[3] += c.a * c.a + c.b * c.b;
    cs[4] += c.v * c.v;
  }
}

Status Segmenter::FinishBackground() {
  if (impl_->background_frames == 0) return InvalidArgument("FinishBackground: no background frame was added");
  Impl* impl = impl_.get();
  const SegmenterOptions& o = options_;
  impl->pool.ParallelFor(static_cast<int>(impl->pods.size()), [&](int i) { impl->Finish(&impl->pods[i], o); });
  impl->background_frames = 0;
  impl->has_model = true;
  return OkStatus();
}

void Segmenter::Impl::Finish(PodState* s, const SegmenterOptions& o) {
  const size_t n = static_cast<size_t>(s->w) * s->h;
  const double frames = background_frames;  // colour means
  s->model.Resize(n);
  s->bg_depth_m.assign(n, 0.0f);
  BgModel& m = s->model;
  const float var_ab0 = o.chroma_sigma * o.chroma_sigma, var_v0 = o.value_sigma * o.value_sigma;
  for (size_t i = 0; i < n; ++i) {
    const int c = s->depth_count[i];
    if (c > 0) {
      // Pixels valid in only some frames (grazing surfaces, far floor) keep
      // the mean of their valid samples; the noise floor covers the few-sample variance.
      const double mean = s->depth_sum[i] / c;
      const double var = c >= 3 ? std::max(0.0, s->depth_sum2[i] / c - mean * mean) : 0.0;
      const double noise = o.depth_noise_at_1m_m * mean * mean;
      const double tau = o.depth_margin_min_m + o.depth_margin_stddevs * std::sqrt(std::max(var, noise * noise));
      m.depth_offset_m[i] = static_cast<float>(mean - tau);
      // A surface within the margin of the camera: keep it a (tiny) valid offset.
      if (m.depth_offset_m[i] <= 0) m.depth_offset_m[i] = 1e-4f;
      s->bg_depth_m[i] = static_cast<float>(mean);
    } else {
      m.depth_offset_m[i] = -1.0f;
    }
    const float* cs = &s->col_sum[5 * i];
    const float inv = static_cast<float>(1.0 / frames);
    m.a[i] = cs[0] * inv;
    m.b[i] = cs[1] * inv;
    m.v[i] = cs[2] * inv;
    const float var_ab = std::max(0.0f, cs[3] * inv - m.a[i] * m.a[i] - m.b[i] * m.b[i]);
    const float var_v = std::max(0.0f, cs[4] * inv - m.v[i] * m.v[i]);
    m.inv_var_ab[i] = 1.0f / (var_ab0 + var_ab);
    m.inv_var_v[i] = 1.0f / (var_v0 + var_v);
  }
  // The sums are no longer needed.
  std::vector<uint16_t>().swap(s->depth_count);
  std::vector<double>().swap(s->depth_sum);
  std::vector<double>().swap(s->depth_sum2);
  std::vector<float>().swap(s->col_sum);
}

void Segmenter::Impl::SetupGrid(PodState* s, const SegmenterOptions& o) {
  const int f = o.downsample;
  s->dw = (s->w + f - 1) / f;
  s->dh = (s->h + f - 1) / f;
  const size_t nd = static_cast<size_t>(s->dw) * s->dh;
  s->unary_ds.resize(nd);
  s->q_ds.resize(nd);
  s->luma_ds.resize(nd);
  s->splat_cell.resize(nd);
  const float ss = o.grid_spatial_px, sr = o.grid_range;
  s->gx = static_cast<int>((s->w - 1) / ss) + 4;
  s->gy = static_cast<int>((s->h - 1) / ss) + 4;
  s->gz = static_cast<int>(255.0f / sr) + 4;
  const size_t cells = static_cast<size_t>(s->gx) * s->gy * s->gz;
  s->grid.assign(2 * cells, 0.0f);
  s->grid_tmp.assign(2 * static_cast<size_t>(s->gx) * s->gy, 0.0f);
  auto table = [](int n, int step, float offset, float scale, std::vector<int32_t>* cell, std::vector<float>* frac) {
    cell->resize(n);
    frac->resize(n);
    for (int i = 0; i < n; ++i) {
      const float g = (static_cast<float>(i * step) + offset) / scale;
      const int gi = static_cast<int>(g);
      (*cell)[i] = gi + 1;  // + pad
      (*frac)[i] = g - static_cast<float>(gi);
    }
  };
  const float centre = 0.5f * static_cast<float>(f - 1);  // full-res position of a downsampled pixel
  table(s->dw, f, centre, ss, &s->col_cell_ds, &s->col_frac_ds);
  table(s->dh, f, centre, ss, &s->row_cell_ds, &s->row_frac_ds);
  table(s->w, 1, 0.0f, ss, &s->col_cell, &s->col_frac);
  table(s->h, 1, 0.0f, ss, &s->row_cell, &s->row_frac);
}

// Splats q_ds into the grid at the nearest cells and blurs it.
void Segmenter::Impl::SplatBlur(PodState* s) {
  float* g = s->grid.data();
  std::fill(s->grid.begin(), s->grid.end(), 0.0f);
  const size_t nd = s->q_ds.size();
  for (size_t i = 0; i < nd; ++i) {
    float* c = g + 2 * static_cast<size_t>(s->splat_cell[i]);
    c[0] += s->q_ds[i];
    c[1] += 1.0f;
  }
  float tmp_elem[2];
  const int gx = s->gx, gy = s->gy, gz = s->gz;
  // x: lines are rows of (gx) cells.
  BlurLines(g, gy * gz, 2 * gx, gx, 2, 2, tmp_elem);
  // y: per z plane, lines along y are whole rows of 2·gx floats.
  for (int z = 0; z < gz; ++z)
    BlurLines(g + static_cast<size_t>(z) * 2 * gx * gy, 1, 0, gy, 2 * gx, 2 * gx, s->grid_tmp.data());
  // z: planes of 2·gx·gy floats; process in row chunks to bound the temporary.
  for (int y = 0; y < gy; ++y)
    BlurLines(g + static_cast<size_t>(y) * 2 * gx, 1, 0, gz, 2 * gx * gy, 2 * gx, s->grid_tmp.data());
}

namespace {

// Trilinear read of (Σq, Σ1) at a cell base and fractions; returns Σq/Σ1.
inline float SliceAt(const float* g, size_t base, float fx, float fy, float fz, size_t sy, size_t sz) {
  const float* c000 = g + 2 * base;
  const float* c010 = c000 + 2 * sy;
  const float* c001 = c000 + 2 * sz;
  const float* c011 = c001 + 2 * sy;
  const float wx0 = 1 - fx, wy0 = 1 - fy, wz0 = 1 - fz;
  const float w00 = wy0 * wz0, w10 = fy * wz0, w01 = wy0 * fz, w11 = fy * fz;
  float q = 0, n = 0;
  q += w00 * (wx0 * c000[0] + fx * c000[2]);
  n += w00 * (wx0 * c000[1] + fx * c000[3]);
  q += w10 * (wx0 * c010[0] + fx * c010[2]);
  n += w10 * (wx0 * c010[1] + fx * c010[3]);
  q += w01 * (wx0 * c001[0] + fx * c001[2]);
  n += w01 * (wx0 * c001[1] + fx * c001[3]);
  q += w11 * (wx0 * c011[0] + fx * c011[2]);
  n += w11 * (wx0 * c011[1] + fx * c011[3]);
  return n > 1e-6f ? q / n : 0.5f;
}

// The unary term's constants, from the options.
struct UnaryParams {
  explicit UnaryParams(const SegmenterOptions& o)
      : inv_sd(1.0f / o.depth_sigma_m),
        dmax(o.depth_max_logodds),
        cmax(o.colour_max_logodds),
        cmin(-o.colour_bg_max_logodds),
        wd(o.depth_weight),
        wc(o.colour_weight),
        appeared(std::clamp(o.depth_appeared_logodds, -o.depth_max_logodds, o.depth_max_logodds)),
        edge_mm(static_cast<int>(o.depth_edge_m * 1000.0f)),
        edge_cap(o.depth_edge_max_logodds),
        colour_scale(o.colour_scale),
        colour_threshold(o.colour_threshold),
        prior(o.prior_logodds) {}
  float inv_sd, dmax, cmax, cmin, wd, wc, appeared;
  int edge_mm;
  float edge_cap, colour_scale, colour_threshold, prior;
};

// The depth term of pixel i (valid depth only): in front of the background
// is foreground evidence; where the background had no depth, `appeared`.
inline float DepthLogOdds(const UnaryParams& p, const BgModel& m, const uint16_t* depth, size_t i) {
  const float off = m.depth_offset_m[i];
  return off < 0 ? p.appeared : std::clamp((off - depth[i] * 0.001f) * p.inv_sd, -p.dmax, p.dmax);
}

// Unary log-odds and luma of pixel i: colour distance to the background
// model plus the depth evidence (in front of the background: foreground);
// at a depth edge (a neighbour more than depth_edge_m away) the depth term
// is capped, since mixed pixels there lie between the two surfaces.
inline void UnaryAt(const UnaryParams& p, const BgModel& m, const uint8_t* rgb, const uint16_t* depth, int W, int H,
                    const float* inv_table, size_t i, float* L, uint8_t* luma, bool force_cap = false) {
  const int r = rgb[3 * i], g = rgb[3 * i + 1], b = rgb[3 * i + 2];
  luma[i] = Luma(r, g, b);
  const Hsv c = ToHsv(r, g, b, inv_table);
  const float da = c.a - m.a[i], db = c.b - m.b[i], dv = c.v - m.v[i];
  const float dist = std::sqrt((da * da + db * db) * m.inv_var_ab[i] + dv * dv * m.inv_var_v[i]);
  const float lc = std::clamp(p.colour_scale * (dist - p.colour_threshold), p.cmin, p.cmax);
  float ld = 0.0f;
  if (depth[i] > 0) {
    ld = DepthLogOdds(p, m, depth, i);
    if (ld > p.edge_cap && force_cap) {
      ld = p.edge_cap;
    } else if (ld > p.edge_cap) {
      const int x = static_cast<int>(i % W), y = static_cast<int>(i / W);
      const int d = depth[i];
      auto edge = [&](size_t j) { return depth[j] > 0 && std::abs(depth[j] - d) > p.edge_mm; };
      if ((x > 0 && edge(i - 1)) || (x + 1 < W && edge(i + 1)) || (y > 0 && edge(i - W)) ||
          (y + 1 < H && edge(i + W)))
        ld = p.edge_cap;
    }
  }
  L[i] = p.prior + p.wd * ld + p.wc * lc;
}

#if defined(HOLO_SEGMENT_AVX2)

// UnaryAt eight pixels at a time: the same operations in the same order (no
// FMA; the division is the table's), so the result is bit-identical. Pixels
// that may sit at a depth edge on the image border go through UnaryAt.
// Returns how many pixels
// it did (a multiple of 8, leaving the last 8 or fewer to the caller: the
// colour gather reads one byte past each pixel).
__attribute__((target("avx2"))) size_t UnaryAvx2(const UnaryParams& p, const BgModel& m, const uint8_t* rgb,
                                                 const uint16_t* depth, int W, int H, const float* inv_table,
                                                 float* L, uint8_t* luma) {
  const size_t n = static_cast<size_t>(W) * H;
  const __m256i lane3 = _mm256_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21);
  const __m256i byte = _mm256_set1_epi32(0xFF);
  const __m256 half = _mm256_set1_ps(0.5f), sqrt3_2 = _mm256_set1_ps(0.8660254f), inv255 = _mm256_set1_ps(1.0f / 255.0f);
  const __m256 scale = _mm256_set1_ps(p.colour_scale), thr = _mm256_set1_ps(p.colour_threshold);
  const __m256 cmin = _mm256_set1_ps(p.cmin), cmax = _mm256_set1_ps(p.cmax);
  const __m256 dmax = _mm256_set1_ps(p.dmax), ndmax = _mm256_set1_ps(-p.dmax), inv_sd = _mm256_set1_ps(p.inv_sd);
  const __m256 mm = _mm256_set1_ps(0.001f), appeared = _mm256_set1_ps(p.appeared), zero = _mm256_setzero_ps();
  const __m256 edge_cap = _mm256_set1_ps(p.edge_cap), prior = _mm256_set1_ps(p.prior);
  const __m256 wd = _mm256_set1_ps(p.wd), wc = _mm256_set1_ps(p.wc);
  const __m256i edge_mm = _mm256_set1_epi32(p.edge_mm);
  size_t i = 0;
  for (; i + 8 < n; i += 8) {
    const __m256i px = _mm256_i32gather_epi32(reinterpret_cast<const int*>(rgb + 3 * i), lane3, 1);
    const __m256i r = _mm256_and_si256(px, byte), g = _mm256_and_si256(_mm256_srli_epi32(px, 8), byte),
                  b = _mm256_and_si256(_mm256_srli_epi32(px, 16), byte);
    // Luma, (77 r + 150 g + 29 b) >> 8, packed to bytes.
    const __m256i y32 = _mm256_srli_epi32(
        _mm256_add_epi32(_mm256_add_epi32(_mm256_mullo_epi32(r, _mm256_set1_epi32(77)),
                                          _mm256_mullo_epi32(g, _mm256_set1_epi32(150))),
                         _mm256_mullo_epi32(b, _mm256_set1_epi32(29))),
        8);
    const __m128i y16 = _mm_packus_epi32(_mm256_castsi256_si128(y32), _mm256_extracti128_si256(y32, 1));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(luma + i), _mm_packus_epi16(y16, y16));
    // ToHsv.
    const __m256i mx = _mm256_max_epi32(r, _mm256_max_epi32(g, b));
    const __m256 inv = _mm256_i32gather_ps(inv_table, mx, 4);
    const __m256 rf = _mm256_cvtepi32_ps(r);
    const __m256 ca = _mm256_mul_ps(_mm256_sub_ps(rf, _mm256_mul_ps(half, _mm256_cvtepi32_ps(_mm256_add_epi32(g, b)))), inv);
    const __m256 cb = _mm256_mul_ps(_mm256_mul_ps(sqrt3_2, _mm256_cvtepi32_ps(_mm256_sub_epi32(g, b))), inv);
    const __m256 cv = _mm256_mul_ps(_mm256_cvtepi32_ps(mx), inv255);
    const __m256 da = _mm256_sub_ps(ca, _mm256_loadu_ps(&m.a[i])), db = _mm256_sub_ps(cb, _mm256_loadu_ps(&m.b[i])),
                 dv = _mm256_sub_ps(cv, _mm256_loadu_ps(&m.v[i]));
    const __m256 dist = _mm256_sqrt_ps(
        _mm256_add_ps(_mm256_mul_ps(_mm256_add_ps(_mm256_mul_ps(da, da), _mm256_mul_ps(db, db)), _mm256_loadu_ps(&m.inv_var_ab[i])),
                      _mm256_mul_ps(_mm256_mul_ps(dv, dv), _mm256_loadu_ps(&m.inv_var_v[i]))));
    const __m256 lc = _mm256_min_ps(_mm256_max_ps(_mm256_mul_ps(scale, _mm256_sub_ps(dist, thr)), cmin), cmax);
    // Depth.
    const __m256i d32 = _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(depth + i)));
    const __m256 valid = _mm256_castsi256_ps(_mm256_cmpgt_epi32(d32, _mm256_setzero_si256()));
    const __m256 off = _mm256_loadu_ps(&m.depth_offset_m[i]);
    const __m256 in_front = _mm256_min_ps(
        _mm256_max_ps(_mm256_mul_ps(_mm256_sub_ps(off, _mm256_mul_ps(_mm256_cvtepi32_ps(d32), mm)), inv_sd), ndmax), dmax);
    __m256 ld = _mm256_and_ps(valid, _mm256_blendv_ps(in_front, appeared, _mm256_cmp_ps(off, zero, _CMP_LT_OQ)));
    // Lanes above the cap: is a 4-neighbour valid and more than edge_mm away?
    const __m256 over = _mm256_cmp_ps(ld, edge_cap, _CMP_GT_OQ);
    const int over_lanes = _mm256_movemask_ps(over);
    const size_t x0 = i % static_cast<size_t>(W);
    const bool interior = i >= static_cast<size_t>(W) && i + 8 + static_cast<size_t>(W) <= n && x0 > 0 &&
                          x0 + 8 < static_cast<size_t>(W);
    if (over_lanes != 0 && interior) {
      auto edge_to = [&](const uint16_t* nb) __attribute__((target("avx2"))) {
        const __m256i v = _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(nb)));
        const __m256i far = _mm256_cmpgt_epi32(_mm256_abs_epi32(_mm256_sub_epi32(v, d32)), edge_mm);
        return _mm256_and_si256(far, _mm256_cmpgt_epi32(v, _mm256_setzero_si256()));
      };
      const __m256i edge = _mm256_or_si256(_mm256_or_si256(edge_to(depth + i - 1), edge_to(depth + i + 1)),
                                           _mm256_or_si256(edge_to(depth + i - W), edge_to(depth + i + W)));
      ld = _mm256_blendv_ps(ld, edge_cap, _mm256_and_ps(over, _mm256_castsi256_ps(edge)));
    }
    _mm256_storeu_ps(L + i, _mm256_add_ps(_mm256_add_ps(prior, _mm256_mul_ps(wd, ld)), _mm256_mul_ps(wc, lc)));
    // At the image border the scalar path checks the neighbours that exist.
    if (over_lanes != 0 && !interior) {
      for (int bits = over_lanes; bits != 0; bits &= bits - 1)
        UnaryAt(p, m, rgb, depth, W, H, inv_table, i + static_cast<size_t>(__builtin_ctz(static_cast<unsigned>(bits))), L,
                luma);
    }
  }
  return i;
}
#endif

// SegmenterOptions::depth_edge_band_px: pixels within `r` of a depth edge
// (a 4-neighbour more than edge_mm away, or valid next to invalid) get the
// unary again with the depth term capped at edge_cap.
void CapDepthInEdgeBand(const UnaryParams& p, PodState* s, const uint8_t* rgb, const uint16_t* depth, int r,
                        const float* inv_table, float* L, uint8_t* luma) {
  const int W = s->w, H = s->h;
  const size_t n = static_cast<size_t>(W) * H;
  std::vector<uint8_t>& edge = s->band_tmp;
  std::vector<uint8_t>& band = s->band;
  edge.assign(n, 0);
  band.assign(n, 0);
  // Branch-free loops over rows (the compiler vectorises them): pixels i and
  // j differ when one has depth and the other not, or both have and are
  // more than edge_mm apart; both are edge pixels then.
  const int edge_mm = p.edge_mm;
  auto differs = [edge_mm](int a, int b) {
    const int va = a > 0, vb = b > 0;
    const int d = a - b;
    return static_cast<uint8_t>((va ^ vb) | (va & vb & ((d > edge_mm) | (-d > edge_mm))));
  };
  for (int y = 0; y < H; ++y) {
    const uint16_t* d = depth + static_cast<size_t>(y) * W;
    uint8_t* e = edge.data() + static_cast<size_t>(y) * W;
    for (int x = 0; x + 1 < W; ++x) {
      const uint8_t h = differs(d[x], d[x + 1]);
      e[x] |= h;
      e[x + 1] |= h;
    }
    if (y + 1 < H) {
      const uint16_t* dn = d + W;
      uint8_t* en = e + W;
      for (int x = 0; x < W; ++x) {
        const uint8_t v = differs(d[x], dn[x]);
        e[x] |= v;
        en[x] |= v;
      }
    }
  }
  // Dilate by r: each row OR its shifts −r..r (into band_row), then each
  // output row the OR of rows y − r .. y + r.
  std::vector<uint8_t>& row = s->band_row;
  row.assign(n, 0);
  for (int y = 0; y < H; ++y) {
    const uint8_t* e = edge.data() + static_cast<size_t>(y) * W;
    uint8_t* o = row.data() + static_cast<size_t>(y) * W;
    for (int k = -r; k <= r; ++k) {
      const int x0 = std::max(0, -k), x1 = std::min(W, W - k);
      for (int x = x0; x < x1; ++x) o[x] |= e[x + k];
    }
  }
  for (int y = 0; y < H; ++y) {
    uint8_t* o = band.data() + static_cast<size_t>(y) * W;
    for (int k = std::max(0, y - r); k <= std::min(H - 1, y + r); ++k) {
      const uint8_t* e = row.data() + static_cast<size_t>(k) * W;
      for (int x = 0; x < W; ++x) o[x] |= e[x];
    }
  }
  // Only where the depth term exceeds the cap is there anything to redo.
  const BgModel& m = s->model;
  for (size_t i = 0; i < n; ++i)
    if (band[i] && depth[i] > 0 && DepthLogOdds(p, m, depth, i) > p.edge_cap)
      UnaryAt(p, m, rgb, depth, W, H, inv_table, i, L, luma, /*force_cap=*/true);
}

}  // namespace

void Segmenter::Impl::SegmentPod(PodState* s, RgbdFrame* f, const SegmenterOptions& o, SegmentDebug* dbg) {
  const int W = s->w, H = s->h;
  const size_t n = static_cast<size_t>(W) * H;
  const uint8_t* rgb = f->color.data();
  if (!s->registered) {
    RegisterColour(s, *f, o.depth_margin_min_m + o.depth_sigma_m);
    rgb = s->colour_in_depth.data();
  }
  // --- Unary log-odds at full resolution.
  const UnaryParams up(o);
  const uint16_t* depth = f->depth.data();
  float* L = s->unary.data();
  uint8_t* luma = s->luma.data();
  size_t done = 0;
#if defined(HOLO_SEGMENT_AVX2)
  if (o.simd && CpuHasAvx2()) done = UnaryAvx2(up, s->model, rgb, depth, W, H, inv_table.data(), L, luma);
#endif
  for (size_t i = done; i < n; ++i) UnaryAt(up, s->model, rgb, depth, W, H, inv_table.data(), i, L, luma);
  if (o.depth_edge_band_px > 0) CapDepthInEdgeBand(up, s, rgb, depth, o.depth_edge_band_px, inv_table.data(), L, luma);
  uint8_t* mask = f->mask.data();
  if (dbg) {
    dbg->unary_logodds = s->unary;
    dbg->unary_mask.Resize(W, H);
    for (size_t i = 0; i < n; ++i) dbg->unary_mask.data()[i] = L[i] > 0 ? 255 : 0;
  }
  if (o.crf_iterations == 0) {
    for (size_t i = 0; i < n; ++i) mask[i] = L[i] > 0 ? 255 : 0;
    return;
  }

  // --- Downsample the unary and the guide; nearest grid cell per pixel.
  const int fct = o.downsample, dw = s->dw, dh = s->dh;
  const size_t sy = static_cast<size_t>(s->gx), sz = static_cast<size_t>(s->gx) * s->gy;
  const float inv_sr = 1.0f / o.grid_range;
  for (int y = 0; y < dh; ++y) {
    const int y0 = y * fct, y1 = std::min(H, y0 + fct);
    for (int x = 0; x < dw; ++x) {
      const int x0 = x * fct, x1 = std::min(W, x0 + fct);
      float sum_l = 0;
      int sum_y = 0, cnt = 0;
      for (int yy = y0; yy < y1; ++yy)
        for (int xx = x0; xx < x1; ++xx) {
          const size_t i = static_cast<size_t>(yy) * W + xx;
          sum_l += L[i];
          sum_y += luma[i];
          ++cnt;
        }
      const size_t j = static_cast<size_t>(y) * dw + x;
      s->unary_ds[j] = sum_l / static_cast<float>(cnt);
      s->luma_ds[j] = static_cast<uint8_t>(sum_y / cnt);
      s->q_ds[j] = Sigmoid(s->unary_ds[j]);
      const int cx = s->col_cell_ds[x] + (s->col_frac_ds[x] >= 0.5f ? 1 : 0);
      const int cy = s->row_cell_ds[y] + (s->row_frac_ds[y] >= 0.5f ? 1 : 0);
      const int cz = static_cast<int>(s->luma_ds[j] * inv_sr + 0.5f) + 1;
      s->splat_cell[j] = static_cast<int32_t>(cx + sy * cy + sz * cz);
    }
  }

  // --- Mean field: q ← σ(L + w (2 q̄ − 1)), q̄ the bilateral average of q.
  const float w = o.crf_weight;
  const float* g = s->grid.data();
  for (int it = 0; it + 1 < o.crf_iterations; ++it) {
    SplatBlur(s);
    for (int y = 0; y < dh; ++y) {
      const size_t row_base = sy * s->row_cell_ds[y];
      const float fy = s->row_frac_ds[y];
      for (int x = 0; x < dw; ++x) {
        const size_t j = static_cast<size_t>(y) * dw + x;
        const float gzf = s->luma_ds[j] * inv_sr;
        const int gzi = static_cast<int>(gzf);
        const size_t base = row_base + s->col_cell_ds[x] + sz * (gzi + 1);
        const float qbar = SliceAt(g, base, s->col_frac_ds[x], fy, gzf - gzi, sy, sz);
        s->q_ds[j] = Sigmoid(s->unary_ds[j] + w * (2 * qbar - 1));
      }
    }
  }
  // Last update at full resolution: mask edges follow the full-res guide.
  SplatBlur(s);
  for (int y = 0; y < H; ++y) {
    const size_t row_base = sy * s->row_cell[y];
    const float fy = s->row_frac[y];
    for (int x = 0; x < W; ++x) {
      const size_t i = static_cast<size_t>(y) * W + x;
      // |w (2 q̄ − 1)| ≤ w: where the unary is stronger the pairwise term
      // cannot flip the label, so the slice is skipped (exact).
      if (L[i] > w || L[i] < -w) {
        mask[i] = L[i] > 0 ? 255 : 0;
        continue;
      }
      const float gzf = luma[i] * inv_sr;
      const int gzi = static_cast<int>(gzf);
      const size_t base = row_base + s->col_cell[x] + sz * (gzi + 1);
      const float qbar = SliceAt(g, base, s->col_frac[x], fy, gzf - gzi, sy, sz);
      mask[i] = L[i] + w * (2 * qbar - 1) > 0 ? 255 : 0;
    }
  }
}

Status Segmenter::Segment(RgbdFrameSet* frames) { return Segment(frames, nullptr); }

Status Segmenter::Segment(RgbdFrameSet* frames, std::vector<SegmentDebug>* debug) {
  if (frames == nullptr) return InvalidArgument("Segment: frames is null");
  if (!impl_->has_model)
    return InvalidArgument("Segment: no background model; call AddBackgroundFrame and FinishBackground first");
  HOLO_RETURN_IF_ERROR(impl_->CheckFrames(*frames, "Segment"));
  for (size_t i = 0; i < impl_->pods.size(); ++i) {
    RgbdFrame& f = frames->frames[i];
    if (f.mask.width() != impl_->pods[i].w || f.mask.height() != impl_->pods[i].h)
      f.mask.Resize(impl_->pods[i].w, impl_->pods[i].h);
  }
  if (debug) debug->resize(impl_->pods.size());
  Impl* impl = impl_.get();
  const SegmenterOptions& o = options_;
  impl->pool.ParallelFor(static_cast<int>(impl->pods.size()), [&](int i) {
    impl->SegmentPod(&impl->pods[i], &frames->frames[i], o, debug ? &(*debug)[i] : nullptr);
  });
  return OkStatus();
}

}  // namespace holo
