#include "client/render/atlas.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "common/worker_pool.h"

namespace holo::render {

Status AtlasBakeOptions::Check() const {
  if (texels_per_edge < 1 || texels_per_edge > 16) return InvalidArgument("atlas texels_per_edge must be in [1, 16]");
  if (!(texels_per_pod_pixel >= 0 && texels_per_pod_pixel <= 64)) {
    return InvalidArgument("atlas texels_per_pod_pixel must be in [0, 64]");
  }
  if (!(min_pod_weight >= 0 && min_pod_weight <= 1)) return InvalidArgument("atlas min_pod_weight must be in [0, 1]");
  if (max_width < texels_per_edge + 1 || max_height < texels_per_edge + 1) {
    return InvalidArgument("atlas max_width/max_height must hold one cell");
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

  const int L = options.texels_per_edge;
  const int cell = L + 1;
  const int cells_per_row = std::max(1, options.max_width / cell);
  const size_t rows = nt == 0 ? 0 : (nt + cells_per_row - 1) / cells_per_row;
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
  // row lies just outside the triangle).
  struct CellTexel {
    int i, j;
    float b[3], c[3];
  };
  // One table per texel count l = 1..L (a triangle small in its pods'
  // images uses fewer texels of its cell: see texels_per_pod_pixel).
  std::vector<std::vector<CellTexel>> tables(L + 1);
  for (int l = 1; l <= L; ++l) {
    for (int j = 0; j <= l; ++j) {
      for (int i = 0; i + j <= l + 1 && i <= l; ++i) {
        CellTexel ct;
        ct.i = i;
        ct.j = j;
        ct.b[1] = static_cast<float>(i) / static_cast<float>(l);
        ct.b[2] = static_cast<float>(j) / static_cast<float>(l);
        ct.b[0] = 1.0f - ct.b[1] - ct.b[2];
        const float c0 = std::max(ct.b[0], 0.0f), cs = c0 + ct.b[1] + ct.b[2];
        ct.c[0] = c0 / cs;
        ct.c[1] = ct.b[1] / cs;
        ct.c[2] = ct.b[2] / cs;
        tables[l].push_back(ct);
      }
    }
  }
  const int nthreads = pool ? pool->num_threads() : 1;
  std::vector<size_t> samples(nthreads, 0), texels(nthreads, 0);
  // Per thread: the texels' accumulators (premultiplied colour, alpha,
  // weight), one cell at a time.
  std::vector<std::vector<float>> scratch(nthreads, std::vector<float>(5 * tables[L].size()));
  const float density = options.texels_per_pod_pixel;
  auto bake_block = [&](size_t begin, size_t end, int thread) {
    size_t my_samples = 0, my_texels = 0;
    float* accum = scratch[thread].data();
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
      const std::vector<CellTexel>& cell_texels = tables[l];
      const int texels_per_cell = static_cast<int>(cell_texels.size());
      out->uv[3 * t] = {(cx + 0.5f) * inv_w, (cy + 0.5f) * inv_h};
      out->uv[3 * t + 1] = {(cx + l + 0.5f) * inv_w, (cy + 0.5f) * inv_h};
      out->uv[3 * t + 2] = {(cx + 0.5f) * inv_w, (cy + l + 0.5f) * inv_h};
      if (!valid) continue;
      my_texels += static_cast<size_t>(texels_per_cell);
      std::fill(accum, accum + 5 * texels_per_cell, 0.0f);
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
        const Eigen::Vector3f q0 = p.projection * pos[tri[0]].homogeneous();
        const Eigen::Vector3f q1 = p.projection * pos[tri[1]].homogeneous();
        const Eigen::Vector3f q2 = p.projection * pos[tri[2]].homogeneous();
        const float* zmap_data = pods[pi].flagged_z;
        const uint8_t* rgba = pods[pi].rgba;
        const int w = p.width, h = p.height;
        const float xmax = static_cast<float>(w) - 0.5f, ymax = static_cast<float>(h) - 0.5f;
        for (int k = 0; k < texels_per_cell; ++k) {
          const CellTexel& ct = cell_texels[k];
          const float wt = ct.c[0] * cw0 + ct.c[1] * cw1 + ct.c[2] * cw2;
          if (wt <= 1e-6f) continue;
          const float qz = ct.b[0] * q0.z() + ct.b[1] * q1.z() + ct.b[2] * q2.z();
          if (qz < 0.05f) continue;
          float x, y;
          if (!p.distorted) {
            const float inv = 1.0f / qz;
            x = (ct.b[0] * q0.x() + ct.b[1] * q1.x() + ct.b[2] * q2.x()) * inv;
            y = (ct.b[0] * q0.y() + ct.b[1] * q1.y() + ct.b[2] * q2.y()) * inv;
          } else {
            Eigen::Vector2f px;
            if (!pods[pi].camera->ProjectCamera(ct.b[0] * q0 + ct.b[1] * q1 + ct.b[2] * q2, &px)) continue;
            x = px.x();
            y = px.y();
          }
          if (!(x >= -0.5f && y >= -0.5f && x < xmax && y < ymax)) continue;
          ++my_samples;
          // Nearest texel of the depth map (x, y ≥ −0.5: truncation rounds).
          const int ix = static_cast<int>(x + 0.5f), iy = static_cast<int>(y + 0.5f);
          const float zf = zmap_data[static_cast<size_t>(iy) * w + ix];
          const float zabs = std::abs(zf);
          if (zabs <= 0.0f || qz > zabs + tol) continue;
          // Bilinear fetch (texel centres on integers), clamped at the border.
          const int fx = static_cast<int>(x + 1.0f) - 1, fy = static_cast<int>(y + 1.0f) - 1;  // floor, x ≥ −1
          const float ax = x - static_cast<float>(fx), ay = y - static_cast<float>(fy);
          const uint8_t *p00, *p10, *p01, *p11;
          if (fx >= 0 && fy >= 0 && fx + 1 < w && fy + 1 < h) {
            p00 = rgba + 4 * (static_cast<size_t>(fy) * w + fx);
            p10 = p00 + 4;
            p01 = p00 + 4 * static_cast<size_t>(w);
            p11 = p01 + 4;
          } else {
            const int x0 = std::clamp(fx, 0, w - 1), x1 = std::clamp(fx + 1, 0, w - 1);
            const int y0 = std::clamp(fy, 0, h - 1), y1 = std::clamp(fy + 1, 0, h - 1);
            p00 = rgba + 4 * (static_cast<size_t>(y0) * w + x0);
            p10 = rgba + 4 * (static_cast<size_t>(y0) * w + x1);
            p01 = rgba + 4 * (static_cast<size_t>(y1) * w + x0);
            p11 = rgba + 4 * (static_cast<size_t>(y1) * w + x1);
          }
          const float kw = zf < 0.0f ? edge_w * wt : wt;
          const float w00 = kw * (1 - ax) * (1 - ay), w10 = kw * ax * (1 - ay), w01 = kw * (1 - ax) * ay,
                      w11 = kw * ax * ay;
          float* a = accum + 5 * k;
#if defined(__SSE2__)
          // The four RGBA texels widened to floats four channels at a time.
          const __m128i zero = _mm_setzero_si128();
          auto texel = [&zero](const uint8_t* q) {
            int32_t v;
            std::memcpy(&v, q, 4);
            const __m128i b = _mm_unpacklo_epi8(_mm_cvtsi32_si128(v), zero);
            return _mm_cvtepi32_ps(_mm_unpacklo_epi16(b, zero));
          };
          __m128 sum = _mm_mul_ps(_mm_set1_ps(w00), texel(p00));
          sum = _mm_add_ps(sum, _mm_mul_ps(_mm_set1_ps(w10), texel(p10)));
          sum = _mm_add_ps(sum, _mm_mul_ps(_mm_set1_ps(w01), texel(p01)));
          sum = _mm_add_ps(sum, _mm_mul_ps(_mm_set1_ps(w11), texel(p11)));
          _mm_storeu_ps(a, _mm_add_ps(_mm_loadu_ps(a), sum));
#else
          for (int ch = 0; ch < 4; ++ch) {
            a[ch] += w00 * p00[ch] + w10 * p10[ch] + w01 * p01[ch] + w11 * p11[ch];
          }
#endif
          a[4] += kw;
        }
      }
      std::array<float, 3> vcol[3];
      for (int k = 0; k < 3; ++k) {
        for (int c = 0; c < 3; ++c) vcol[k][c] = has_colors ? (*mesh.colors)[tri[k]][c] : 180.0f;
      }
      for (int k = 0; k < texels_per_cell; ++k) {
        const CellTexel& ct = cell_texels[k];
        const float* a = accum + 5 * k;
        uint8_t* dst = &out->rgba[4 * (static_cast<size_t>(cy + ct.j) * out->width + cx + ct.i)];
        // a[0..2] / a[3] is the unpremultiplied colour; a[3] / (255 a[4])
        // the mean mask weight of the samples.
        const float f = a[3] > 0 ? Smoothstep(min_conf, a[3] / (255.0f * a[4])) : 0.0f;
        const float inv_a = a[3] > 0 ? 255.0f / a[3] : 0.0f;
        for (int ch = 0; ch < 3; ++ch) {
          const float vc = ct.c[0] * vcol[0][ch] + ct.c[1] * vcol[1][ch] + ct.c[2] * vcol[2][ch];
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
