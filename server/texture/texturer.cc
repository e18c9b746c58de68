#include "server/texture/texturer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <cstdio>
#include <time.h>
#include <cstdlib>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "common/metrics/parallel.h"
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
  MeshRasterizer raster;
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
  threads_ = metrics::ResolveThreadCount(options_.threads);
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
  simd_pods_ = !pods_.empty();
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
  return pods_[static_cast<size_t>(pod)]->raster.inv_z();
}

void Texturer::PreparePod(int pod, const Mesh& mesh) {
  PodState& s = *pods_[static_cast<size_t>(pod)];
  // Visibility comes from the mesh itself: the nearest surface along each ray.
  s.raster.Rasterize(mesh.positions, mesh.triangles, s.color_camera, /*want_attributes=*/false,
                     options_.cull_back_faces, kNear);
  if (!options_.discontinuity_test) return;
  const int w = s.raster.width(), h = s.raster.height();
  // Only the region around the drawn pixels matters: every vertex projects
  // into it (2 px margin for vertices whose pixel centre the raster missed).
  s.rx0 = std::max(0, s.raster.box_x0() - 2);
  s.ry0 = std::max(0, s.raster.box_y0() - 2);
  s.rx1 = std::min(w - 1, s.raster.box_x1() + 2);
  s.ry1 = std::min(h - 1, s.raster.box_y1() + 2);
  if (s.rx0 > s.rx1 || s.ry0 > s.ry1) return;
  const std::vector<float>& iz = s.raster.inv_z();
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
                              s.raster.max_inv_z();
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
      const float izr = s.raster.inv_z()[pix];
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
      // same float operations in the same order as the scalar path below,
      // so the same results), then the rest for the views left, in pod order.
      const __m128 px = _mm_set1_ps(p.x()), py = _mm_set1_ps(p.y()), pz = _mm_set1_ps(p.z());
      const __m128 nx = _mm_set1_ps(n.x()), ny = _mm_set1_ps(n.y()), nz = _mm_set1_ps(n.z());
      for (size_t g = 0; g < pod_simd_.size(); ++g) {
        const PodSimd& q = pod_simd_[g];
        const __m128 tx = _mm_sub_ps(q.cx, px), ty = _mm_sub_ps(q.cy, py), tz = _mm_sub_ps(q.cz, pz);
        const __m128 ndv_raw = _mm_add_ps(_mm_add_ps(_mm_mul_ps(nx, tx), _mm_mul_ps(ny, ty)), _mm_mul_ps(nz, tz));
        const auto row = [&](const __m128* r, __m128 t) {
          return _mm_add_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(r[0], px), _mm_mul_ps(r[1], py)), _mm_mul_ps(r[2], pz)), t);
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
        _mm_store_ps(alen, _mm_sqrt_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(tx, tx), _mm_mul_ps(ty, ty)), _mm_mul_ps(tz, tz))));
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
  adjacency_built_ = true;
  const size_t n = mesh.num_vertices();
  // Vertex adjacency (CSR) from the triangles' edges; duplicates are harmless.
  adj_offsets_.assign(n + 1, 0);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) adj_offsets_[t[k] + 1] += 2;
  for (size_t v = 0; v < n; ++v) adj_offsets_[v + 1] += adj_offsets_[v];
  adj_.resize(adj_offsets_[n]);
  // cluster_count_ serves as the per-vertex write cursor.
  cluster_count_.assign(adj_offsets_.begin(), adj_offsets_.end() - 1);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = t[k];
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

  BuildAdjacency(*mesh);
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
  pool_->Run(static_cast<int>(pods_.size()), [&](int pod, int) { PreparePod(pod, *visibility_mesh); });
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

}  // namespace holo
