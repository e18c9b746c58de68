#include "studio/render.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/status.h"

namespace holo::studio {
namespace {

using Eigen::Vector3f;

constexpr float kNear = 0.05f;
constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kShadowTexel = 0.004f;  // metres
constexpr int kShadowMaxSize = 1536;
constexpr float kNormalOffset = 0.008f; // metres along the surface normal

// Inverse CDF of the standard normal at (i + 0.5) / 4096.
struct GaussTable {
  float v[4096];
  GaussTable() {
    for (int i = 0; i < 4096; ++i) {
      const double p = (i + 0.5) / 4096.0;
      double lo = -8, hi = 8;
      for (int it = 0; it < 60; ++it) {
        const double mid = 0.5 * (lo + hi);
        (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p ? lo : hi) = mid;
      }
      v[i] = static_cast<float>(0.5 * (lo + hi));
    }
  }
};
const GaussTable& Gauss() {
  static const GaussTable table;
  return table;
}

inline uint8_t ToByte(float v) { return static_cast<uint8_t>(std::clamp(v * 255.0f + 0.5f, 0.0f, 255.0f)); }

inline uint16_t ToMm(float z) {
  if (!(z > 0.0f) || z > 65.535f) return 0;
  return static_cast<uint16_t>(z * 1000.0f + 0.5f);
}

}  // namespace

void ShadowMap::Prepare(const std::vector<Vector3f>& positions) {
  l = LightDirection();
  e1 = l.cross(Vector3f::UnitZ()).normalized();
  e2 = l.cross(e1).normalized();
  w = h = 0;
  if (positions.empty()) return;
  float umin = kInf, umax = -kInf, vmin = kInf, vmax = -kInf;
  for (const auto& p : positions) {
    const float u = e1.dot(p), v = e2.dot(p);
    umin = std::min(umin, u), umax = std::max(umax, u);
    vmin = std::min(vmin, v), vmax = std::max(vmax, v);
  }
  float texel = kShadowTexel;
  const float extent = std::max(umax - umin, vmax - vmin);
  if (extent / texel > kShadowMaxSize - 4) texel = extent / (kShadowMaxSize - 4);
  inv_texel = 1.0f / texel;
  u0 = umin - 2 * texel;
  v0 = vmin - 2 * texel;
  w = static_cast<int>((umax - u0) * inv_texel) + 3;
  h = static_cast<int>((vmax - v0) * inv_texel) + 3;
  depth.assign(static_cast<size_t>(w) * h, -kInf);
}

void ShadowMap::Build(const std::vector<Vector3f>& positions, const std::vector<std::array<uint32_t, 3>>& triangles) {
  Prepare(positions);
  Rasterize(positions, triangles, 0, h);
}

void ShadowMap::Rasterize(const std::vector<Vector3f>& positions,
                          const std::vector<std::array<uint32_t, 3>>& triangles, int row_begin, int row_end) {
  // Orthographic rasterization, both faces, keeping the surface nearest the light.
  for (const auto& t : triangles) {
    float x[3], y[3], d[3];
    for (int k = 0; k < 3; ++k) {
      const Vector3f& p = positions[t[k]];
      x[k] = (e1.dot(p) - u0) * inv_texel - 0.5f;
      y[k] = (e2.dot(p) - v0) * inv_texel - 0.5f;
      d[k] = l.dot(p);
    }
    const float area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
    if (std::abs(area) < 1e-12f) continue;
    const float ia = 1.0f / area;
    const int xa = std::max(0, static_cast<int>(std::ceil(std::min({x[0], x[1], x[2]}))));
    const int xb = std::min(w - 1, static_cast<int>(std::floor(std::max({x[0], x[1], x[2]}))));
    const int ya = std::max(row_begin, static_cast<int>(std::ceil(std::min({y[0], y[1], y[2]}))));
    const int yb = std::min(row_end - 1, static_cast<int>(std::floor(std::max({y[0], y[1], y[2]}))));
    for (int py = ya; py <= yb; ++py) {
      float* row = depth.data() + static_cast<size_t>(py) * w;
      for (int px = xa; px <= xb; ++px) {
        const float l0 = ((x[2] - x[1]) * (py - y[1]) - (y[2] - y[1]) * (px - x[1])) * ia;
        const float l1 = ((x[0] - x[2]) * (py - y[2]) - (y[0] - y[2]) * (px - x[2])) * ia;
        const float l2 = 1.0f - l0 - l1;
        if (l0 < -1e-5f || l1 < -1e-5f || l2 < -1e-5f) continue;
        const float dd = l0 * d[0] + l1 * d[1] + l2 * d[2];
        if (dd > row[px]) row[px] = dd;
      }
    }
  }
}

void ViewCache::Init(const CameraModel& cam) {
  camera = cam;
  const Intrinsics& k = cam.intrinsics;
  distorted = k.HasDistortion();
  render = k;
  render.distortion = {0, 0, 0, 0, 0};
  std::vector<Eigen::Vector2f> undist;
  if (distorted) {
    // Render a pinhole image (same focal lengths) large enough to hold every
    // output pixel's ray, then remap.
    undist.resize(static_cast<size_t>(k.width) * k.height);
    double xmin = 1e9, xmax = -1e9, ymin = 1e9, ymax = -1e9;
    for (int y = 0; y < k.height; ++y)
      for (int x = 0; x < k.width; ++x) {
        const Eigen::Vector2d n = Undistort(k.distortion, {(x - k.cx) / k.fx, (y - k.cy) / k.fy});
        undist[static_cast<size_t>(y) * k.width + x] = n.cast<float>();
        xmin = std::min(xmin, n.x()), xmax = std::max(xmax, n.x());
        ymin = std::min(ymin, n.y()), ymax = std::max(ymax, n.y());
      }
    xmin = std::max(xmin, -(k.cx + 0.5 * k.width) / k.fx);
    xmax = std::min(xmax, (1.5 * k.width - k.cx) / k.fx);
    ymin = std::max(ymin, -(k.cy + 0.5 * k.height) / k.fy);
    ymax = std::min(ymax, (1.5 * k.height - k.cy) / k.fy);
    render.cx = -xmin * k.fx + 1.0;
    render.cy = -ymin * k.fy + 1.0;
    render.width = static_cast<int>(std::ceil((xmax - xmin) * k.fx)) + 3;
    render.height = static_cast<int>(std::ceil((ymax - ymin) * k.fy)) + 3;
    remap.assign(undist.size(), -1);
    for (size_t i = 0; i < undist.size(); ++i) {
      const long rx = std::lround(render.fx * undist[i].x() + render.cx);
      const long ry = std::lround(render.fy * undist[i].y() + render.cy);
      if (rx >= 0 && ry >= 0 && rx < render.width && ry < render.height)
        remap[i] = static_cast<int32_t>(ry * render.width + rx);
    }
  } else {
    remap.clear();
  }
  const Eigen::Matrix3f world_from_cam = cam.world_from_camera.linear();
  center = cam.world_from_camera.translation();
  cam_from_world = world_from_cam.transpose();
  cam_from_world_t = -cam_from_world * center;
  // Light coordinates of p = center + z·R·(xn, yn, 1).
  const Vector3f l = LightDirection();
  const Vector3f e1 = l.cross(Vector3f::UnitZ()).normalized();
  const Vector3f e2 = l.cross(e1).normalized();
  light_c = Vector3f(e1.dot(center), e2.dot(center), l.dot(center));
  light_g.row(0) = (cam_from_world * e1).transpose();
  light_g.row(1) = (cam_from_world * e2).transpose();
  light_g.row(2) = (cam_from_world * l).transpose();

  const size_t n = static_cast<size_t>(render.width) * render.height;
  bg_z.assign(n, kInf);
  bg_cos.assign(n, 0.0f);
  bg_lit.assign(n, {0, 0, 0});
  bg_dark.assign(n, {0, 0, 0});
  for (int y = 0; y < render.height; ++y)
    for (int x = 0; x < render.width; ++x) {
      const Vector3f dc(static_cast<float>((x - render.cx) / render.fx), static_cast<float>((y - render.cy) / render.fy),
                        1.0f);
      const Vector3f dw = world_from_cam * dc;
      const float len = dw.norm();
      const Vector3f dir = dw / len;
      RoomHit hit;
      if (!IntersectRoom(center, dir, &hit)) continue;
      const size_t i = static_cast<size_t>(y) * render.width + x;
      bg_z[i] = hit.t / len;
      bg_cos[i] = std::abs(hit.normal.dot(dir));
      const float ndl = std::max(0.0f, hit.normal.dot(l));
      const Vector3f lit = hit.albedo * (kAmbient + kDiffuse * ndl), dark = hit.albedo * kAmbient;
      bg_lit[i] = {ToByte(lit.x()), ToByte(lit.y()), ToByte(lit.z())};
      bg_dark[i] = {ToByte(dark.x()), ToByte(dark.y()), ToByte(dark.z())};
    }
}

void RenderViewCore(const ViewCache& view, const SceneTemplate& tmpl, const FrameScene& scene, bool shade_color,
                    RenderScratch* s) {
  const Intrinsics& k = view.render;
  const int W = k.width, H = k.height;
  const size_t n = static_cast<size_t>(W) * H;
  const float fx = static_cast<float>(k.fx), fy = static_cast<float>(k.fy);
  const float cx = static_cast<float>(k.cx), cy = static_cast<float>(k.cy);

  // Project vertices.
  const size_t nv = scene.positions.size();
  s->sx.resize(nv), s->sy.resize(nv), s->siz.resize(nv), s->vok.resize(nv);
  const Eigen::Matrix3f& R = view.cam_from_world;
  const Vector3f& t = view.cam_from_world_t;
  for (size_t i = 0; i < nv; ++i) {
    const Vector3f p = R * scene.positions[i] + t;
    if (p.z() < kNear) {
      s->vok[i] = 0;
      continue;
    }
    const float iz = 1.0f / p.z();
    s->vok[i] = 1;
    s->siz[i] = iz;
    s->sx[i] = fx * p.x() * iz + cx;
    s->sy[i] = fy * p.y() * iz + cy;
  }

  // Visibility buffer, initialised with the room.
  s->z.assign(view.bg_z.begin(), view.bg_z.end());
  s->id.assign(n, -1);
  s->b1.resize(n), s->b2.resize(n);
  float* zb = s->z.data();
  int32_t* idb = s->id.data();
  float* b1b = s->b1.data();
  float* b2b = s->b2.data();
  const int ntri = static_cast<int>(tmpl.triangles.size());
  for (int ti = 0; ti < ntri; ++ti) {
    const auto& tri = tmpl.triangles[ti];
    const uint32_t i0 = tri[0], i1 = tri[1], i2 = tri[2];
    if (!(s->vok[i0] & s->vok[i1] & s->vok[i2])) continue;
    const float x0 = s->sx[i0], y0 = s->sy[i0], x1 = s->sx[i1], y1 = s->sy[i1], x2 = s->sx[i2], y2 = s->sy[i2];
    const float area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    // Counter-clockwise seen from outside is clockwise in a y-down image.
    if (!(area < -1e-9f)) continue;
    const int xa = std::max(0, static_cast<int>(std::ceil(std::min({x0, x1, x2}))));
    const int xb = std::min(W - 1, static_cast<int>(std::floor(std::max({x0, x1, x2}))));
    if (xa > xb) continue;
    const int ya = std::max(0, static_cast<int>(std::ceil(std::min({y0, y1, y2}))));
    const int yb = std::min(H - 1, static_cast<int>(std::floor(std::max({y0, y1, y2}))));
    if (ya > yb) continue;
    const float ia = 1.0f / area;
    // l_k(x, y) = a_k x + b_k y + c_k, normalised barycentrics.
    const float a0 = -(y2 - y1) * ia, b0 = (x2 - x1) * ia, c0 = -(a0 * x1 + b0 * y1);
    const float a1 = -(y0 - y2) * ia, b1 = (x0 - x2) * ia, c1 = -(a1 * x2 + b1 * y2);
    const float iz0 = s->siz[i0], iz1 = s->siz[i1], iz2 = s->siz[i2];
    constexpr float kEps = -1e-5f;
    for (int py = ya; py <= yb; ++py) {
      float l0 = a0 * xa + b0 * py + c0;
      float l1 = a1 * xa + b1 * py + c1;
      const size_t row = static_cast<size_t>(py) * W;
      for (int px = xa; px <= xb; ++px, l0 += a0, l1 += a1) {
        const float l2 = 1.0f - l0 - l1;
        if (l0 < kEps || l1 < kEps || l2 < kEps) continue;
        const float iz = l0 * iz0 + l1 * iz1 + l2 * iz2;
        const float z = 1.0f / iz;
        const size_t p = row + px;
        if (z < zb[p]) {
          zb[p] = z;
          idb[p] = ti;
          b1b[p] = l1 * iz1 * z;
          b2b[p] = l2 * iz2 * z;
        }
      }
    }
  }

  // Deferred shading.
  s->cosg.resize(n);
  s->fg.resize(n);
  if (shade_color) s->rgb.resize(n * 3);
  const Vector3f light = LightDirection();
  const ShadowMap& sm = scene.shadow;
  const Vector3f gx = view.light_g.col(0) / fx;  // change of g per pixel in x
  for (int py = 0; py < H; ++py) {
    const float yn = (py - cy) / fy;
    // g(px) = light_g·(xn, yn, 1), advanced incrementally along the row.
    Vector3f g = view.light_g * Vector3f(-cx / fx, yn, 1.0f);
    for (int px = 0; px < W; ++px, g += gx) {
      const size_t p = static_cast<size_t>(py) * W + px;
      const int32_t ti = idb[p];
      if (ti < 0) {
        s->fg[p] = 0;
        s->cosg[p] = view.bg_cos[p];
        if (!shade_color) continue;
        const auto& lit = view.bg_lit[p];
        float vis = 1.0f;
        if (sm.w > 0 && zb[p] < kInf) {
          const Vector3f lc = view.light_c + zb[p] * g;
          vis = sm.Visibility(lc.x(), lc.y(), lc.z());
        }
        uint8_t* out = &s->rgb[p * 3];
        if (vis >= 1.0f) {
          out[0] = lit[0], out[1] = lit[1], out[2] = lit[2];
        } else {
          const auto& dark = view.bg_dark[p];
          for (int c = 0; c < 3; ++c)
            out[c] = static_cast<uint8_t>(dark[c] + vis * (lit[c] - dark[c]) + 0.5f);
        }
        continue;
      }
      s->fg[p] = 1;
      const auto& tri = tmpl.triangles[ti];
      const float w1 = b1b[p], w2 = b2b[p], w0 = 1.0f - w1 - w2;
      const Vector3f pos = w0 * scene.positions[tri[0]] + w1 * scene.positions[tri[1]] + w2 * scene.positions[tri[2]];
      Vector3f nrm = w0 * scene.normals[tri[0]] + w1 * scene.normals[tri[1]] + w2 * scene.normals[tri[2]];
      nrm.normalize();
      const Vector3f to_cam = (view.center - pos).normalized();
      s->cosg[p] = std::abs(nrm.dot(to_cam));
      if (!shade_color) continue;
      const Vector3f tex = w0 * tmpl.tex[tri[0]] + w1 * tmpl.tex[tri[1]] + w2 * tmpl.tex[tri[2]];
      const Vector3f albedo = Albedo(tmpl.tri_material[ti], tmpl.tri_palette[ti], tex);
      const float ndl = nrm.dot(light);
      float shade = kAmbient;
      if (ndl > 0.0f) shade += kDiffuse * ndl * sm.Visibility(pos + kNormalOffset * nrm);
      uint8_t* out = &s->rgb[p * 3];
      out[0] = ToByte(albedo.x() * shade);
      out[1] = ToByte(albedo.y() * shade);
      out[2] = ToByte(albedo.z() * shade);
    }
  }

  if (!view.distorted) {
    s->out_z = s->z.data();
    s->out_cos = s->cosg.data();
    s->out_fg = s->fg.data();
    s->out_rgb = shade_color ? s->rgb.data() : nullptr;
    return;
  }
  // Nearest-neighbour remap into the distorted output image.
  const size_t no = view.remap.size();
  s->oz.resize(no), s->ocos.resize(no), s->ofg.resize(no);
  if (shade_color) s->orgb.resize(no * 3);
  for (size_t i = 0; i < no; ++i) {
    const int32_t r = view.remap[i];
    if (r < 0) {
      s->oz[i] = kInf, s->ocos[i] = 0, s->ofg[i] = 0;
      if (shade_color) s->orgb[i * 3] = s->orgb[i * 3 + 1] = s->orgb[i * 3 + 2] = 0;
      continue;
    }
    s->oz[i] = s->z[r], s->ocos[i] = s->cosg[r], s->ofg[i] = s->fg[r];
    if (shade_color)
      for (int c = 0; c < 3; ++c) s->orgb[i * 3 + c] = s->rgb[static_cast<size_t>(r) * 3 + c];
  }
  s->out_z = s->oz.data();
  s->out_cos = s->ocos.data();
  s->out_fg = s->ofg.data();
  s->out_rgb = shade_color ? s->orgb.data() : nullptr;
}

ColorVariation PodColorVariation(uint64_t seed, int pod_id) {
  ColorVariation v;
  for (int c = 0; c < 3; ++c) {
    const uint64_t h = HashOf(seed, 0xC0104ULL, static_cast<uint64_t>(pod_id), static_cast<uint64_t>(c));
    v.gain[c] = 0.85f + 0.30f * static_cast<float>(h & 0xffff) / 65535.0f;
    v.offset[c] = -10.0f + 20.0f * static_cast<float>((h >> 16) & 0xffff) / 65535.0f;
  }
  return v;
}

namespace {
template <typename Img>
void EnsureSize(Img* img, int w, int h) {
  if (img->width() != w || img->height() != h) img->Resize(w, h);
}
}  // namespace

void WriteColor(const ViewCache& view, const RenderScratch& s, const ColorVariation* variation, ImageRgb8* color) {
  const int W = view.camera.intrinsics.width, H = view.camera.intrinsics.height;
  EnsureSize(color, W, H);
  const size_t n = static_cast<size_t>(W) * H * 3;
  uint8_t* out = color->data();
  if (!variation) {
    std::copy(s.out_rgb, s.out_rgb + n, out);
    return;
  }
  // A lookup table per channel: the variation is affine in the input value.
  uint8_t lut[3][256];
  for (int c = 0; c < 3; ++c)
    for (int v = 0; v < 256; ++v)
      lut[c][v] = static_cast<uint8_t>(std::clamp(variation->gain[c] * v + variation->offset[c] + 0.5f, 0.0f, 255.0f));
  for (size_t i = 0; i < n; i += 3) {
    out[i] = lut[0][s.out_rgb[i]];
    out[i + 1] = lut[1][s.out_rgb[i + 1]];
    out[i + 2] = lut[2][s.out_rgb[i + 2]];
  }
}

void WriteTruth(const ViewCache& view, const RenderScratch& s, ImageDepth16* depth, ImageGray8* mask) {
  const int W = view.camera.intrinsics.width, H = view.camera.intrinsics.height;
  const size_t n = static_cast<size_t>(W) * H;
  if (depth) {
    EnsureSize(depth, W, H);
    uint16_t* d = depth->data();
    for (size_t i = 0; i < n; ++i) d[i] = ToMm(s.out_z[i]);
  }
  if (mask) {
    EnsureSize(mask, W, H);
    uint8_t* m = mask->data();
    for (size_t i = 0; i < n; ++i) m[i] = s.out_fg[i] ? 255 : 0;
  }
}

void WriteNoisyDepth(const ViewCache& view, const RenderScratch& s, const DepthNoiseOptions& noise, uint64_t stream,
                     ImageDepth16* depth) {
  const int W = view.camera.intrinsics.width, H = view.camera.intrinsics.height;
  EnsureSize(depth, W, H);
  const float* z = s.out_z;
  const float* cosg = s.out_cos;
  uint16_t* out = depth->data();
  const float* gauss = Gauss().v;
  constexpr float kDegF = 3.14159265f / 180.0f;
  const float ramp_start = std::max(0.0f, noise.grazing_dropout_deg - 10.0f);
  const float cos_start = std::cos(ramp_start * kDegF);
  // Drop when the angle exceeds ramp_start + 10°·u, i.e. cos < cos_drop[u].
  float cos_drop[1024];
  for (int i = 0; i < 1024; ++i)
    cos_drop[i] = std::cos(std::min(90.0f, ramp_start + 10.0f * (i + 0.5f) / 1024.0f) * kDegF);
  const uint32_t dropout_threshold = static_cast<uint32_t>(noise.random_dropout_prob * 1048576.0f);
  const float edge_m = noise.flying_edge_mm * 0.001f;
  const uint32_t fly_threshold = static_cast<uint32_t>(noise.flying_pixel_prob * 1024.0f);
  const float sigma1 = noise.sigma_at_1m_mm;
  const float max_range = noise.max_range_m;
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const size_t p = static_cast<size_t>(y) * W + x;
      float zz = z[p];
      if (!(zz < kInf) || zz > max_range) {
        out[p] = 0;
        continue;
      }
      const uint64_t h = Mix64(stream + p * 0x9e3779b97f4a7c15ULL);
      if (static_cast<uint32_t>(h & 0xfffff) < dropout_threshold) {
        out[p] = 0;
        continue;
      }
      const float c = cosg[p];
      if (c < cos_start && c < cos_drop[(h >> 20) & 0x3ff]) {
        out[p] = 0;
        continue;
      }
      // Mixed pixel at a depth edge: somewhere between the two surfaces.
      // Fast test first (branch-free); the rare edge pixels take the slow path.
      const float dl = x > 0 ? std::abs(z[p - (x > 0)] - zz) : 0.0f;
      const float dr = x + 1 < W ? std::abs(z[p + (x + 1 < W)] - zz) : 0.0f;
      const float du = y > 0 ? std::abs(z[p - (y > 0) * W] - zz) : 0.0f;
      const float dd = y + 1 < H ? std::abs(z[p + (y + 1 < H) * W] - zz) : 0.0f;
      if (std::max(std::max(dl, dr), std::max(du, dd)) > edge_m &&
          static_cast<uint32_t>((h >> 30) & 0x3ff) < fly_threshold) {
        float zn = zz, best = 0.0f;
        auto consider = [&](size_t q) {
          const float d = std::abs(z[q] - zz);
          if (z[q] < kInf && d > best) best = d, zn = z[q];
        };
        if (x > 0) consider(p - 1);
        if (x + 1 < W) consider(p + 1);
        if (y > 0) consider(p - W);
        if (y + 1 < H) consider(p + W);
        if (best > edge_m) zz += (static_cast<float>((h >> 40) & 0x3ff) + 0.5f) / 1024.0f * (zn - zz);
      }
      const float mm = zz * 1000.0f + sigma1 * zz * zz * gauss[(h >> 50) & 0xfff];
      out[p] = (mm >= 0.5f && mm < 65535.0f && zz <= max_range) ? static_cast<uint16_t>(mm + 0.5f) : 0;
    }
  }
}

}  // namespace holo::studio
