#include "texture/texturer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <cstdio>
#include <time.h>
#include <cstdlib>
#include <cstring>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "common/worker_pool.h"

namespace holo {
namespace {

using Eigen::Vector3f;

constexpr int kVertexChunk = 1024;
constexpr float kNear = 0.05f;
// Distance map value of pixels farther than the largest radius needed.
constexpr uint8_t kFar = 255;
// Cap on the dilation rounds (pixels of radius) per view.
constexpr int kMaxRounds = 32;

enum VertexState : uint8_t { kUnset = 0, kObserved, kFilled };

// Phase timers (wall clock). HOLO_TEXTURE_CPU_TIMES=1 makes them process CPU
// time instead, which is what to read with --threads 1 on a loaded machine.
using TimePoint = double;
const bool kCpuTimes = std::getenv("HOLO_TEXTURE_CPU_TIMES") != nullptr;
double NowCpu() {
  timespec ts{};
  clock_gettime(kCpuTimes ? CLOCK_PROCESS_CPUTIME_ID : CLOCK_MONOTONIC, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}
double MsSince(TimePoint t0) {
  return NowCpu() - t0;
}

// max(0, x)^alpha, with a fast path for small integer exponents.
inline float PowWeight(float x, float alpha, int int_alpha) {
  if (int_alpha >= 0) {
    float r = 1.0f;
    for (int i = 0; i < int_alpha; ++i) r *= x;
    return r;
  }
  return std::pow(x, alpha);
}

inline float Dist2(const float* a, const float* b) {
  const float d0 = a[0] - b[0], d1 = a[1] - b[1], d2 = a[2] - b[2];
  return d0 * d0 + d1 * d1 + d2 * d2;
}

std::string Str(float v) { return std::to_string(v); }

}  // namespace

Status TextureOptions::Check() const {
  if (!(alpha >= 0.0f && alpha <= 64.0f)) return InvalidArgument("alpha must be in [0, 64], got " + Str(alpha));
  if (!(discontinuity_radius_m >= 0.0f && discontinuity_radius_m <= 1.0f))
    return InvalidArgument("discontinuity_radius_m must be in [0, 1], got " + Str(discontinuity_radius_m));
  if (!(discontinuity_jump_m > 0.0f)) return InvalidArgument("discontinuity_jump_m must be > 0, got " + Str(discontinuity_jump_m));
  if (!(visibility_tolerance_m >= 0.0f && visibility_tolerance_m <= 1.0f))
    return InvalidArgument("visibility_tolerance_m must be in [0, 1], got " + Str(visibility_tolerance_m));
  if (voting_levels < 0 || voting_levels > 8)
    return InvalidArgument("voting_levels must be in [0, 8], got " + std::to_string(voting_levels));
  if (!(vote_threshold > 0.0f)) return InvalidArgument("vote_threshold must be > 0, got " + Str(vote_threshold));
  if (fill_iterations < 0) return InvalidArgument("fill_iterations must be >= 0, got " + std::to_string(fill_iterations));
  if (threads < 0) return InvalidArgument("threads must be >= 0, got " + std::to_string(threads));
  if (mask_edge_px < 0 || mask_edge_px > 16)
    return InvalidArgument("mask_edge_px must be in [0, 16], got " + std::to_string(mask_edge_px));
  if (!(cluster_size_m >= 0.0f && cluster_size_m <= 1.0f))
    return InvalidArgument("cluster_size_m must be in [0, 1], got " + Str(cluster_size_m));
 if (cluster_transfer < 0 || cluster_transfer > 2)
    return InvalidArgument("cluster_transfer must be 0, 1 or 2, got " + std::to_string(cluster_transfer));
  return OkStatus();
}

struct Texturer::PodState {
  CameraModel color_camera, depth_camera;
  bool registered = true;
  Eigen::Matrix3f rot;  // colour camera from world
  Vector3f trans, center;
  Eigen::Matrix3f depth_rot;  // depth camera from world
  Vector3f depth_trans;
  MeshRasterizer raster;  // single-view path (distorted cameras, non-SSE2 builds)
  // The visibility depth map: 1/z per pixel (0 = empty), the box of drawn
  // pixels and the largest 1/z of any projected vertex.
  std::vector<float> iz;
  int w = 0, h = 0;
  int box[4] = {0, 0, -1, -1};
  float max_iz = 0.0f;
  std::vector<uint8_t> dist;  // chessboard distance to the nearest discontinuity, px (capped)
  std::vector<uint8_t> tmp;   // region-sized scratch of the dilation
  int rx0 = 0, ry0 = 0, rx1 = -1, ry1 = -1;  // region where `dist` is valid
  std::vector<uint8_t> hedge, vedge, vedge_prev;  // seed scratch, one row
};

#if defined(__SSE2__)
struct Texturer::PodSimd {
  __m128 cx, cy, cz;           // pod centres
  __m128 r0[3], r1[3], r2[3];  // rows of colour camera from world
  __m128 tx, ty, tz;
  __m128 fx, fy, ccx, ccy, wmax, hmax;  // intrinsics; width − 0.5, height − 0.5
  __m128i wlast, hlast;                 // width − 1, height − 1
};
#else
struct Texturer::PodSimd {};
#endif

struct Texturer::ThreadScratch {
  struct Sample {
    float rgb[3];
    float weight;
    int pod;
    int px, py;  // nearest pixel in the pod's colour image
    bool near_edge;
  };
  std::vector<Sample> samples;
  size_t voted = 0, min_variance = 0, edge_only = 0;
};

Texturer::Texturer(const Rig& rig, TextureOptions options) : rig_(rig), options_(options) {
  init_status_ = options_.Check();
  if (init_status_.ok()) init_status_ = rig_.Check();
  if (init_status_.ok() && rig_.pods.empty()) init_status_ = InvalidArgument("rig has no pods");
  if (!init_status_.ok()) init_status_ = init_status_.WithContext("Texturer");
  threads_ = ResolveThreadCount(options_.threads);
  for (const PodCalibration& pod : rig_.pods) {
    auto s = std::make_unique<PodState>();
    s->color_camera = pod.ColorCamera();
    s->depth_camera = pod.DepthCamera();
    s->registered = pod.IsRegistered();
    s->rot = s->color_camera.world_from_camera.linear().transpose();
    s->center = s->color_camera.world_from_camera.translation();
    s->trans = -s->rot * s->center;
    s->depth_rot = s->depth_camera.world_from_camera.linear().transpose();
    s->depth_trans = -s->depth_rot * s->depth_camera.world_from_camera.translation();
    pods_.push_back(std::move(s));
  }
#if defined(__SSE2__)
  // Pods in groups of four for the vectorized view tests (undistorted colour
  // cameras only; padding lanes have z = −1 and fail the depth test).
  simd_pods_ = options_.vectorize && !pods_.empty();
  for (const auto& s : pods_) simd_pods_ = simd_pods_ && !s->color_camera.intrinsics.HasDistortion();
  if (simd_pods_) {
    pod_simd_.resize((pods_.size() + 3) / 4);
    for (size_t g = 0; g < pod_simd_.size(); ++g) {
      alignas(16) float v[24][4];
      for (int lane = 0; lane < 4; ++lane) {
        const size_t pi = 4 * g + static_cast<size_t>(lane);
        for (auto& a : v) a[lane] = 0.0f;
        if (pi >= pods_.size()) {
          v[11][lane] = -1.0f;  // tz: z = −1
          v[12][lane] = v[13][lane] = 1.0f;  // fx, fy (no division by zero issues)
          continue;
        }
        const PodState& s = *pods_[pi];
        const Intrinsics& k = s.color_camera.intrinsics;
        v[0][lane] = s.center.x(), v[1][lane] = s.center.y(), v[2][lane] = s.center.z();
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) v[3 + 3 * r + c][lane] = s.rot(r, c);
        // rows: v[3..5] row 0, v[6..8] row 1, v[12..] below; translation at 9..11
        v[9][lane] = s.trans.x(), v[10][lane] = s.trans.y(), v[11][lane] = s.trans.z();
        v[12][lane] = static_cast<float>(k.fx), v[13][lane] = static_cast<float>(k.fy);
        v[14][lane] = static_cast<float>(k.cx), v[15][lane] = static_cast<float>(k.cy);
        v[16][lane] = k.width - 0.5f, v[17][lane] = k.height - 0.5f;
      }
      PodSimd& q = pod_simd_[g];
      const auto ld = [&](int i) { return _mm_load_ps(v[i]); };
      q.cx = ld(0), q.cy = ld(1), q.cz = ld(2);
      for (int c = 0; c < 3; ++c) q.r0[c] = ld(3 + c), q.r1[c] = ld(6 + c);
      q.tx = ld(9), q.ty = ld(10), q.tz = ld(11);
      q.fx = ld(12), q.fy = ld(13), q.ccx = ld(14), q.ccy = ld(15), q.wmax = ld(16), q.hmax = ld(17);
      // Row 2 of the rotation.
      alignas(16) float r2[3][4];
      for (int lane = 0; lane < 4; ++lane) {
        const size_t pi = 4 * g + static_cast<size_t>(lane);
        for (int c = 0; c < 3; ++c) r2[c][lane] = pi < pods_.size() ? pods_[pi]->rot(2, c) : 0.0f;
      }
      for (int c = 0; c < 3; ++c) q.r2[c] = _mm_load_ps(r2[c]);
      alignas(16) int32_t wl[4], hl[4];
      for (int lane = 0; lane < 4; ++lane) {
        const size_t pi = 4 * g + static_cast<size_t>(lane);
        // Padding lanes: an empty image (no pixel is ever inside).
        wl[lane] = pi < pods_.size() ? pods_[pi]->color_camera.intrinsics.width - 1 : -1;
        hl[lane] = pi < pods_.size() ? pods_[pi]->color_camera.intrinsics.height - 1 : -1;
      }
      q.wlast = _mm_load_si128(reinterpret_cast<const __m128i*>(wl));
      q.hlast = _mm_load_si128(reinterpret_cast<const __m128i*>(hl));
    }
  }
#endif
  for (int t = 0; t < threads_; ++t) {
    scratch_.push_back(std::make_unique<ThreadScratch>());
    scratch_.back()->samples.reserve(rig_.pods.size());
  }
  pool_ = std::make_unique<WorkerPool>(threads_);
}

Texturer::~Texturer() = default;

const std::vector<float>& Texturer::RasterInverseDepth(int pod) const {
  HOLO_CHECK(pod >= 0 && pod < static_cast<int>(pods_.size()));
  return pods_[static_cast<size_t>(pod)]->iz;
}

void Texturer::PreparePod(int pod, const Mesh& mesh) {
  PodState& s = *pods_[static_cast<size_t>(pod)];
  // Visibility comes from the mesh itself: the nearest surface along each ray.
  s.raster.Rasterize(mesh.positions, mesh.triangles, s.color_camera, /*want_attributes=*/false,
                     options_.cull_back_faces, kNear);
  s.iz = s.raster.inv_z();
  s.w = s.raster.width(), s.h = s.raster.height();
  s.box[0] = s.raster.box_x0(), s.box[1] = s.raster.box_y0(), s.box[2] = s.raster.box_x1(), s.box[3] = s.raster.box_y1();
  s.max_iz = s.raster.max_inv_z();
  DiscontinuityMap(pod);
}

void Texturer::DiscontinuityMap(int pod) {
  PodState& s = *pods_[static_cast<size_t>(pod)];
  if (!options_.discontinuity_test) return;
  const int w = s.w, h = s.h;
  // Only the region around the drawn pixels matters: every vertex projects
  // into it (2 px margin for vertices whose pixel centre the raster missed).
  s.rx0 = std::max(0, s.box[0] - 2);
  s.ry0 = std::max(0, s.box[1] - 2);
  s.rx1 = std::min(w - 1, s.box[2] + 2);
  s.ry1 = std::min(h - 1, s.box[3] + 2);
  if (s.rx0 > s.rx1 || s.ry0 > s.ry1) return;
  const std::vector<float>& iz = s.iz;
  s.dist.resize(iz.size());
  // Seeds: pixels with a 4-neighbour across a depth jump or a silhouette.
  // In inverse depth (0 = empty): |1/a − 1/b| > jump ⇔ |a − b| > jump·a·b,
  // which is also true for exactly one empty side and false for two: no
  // branches, no divisions, so the row loops vectorize.
  const float jump = options_.discontinuity_jump_m;
  const int rw = s.rx1 - s.rx0 + 1;
  s.hedge.resize(static_cast<size_t>(rw));
  s.vedge_prev.resize(static_cast<size_t>(rw));
  s.vedge.resize(static_cast<size_t>(rw));
  auto jumps = [jump](float a, float b) -> uint8_t { return std::abs(a - b) > jump * a * b; };
  for (int y = s.ry0; y <= s.ry1; ++y) {
    const float* row = iz.data() + static_cast<size_t>(y) * w + s.rx0;
    const float* below = y + 1 < h ? row + w : row;  // last row: compares with itself, no edge
    uint8_t* he = s.hedge.data();
    uint8_t* ve = s.vedge.data();
    for (int x = 0; x + 1 < rw; ++x) he[x] = jumps(row[x], row[x + 1]);
    he[rw - 1] = 0;
    for (int x = 0; x < rw; ++x) ve[x] = jumps(row[x], below[x]);
    const uint8_t* vp = s.vedge_prev.data();
    uint8_t* d = s.dist.data() + static_cast<size_t>(y) * w + s.rx0;
    const bool first = y == s.ry0;
    d[0] = (he[0] | ve[0] | (first ? 0 : vp[0])) ? 0 : kFar;
    for (int x = 1; x < rw; ++x) d[x] = (he[x] | he[x - 1] | ve[x] | (first ? 0 : vp[x])) ? 0 : kFar;
    s.vedge_prev.swap(s.vedge);
  }
  // The dilated discontinuity map, as a chessboard distance to the nearest
  // seed capped past the largest radius any vertex of this view needs (the
  // radius in pixels follows each vertex's depth, so one map serves all).
  // Each round is a separable 3×3 min filter + 1: plain row loops that
  // vectorize, a few rounds at our resolutions.
  const float max_radius_px = options_.discontinuity_radius_m * static_cast<float>(s.color_camera.intrinsics.fx) *
                              s.max_iz;
  const int rounds = std::min(kMaxRounds, static_cast<int>(std::floor(max_radius_px)));
  const int rh = s.ry1 - s.ry0 + 1;
  s.tmp.resize(static_cast<size_t>(rw) * rh);
  for (int round = 0; round < rounds; ++round) {
    for (int y = 0; y < rh; ++y) {
      const uint8_t* r = s.dist.data() + static_cast<size_t>(y + s.ry0) * w + s.rx0;
      uint8_t* t = s.tmp.data() + static_cast<size_t>(y) * rw;
      t[0] = std::min(r[0], r[rw > 1 ? 1 : 0]);
      for (int x = 1; x + 1 < rw; ++x) t[x] = std::min(std::min(r[x - 1], r[x]), r[x + 1]);
      if (rw > 1) t[rw - 1] = std::min(r[rw - 2], r[rw - 1]);
    }
    for (int y = 0; y < rh; ++y) {
      const uint8_t* t0 = s.tmp.data() + static_cast<size_t>(y > 0 ? y - 1 : y) * rw;
      const uint8_t* t1 = s.tmp.data() + static_cast<size_t>(y) * rw;
      const uint8_t* t2 = s.tmp.data() + static_cast<size_t>(y + 1 < rh ? y + 1 : y) * rw;
      uint8_t* r = s.dist.data() + static_cast<size_t>(y + s.ry0) * w + s.rx0;
      for (int x = 0; x < rw; ++x) {
        const int m = std::min(std::min(t0[x], t1[x]), t2[x]) + 1;
        r[x] = static_cast<uint8_t>(std::min<int>(r[x], std::min(m, 255)));
      }
    }
  }
}

namespace {

// Bilinear colour at `(u, v)` (pixel centres at integers), clamped to the image.
inline void SampleBilinear(const ImageRgb8& img, float u, float v, float* out) {
  const int w = img.width(), h = img.height();
  u = std::clamp(u, 0.0f, static_cast<float>(w - 1));
  v = std::clamp(v, 0.0f, static_cast<float>(h - 1));
  const int x0 = std::min(static_cast<int>(u), w - 2 < 0 ? 0 : w - 2);
  const int y0 = std::min(static_cast<int>(v), h - 2 < 0 ? 0 : h - 2);
  const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
  const float ax = u - x0, ay = v - y0;
  const uint8_t* p00 = img.row(y0) + 3 * x0;
  const uint8_t* p01 = img.row(y0) + 3 * x1;
  const uint8_t* p10 = img.row(y1) + 3 * x0;
  const uint8_t* p11 = img.row(y1) + 3 * x1;
  for (int c = 0; c < 3; ++c)
    out[c] = (p00[c] * (1 - ax) + p01[c] * ax) * (1 - ay) + (p10[c] * (1 - ax) + p11[c] * ax) * ay;
}

// Variance of the luma in the 3×3 neighbourhood of (x, y).
float LocalVariance(const ImageRgb8& img, int x, int y) {
  float sum = 0, sum2 = 0;
  int n = 0;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      if (!img.Contains(x + dx, y + dy)) continue;
      const uint8_t* p = img.row(y + dy) + 3 * (x + dx);
      const float l = 0.299f * p[0] + 0.587f * p[1] + 0.114f * p[2];
      sum += l;
      sum2 += l * l;
      ++n;
    }
  if (n == 0) return 1e30f;
  const float mean = sum / n;
  return sum2 / n - mean * mean;
}

inline std::array<uint8_t, 3> ToRgb8(const float* c) {
  std::array<uint8_t, 3> out;
  for (int k = 0; k < 3; ++k) out[k] = static_cast<uint8_t>(std::clamp(c[k] + 0.5f, 0.0f, 255.0f));
  return out;
}

}  // namespace

void Texturer::ColorVertices(const RgbdFrameSet& frames, const Mesh& mesh, const std::vector<Vector3f>& normals,
                             size_t begin, size_t end, ThreadScratch* scratch) {
  using Sample = ThreadScratch::Sample;
  const TextureOptions& o = options_;
  const int int_alpha = o.alpha == std::floor(o.alpha) && o.alpha <= 8.0f ? static_cast<int>(o.alpha) : -1;
  const size_t num_pods = pods_.size();
  std::vector<Sample>& samples = scratch->samples;
  for (size_t vi = begin; vi < end; ++vi) {
    const Vector3f& p = mesh.positions[vi];
    Vector3f n = normals[vi];
    const float nn = n.norm();
    n = nn > 0.0f ? Vector3f(n / nn) : Vector3f::Zero();
    samples.clear();
    // The rest of the tests for a view the vertex faces, is in front of and
    // projects inside: visibility, discontinuities, mask; then the sample.
    const auto consider = [&](size_t pi, const Eigen::Vector2f& uv, float pcz, float ndv_raw, float to_pod_len) {
      const PodState& s = *pods_[pi];
      const Intrinsics& k = s.color_camera.intrinsics;
    // uv > -0.5, so truncation of uv + 0.5 rounds to nearest.
    const int ix = std::min(static_cast<int>(uv.x() + 0.5f), k.width - 1);
    const int iy = std::min(static_cast<int>(uv.y() + 0.5f), k.height - 1);
    float weight = 1.0f;
    if (o.normal_weighting) {
      const float ndv = ndv_raw / to_pod_len;
      weight = PowWeight(ndv, o.alpha, int_alpha);
      if (!(weight > 0.0f)) return;
    }
    const size_t pix = static_cast<size_t>(iy) * k.width + ix;
    // Hidden if the rasterized surface at the pixel is nearer by more than
    // the tolerance (1/iz: the raster's depth; empty pixels never hide).
    if (o.visibility_test) {
      const float izr = s.iz[pix];
      if (izr > 0.0f && pcz * izr > 1.0f + o.visibility_tolerance_m * izr) return;
    }
    bool near_edge = false;
    if (o.discontinuity_test) {
      const float radius_px = o.discontinuity_radius_m * static_cast<float>(k.fx) / pcz;
      // Outside the valid region means off the mesh's raster: a silhouette.
      const bool in_region = ix >= s.rx0 && ix <= s.rx1 && iy >= s.ry0 && iy <= s.ry1;
      near_edge = !in_region || s.dist[pix] <= radius_px;
      if (near_edge && !o.discontinuity_fallback) return;
    }
    const RgbdFrame& frame = frames.frames[pi];
    if (o.use_masks && !frame.mask.empty()) {
      int mx = ix, my = iy;
      if (!s.registered) {
        Eigen::Vector2f muv;
        if (!s.depth_camera.ProjectCamera(s.depth_rot * p + s.depth_trans, &muv)) return;
        mx = static_cast<int>(std::lround(muv.x()));
        my = static_cast<int>(std::lround(muv.y()));
        if (!frame.mask.Contains(mx, my)) return;
      }
      if (frame.mask.at(mx, my) == 0) return;
      // Near the mask's edge the sample (and its bilinear neighbours) may be
      // background: a segmentation edge is often a pixel or two off. Such a
      // view counts only where no other is clean (as near a discontinuity).
      if (o.mask_edge_px > 0) {
        const int r = o.mask_edge_px;
        const int x0 = std::max(0, mx - r), x1 = std::min(frame.mask.width() - 1, mx + r);
        const int y0 = std::max(0, my - r), y1 = std::min(frame.mask.height() - 1, my + r);
        bool mask_edge = x0 != mx - r || x1 != mx + r || y0 != my - r || y1 != my + r;
        for (int yy = y0; yy <= y1 && !mask_edge; ++yy) {
          const uint8_t* row = &frame.mask.at(0, yy);
          for (int xx = x0; xx <= x1; ++xx) mask_edge |= row[xx] == 0;
        }
        // Never used, not even as a fallback: a vertex every view sees only
        // at a mask edge (a silhouette rim) is better filled from its
        // observed neighbours than painted with the room.
        if (mask_edge) return;
      }
    }
    Sample& smp = samples.emplace_back();
    SampleBilinear(frame.color, uv.x(), uv.y(), smp.rgb);
    smp.weight = weight;
    smp.pod = static_cast<int>(pi);
    smp.px = ix;
    smp.py = iy;
    smp.near_edge = near_edge;
    };
#if defined(__SSE2__)
    if (simd_pods_) {
      // Facing, depth and image-bounds tests for four views at a time (the
      // same float operations in the same order as the scalar path below —
      // Eigen sums three products as a0 + (a1 + a2) — so the same results),
      // then the rest for the views left, in pod order.
      const __m128 px = _mm_set1_ps(p.x()), py = _mm_set1_ps(p.y()), pz = _mm_set1_ps(p.z());
      const __m128 nx = _mm_set1_ps(n.x()), ny = _mm_set1_ps(n.y()), nz = _mm_set1_ps(n.z());
      for (size_t g = 0; g < pod_simd_.size(); ++g) {
        const PodSimd& q = pod_simd_[g];
        const __m128 tx = _mm_sub_ps(q.cx, px), ty = _mm_sub_ps(q.cy, py), tz = _mm_sub_ps(q.cz, pz);
        const __m128 ndv_raw = _mm_add_ps(_mm_mul_ps(nx, tx), _mm_add_ps(_mm_mul_ps(ny, ty), _mm_mul_ps(nz, tz)));
        const auto row = [&](const __m128* r, __m128 t) {
          return _mm_add_ps(_mm_add_ps(_mm_mul_ps(r[0], px), _mm_add_ps(_mm_mul_ps(r[1], py), _mm_mul_ps(r[2], pz))), t);
        };
        const __m128 pcx = row(q.r0, q.tx), pcy = row(q.r1, q.ty), pcz = row(q.r2, q.tz);
        const __m128 u = _mm_add_ps(_mm_div_ps(_mm_mul_ps(q.fx, pcx), pcz), q.ccx);
        const __m128 v = _mm_add_ps(_mm_div_ps(_mm_mul_ps(q.fy, pcy), pcz), q.ccy);
        const __m128 half = _mm_set1_ps(-0.5f);
        __m128 ok = _mm_and_ps(_mm_cmpgt_ps(pcz, _mm_set1_ps(kNear)),
                               _mm_and_ps(_mm_and_ps(_mm_cmpgt_ps(u, half), _mm_cmpgt_ps(v, half)),
                                          _mm_and_ps(_mm_cmplt_ps(u, q.wmax), _mm_cmplt_ps(v, q.hmax))));
        if (o.normal_weighting) ok = _mm_and_ps(ok, _mm_cmpgt_ps(ndv_raw, _mm_setzero_ps()));
        int bits = _mm_movemask_ps(ok);
        if (bits == 0) continue;
        alignas(16) float au[4], av[4], az[4], andv[4], alen[4];
        _mm_store_ps(au, u);
        _mm_store_ps(av, v);
        _mm_store_ps(az, pcz);
        _mm_store_ps(andv, ndv_raw);
        _mm_store_ps(alen, _mm_sqrt_ps(_mm_add_ps(_mm_mul_ps(tx, tx), _mm_add_ps(_mm_mul_ps(ty, ty), _mm_mul_ps(tz, tz)))));
        for (; bits != 0; bits &= bits - 1) {
          const int lane = __builtin_ctz(static_cast<unsigned>(bits));
          consider(4 * g + static_cast<size_t>(lane), Eigen::Vector2f(au[lane], av[lane]), az[lane], andv[lane], alen[lane]);
        }
      }
    } else
#endif
    for (size_t pi = 0; pi < num_pods; ++pi) {
      const PodState& s = *pods_[pi];
      // Facing test first: it rejects about half the views for the cost of a
      // dot product (the sign of n·v needs no normalization).
      const Vector3f to_pod = s.center - p;
      const float ndv_raw = n.dot(to_pod);
      if (o.normal_weighting && !(ndv_raw > 0.0f)) continue;
      const Vector3f pc = s.rot * p + s.trans;
      if (!(pc.z() > kNear)) continue;
      const Intrinsics& k = s.color_camera.intrinsics;
      Eigen::Vector2f uv;
      if (k.HasDistortion()) {
        s.color_camera.ProjectCamera(pc, &uv);
      } else {
        uv.x() = static_cast<float>(k.fx) * pc.x() / pc.z() + static_cast<float>(k.cx);
        uv.y() = static_cast<float>(k.fy) * pc.y() / pc.z() + static_cast<float>(k.cy);
      }
      if (!(uv.x() > -0.5f && uv.y() > -0.5f && uv.x() < k.width - 0.5f && uv.y() < k.height - 0.5f)) continue;
      consider(pi, uv, pc.z(), ndv_raw, to_pod.norm());
    }
    if (o.discontinuity_test && o.discontinuity_fallback) {
      // Views near a discontinuity only count when no other view remains.
      size_t clean = 0;
      for (const Sample& smp : samples) clean += !smp.near_edge;
      if (clean > 0 && clean < samples.size()) {
        size_t out = 0;
        for (size_t j = 0; j < samples.size(); ++j)
          if (!samples[j].near_edge) samples[out++] = samples[j];
        samples.resize(out);
      } else if (clean == 0 && !samples.empty()) {
        ++scratch->edge_only;
      }
    }

    const size_t m = samples.size();
    if (m == 0) {
      state_[vi] = kUnset;
      continue;
    }
    state_[vi] = kObserved;
    // Default: weighted average of every kept sample.
    auto average = [&](auto&& include) {
      float acc[3] = {0, 0, 0}, wsum = 0;
      for (size_t j = 0; j < m; ++j) {
        if (!include(j)) continue;
        const float w = samples[j].weight;
        for (int c = 0; c < 3; ++c) acc[c] += w * samples[j].rgb[c];
        wsum += w;
      }
      if (!(wsum > 0.0f)) {  // all weights underflowed: plain mean
        int cnt = 0;
        for (size_t j = 0; j < m; ++j) {
          if (!include(j)) continue;
          for (int c = 0; c < 3; ++c) acc[c] += samples[j].rgb[c];
          ++cnt;
        }
        wsum = static_cast<float>(std::max(cnt, 1));
      }
      std::array<float, 3> out;
      for (int c = 0; c < 3; ++c) out[c] = acc[c] / wsum;
      return out;
    };
    std::array<float, 3> result;
    bool decided = false;
    if (o.voting_levels > 0 && m >= 2) {
      float tau = o.vote_threshold;
      for (int level = 0; level < o.voting_levels && !decided; ++level, tau *= 2.0f) {
        const float tau2 = tau * tau;
        size_t best = 0, best_count = 0;
        float best_w = -1.0f;
        for (size_t i = 0; i < m; ++i) {
          size_t count = 0;
          float wsum = 0;
          for (size_t j = 0; j < m; ++j)
            if (Dist2(samples[i].rgb, samples[j].rgb) <= tau2) ++count, wsum += samples[j].weight;
          if (count > best_count || (count == best_count && wsum > best_w)) best = i, best_count = count, best_w = wsum;
        }
        if (2 * best_count > m) {
          const float* ref = samples[best].rgb;
          result = average([&](size_t j) { return Dist2(ref, samples[j].rgb) <= tau2; });
          if (best_count < m) ++scratch->voted;
          decided = true;
        }
      }
      if (!decided) {
        // No majority at any level: trust the view whose image is smoothest
        // around the vertex (least likely to straddle an edge or occluder).
        size_t best = 0;
        float best_var = 3e38f;
        for (size_t j = 0; j < m; ++j) {
          const float var = LocalVariance(frames.frames[static_cast<size_t>(samples[j].pod)].color, samples[j].px,
                                          samples[j].py);
          if (var < best_var) best_var = var, best = j;
        }
        result = {samples[best].rgb[0], samples[best].rgb[1], samples[best].rgb[2]};
        ++scratch->min_variance;
        decided = true;
      }
    }
    if (!decided) result = average([](size_t) { return true; });
    accum_[vi] = result;
  }
}

void Texturer::BuildAdjacency(const Mesh& mesh) {
  if (adjacency_built_) return;
  FillAdjacency(mesh, /*only_unset=*/false);
  adjacency_built_ = true;
}

void Texturer::BuildUnsetAdjacency(const Mesh& mesh) {
  FillAdjacency(mesh, /*only_unset=*/true);
  adjacency_built_ = false;  // the lists are partial: BuildAdjacency must rebuild them
}

void Texturer::FillAdjacency(const Mesh& mesh, bool only_unset) {
  const size_t n = mesh.num_vertices();
  const auto wanted = [&](uint32_t v) { return !only_unset || state_[v] == kUnset; };
  // Vertex adjacency (CSR) from the triangles' edges; duplicates are harmless.
  adj_offsets_.assign(n + 1, 0);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k)
      if (wanted(t[k])) adj_offsets_[t[k] + 1] += 2;
  for (size_t v = 0; v < n; ++v) adj_offsets_[v + 1] += adj_offsets_[v];
  adj_.resize(adj_offsets_[n]);
  // cluster_count_ serves as the per-vertex write cursor.
  cluster_count_.assign(adj_offsets_.begin(), adj_offsets_.end() - 1);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = t[k];
      if (!wanted(a)) continue;
      adj_[cluster_count_[a]++] = t[(k + 1) % 3];
      adj_[cluster_count_[a]++] = t[(k + 2) % 3];
    }
}

void Texturer::FillUnobserved(const RgbdFrameSet& frames, Mesh* mesh, const std::vector<Vector3f>& normals) {
  const size_t n = mesh->num_vertices();
  frontier_.clear();
  for (size_t v = 0; v < n; ++v)
    if (state_[v] == kUnset) frontier_.push_back(static_cast<uint32_t>(v));
  if (frontier_.empty()) return;

  BuildUnsetAdjacency(*mesh);
  // Rounds of neighbour averaging, Jacobi style (a vertex filled in this
  // round is not used before the next), so the result is order-independent.
  for (int it = 0; it < options_.fill_iterations && !frontier_.empty(); ++it) {
    next_frontier_.clear();
    size_t filled_now = 0;
    for (uint32_t v : frontier_) {
      float acc[3] = {0, 0, 0};
      int cnt = 0;
      for (uint32_t a = adj_offsets_[v]; a < adj_offsets_[v + 1]; ++a) {
        const uint32_t u = adj_[a];
        if (state_[u] == kObserved || state_[u] == kFilled) {
          for (int c = 0; c < 3; ++c) acc[c] += accum_[u][c];
          ++cnt;
        }
      }
      if (cnt == 0) {
        next_frontier_.push_back(v);
        continue;
      }
      // Stash the result in the mesh colour; committed below.
      for (int c = 0; c < 3; ++c) acc[c] /= static_cast<float>(cnt);
      mesh->colors[v] = ToRgb8(acc);
      frontier_[filled_now++] = v;  // compact: filled vertices at the front
    }
    for (size_t i = 0; i < filled_now; ++i) {
      const uint32_t v = frontier_[i];
      state_[v] = kFilled;
      for (int c = 0; c < 3; ++c) accum_[v][c] = mesh->colors[v][c];
    }
    stats_.filled_from_neighbours += filled_now;
    frontier_.swap(next_frontier_);
  }

  // Last resort for parts no view observed at all: the facing view with the
  // smoothest image around the vertex, visibility and discontinuities ignored.
  for (uint32_t v : frontier_) {
    const Vector3f& p = mesh->positions[v];
    const Vector3f nrm = normals[v];
    int best_pod = -1;
    float best_var = 3e38f, best_uv[2] = {0, 0};
    for (size_t pi = 0; pi < pods_.size(); ++pi) {
      const PodState& s = *pods_[pi];
      Eigen::Vector2f uv;
      if (!s.color_camera.ProjectCamera(s.rot * p + s.trans, &uv)) continue;
      const Intrinsics& k = s.color_camera.intrinsics;
      if (!(uv.x() > -0.5f && uv.y() > -0.5f && uv.x() < k.width - 0.5f && uv.y() < k.height - 0.5f)) continue;
      if (nrm.dot(s.center - p) <= 0.0f) continue;
      const float var = LocalVariance(frames.frames[pi].color, static_cast<int>(std::lround(uv.x())),
                                      static_cast<int>(std::lround(uv.y())));
      if (var < best_var) best_var = var, best_pod = static_cast<int>(pi), best_uv[0] = uv.x(), best_uv[1] = uv.y();
    }
    if (best_pod < 0) {
      mesh->colors[v] = {128, 128, 128};
      ++stats_.uncoloured;
      continue;
    }
    float rgb[3];
    SampleBilinear(frames.frames[static_cast<size_t>(best_pod)].color, best_uv[0], best_uv[1], rgb);
    mesh->colors[v] = ToRgb8(rgb);
    ++stats_.fallback;
  }
}

Status Texturer::Apply(const RgbdFrameSet& frames, Mesh* mesh) {
  const TimePoint t0 = NowCpu();
  if (!init_status_.ok()) return init_status_;
  if (mesh == nullptr) return InvalidArgument("Texturer::Apply: mesh is null");
  if (frames.frames.size() != pods_.size())
    return InvalidArgument("Texturer::Apply: " + std::to_string(frames.frames.size()) + " frames for a rig of " +
                           std::to_string(pods_.size()) + " pods");
  for (size_t i = 0; i < pods_.size(); ++i) {
    const RgbdFrame& f = frames.frames[i];
    const Intrinsics& c = rig_.pods[i].color;
    const Intrinsics& d = rig_.pods[i].depth;
    if (f.color.width() != c.width || f.color.height() != c.height)
      return InvalidArgument("Texturer::Apply: pod " + std::to_string(i) + " colour image is " +
                             std::to_string(f.color.width()) + "x" + std::to_string(f.color.height()) +
                             ", calibration says " + std::to_string(c.width) + "x" + std::to_string(c.height));
    if (!f.mask.empty() && (f.mask.width() != d.width || f.mask.height() != d.height))
      return InvalidArgument("Texturer::Apply: pod " + std::to_string(i) + " mask is " + std::to_string(f.mask.width()) +
                             "x" + std::to_string(f.mask.height()) + ", depth camera is " + std::to_string(d.width) +
                             "x" + std::to_string(d.height));
  }
  if (Status s = mesh->Validate(); !s.ok()) return s.WithContext("Texturer::Apply");

  const size_t n = mesh->num_vertices();
  stats_ = TextureStats{};
  stats_.num_vertices = n;
  const std::vector<Vector3f>* normals = &mesh->normals;
  if (mesh->normals.size() != n) {
    // Area-weighted face normals (the cross product's length is twice the area).
    normals_.assign(n, Vector3f::Zero());
    for (const auto& t : mesh->triangles) {
      const Vector3f fn =
          (mesh->positions[t[1]] - mesh->positions[t[0]]).cross(mesh->positions[t[2]] - mesh->positions[t[0]]);
      for (int k = 0; k < 3; ++k) normals_[t[k]] += fn;
    }
    normals = &normals_;
  }
  if (options_.cluster_size_m > 0.0f) {
    const TimePoint tc = NowCpu();
    BuildClusters(*mesh, *normals);
    stats_.coarse_vertices = coarse_.num_vertices();
    stats_.coarse_triangles = coarse_.num_triangles();
    stats_.ms_cluster = MsSince(tc);
    if (options_.cluster_transfer == 2) {
      // Visibility from the coarse mesh, colours for every vertex.
      TextureMesh(frames, mesh, *normals, &coarse_);
    } else {
      TextureMesh(frames, &coarse_, coarse_.normals);
      const TimePoint tt = NowCpu();
      TransferColors(mesh);
      stats_.ms_transfer = MsSince(tt);
    }
  } else {
    TextureMesh(frames, mesh, *normals);
  }
  stats_.ms_total = MsSince(t0);
  return OkStatus();
}

void Texturer::TextureMesh(const RgbdFrameSet& frames, Mesh* mesh, const std::vector<Vector3f>& normals,
                           const Mesh* visibility_mesh) {
  if (visibility_mesh == nullptr) visibility_mesh = mesh;
  const size_t n = mesh->num_vertices();
  adjacency_built_ = false;
  state_.resize(n);
  accum_.resize(n);
  mesh->colors.resize(n);

  const TimePoint t0 = NowCpu();
#if defined(__SSE2__)
  if (simd_pods_) {
    RasterizeAllPods(*visibility_mesh);
  } else
#endif
  {
    pool_->Run(static_cast<int>(pods_.size()), [&](int pod, int) { PreparePod(pod, *visibility_mesh); });
  }
  stats_.ms_raster = MsSince(t0);

  const TimePoint t1 = NowCpu();
  for (auto& s : scratch_) s->voted = s->min_variance = s->edge_only = 0;
  const int chunks = static_cast<int>((n + kVertexChunk - 1) / kVertexChunk);
  pool_->Run(chunks, [&](int chunk, int thread) {
    const size_t begin = static_cast<size_t>(chunk) * kVertexChunk;
    ColorVertices(frames, *mesh, normals, begin, std::min(n, begin + kVertexChunk),
                  scratch_[static_cast<size_t>(thread)].get());
  });
  for (size_t v = 0; v < n; ++v)
    if (state_[v] == kObserved) {
      mesh->colors[v] = ToRgb8(accum_[v].data());
      ++stats_.observed;
    }
  for (auto& s : scratch_) stats_.voted += s->voted, stats_.min_variance += s->min_variance, stats_.edge_only += s->edge_only;
  stats_.ms_sample = MsSince(t1);

  const TimePoint t2 = NowCpu();
  FillUnobserved(frames, mesh, normals);
  stats_.ms_fill = MsSince(t2);
}

namespace {
// Dominant axis and sign of a normal: 0..5 (6 for a zero normal).
inline uint64_t NormalBin(const Vector3f& n) {
  const float ax = std::abs(n.x()), ay = std::abs(n.y()), az = std::abs(n.z());
  if (ax >= ay && ax >= az) return ax > 0.0f ? (n.x() > 0.0f ? 0 : 1) : 6;
  if (ay >= az) return n.y() > 0.0f ? 2 : 3;
  return n.z() > 0.0f ? 4 : 5;
}
inline uint64_t HashKey(uint64_t key, int bits) { return (key * 0x9E3779B97F4A7C15ull) >> (64 - bits); }
}  // namespace

void Texturer::BuildClusters(const Mesh& mesh, const std::vector<Vector3f>& normals) {
  const size_t n = mesh.num_vertices();
  const float inv_cell = 1.0f / options_.cluster_size_m;
  size_t cap = 1024;
  int bits = 10;
  while (cap < 2 * n) cap *= 2, ++bits;
  const uint64_t mask = cap - 1;
  hash_keys_.assign(cap, ~uint64_t{0});
  hash_values_.resize(cap);
  cluster_of_.resize(n);
  coarse_.positions.clear();
  coarse_.normals.clear();
  coarse_.colors.clear();
  coarse_.triangles.clear();
  cluster_count_.clear();
  // Cells are keyed by 20-bit grid coordinates (wrapping far away is
  // harmless: only a merge of clusters 8 km apart) and the normal bin.
  constexpr int64_t kOff = int64_t{1} << 19;
  for (size_t v = 0; v < n; ++v) {
    const Vector3f& p = mesh.positions[v];
    const auto cell = [&](float x) {
      return static_cast<uint64_t>((static_cast<int64_t>(std::floor(x * inv_cell)) + kOff) & 0xFFFFF);
    };
    const uint64_t key = cell(p.x()) | cell(p.y()) << 20 | cell(p.z()) << 40 | NormalBin(normals[v]) << 60;
    uint64_t slot = HashKey(key, bits);
    while (hash_keys_[slot] != key && hash_keys_[slot] != ~uint64_t{0}) slot = (slot + 1) & mask;
    uint32_t c;
    if (hash_keys_[slot] == key) {
      c = hash_values_[slot];
      coarse_.positions[c] += p;
      coarse_.normals[c] += normals[v];
      ++cluster_count_[c];
    } else {
      hash_keys_[slot] = key;
      c = static_cast<uint32_t>(coarse_.positions.size());
      hash_values_[slot] = c;
      coarse_.positions.push_back(p);
      coarse_.normals.push_back(normals[v]);
      cluster_count_.push_back(1);
    }
    cluster_of_[v] = c;
  }
  for (size_t c = 0; c < coarse_.positions.size(); ++c)
    coarse_.positions[c] /= static_cast<float>(cluster_count_[c]);
  for (const auto& t : mesh.triangles) {
    const uint32_t a = cluster_of_[t[0]], b = cluster_of_[t[1]], c = cluster_of_[t[2]];
    if (a == b || b == c || a == c) continue;  // collapsed
    coarse_.triangles.push_back({a, b, c});
  }
}

void Texturer::TransferColors(Mesh* mesh) {
  const size_t n = mesh->num_vertices();
  mesh->colors.resize(n);
  if (options_.cluster_transfer == 0) {
    for (size_t v = 0; v < n; ++v) mesh->colors[v] = coarse_.colors[cluster_of_[v]];
    return;
  }
  BuildAdjacency(coarse_);
  // Distance-weighted mean over the vertex's cluster and its neighbours in
  // the coarse mesh: weight (1 − d/R)², R = 2 cells (a cluster mean is at
  // most √3 cells from any of its vertices, so the own cluster counts).
  const float r = 2.0f * options_.cluster_size_m, inv_r = 1.0f / r;
  const auto weight = [&](const Vector3f& p, uint32_t c) {
    const float d = (coarse_.positions[c] - p).norm() * inv_r;
    const float w = std::max(0.0f, 1.0f - d);
    return w * w;
  };
  const int chunks = static_cast<int>((n + kVertexChunk - 1) / kVertexChunk);
  pool_->Run(chunks, [&](int chunk, int) {
    const size_t begin = static_cast<size_t>(chunk) * kVertexChunk, end = std::min(n, begin + kVertexChunk);
    for (size_t v = begin; v < end; ++v) {
      const Vector3f& p = mesh->positions[v];
      const uint32_t own = cluster_of_[v];
      float w = weight(p, own) + 1e-6f;
      float acc[3];
      for (int k = 0; k < 3; ++k) acc[k] = w * coarse_.colors[own][k];
      float wsum = w;
      for (uint32_t a = adj_offsets_[own]; a < adj_offsets_[own + 1]; ++a) {
        const uint32_t c = adj_[a];
        w = weight(p, c);
        if (!(w > 0.0f)) continue;
        for (int k = 0; k < 3; ++k) acc[k] += w * coarse_.colors[c][k];
        wsum += w;
      }
      for (int k = 0; k < 3; ++k) acc[k] /= wsum;
      mesh->colors[v] = ToRgb8(acc);
    }
  });
}


#if defined(__SSE2__)
namespace {
constexpr int kSubShift = 8;
constexpr int64_t kSub = int64_t{1} << kSubShift;  // sub-pixel steps per pixel (as MeshRasterizer)
constexpr float kMaxCoord = 1048576.0f;             // |screen coordinate| limit, pixels
inline bool OwnsTies(int64_t ax, int64_t ay, int64_t bx, int64_t by) {
  const int64_t dy = by - ay;
  return dy > 0 || (dy == 0 && bx - ax < 0);
}
}  // namespace

// Visibility depth maps of all pods at once. Same pixels and the same 1/z
// values as MeshRasterizer (depth only, back faces culled in screen space):
//  1. every vertex is projected into all pods, four pods per SSE2 vector
//     (pinhole; snapped to 1/256 px exactly as MeshRasterizer does), into
//     one record per vertex and group of four pods (x[4], y[4], 1/z[4]);
//  2. per group of four pods (one task each), every triangle is tested in
//     the four pods at once: all three vertices projected, a pixel centre
//     inside its box, not clearly back-facing (a float area with a margin: a
//     superset of what is drawn). On a mesh finer than the pixels most
//     triangles stop here, for a fraction of the scalar cost and without
//     mispredicted branches. Survivors are drawn at once in their pod with
//     MeshRasterizer's exact integer edge functions (the records are still
//     in cache);
//  3. per pod, the discontinuity map.
void Texturer::RasterizeAllPods(const Mesh& mesh) {
  const size_t n = mesh.num_vertices();
  const size_t groups = pod_simd_.size();
  const size_t stride = 4 * groups;
  screen_.resize(n * groups * 12);
  const int threads = pool_->num_threads();
  max_iz_lanes_.assign(static_cast<size_t>(threads) * stride, 0.0f);
  // 1. Projection.
  const int vchunks = static_cast<int>((n + kVertexChunk - 1) / kVertexChunk);
  pool_->Run(vchunks, [&](int chunk, int thread) {
    const size_t begin = static_cast<size_t>(chunk) * kVertexChunk, end = std::min(n, begin + kVertexChunk);
    const __m128 near = _mm_set1_ps(kNear), one = _mm_set1_ps(1.0f), sub = _mm_set1_ps(static_cast<float>(kSub));
    const __m128 half = _mm_set1_ps(0.5f), lim = _mm_set1_ps(kMaxCoord);
    const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
    float* max_lane = max_iz_lanes_.data() + static_cast<size_t>(thread) * stride;
    for (size_t g = 0; g < groups; ++g) {
      const PodSimd& q = pod_simd_[g];
      __m128 mx = _mm_loadu_ps(max_lane + 4 * g);
      float* rec = screen_.data() + (g * n + begin) * 12;
      for (size_t i = begin; i < end; ++i, rec += 12) {
        const Vector3f& p = mesh.positions[i];
        const __m128 px = _mm_set1_ps(p.x()), py = _mm_set1_ps(p.y()), pz = _mm_set1_ps(p.z());
        const auto row = [&](const __m128* r, __m128 t) {
          return _mm_add_ps(_mm_add_ps(_mm_mul_ps(r[0], px), _mm_add_ps(_mm_mul_ps(r[1], py), _mm_mul_ps(r[2], pz))), t);
        };
        const __m128 cx = row(q.r0, q.tx), cy = row(q.r1, q.ty), cz = row(q.r2, q.tz);
        const __m128 front = _mm_cmpge_ps(cz, near);
        const __m128 izv = _mm_div_ps(one, cz);
        mx = _mm_max_ps(mx, _mm_and_ps(front, izv));
        const __m128 fxp = _mm_add_ps(_mm_mul_ps(_mm_mul_ps(q.fx, cx), izv), q.ccx);
        const __m128 fyp = _mm_add_ps(_mm_mul_ps(_mm_mul_ps(q.fy, cy), izv), q.ccy);
        const __m128 ok = _mm_and_ps(front, _mm_and_ps(_mm_cmplt_ps(_mm_and_ps(fxp, abs_mask), lim),
                                                        _mm_cmplt_ps(_mm_and_ps(fyp, abs_mask), lim)));
        // floor(v·256 + 0.5) as FloorToInt: truncate, one down where it rounded up.
        const auto snap = [&](__m128 v) {
          const __m128 f = _mm_add_ps(_mm_mul_ps(v, sub), half);
          const __m128i t = _mm_cvttps_epi32(f);
          return _mm_add_epi32(t, _mm_castps_si128(_mm_cmpgt_ps(_mm_cvtepi32_ps(t), f)));  // −1 where t > f
        };
        const __m128i oki = _mm_castps_si128(ok);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(rec), _mm_and_si128(snap(fxp), oki));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(rec + 4), _mm_and_si128(snap(fyp), oki));
        _mm_storeu_ps(rec + 8, _mm_and_ps(izv, ok));
      }
      _mm_storeu_ps(max_lane + 4 * g, mx);
    }
  });
  for (size_t pi = 0; pi < pods_.size(); ++pi) {
    float m = 0.0f;
    for (int t = 0; t < threads; ++t) m = std::max(m, max_iz_lanes_[static_cast<size_t>(t) * stride + pi]);
    pods_[pi]->max_iz = m;
  }
  // 2. Per group of four pods: test every triangle, draw the survivors.
  const size_t nt = mesh.num_triangles();
  const size_t num_pods = pods_.size();
  const bool cull = options_.cull_back_faces;
  pool_->Run(static_cast<int>(groups), [&](int gi, int) {
    const size_t g = static_cast<size_t>(gi);
    const PodSimd& q = pod_simd_[g];
    PodState* ps[4] = {nullptr, nullptr, nullptr, nullptr};
    for (size_t lane = 0; lane < 4 && 4 * g + lane < num_pods; ++lane) {
      PodState& s = *pods_[4 * g + lane];
      const Intrinsics& k = s.color_camera.intrinsics;
      s.w = k.width, s.h = k.height;
      s.iz.assign(static_cast<size_t>(s.w) * s.h, 0.0f);
      s.box[0] = s.w, s.box[1] = s.h, s.box[2] = -1, s.box[3] = -1;
      ps[lane] = &s;
    }
    const float* recs = screen_.data() + g * n * 12;
    const __m128 zero = _mm_setzero_ps();
    const __m128 margin = _mm_set1_ps(1.0f / 65536.0f);
    const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
    const __m128i c255 = _mm_set1_epi32(static_cast<int>(kSub - 1)), minus1 = _mm_set1_epi32(-1);
    for (size_t ti = 0; ti < nt; ++ti) {
      const auto& tr = mesh.triangles[ti];
      const float* r0 = recs + static_cast<size_t>(tr[0]) * 12;
      const float* r1 = recs + static_cast<size_t>(tr[1]) * 12;
      const float* r2 = recs + static_cast<size_t>(tr[2]) * 12;
      const auto ldx = [](const float* r) {
        return _mm_cvtepi32_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(r)));
      };
      const __m128 x0 = ldx(r0), x1 = ldx(r1), x2 = ldx(r2);
      const __m128 y0 = ldx(r0 + 4), y1 = ldx(r1 + 4), y2 = ldx(r2 + 4);
      const __m128 valid = _mm_and_ps(_mm_cmpgt_ps(_mm_loadu_ps(r0 + 8), zero),
                                      _mm_and_ps(_mm_cmpgt_ps(_mm_loadu_ps(r1 + 8), zero),
                                                 _mm_cmpgt_ps(_mm_loadu_ps(r2 + 8), zero)));
      // Box in whole pixels (the float values of the snapped integers; far
      // off-screen ones may round but stay off-screen on the same side).
      const __m128i xa = _mm_srai_epi32(_mm_add_epi32(_mm_cvttps_epi32(_mm_min_ps(_mm_min_ps(x0, x1), x2)), c255), kSubShift);
      const __m128i xb = _mm_srai_epi32(_mm_cvttps_epi32(_mm_max_ps(_mm_max_ps(x0, x1), x2)), kSubShift);
      const __m128i ya = _mm_srai_epi32(_mm_add_epi32(_mm_cvttps_epi32(_mm_min_ps(_mm_min_ps(y0, y1), y2)), c255), kSubShift);
      const __m128i yb = _mm_srai_epi32(_mm_cvttps_epi32(_mm_max_ps(_mm_max_ps(y0, y1), y2)), kSubShift);
      // Inside: max(xa, 0) ≤ min(xb, w − 1) ⇔ xa ≤ xb, xa ≤ w − 1, xb ≥ 0 (same for y).
      __m128i in = _mm_andnot_si128(_mm_cmpgt_epi32(xa, xb), minus1);
      in = _mm_andnot_si128(_mm_cmpgt_epi32(ya, yb), in);
      in = _mm_andnot_si128(_mm_cmpgt_epi32(xa, q.wlast), in);
      in = _mm_andnot_si128(_mm_cmpgt_epi32(ya, q.hlast), in);
      in = _mm_andnot_si128(_mm_cmplt_epi32(xb, _mm_setzero_si128()), in);
      in = _mm_andnot_si128(_mm_cmplt_epi32(yb, _mm_setzero_si128()), in);
      __m128 keep = _mm_and_ps(valid, _mm_castsi128_ps(in));
      if (cull) {
        // Back-facing when the area is > 0; kept unless clearly so.
        const __m128 t1 = _mm_mul_ps(_mm_sub_ps(x1, x0), _mm_sub_ps(y2, y0));
        const __m128 t2 = _mm_mul_ps(_mm_sub_ps(x2, x0), _mm_sub_ps(y1, y0));
        const __m128 tol = _mm_mul_ps(margin, _mm_add_ps(_mm_and_ps(t1, abs_mask), _mm_and_ps(t2, abs_mask)));
        keep = _mm_and_ps(keep, _mm_cmple_ps(_mm_sub_ps(t1, t2), tol));
      }
      for (int bits = _mm_movemask_ps(keep); bits != 0; bits &= bits - 1) {
        const int lane = __builtin_ctz(static_cast<unsigned>(bits));
        PodState& s = *ps[lane];
        // The exact test and drawing, as MeshRasterizer.
        int64_t x[3], y[3];
        float iz[3];
        const float* rr[3] = {r0, r1, r2};
        for (int c = 0; c < 3; ++c) {
          int32_t xi, yi;
          std::memcpy(&xi, rr[c] + lane, 4);
          std::memcpy(&yi, rr[c] + 4 + lane, 4);
          x[c] = xi, y[c] = yi, iz[c] = rr[c][8 + lane];
        }
        const int64_t minx = std::min({x[0], x[1], x[2]}), maxx = std::max({x[0], x[1], x[2]});
        const int64_t miny = std::min({y[0], y[1], y[2]}), maxy = std::max({y[0], y[1], y[2]});
        const int bxa = static_cast<int>(std::max<int64_t>(0, (minx + kSub - 1) >> kSubShift));
        const int bxb = static_cast<int>(std::min<int64_t>(s.w - 1, maxx >> kSubShift));
        if (bxa > bxb) continue;
        const int bya = static_cast<int>(std::max<int64_t>(0, (miny + kSub - 1) >> kSubShift));
        const int byb = static_cast<int>(std::min<int64_t>(s.h - 1, maxy >> kSubShift));
        if (bya > byb) continue;
        int64_t area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
        if (area == 0) continue;
        if (cull && area > 0) continue;
        if (area < 0) {
          std::swap(x[1], x[2]);
          std::swap(y[1], y[2]);
          std::swap(iz[1], iz[2]);
          area = -area;
        }
        s.box[0] = std::min(s.box[0], bxa), s.box[1] = std::min(s.box[1], bya);
        s.box[2] = std::max(s.box[2], bxb), s.box[3] = std::max(s.box[3], byb);
        const float inv_area = 1.0f / static_cast<float>(area);
        const int ea[3] = {1, 2, 0}, eb[3] = {2, 0, 1};
        int64_t dxp[3], dyp[3], e_row[3];
        for (int e = 0; e < 3; ++e) {
          const int a = ea[e], b = eb[e];
          dxp[e] = -(y[b] - y[a]) * kSub;
          dyp[e] = (x[b] - x[a]) * kSub;
          e_row[e] = (x[b] - x[a]) * (int64_t{bya} * kSub - y[a]) - (y[b] - y[a]) * (int64_t{bxa} * kSub - x[a]);
          if (!OwnsTies(x[a], y[a], x[b], y[b])) e_row[e] -= 1;
        }
        const float diz_dx = (static_cast<float>(dxp[0]) * iz[0] + static_cast<float>(dxp[1]) * iz[1] +
                              static_cast<float>(dxp[2]) * iz[2]) * inv_area;
        for (int py = bya; py <= byb; ++py) {
          int64_t e0 = e_row[0], e1 = e_row[1], e2 = e_row[2];
          float izp = (static_cast<float>(e0) * iz[0] + static_cast<float>(e1) * iz[1] + static_cast<float>(e2) * iz[2]) *
                      inv_area;
          float* buf = s.iz.data() + static_cast<size_t>(py) * s.w;
          for (int px = bxa; px <= bxb; ++px, e0 += dxp[0], e1 += dxp[1], e2 += dxp[2], izp += diz_dx) {
            if ((e0 | e1 | e2) < 0) continue;
            if (izp > buf[px]) buf[px] = izp;
          }
          e_row[0] += dyp[0];
          e_row[1] += dyp[1];
          e_row[2] += dyp[2];
        }
      }
    }
  });
  // 3. Discontinuity maps.
  pool_->Run(static_cast<int>(num_pods), [&](int pod, int) { DiscontinuityMap(pod); });
}
#endif

}  // namespace holo
