#include "texture/mesh_renderer.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace holo {
namespace {

using Eigen::Vector3f;

// Whether a pixel centre exactly on edge a→b belongs to the triangle. The
// rule is antisymmetric in the edge direction, so of two consistently
// oriented triangles sharing an edge exactly one owns the centres on it.
inline bool OwnsTies(int64_t ax, int64_t ay, int64_t bx, int64_t by) {
  const int64_t dy = by - ay;
  return dy > 0 || (dy == 0 && bx - ax < 0);
}

constexpr int kSubShift = 8;
constexpr int64_t kSub = int64_t{1} << kSubShift;  // sub-pixel steps per pixel
constexpr float kMaxCoord = 1048576.0f;  // |screen coordinate| limit, pixels

// floor for |v| < 2^31 without a libm call or SSE4.1 (truncation, then one
// down where it rounded up); equal to std::floor here since |v| < 2^28.
inline int32_t FloorToInt(float v) {
  const int32_t i = static_cast<int32_t>(v);
  return i - (static_cast<float>(i) > v);
}

inline uint8_t ToByte(float v) { return static_cast<uint8_t>(std::clamp(v + 0.5f, 0.0f, 255.0f)); }

}  // namespace

void MeshRasterizer::Rasterize(const std::vector<Vector3f>& positions,
                               const std::vector<std::array<uint32_t, 3>>& triangles, const CameraModel& camera,
                               bool want_attributes, bool cull_back_faces, float near_m) {
  const Intrinsics& k = camera.intrinsics;
  width_ = k.width;
  height_ = k.height;
  const size_t num_pixels = static_cast<size_t>(width_) * height_;
  iz_buf_.assign(num_pixels, 0.0f);
  max_iz_ = 0.0f;
  box_[0] = width_, box_[1] = height_, box_[2] = -1, box_[3] = -1;
  if (want_attributes) {
    tri_.assign(num_pixels, -1);
    b1_.resize(num_pixels);
    b2_.resize(num_pixels);
  }

  // Project every vertex once.
  const size_t n = positions.size();
  sv_.resize(n);
  siz_.resize(n);
  const Eigen::Matrix3f cam_from_world = camera.world_from_camera.linear().transpose();
  const Vector3f center = camera.world_from_camera.translation();
  const Vector3f t = -cam_from_world * center;
  const bool distorted = k.HasDistortion();
  const float fx = static_cast<float>(k.fx), fy = static_cast<float>(k.fy);
  const float cx = static_cast<float>(k.cx), cy = static_cast<float>(k.cy);
  for (size_t i = 0; i < n; ++i) {
    const Vector3f p = cam_from_world * positions[i] + t;
    ScreenXY& v = sv_[i];
    siz_[i] = 0.0f;
    v.x = v.y = 0;
    if (!(p.z() >= near_m)) continue;
    const float izv = 1.0f / p.z();
    max_iz_ = std::max(max_iz_, izv);
    float fxp, fyp;
    if (distorted) {
      Eigen::Vector2f px;
      camera.ProjectCamera(p, &px);
      fxp = px.x();
      fyp = px.y();
    } else {
      fxp = fx * p.x() * izv + cx;
      fyp = fy * p.y() * izv + cy;
    }
    // Vertices beyond ±2^20 px drop their triangles (int32/int64 safe).
    if (!(std::abs(fxp) < kMaxCoord && std::abs(fyp) < kMaxCoord)) continue;
    siz_[i] = izv;
    // Screen positions snapped to 1/256 px once per vertex: integer edge
    // functions are exact, so two triangles sharing an edge agree on every
    // pixel centre (no cracks, no double coverage).
    v.x = FloorToInt(fxp * kSub + 0.5f);
    v.y = FloorToInt(fyp * kSub + 0.5f);
  }

  // Culling in screen space: for a pinhole camera the signed screen area of
  // a triangle is n·(p0 − centre)·fx·fy / (z0·z1·z2), so front faces (n
  // towards the camera) are exactly those with area < 0. Distorted cameras
  // keep the 3D test.
  const bool screen_cull = cull_back_faces && !distorted;
  const bool world_cull = cull_back_faces && distorted;
  // First pass, branch-free: the triangles that can cover a pixel centre
  // (all vertices projected, a pixel centre inside the box, nonzero area,
  // front-facing when culling in screen space). On a mesh finer than the
  // pixels most triangles fail these tests, and as branches they are
  // mispredicted about half the time; here they only decide whether the
  // index is kept. The second pass re-tests each survivor exactly as before.
  const size_t num_tris = triangles.size();
  survivors_.resize(num_tris);
  size_t num_survivors = 0;
  {
    const int64_t xmax = width_ - 1, ymax = height_ - 1;
    const int64_t cull = screen_cull ? 1 : 0;
    uint32_t* out = survivors_.data();
    for (size_t ti = 0; ti < num_tris; ++ti) {
      const auto& tr = triangles[ti];
      const ScreenXY& v0 = sv_[tr[0]];
      const ScreenXY& v1 = sv_[tr[1]];
      const ScreenXY& v2 = sv_[tr[2]];
      const int64_t x0 = v0.x, x1 = v1.x, x2 = v2.x, y0 = v0.y, y1 = v1.y, y2 = v2.y;
      const int64_t xa = std::max<int64_t>(0, (std::min(std::min(x0, x1), x2) + kSub - 1) >> kSubShift);
      const int64_t xb = std::min<int64_t>(xmax, std::max(std::max(x0, x1), x2) >> kSubShift);
      const int64_t ya = std::max<int64_t>(0, (std::min(std::min(y0, y1), y2) + kSub - 1) >> kSubShift);
      const int64_t yb = std::min<int64_t>(ymax, std::max(std::max(y0, y1), y2) >> kSubShift);
      const int64_t area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
      // (A vertex not projected has x = y = 0 and may let its triangle
      // through here; the second pass drops it by its 1/z.)
      const bool keep = static_cast<int>(xa <= xb) & static_cast<int>(ya <= yb) &
                        static_cast<int>(area != 0) & static_cast<int>((area & ~(area >> 63) & -cull) == 0);
      out[num_survivors] = static_cast<uint32_t>(ti);
      num_survivors += keep;
    }
  }
  for (size_t si = 0; si < num_survivors; ++si) {
    const size_t ti = survivors_[si];
    const auto& tr = triangles[ti];
    const ScreenXY& v0 = sv_[tr[0]];
    const ScreenXY& v1 = sv_[tr[1]];
    const ScreenXY& v2 = sv_[tr[2]];
    const float iz0 = siz_[tr[0]], iz1 = siz_[tr[1]], iz2 = siz_[tr[2]];
    if (!(iz0 > 0.0f && iz1 > 0.0f && iz2 > 0.0f)) continue;
    int64_t x[3] = {v0.x, v1.x, v2.x}, y[3] = {v0.y, v1.y, v2.y};
    const int64_t minx = std::min({x[0], x[1], x[2]}), maxx = std::max({x[0], x[1], x[2]});
    const int64_t miny = std::min({y[0], y[1], y[2]}), maxy = std::max({y[0], y[1], y[2]});
    // Pixel centres inside the box: ceil(min / kSub) .. floor(max / kSub)
    // (arithmetic shifts round toward −∞). Most triangles of a fine mesh
    // cover no pixel centre at all and stop here.
    const int xa = static_cast<int>(std::max<int64_t>(0, (minx + kSub - 1) >> kSubShift));
    const int xb = static_cast<int>(std::min<int64_t>(width_ - 1, maxx >> kSubShift));
    if (xa > xb) continue;
    const int ya = static_cast<int>(std::max<int64_t>(0, (miny + kSub - 1) >> kSubShift));
    const int yb = static_cast<int>(std::min<int64_t>(height_ - 1, maxy >> kSubShift));
    if (ya > yb) continue;
    int64_t area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
    if (area == 0) continue;
    if (screen_cull && area > 0) continue;
    if (world_cull) {
      const Vector3f& p0 = positions[tr[0]];
      const Vector3f normal = (positions[tr[1]] - p0).cross(positions[tr[2]] - p0);
      if (normal.dot(p0 - center) >= 0.0f) continue;
    }
    float iz[3] = {iz0, iz1, iz2};
    int slot[3] = {0, 1, 2};  // original vertex of each screen vertex
    if (area < 0) {
      std::swap(x[1], x[2]);
      std::swap(y[1], y[2]);
      std::swap(iz[1], iz[2]);
      std::swap(slot[1], slot[2]);
      area = -area;
    }
    box_[0] = std::min(box_[0], xa), box_[1] = std::min(box_[1], ya);
    box_[2] = std::max(box_[2], xb), box_[3] = std::max(box_[3], yb);
    const float inv_area = 1.0f / static_cast<float>(area);
    // Edge e is opposite vertex e: e0 = 1→2, e1 = 2→0, e2 = 0→1; its function
    // E(p) = (b−a)×(p−a) is area·(barycentric of vertex e). A pixel centre
    // exactly on an edge is covered only if the edge owns ties (bias −1).
    const int ea[3] = {1, 2, 0}, eb[3] = {2, 0, 1};
    int64_t dxp[3], dyp[3], e_row[3];
    for (int e = 0; e < 3; ++e) {
      const int a = ea[e], b = eb[e];
      dxp[e] = -(y[b] - y[a]) * kSub;  // change per pixel step in x
      dyp[e] = (x[b] - x[a]) * kSub;   // per step in y
      e_row[e] = (x[b] - x[a]) * (int64_t{ya} * kSub - y[a]) - (y[b] - y[a]) * (int64_t{xa} * kSub - x[a]);
      if (!OwnsTies(x[a], y[a], x[b], y[b])) e_row[e] -= 1;
    }
    // 1/z is affine on screen: stepped per pixel in the depth-only path.
    const float diz_dx = (static_cast<float>(dxp[0]) * iz[0] + static_cast<float>(dxp[1]) * iz[1] +
                          static_cast<float>(dxp[2]) * iz[2]) * inv_area;
    for (int py = ya; py <= yb; ++py) {
      int64_t e0 = e_row[0], e1 = e_row[1], e2 = e_row[2];
      const size_t row = static_cast<size_t>(py) * width_;
      if (!want_attributes) {
        float izp = (static_cast<float>(e0) * iz[0] + static_cast<float>(e1) * iz[1] + static_cast<float>(e2) * iz[2]) *
                    inv_area;
        float* buf = iz_buf_.data() + row;
        for (int px = xa; px <= xb; ++px, e0 += dxp[0], e1 += dxp[1], e2 += dxp[2], izp += diz_dx) {
          if ((e0 | e1 | e2) < 0) continue;
          if (izp > buf[px]) buf[px] = izp;
        }
      } else {
        for (int px = xa; px <= xb; ++px, e0 += dxp[0], e1 += dxp[1], e2 += dxp[2]) {
          if ((e0 | e1 | e2) < 0) continue;
          const float l0 = static_cast<float>(e0) * inv_area, l1 = static_cast<float>(e1) * inv_area;
          const float l2 = std::max(0.0f, 1.0f - l0 - l1);
          const float izp = l0 * iz[0] + l1 * iz[1] + l2 * iz[2];
          const size_t idx = row + px;
          if (izp <= iz_buf_[idx]) continue;  // not nearer
          iz_buf_[idx] = izp;
          const float zp = 1.0f / izp;
          tri_[idx] = static_cast<int32_t>(ti);
          // Perspective-correct weight of each original vertex.
          float w[3];
          w[slot[0]] = l0 * iz[0] * zp;
          w[slot[1]] = l1 * iz[1] * zp;
          w[slot[2]] = l2 * iz[2] * zp;
          b1_[idx] = w[1];
          b2_[idx] = w[2];
        }
      }
      e_row[0] += dyp[0];
      e_row[1] += dyp[1];
      e_row[2] += dyp[2];
    }
  }
}

Status RenderMesh(const Mesh& mesh, const CameraModel& camera, ImageRgb8* color, ImageDepth16* depth,
                  ImageGray8* mask, const MeshRenderOptions& options) {
  if (Status s = camera.intrinsics.Check(); !s.ok()) return s.WithContext("RenderMesh: camera");
  if (!(options.near_m > 0.0f)) return InvalidArgument("RenderMesh: near_m must be > 0, got " + std::to_string(options.near_m));
  if (Status s = mesh.Validate(); !s.ok()) return s.WithContext("RenderMesh: mesh");
  MeshRasterizer raster;
  raster.Rasterize(mesh.positions, mesh.triangles, camera, color != nullptr, options.cull_back_faces, options.near_m);
  const int w = raster.width(), h = raster.height();
  const std::vector<float>& iz = raster.inv_z();
  if (depth) {
    depth->Resize(w, h);
    uint16_t* d = depth->data();
    for (size_t i = 0; i < iz.size(); ++i) {
      const float mm = iz[i] > 0.0f ? 1000.0f / iz[i] + 0.5f : 0.0f;
      d[i] = mm >= 65536.0f ? 0 : static_cast<uint16_t>(mm);
    }
  }
  if (mask) {
    mask->Resize(w, h);
    uint8_t* m = mask->data();
    for (size_t i = 0; i < iz.size(); ++i) m[i] = iz[i] > 0.0f ? 255 : 0;
  }
  if (color) {
    color->Resize(w, h);
    uint8_t* c = color->data();
    const bool has_colors = mesh.colors.size() == mesh.positions.size();
    const auto& ids = raster.triangle_ids();
    const auto& b1 = raster.bary1();
    const auto& b2 = raster.bary2();
    for (size_t i = 0; i < iz.size(); ++i, c += 3) {
      const int32_t t = ids[i];
      if (t < 0) {
        c[0] = options.background[0], c[1] = options.background[1], c[2] = options.background[2];
        continue;
      }
      if (!has_colors) {
        c[0] = options.default_color[0], c[1] = options.default_color[1], c[2] = options.default_color[2];
        continue;
      }
      const auto& tr = mesh.triangles[static_cast<size_t>(t)];
      const float w1 = b1[i], w2 = b2[i], w0 = 1.0f - w1 - w2;
      const auto& c0 = mesh.colors[tr[0]];
      const auto& c1 = mesh.colors[tr[1]];
      const auto& c2 = mesh.colors[tr[2]];
      for (int ch = 0; ch < 3; ++ch) c[ch] = ToByte(w0 * c0[ch] + w1 * c1[ch] + w2 * c2[ch]);
    }
  }
  return OkStatus();
}

Status RenderMesh(const Mesh& mesh, const CameraModel& camera, ImageRgb8* color, ImageDepth16* depth,
                  ImageGray8* mask) {
  return RenderMesh(mesh, camera, color, depth, mask, MeshRenderOptions{});
}

}  // namespace holo
