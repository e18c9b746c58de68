#include "server/segment/segmenter.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>

#include <Eigen/Core>

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

// Background model of one pixel, prepared for the unary term.
struct BgPixel {
  // Background depth minus the margin τ, metres; negative when the empty
  // room had no depth here.
  float depth_offset_m;
  float a, b, v;
  float inv_var_ab, inv_var_v;
};

}  // namespace

Status SegmenterOptions::Check() const {
  HOLO_RETURN_IF_ERROR(CheckPositive("depth_sigma_m", depth_sigma_m));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("depth_margin_min_m", depth_margin_min_m));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("depth_margin_stddevs", depth_margin_stddevs));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("depth_max_logodds", depth_max_logodds));
  HOLO_RETURN_IF_ERROR(CheckPositive("depth_edge_m", depth_edge_m));
  HOLO_RETURN_IF_ERROR(CheckNonNegative("depth_edge_max_logodds", depth_edge_max_logodds));
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
  std::vector<BgPixel> model;
  std::vector<float> bg_depth_m;  // mean background depth (0 = none), for colour registration

  // Non-registered pods: unit-depth rays of the depth camera, and colour
  // sampled into the depth camera.
  std::vector<Eigen::Vector3f> rays;
  ImageRgb8 colour_in_depth;

  // Per frame buffers.
  ImageFloat unary;
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
  s->model.resize(n);
  s->bg_depth_m.assign(n, 0.0f);
  const float var_ab0 = o.chroma_sigma * o.chroma_sigma, var_v0 = o.value_sigma * o.value_sigma;
  for (size_t i = 0; i < n; ++i) {
    BgPixel& m = s->model[i];
    const int c = s->depth_count[i];
    if (c > 0) {
      // Pixels valid in only some frames (grazing surfaces, far floor) keep
      // the mean of their valid samples; the noise floor covers the few-sample variance.
      const double mean = s->depth_sum[i] / c;
      const double var = c >= 3 ? std::max(0.0, s->depth_sum2[i] / c - mean * mean) : 0.0;
      const double noise = o.depth_noise_at_1m_m * mean * mean;
      const double tau = o.depth_margin_min_m + o.depth_margin_stddevs * std::sqrt(std::max(var, noise * noise));
      m.depth_offset_m = static_cast<float>(mean - tau);
      // A surface within the margin of the camera: keep it a (tiny) valid offset.
      if (m.depth_offset_m <= 0) m.depth_offset_m = 1e-4f;
      s->bg_depth_m[i] = static_cast<float>(mean);
    } else {
      m.depth_offset_m = -1.0f;
    }
    const float* cs = &s->col_sum[5 * i];
    const float inv = static_cast<float>(1.0 / frames);
    m.a = cs[0] * inv;
    m.b = cs[1] * inv;
    m.v = cs[2] * inv;
    const float var_ab = std::max(0.0f, cs[3] * inv - m.a * m.a - m.b * m.b);
    const float var_v = std::max(0.0f, cs[4] * inv - m.v * m.v);
    m.inv_var_ab = 1.0f / (var_ab0 + var_ab);
    m.inv_var_v = 1.0f / (var_v0 + var_v);
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
  const uint16_t* depth = f->depth.data();
  const BgPixel* model = s->model.data();
  float* L = s->unary.data();
  uint8_t* luma = s->luma.data();
  const float inv_sd = 1.0f / o.depth_sigma_m;
  const float dmax = o.depth_max_logodds, cmax = o.colour_max_logodds, cmin = -o.colour_bg_max_logodds;
  const float wd = o.depth_weight, wc = o.colour_weight;
  const float appeared = std::clamp(o.depth_appeared_logodds, -dmax, dmax);
  const int edge_mm = static_cast<int>(o.depth_edge_m * 1000.0f);
  const float edge_cap = o.depth_edge_max_logodds;
  for (size_t i = 0; i < n; ++i) {
    const int r = rgb[3 * i], g = rgb[3 * i + 1], b = rgb[3 * i + 2];
    luma[i] = Luma(r, g, b);
    const BgPixel& m = model[i];
    const Hsv c = ToHsv(r, g, b, inv_table.data());
    const float da = c.a - m.a, db = c.b - m.b, dv = c.v - m.v;
    const float dist = std::sqrt((da * da + db * db) * m.inv_var_ab + dv * dv * m.inv_var_v);
    const float lc = std::clamp(o.colour_scale * (dist - o.colour_threshold), cmin, cmax);
    float ld = 0.0f;
    if (depth[i] > 0) {
      ld = m.depth_offset_m < 0 ? appeared
                                : std::clamp((m.depth_offset_m - depth[i] * 0.001f) * inv_sd, -dmax, dmax);
      if (ld > edge_cap) {
        const int x = static_cast<int>(i % W), y = static_cast<int>(i / W);
        const int d = depth[i];
        auto edge = [&](size_t j) { return depth[j] > 0 && std::abs(depth[j] - d) > edge_mm; };
        if ((x > 0 && edge(i - 1)) || (x + 1 < W && edge(i + 1)) || (y > 0 && edge(i - W)) ||
            (y + 1 < H && edge(i + W)))
          ld = edge_cap;
      }
    }
    L[i] = o.prior_logodds + wd * ld + wc * lc;
  }
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
