#include "client/render/atlas.h"

#include <algorithm>
#include <cmath>
#include <string>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define HOLO_ATLAS_AVX2 1
#endif

#include "common/cpu_features.h"
#include "common/worker_pool.h"

namespace holo::render {

Status AtlasBakeOptions::Check() const {
  if (texels_per_edge < 1 || texels_per_edge > 16) return InvalidArgument("atlas texels_per_edge must be in [1, 16]");
  if (!(texels_per_pod_pixel >= 0 && texels_per_pod_pixel <= 64)) {
    return InvalidArgument("atlas texels_per_pod_pixel must be in [0, 64]");
  }
  if (!(min_pod_weight >= 0 && min_pod_weight <= 1)) return InvalidArgument("atlas min_pod_weight must be in [0, 1]");
  if (max_width < texels_per_edge + 1 || max_height < 2) {
    return InvalidArgument("atlas max_width must hold one cell, max_height one cell of one texel per edge");
  }
  if (!(alpha >= 0 && alpha <= 64)) return InvalidArgument("atlas alpha must be in [0, 64]");
  if (!(visibility_tolerance_m > 0 && visibility_tolerance_m < 1)) {
    return InvalidArgument("atlas visibility_tolerance_m must be in (0, 1)");
  }
  if (!(discontinuity_weight > 0 && discontinuity_weight <= 1)) {
    return InvalidArgument("atlas discontinuity_weight must be in (0, 1]");
  }
  if (!(min_mask_confidence >= 0 && min_mask_confidence <= 1)) {
    return InvalidArgument("atlas min_mask_confidence must be in [0, 1]");
  }
  return OkStatus();
}

namespace {

constexpr int kMaxAtlasPods = 16;

// Per pod, precomputed once per bake: 3×4 projection (pixel·z rows for an
// undistorted camera, camera coordinates otherwise) and the camera centre.
struct PodInfo {
  Eigen::Matrix<float, 3, 4> projection;
  Eigen::Vector3f center;
  bool distorted = false;
  float focal = 1;  // fx, to turn normalized distances into pixels when distorted
  int width = 0, height = 0;
};

float Smoothstep(float e, float x) {
  if (e <= 0.0f) return 1.0f;
  const float t = std::clamp(x / e, 0.0f, 1.0f);
  return t * t * (3.0f - 2.0f * t);
}

// The texels of a cell with l texels per edge, one array per field, padded
// to a multiple of 8 with texels of zero weight (c = 0).
struct CellTable {
  int count = 0, padded = 0;
  std::vector<int> i, j;
  std::vector<float> b0, b1, b2, c0, c1, c2;
};

// One pod's samples of one triangle's cell: what the bake loop needs.
struct PodPass {
  Eigen::Vector3f q0, q1, q2;  // corners through the pod's projection (pixel·z, z)
  float cw0, cw1, cw2;         // the corners' facing weights
  const float* zmap;
  const uint8_t* rgba;
  int w, h;
  float tol, edge_w;
};

// Accumulators of a cell's texels, one array per field (`stride` floats
// each): premultiplied R, G, B, alpha, weight.
struct CellAccum {
  float* f[5];
};

// One sample of a pod at image point (x, y) (inside the image) for texel k
// at camera depth qz with facing weight wt: the depth test against the
// pod's flagged map, then the bilinear colour fetch added to the texel.
inline void AddSample(const PodPass& pp, float x, float y, float qz, float wt, int k, const CellAccum& acc) {
  // Nearest texel of the depth map (x, y ≥ −0.5: truncation rounds).
  const int ix = static_cast<int>(x + 0.5f), iy = static_cast<int>(y + 0.5f);
  const float zf = pp.zmap[static_cast<size_t>(iy) * pp.w + ix];
  const float zabs = std::abs(zf);
  if (zabs <= 0.0f || qz > zabs + pp.tol) return;
  // Bilinear fetch (texel centres on integers), clamped at the border.
  const int fx = static_cast<int>(x + 1.0f) - 1, fy = static_cast<int>(y + 1.0f) - 1;  // floor, x ≥ −1
  const float ax = x - static_cast<float>(fx), ay = y - static_cast<float>(fy);
  const int x0 = std::clamp(fx, 0, pp.w - 1), x1 = std::clamp(fx + 1, 0, pp.w - 1);
  const int y0 = std::clamp(fy, 0, pp.h - 1), y1 = std::clamp(fy + 1, 0, pp.h - 1);
  const uint8_t* p00 = pp.rgba + 4 * (static_cast<size_t>(y0) * pp.w + x0);
  const uint8_t* p10 = pp.rgba + 4 * (static_cast<size_t>(y0) * pp.w + x1);
  const uint8_t* p01 = pp.rgba + 4 * (static_cast<size_t>(y1) * pp.w + x0);
  const uint8_t* p11 = pp.rgba + 4 * (static_cast<size_t>(y1) * pp.w + x1);
  const float kw = zf < 0.0f ? pp.edge_w * wt : wt;
  const float w00 = kw * (1 - ax) * (1 - ay), w10 = kw * ax * (1 - ay), w01 = kw * (1 - ax) * ay, w11 = kw * ax * ay;
  for (int ch = 0; ch < 4; ++ch) acc.f[ch][k] += w00 * p00[ch] + w10 * p10[ch] + w01 * p01[ch] + w11 * p11[ch];
  acc.f[4][k] += kw;
}

// Adds the pod's samples to the texels of the cell. `distorted`: the pod's
// camera, whose distortion model maps each texel (q rows are then camera
// coordinates); null for a pinhole pod (q rows are pixel·z, z). Returns the
// samples taken (texels inside the image with weight).
size_t SampleCellPortable(const CellTable& ct, const PodPass& pp, const CameraModel* distorted, const CellAccum& acc) {
  size_t samples = 0;
  const float xmax = static_cast<float>(pp.w) - 0.5f, ymax = static_cast<float>(pp.h) - 0.5f;
  for (int k = 0; k < ct.count; ++k) {
    const float wt = ct.c0[k] * pp.cw0 + ct.c1[k] * pp.cw1 + ct.c2[k] * pp.cw2;
    if (wt <= 1e-6f) continue;
    const float qz = ct.b0[k] * pp.q0.z() + ct.b1[k] * pp.q1.z() + ct.b2[k] * pp.q2.z();
    if (qz < 0.05f) continue;
    float x, y;
    if (distorted == nullptr) {
      const float inv = 1.0f / qz;
      x = (ct.b0[k] * pp.q0.x() + ct.b1[k] * pp.q1.x() + ct.b2[k] * pp.q2.x()) * inv;
      y = (ct.b0[k] * pp.q0.y() + ct.b1[k] * pp.q1.y() + ct.b2[k] * pp.q2.y()) * inv;
    } else {
      Eigen::Vector2f px;
      if (!distorted->ProjectCamera(ct.b0[k] * pp.q0 + ct.b1[k] * pp.q1 + ct.b2[k] * pp.q2, &px)) continue;
      x = px.x();
      y = px.y();
    }
    if (!(x >= -0.5f && y >= -0.5f && x < xmax && y < ymax)) continue;
    ++samples;
    AddSample(pp, x, y, qz, wt, k, acc);
  }
  return samples;
}

#if defined(HOLO_ATLAS_AVX2)

// SampleCellPortable for a pinhole pod, eight texels at a time: the same operations in the
// same order (no FMA), so the sums are bit-identical; lanes that the
// portable loop skips add zero.
__attribute__((target("avx2"))) size_t SampleCellAvx2(const CellTable& ct, const PodPass& pp,
                                                      const CellAccum& acc) {
  size_t samples = 0;
  const __m256 cw0 = _mm256_set1_ps(pp.cw0), cw1 = _mm256_set1_ps(pp.cw1), cw2 = _mm256_set1_ps(pp.cw2);
  const __m256 q0x = _mm256_set1_ps(pp.q0.x()), q0y = _mm256_set1_ps(pp.q0.y()), q0z = _mm256_set1_ps(pp.q0.z());
  const __m256 q1x = _mm256_set1_ps(pp.q1.x()), q1y = _mm256_set1_ps(pp.q1.y()), q1z = _mm256_set1_ps(pp.q1.z());
  const __m256 q2x = _mm256_set1_ps(pp.q2.x()), q2y = _mm256_set1_ps(pp.q2.y()), q2z = _mm256_set1_ps(pp.q2.z());
  const __m256 xmax = _mm256_set1_ps(static_cast<float>(pp.w) - 0.5f);
  const __m256 ymax = _mm256_set1_ps(static_cast<float>(pp.h) - 0.5f);
  const __m256 half = _mm256_set1_ps(0.5f), one = _mm256_set1_ps(1.0f), minus_half = _mm256_set1_ps(-0.5f);
  const __m256 tol = _mm256_set1_ps(pp.tol), edge_w = _mm256_set1_ps(pp.edge_w), zero = _mm256_setzero_ps();
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
  const __m256i width = _mm256_set1_epi32(pp.w), wmax = _mm256_set1_epi32(pp.w - 1),
                hmax = _mm256_set1_epi32(pp.h - 1), izero = _mm256_setzero_si256(), ione = _mm256_set1_epi32(1),
                byte = _mm256_set1_epi32(0xFF);
  const int* rgba = reinterpret_cast<const int*>(pp.rgba);
  for (int k = 0; k < ct.count; k += 8) {
    const __m256 c0 = _mm256_loadu_ps(&ct.c0[k]), c1 = _mm256_loadu_ps(&ct.c1[k]), c2 = _mm256_loadu_ps(&ct.c2[k]);
    const __m256 b0 = _mm256_loadu_ps(&ct.b0[k]), b1 = _mm256_loadu_ps(&ct.b1[k]), b2 = _mm256_loadu_ps(&ct.b2[k]);
    const __m256 wt = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(c0, cw0), _mm256_mul_ps(c1, cw1)), _mm256_mul_ps(c2, cw2));
    const __m256 qz = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(b0, q0z), _mm256_mul_ps(b1, q1z)), _mm256_mul_ps(b2, q2z));
    __m256 live = _mm256_and_ps(_mm256_cmp_ps(wt, _mm256_set1_ps(1e-6f), _CMP_GT_OQ),
                                _mm256_cmp_ps(qz, _mm256_set1_ps(0.05f), _CMP_GE_OQ));
    if (_mm256_testz_ps(live, live)) continue;
    const __m256 inv = _mm256_div_ps(one, qz);
    const __m256 x = _mm256_mul_ps(
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(b0, q0x), _mm256_mul_ps(b1, q1x)), _mm256_mul_ps(b2, q2x)), inv);
    const __m256 y = _mm256_mul_ps(
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(b0, q0y), _mm256_mul_ps(b1, q1y)), _mm256_mul_ps(b2, q2y)), inv);
    live = _mm256_and_ps(live, _mm256_and_ps(_mm256_cmp_ps(x, minus_half, _CMP_GE_OQ),
                                             _mm256_cmp_ps(y, minus_half, _CMP_GE_OQ)));
    live = _mm256_and_ps(live, _mm256_and_ps(_mm256_cmp_ps(x, xmax, _CMP_LT_OQ), _mm256_cmp_ps(y, ymax, _CMP_LT_OQ)));
    const int in_image = _mm256_movemask_ps(live);
    if (in_image == 0) continue;
    samples += static_cast<size_t>(__builtin_popcount(static_cast<unsigned>(in_image)));
    // Lanes out of the image index texel 0 (masked gather) and add zero.
    const __m256i ix = _mm256_cvttps_epi32(_mm256_add_ps(x, half));
    const __m256i iy = _mm256_cvttps_epi32(_mm256_add_ps(y, half));
    const __m256i zi = _mm256_and_si256(_mm256_add_epi32(_mm256_mullo_epi32(iy, width), ix), _mm256_castps_si256(live));
    const __m256 zf = _mm256_mask_i32gather_ps(zero, pp.zmap, zi, live, 4);
    const __m256 zabs = _mm256_and_ps(zf, abs_mask);
    live = _mm256_and_ps(live, _mm256_and_ps(_mm256_cmp_ps(zabs, zero, _CMP_GT_OQ),
                                             _mm256_cmp_ps(qz, _mm256_add_ps(zabs, tol), _CMP_LE_OQ)));
    if (_mm256_testz_ps(live, live)) continue;
    const __m256i fx = _mm256_sub_epi32(_mm256_cvttps_epi32(_mm256_add_ps(x, one)), ione);
    const __m256i fy = _mm256_sub_epi32(_mm256_cvttps_epi32(_mm256_add_ps(y, one)), ione);
    const __m256 ax = _mm256_sub_ps(x, _mm256_cvtepi32_ps(fx)), ay = _mm256_sub_ps(y, _mm256_cvtepi32_ps(fy));
    const __m256i x0 = _mm256_min_epi32(_mm256_max_epi32(fx, izero), wmax);
    const __m256i x1 = _mm256_min_epi32(_mm256_max_epi32(_mm256_add_epi32(fx, ione), izero), wmax);
    const __m256i y0 = _mm256_mullo_epi32(_mm256_min_epi32(_mm256_max_epi32(fy, izero), hmax), width);
    const __m256i y1 =
        _mm256_mullo_epi32(_mm256_min_epi32(_mm256_max_epi32(_mm256_add_epi32(fy, ione), izero), hmax), width);
    const __m256i live_i = _mm256_castps_si256(live);
    const __m256i t00 = _mm256_mask_i32gather_epi32(izero, rgba, _mm256_add_epi32(y0, x0), live_i, 4);
    const __m256i t10 = _mm256_mask_i32gather_epi32(izero, rgba, _mm256_add_epi32(y0, x1), live_i, 4);
    const __m256i t01 = _mm256_mask_i32gather_epi32(izero, rgba, _mm256_add_epi32(y1, x0), live_i, 4);
    const __m256i t11 = _mm256_mask_i32gather_epi32(izero, rgba, _mm256_add_epi32(y1, x1), live_i, 4);
    const __m256 kw = _mm256_and_ps(live, _mm256_blendv_ps(wt, _mm256_mul_ps(edge_w, wt),
                                                           _mm256_cmp_ps(zf, zero, _CMP_LT_OQ)));
    const __m256 ax1 = _mm256_sub_ps(one, ax), ay1 = _mm256_sub_ps(one, ay);
    // Dead lanes: kw = 0, but ax may be NaN there; mask the products.
    const __m256 w00 = _mm256_and_ps(live, _mm256_mul_ps(_mm256_mul_ps(kw, ax1), ay1));
    const __m256 w10 = _mm256_and_ps(live, _mm256_mul_ps(_mm256_mul_ps(kw, ax), ay1));
    const __m256 w01 = _mm256_and_ps(live, _mm256_mul_ps(_mm256_mul_ps(kw, ax1), ay));
    const __m256 w11 = _mm256_and_ps(live, _mm256_mul_ps(_mm256_mul_ps(kw, ax), ay));
    for (int ch = 0; ch < 4; ++ch) {
      const __m256 p00 = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(t00, 8 * ch), byte));
      const __m256 p10 = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(t10, 8 * ch), byte));
      const __m256 p01 = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(t01, 8 * ch), byte));
      const __m256 p11 = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(t11, 8 * ch), byte));
      __m256 sum = _mm256_mul_ps(w00, p00);
      sum = _mm256_add_ps(sum, _mm256_mul_ps(w10, p10));
      sum = _mm256_add_ps(sum, _mm256_mul_ps(w01, p01));
      sum = _mm256_add_ps(sum, _mm256_mul_ps(w11, p11));
      _mm256_storeu_ps(acc.f[ch] + k, _mm256_add_ps(_mm256_loadu_ps(acc.f[ch] + k), sum));
    }
    _mm256_storeu_ps(acc.f[4] + k, _mm256_add_ps(_mm256_loadu_ps(acc.f[4] + k), kw));
  }
  return samples;
}
#endif

}  // namespace

Eigen::Matrix<float, 3, 4> PodProjection(const CameraModel& camera) {
  Eigen::Matrix3f k = Eigen::Matrix3f::Identity();
  if (!camera.intrinsics.HasDistortion()) {
    k(0, 0) = static_cast<float>(camera.intrinsics.fx);
    k(1, 1) = static_cast<float>(camera.intrinsics.fy);
    k(0, 2) = static_cast<float>(camera.intrinsics.cx);
    k(1, 2) = static_cast<float>(camera.intrinsics.cy);
  }
  return k * camera.world_from_camera.inverse().matrix().topRows<3>();
}

Status BakeAtlas(const AtlasMeshInput& mesh, const std::vector<AtlasPod>& pods, const AtlasBakeOptions& options,
                 WorkerPool* pool, Atlas* out) {
  HOLO_RETURN_IF_ERROR(options.Check());
  if (!mesh.positions || !mesh.normals || !mesh.triangles || !mesh.vertex_pods || !mesh.triangle_pods) {
    return InvalidArgument("atlas bake: mesh input incomplete");
  }
  const auto& pos = *mesh.positions;
  const auto& nrm = *mesh.normals;
  const auto& tris = *mesh.triangles;
  const size_t nv = pos.size(), nt = tris.size();
  if (nrm.size() != nv || mesh.vertex_pods->size() != nv || mesh.triangle_pods->size() != nt) {
    return InvalidArgument("atlas bake: " + std::to_string(nv) + " positions but " + std::to_string(nrm.size()) +
                           " normals, " + std::to_string(mesh.vertex_pods->size()) + " vertex pod sets and " +
                           std::to_string(mesh.triangle_pods->size()) + " triangle pod sets for " +
                           std::to_string(nt) + " triangles");
  }
  const bool has_colors = mesh.colors && mesh.colors->size() == nv;
  const int n = static_cast<int>(pods.size());
  if (n > kMaxAtlasPods) return InvalidArgument("atlas bake: at most 16 pods");
  std::vector<PodInfo> info(n);
  for (int i = 0; i < n; ++i) {
    if (!pods[i].camera || !pods[i].flagged_z || !pods[i].rgba) {
      return InvalidArgument("atlas bake: pod " + std::to_string(i) + " incomplete");
    }
    const CameraModel& cam = *pods[i].camera;
    HOLO_RETURN_IF_ERROR(cam.intrinsics.Check().WithContext("atlas bake: pod " + std::to_string(i)));
    PodInfo& p = info[i];
    p.distorted = cam.intrinsics.HasDistortion();
    p.projection = PodProjection(cam);
    p.center = cam.Center();
    p.focal = static_cast<float>(cam.intrinsics.fx);
    p.width = cam.intrinsics.width;
    p.height = cam.intrinsics.height;
  }

  // Every triangle has an (L+1)² cell: a mesh whose cells would not fit
  // max_height gets L/2, L/4, … texels per edge before it is refused.
  // Texel rows the cells of L texels per edge take.
  auto height_for = [&](int l) {
    const size_t per_row = static_cast<size_t>(std::max(1, options.max_width / (l + 1)));
    return (nt + per_row - 1) / per_row * static_cast<size_t>(l + 1);
  };
  int L = options.texels_per_edge;
  while (L > 1 && height_for(L) > static_cast<size_t>(options.max_height)) L /= 2;
  out->texels_per_edge = L;
  const int cell = L + 1;
  const int cells_per_row = std::max(1, options.max_width / cell);
  const size_t rows = height_for(L) / static_cast<size_t>(cell);
  if (rows * cell > static_cast<size_t>(options.max_height)) {
    return OutOfRange("atlas bake: " + std::to_string(nt) + " triangles at " + std::to_string(L) +
                             " texels per edge need " + std::to_string(rows * cell) + " rows, more than " +
                             std::to_string(options.max_height));
  }
  out->width = nt == 0 ? 0 : static_cast<int>(std::min<size_t>(nt, cells_per_row)) * cell;
  out->height = static_cast<int>(rows) * cell;
  out->rgba.assign(static_cast<size_t>(out->width) * out->height * 4, 0);
  out->uv.resize(nt * 3);
  const float inv_w = out->width > 0 ? 1.0f / static_cast<float>(out->width) : 0.0f;
  const float inv_h = out->height > 0 ? 1.0f / static_cast<float>(out->height) : 0.0f;

  // Facing weight of every (vertex, pod) the selection kept: max(0, n·d)^α.
  std::vector<float> facing(nv * static_cast<size_t>(n), 0.0f);
  auto facing_block = [&](size_t begin, size_t end) {
    for (size_t v = begin; v < end; ++v) {
      const uint16_t bits = (*mesh.vertex_pods)[v];
      const float nn = nrm[v].norm();
      if (!(nn > 0)) continue;
      for (int i = 0; i < n; ++i) {
        if (!(bits & (1u << i))) continue;
        const Eigen::Vector3f d = info[i].center - pos[v];
        const float len = d.norm();
        if (!(len > 0)) continue;
        const float ndv = nrm[v].dot(d) / (nn * len);
        if (!(ndv > 0)) continue;
        facing[v * n + i] = options.alpha == 2.0f ? ndv * ndv : std::pow(ndv, options.alpha);
      }
    }
  };
  if (pool) {
    pool->ParallelForBlocks(nv, 4096, facing_block);
  } else {
    facing_block(0, nv);
  }

  const float tol = options.visibility_tolerance_m;
  const float edge_w = options.discontinuity_weight;
  const float min_conf = options.min_mask_confidence;
  // The cell's texels: offset, barycentrics (exact, for the position) and
  // clamped ones (for the weights and the vertex colour: the extrapolated
  // row lies just outside the triangle). One table per texel count
  // l = 1..L (a triangle small in its pods' images uses fewer texels of its
  // cell: see texels_per_pod_pixel).
  std::vector<CellTable> tables(L + 1);
  for (int l = 1; l <= L; ++l) {
    CellTable& ct = tables[l];
    for (int j = 0; j <= l; ++j) {
      for (int i = 0; i + j <= l + 1 && i <= l; ++i) {
        const float b1 = static_cast<float>(i) / static_cast<float>(l);
        const float b2 = static_cast<float>(j) / static_cast<float>(l);
        const float b0 = 1.0f - b1 - b2;
        const float c0 = std::max(b0, 0.0f), cs = c0 + b1 + b2;
        ct.i.push_back(i);
        ct.j.push_back(j);
        ct.b0.push_back(b0);
        ct.b1.push_back(b1);
        ct.b2.push_back(b2);
        ct.c0.push_back(c0 / cs);
        ct.c1.push_back(b1 / cs);
        ct.c2.push_back(b2 / cs);
      }
    }
    ct.count = static_cast<int>(ct.i.size());
    ct.padded = (ct.count + 7) / 8 * 8;
    for (auto* v : {&ct.b0, &ct.b1, &ct.b2, &ct.c0, &ct.c1, &ct.c2}) v->resize(ct.padded, 0.0f);
  }
  bool vectorized = false;
#if defined(HOLO_ATLAS_AVX2)
  vectorized = options.vectorized && CpuHasAvx2();
#endif
  const int nthreads = pool ? pool->num_threads() : 1;
  std::vector<size_t> samples(nthreads, 0), texels(nthreads, 0);
  // Per thread: the texels' accumulators (premultiplied colour, alpha,
  // weight), one cell at a time, one array per field.
  const int stride = tables[L].padded;
  std::vector<std::vector<float>> scratch(nthreads, std::vector<float>(5 * static_cast<size_t>(stride)));
  const float density = options.texels_per_pod_pixel;
  auto bake_block = [&](size_t begin, size_t end, int thread) {
    size_t my_samples = 0, my_texels = 0;
    CellAccum acc;
    for (int f = 0; f < 5; ++f) acc.f[f] = scratch[thread].data() + static_cast<size_t>(f) * stride;
    for (size_t t = begin; t < end; ++t) {
      const auto& tri = tris[t];
      const int cx = static_cast<int>(t % cells_per_row) * cell, cy = static_cast<int>(t / cells_per_row) * cell;
      const bool valid = tri[0] < nv && tri[1] < nv && tri[2] < nv;  // validated by the renderer; stay safe
      const uint16_t bits = valid ? (*mesh.triangle_pods)[t] : 0;
      // Texels along an edge: the triangle's longest edge in the image of
      // its most heavily weighted pod, times the density, 1..L.
      int l = L;
      if (density > 0) {
        int best = -1;
        float best_w = 0;
        for (int pi = 0; pi < n; ++pi) {
          if (!(bits & (1u << pi))) continue;
          const float wsum = facing[tri[0] * n + pi] + facing[tri[1] * n + pi] + facing[tri[2] * n + pi];
          if (wsum > best_w) {
            best_w = wsum;
            best = pi;
          }
        }
        if (best >= 0) {
          const PodInfo& p = info[best];
          Eigen::Vector2f px[3];
          bool ok = true;
          for (int k = 0; k < 3; ++k) {
            const Eigen::Vector3f q = p.projection * pos[tri[k]].homogeneous();
            ok &= q.z() > 0.05f;
            px[k] = q.head<2>() / std::max(q.z(), 0.05f) * (p.distorted ? p.focal : 1.0f);
          }
          if (ok) {
            const float edge = std::max({(px[1] - px[0]).norm(), (px[2] - px[1]).norm(), (px[0] - px[2]).norm()});
            l = std::clamp(static_cast<int>(std::ceil(edge * density)), 1, L);
          }
        } else {
          l = 1;
        }
      }
      const CellTable& ct = tables[l];
      out->uv[3 * t] = {(cx + 0.5f) * inv_w, (cy + 0.5f) * inv_h};
      out->uv[3 * t + 1] = {(cx + l + 0.5f) * inv_w, (cy + 0.5f) * inv_h};
      out->uv[3 * t + 2] = {(cx + 0.5f) * inv_w, (cy + l + 0.5f) * inv_h};
      if (!valid) continue;
      my_texels += static_cast<size_t>(ct.count);
      for (int f = 0; f < 5; ++f) std::fill(acc.f[f], acc.f[f] + ct.padded, 0.0f);
      // Pod by pod (its maps stay in cache), every texel of the cell.
      // Pods far weaker than the triangle's strongest add little but cost
      // as much (min_pod_weight).
      float max_sum = 0;
      for (int pi = 0; pi < n; ++pi) {
        if (bits & (1u << pi)) {
          max_sum = std::max(max_sum, facing[tri[0] * n + pi] + facing[tri[1] * n + pi] + facing[tri[2] * n + pi]);
        }
      }
      const float min_sum = options.min_pod_weight * max_sum;
      for (int pi = 0; pi < n; ++pi) {
        if (!(bits & (1u << pi))) continue;
        const float cw0 = facing[tri[0] * n + pi], cw1 = facing[tri[1] * n + pi], cw2 = facing[tri[2] * n + pi];
        if (!(cw0 > 0 || cw1 > 0 || cw2 > 0)) continue;
        if (cw0 + cw1 + cw2 < min_sum) continue;
        const PodInfo& p = info[pi];
        PodPass pp;
        pp.q0 = p.projection * pos[tri[0]].homogeneous();
        pp.q1 = p.projection * pos[tri[1]].homogeneous();
        pp.q2 = p.projection * pos[tri[2]].homogeneous();
        pp.cw0 = cw0;
        pp.cw1 = cw1;
        pp.cw2 = cw2;
        pp.zmap = pods[pi].flagged_z;
        pp.rgba = pods[pi].rgba;
        pp.w = p.width;
        pp.h = p.height;
        pp.tol = tol;
        pp.edge_w = edge_w;
#if defined(HOLO_ATLAS_AVX2)
        if (vectorized && !p.distorted) {
          my_samples += SampleCellAvx2(ct, pp, acc);
          continue;
        }
#endif
        my_samples += SampleCellPortable(ct, pp, p.distorted ? pods[pi].camera : nullptr, acc);
      }
      std::array<float, 3> vcol[3];
      for (int k = 0; k < 3; ++k) {
        for (int c = 0; c < 3; ++c) vcol[k][c] = has_colors ? (*mesh.colors)[tri[k]][c] : 180.0f;
      }
      for (int k = 0; k < ct.count; ++k) {
        const float a[5] = {acc.f[0][k], acc.f[1][k], acc.f[2][k], acc.f[3][k], acc.f[4][k]};
        const float c[3] = {ct.c0[k], ct.c1[k], ct.c2[k]};
        uint8_t* dst = &out->rgba[4 * (static_cast<size_t>(cy + ct.j[k]) * out->width + cx + ct.i[k])];
        // a[0..2] / a[3] is the unpremultiplied colour; a[3] / (255 a[4])
        // the mean mask weight of the samples.
        const float f = a[3] > 0 ? Smoothstep(min_conf, a[3] / (255.0f * a[4])) : 0.0f;
        const float inv_a = a[3] > 0 ? 255.0f / a[3] : 0.0f;
        for (int ch = 0; ch < 3; ++ch) {
          const float vc = c[0] * vcol[0][ch] + c[1] * vcol[1][ch] + c[2] * vcol[2][ch];
          const float v = vc + (a[ch] * inv_a - vc) * f;
          dst[ch] = static_cast<uint8_t>(std::clamp(v + 0.5f, 0.0f, 255.0f));
        }
        dst[3] = 255;
      }
    }
    samples[thread] += my_samples;
    texels[thread] += my_texels;
  };
  if (pool) {
    // Blocks of triangles; each writes only its own cells.
    const size_t block = 256;
    const size_t nblocks = (nt + block - 1) / block;
    pool->Run(nblocks, [&](int b, int thread) {
      const size_t begin = static_cast<size_t>(b) * block;
      bake_block(begin, std::min(nt, begin + block), thread);
    });
  } else {
    bake_block(0, nt, 0);
  }
  out->texels_baked = 0;
  out->samples = 0;
  for (size_t k : samples) out->samples += k;
  for (size_t k : texels) out->texels_baked += k;
  return OkStatus();
}

}  // namespace holo::render
