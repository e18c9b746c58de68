#include "client/reproject/reproject.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace holo::reproject {
namespace {

// Bilinear sample of `img` at pixel coordinates (x, y), clamped to the
// image (callers pass points inside the half-pixel rim).
inline void Sample(const ImageRgb8& img, float x, float y, uint8_t* out) {
  const int w = img.width(), h = img.height();
  x = std::clamp(x, 0.0f, static_cast<float>(w - 1));
  y = std::clamp(y, 0.0f, static_cast<float>(h - 1));
  const int x0 = std::min(static_cast<int>(x), w - 2);
  const int y0 = std::min(static_cast<int>(y), h - 2);
  const float ax = x - x0, ay = y - y0;
  const uint8_t* p = img.data() + (static_cast<size_t>(y0) * w + x0) * 3;
  const uint8_t* q = p + static_cast<size_t>(w) * 3;
  for (int c = 0; c < 3; ++c) {
    const float top = p[c] + ax * (p[c + 3] - p[c]);
    const float bot = q[c] + ax * (q[c + 3] - q[c]);
    out[c] = static_cast<uint8_t>(top + ay * (bot - top) + 0.5f);  // in [0, 255]: a convex combination
  }
}

// Catmull-Rom weights for fractional position `t` in [0, 1).
inline void CubicWeights(float t, float w[4]) {
  const float t2 = t * t, t3 = t2 * t;
  w[0] = 0.5f * (-t3 + 2 * t2 - t);
  w[1] = 0.5f * (3 * t3 - 5 * t2 + 2);
  w[2] = 0.5f * (-3 * t3 + 4 * t2 + t);
  w[3] = 0.5f * (t3 - t2);
}

// Bicubic (Catmull-Rom) sample, edges clamped. Sharper than bilinear: a
// sub-pixel shift keeps most of the image's detail.
inline void SampleCubic(const ImageRgb8& img, float x, float y, uint8_t* out) {
  const int w = img.width(), h = img.height();
  x = std::clamp(x, 0.0f, static_cast<float>(w - 1));
  y = std::clamp(y, 0.0f, static_cast<float>(h - 1));
  const int ix = static_cast<int>(x), iy = static_cast<int>(y);
  float wx[4], wy[4];
  CubicWeights(x - ix, wx);
  CubicWeights(y - iy, wy);
  float acc[3] = {0, 0, 0};
  for (int j = 0; j < 4; ++j) {
    const uint8_t* row = img.row(std::clamp(iy - 1 + j, 0, h - 1));
    float r[3] = {0, 0, 0};
    for (int i = 0; i < 4; ++i) {
      const uint8_t* p = row + 3 * std::clamp(ix - 1 + i, 0, w - 1);
      r[0] += wx[i] * p[0];
      r[1] += wx[i] * p[1];
      r[2] += wx[i] * p[2];
    }
    acc[0] += wy[j] * r[0];
    acc[1] += wy[j] * r[1];
    acc[2] += wy[j] * r[2];
  }
  for (int c = 0; c < 3; ++c) out[c] = static_cast<uint8_t>(std::clamp(acc[c] + 0.5f, 0.0f, 255.0f));
}

inline void SampleWith(ReprojectFilter f, const ImageRgb8& img, float x, float y, uint8_t* out) {
  if (f == ReprojectFilter::kBicubic) {
    SampleCubic(img, x, y, out);
  } else {
    Sample(img, x, y, out);
  }
}

// Source pixel coordinates are inside the image, including the half-pixel
// rim the image edges cover.
inline bool InSource(float x, float y, int w, int h) {
  return x >= -0.5f && y >= -0.5f && x <= w - 0.5f && y <= h - 0.5f;
}

struct Relative {
  Eigen::Matrix3f r;  // source_from_target rotation
  Eigen::Vector3f t;  // source_from_target translation (target centre in source coordinates)
};

Relative SourceFromTarget(const CameraModel& source, const CameraModel& target) {
  const Pose s = source.world_from_camera.inverse() * target.world_from_camera;
  return {s.linear(), s.translation()};
}

}  // namespace

const char* ReprojectMethodName(ReprojectMethod m) {
  switch (m) {
    case ReprojectMethod::kNone: return "none";
    case ReprojectMethod::kRotation: return "rotation";
    case ReprojectMethod::kPlane: return "plane";
    case ReprojectMethod::kDepth: return "depth";
  }
  return "?";
}

StatusOr<ReprojectMethod> ParseReprojectMethod(const std::string& name) {
  for (ReprojectMethod m : {ReprojectMethod::kNone, ReprojectMethod::kRotation, ReprojectMethod::kPlane,
                            ReprojectMethod::kDepth}) {
    if (name == ReprojectMethodName(m)) return m;
  }
  return InvalidArgument("unknown reprojection method '" + name + "' (known: none, rotation, plane, depth)");
}

Status ReprojectOptions::Check() const {
  if (!std::isfinite(plane_distance_m) || !(plane_distance_m > 0.01f)) {
    return InvalidArgument("plane_distance_m must be > 0.01, got " + std::to_string(plane_distance_m));
  }
  return OkStatus();
}

float MedianDepthM(const ImageDepth16& depth, float fallback) {
  std::vector<uint16_t> v;
  v.reserve(depth.num_pixels() / 4);
  for (uint16_t d : depth.storage()) {
    if (d) v.push_back(d);
  }
  if (v.empty()) return fallback;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2] * 1e-3f;
}

Status Reproject(const ImageRgb8& source, const ImageDepth16* source_depth, const CameraModel& source_camera,
                 const CameraModel& target_camera, const ReprojectOptions& options, ImageRgb8* out,
                 ImageGray8* valid, ReprojectStats* stats) {
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_RETURN_IF_ERROR(source_camera.intrinsics.Check().WithContext("source camera"));
  HOLO_RETURN_IF_ERROR(target_camera.intrinsics.Check().WithContext("target camera"));
  if (source_camera.intrinsics.HasDistortion() || target_camera.intrinsics.HasDistortion()) {
    return InvalidArgument("Reproject: cameras must be undistorted pinholes");
  }
  const int sw = source.width(), sh = source.height();
  if (sw != source_camera.intrinsics.width || sh != source_camera.intrinsics.height || sw < 2 || sh < 2) {
    return InvalidArgument("Reproject: source image " + std::to_string(sw) + "x" + std::to_string(sh) +
                           " does not match the source camera " + std::to_string(source_camera.intrinsics.width) +
                           "x" + std::to_string(source_camera.intrinsics.height));
  }
  const bool has_depth = source_depth != nullptr && !source_depth->empty();
  if (has_depth && (source_depth->width() != sw || source_depth->height() != sh)) {
    return InvalidArgument("Reproject: source depth size differs from the source image");
  }
  if (options.method == ReprojectMethod::kDepth && !has_depth) {
    return InvalidArgument("Reproject: method depth needs the source depth");
  }
  if (out == nullptr) return InvalidArgument("Reproject: null output");

  const Intrinsics& ks = source_camera.intrinsics;
  const Intrinsics& kt = target_camera.intrinsics;
  const int tw = kt.width, th = kt.height;
  out->Resize(tw, th);
  ImageGray8 local_valid;
  ImageGray8& ok = valid ? *valid : local_valid;
  ok.Resize(tw, th);

  Relative rel = SourceFromTarget(source_camera, target_camera);
  if (options.method == ReprojectMethod::kNone) rel = {Eigen::Matrix3f::Identity(), Eigen::Vector3f::Zero()};
  const bool use_plane = options.method == ReprojectMethod::kPlane;
  float plane_z = options.plane_distance_m;
  if (use_plane && has_depth) plane_z = MedianDepthM(*source_depth, options.plane_distance_m);
  const float fxs = static_cast<float>(ks.fx), fys = static_cast<float>(ks.fy);
  const float cxs = static_cast<float>(ks.cx), cys = static_cast<float>(ks.cy);

  // Inverse mapping target pixel → source pixel for the rotation / plane
  // part (the background in the depth method).
  size_t border = 0;
  for (int y = 0; y < th; ++y) {
    uint8_t* orow = out->row(y);
    uint8_t* vrow = ok.row(y);
    const float ry = static_cast<float>((y - kt.cy) / kt.fy);
    for (int x = 0; x < tw; ++x) {
      const float rx = static_cast<float>((x - kt.cx) / kt.fx);
      const Eigen::Vector3f d = rel.r * Eigen::Vector3f(rx, ry, 1.0f);  // ray direction, source frame
      Eigen::Vector3f p;
      bool hit = true;
      if (use_plane) {
        // Ray from the target centre (rel.t) to the plane z = plane_z.
        const float lambda = d.z() > 1e-6f ? (plane_z - rel.t.z()) / d.z() : -1.0f;
        if (lambda > 0) {
          p = rel.t + lambda * d;
        } else {
          p = d;  // target beyond the plane or ray parallel: fall back to rotation
        }
      } else {
        p = d;
      }
      float sx = 0, sy = 0;
      if (p.z() > 1e-6f) {
        sx = fxs * p.x() / p.z() + cxs;
        sy = fys * p.y() / p.z() + cys;
        hit = InSource(sx, sy, sw, sh);
      } else {
        hit = false;
      }
      if (hit) {
        SampleWith(options.filter, source, sx, sy, orow + 3 * x);
        vrow[x] = 255;
      } else {
        orow[3 * x] = options.fill[0];
        orow[3 * x + 1] = options.fill[1];
        orow[3 * x + 2] = options.fill[2];
        vrow[x] = 0;
        ++border;
      }
    }
  }

  size_t holes = 0;
  if (options.method == ReprojectMethod::kDepth) {
    // Forward splat of every source pixel with depth: z-buffer of target z
    // and the (sub-pixel) source coordinate each target pixel takes.
    const Relative tfs{rel.r.transpose(), -(rel.r.transpose() * rel.t)};  // target_from_source
    const float fxt = static_cast<float>(kt.fx), fyt = static_cast<float>(kt.fy);
    const float cxt = static_cast<float>(kt.cx), cyt = static_cast<float>(kt.cy);
    std::vector<float> zbuf(static_cast<size_t>(tw) * th, std::numeric_limits<float>::infinity());
    std::vector<float> src_x(zbuf.size()), src_y(zbuf.size());
    for (int y = 0; y < sh; ++y) {
      const uint16_t* drow = source_depth->row(y);
      for (int x = 0; x < sw; ++x) {
        if (drow[x] == 0) continue;
        const float zs = drow[x] * 1e-3f;
        const Eigen::Vector3f ps((x - cxs) / fxs * zs, (y - cys) / fys * zs, zs);
        const Eigen::Vector3f pt = tfs.r * ps + tfs.t;
        if (pt.z() < 0.05f) continue;
        const float u = fxt * pt.x() / pt.z() + cxt, v = fyt * pt.y() / pt.z() + cyt;
        // Footprint: half the source pixel's size on the target, at least
        // half a pixel (no cracks at 1:1), at most 2 pixels.
        const float scale = std::clamp(0.5f * (fxt / fxs) * (zs / pt.z()) + 0.1f, 0.6f, 2.0f);
        const int x0 = std::max(0, static_cast<int>(std::ceil(u - scale)));
        const int x1 = std::min(tw - 1, static_cast<int>(std::floor(u + scale)));
        const int y0 = std::max(0, static_cast<int>(std::ceil(v - scale)));
        const int y1 = std::min(th - 1, static_cast<int>(std::floor(v + scale)));
        for (int ty = y0; ty <= y1; ++ty) {
          for (int tx = x0; tx <= x1; ++tx) {
            const size_t i = static_cast<size_t>(ty) * tw + tx;
            if (pt.z() < zbuf[i]) {
              zbuf[i] = pt.z();
              // First-order: neighbouring target pixels map to neighbouring
              // source pixels with the local scale.
              const float k = (fxs / fxt) * (pt.z() / zs);
              src_x[i] = x + (tx - u) * k;
              src_y[i] = y + (ty - v) * k;
            }
          }
        }
      }
    }
    // Per target row: splatted pixels take their source coordinate; the
    // others keep the rotation-homography sample if it shows background
    // (source pixel without depth); if it lands on a surface the pixel is a
    // disocclusion hole: it takes the farther of its nearest splatted (or
    // background) neighbours on the row, extrapolated — the background
    // stretched into the gap, as a depth-image warper does.
    enum : uint8_t { kSplat, kBackground, kHole, kBorder };
    std::vector<uint8_t> kind(static_cast<size_t>(tw));
    const float k_default = fxs / fxt;
    for (int y = 0; y < th; ++y) {
      uint8_t* orow = out->row(y);
      uint8_t* vrow = ok.row(y);
      const size_t row0 = static_cast<size_t>(y) * tw;
      for (int x = 0; x < tw; ++x) {
        const size_t i = row0 + x;
        if (std::isfinite(zbuf[i])) {
          kind[x] = kSplat;
        } else if (!vrow[x]) {
          kind[x] = kBorder;
        } else {
          const Eigen::Vector3f d = rel.r * Eigen::Vector3f(static_cast<float>((x - kt.cx) / kt.fx),
                                                            static_cast<float>((y - kt.cy) / kt.fy), 1.0f);
          const int sx = std::clamp(static_cast<int>(std::lround(fxs * d.x() / d.z() + cxs)), 0, sw - 1);
          const int sy = std::clamp(static_cast<int>(std::lround(fys * d.y() / d.z() + cys)), 0, sh - 1);
          kind[x] = source_depth->at(sx, sy) != 0 ? kHole : kBackground;
        }
      }
      for (int x = 0; x < tw; ++x) {
        const size_t i = row0 + x;
        if (kind[x] == kSplat) {
          if (!vrow[x]) --border;  // a splat reached past the rotation border
          SampleWith(options.filter, source, src_x[i], src_y[i], orow + 3 * x);
          vrow[x] = 255;
        } else if (kind[x] == kHole) {
          ++holes;
          // Nearest non-hole neighbour on each side and its depth (inf = background).
          int best = -1;
          float best_z = -1;
          for (int dir : {-1, 1}) {
            int n = x + dir;
            while (n >= 0 && n < tw && kind[n] == kHole) n += dir;
            if (n < 0 || n >= tw || kind[n] == kBorder) continue;
            const float z = kind[n] == kSplat ? zbuf[row0 + n] : std::numeric_limits<float>::infinity();
            if (z > best_z) {
              best_z = z;
              best = n;
            }
          }
          if (best >= 0 && kind[best] == kSplat) {
            SampleWith(options.filter, source, src_x[row0 + best] + (x - best) * k_default, src_y[row0 + best],
                       orow + 3 * x);
          } else {
            orow[3 * x] = options.background[0];
            orow[3 * x + 1] = options.background[1];
            orow[3 * x + 2] = options.background[2];
          }
        }
      }
    }
  }

  if (stats) {
    const double n = static_cast<double>(tw) * th;
    stats->black_border_fraction = border / n;
    stats->hole_fraction = holes / n;
    stats->plane_distance_m = use_plane ? plane_z : 0.0f;
  }
  return OkStatus();
}

}  // namespace holo::reproject
