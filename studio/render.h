// Internal to the synthetic studio: the CPU rasterizer (visibility buffer +
// deferred shading), the light's shadow map and the depth noise model.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/camera.h"
#include "studio/scene.h"
#include "studio/studio.h"

namespace holo::studio {

// Counter-based random numbers: identical for any thread count.
inline uint64_t Mix64(uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}
inline uint64_t HashOf(uint64_t a, uint64_t b, uint64_t c = 0, uint64_t d = 0) {
  return Mix64(Mix64(Mix64(Mix64(a + 0x9e3779b97f4a7c15ULL) ^ b) ^ (c + 0x632be59bd9b4e019ULL)) ^ d);
}

// Orthographic depth map of the foreground seen from the light, rebuilt
// every frame around the posed objects.
struct ShadowMap {
  Eigen::Vector3f e1, e2, l;  // light basis; l points towards the light
  float u0 = 0, v0 = 0, inv_texel = 1;
  int w = 0, h = 0;
  std::vector<float> depth;  // l·p of the surface nearest the light, -inf = none
  static constexpr float kBias = 0.012f;  // metres along the light direction

  // Sets the map's frame around `positions` and clears it.
  void Prepare(const std::vector<Eigen::Vector3f>& positions);
  // Rasterizes `triangles` into texel rows [row_begin, row_end).
  void Rasterize(const std::vector<Eigen::Vector3f>& positions, const std::vector<std::array<uint32_t, 3>>& triangles,
                 int row_begin, int row_end);

  void Build(const std::vector<Eigen::Vector3f>& positions, const std::vector<std::array<uint32_t, 3>>& triangles);
  // Fraction of light reaching a point with light coordinates (u, v, d), 0..1.
  float Visibility(float u, float v, float d) const {
    if (w == 0) return 1.0f;
    const float fx = (u - u0) * inv_texel - 0.5f, fy = (v - v0) * inv_texel - 0.5f;
    if (!(fx >= 0.0f && fy >= 0.0f && fx < w - 1 && fy < h - 1)) return 1.0f;
    const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
    const float ax = fx - ix, ay = fy - iy;
    const float* r0 = depth.data() + static_cast<size_t>(iy) * w + ix;
    const float* r1 = r0 + w;
    const float dd = d + kBias;
    const float s00 = dd >= r0[0], s01 = dd >= r0[1], s10 = dd >= r1[0], s11 = dd >= r1[1];
    return (s00 * (1 - ax) + s01 * ax) * (1 - ay) + (s10 * (1 - ax) + s11 * ax) * ay;
  }
  float Visibility(const Eigen::Vector3f& p) const { return Visibility(e1.dot(p), e2.dot(p), l.dot(p)); }
};

// The posed scene at one frame.
struct FrameScene {
  int64_t frame = -1;
  std::vector<Eigen::Vector3f> positions, normals;
  std::vector<Eigen::Isometry3f> part_poses;
  ShadowMap shadow;
};

// What a camera sees of the static room, precomputed once per camera.
struct ViewCache {
  CameraModel camera;      // the output camera
  Intrinsics render;       // pinhole intrinsics actually rasterized
  bool distorted = false;  // output = remap(render) when true
  std::vector<int32_t> remap;  // per output pixel: render pixel index or -1
  Eigen::Matrix3f cam_from_world;
  Eigen::Vector3f cam_from_world_t, center;
  std::vector<float> bg_z;     // camera z of the room, metres (inf: none)
  std::vector<float> bg_cos;   // |cos| between the view ray and the room's normal
  std::vector<std::array<uint8_t, 3>> bg_lit, bg_dark;  // room colour lit / in shadow
  // Light coordinates of a room pixel: c + z·(g·(xn, yn, 1)).
  Eigen::Vector3f light_c;
  Eigen::Matrix3f light_g;

  void Init(const CameraModel& camera);
};

// Per-thread buffers, reused from frame to frame.
struct RenderScratch {
  std::vector<float> sx, sy, siz;  // projected vertices
  std::vector<uint8_t> vok;
  std::vector<float> z, b1, b2;
  std::vector<int32_t> id;
  std::vector<float> cosg;
  std::vector<uint8_t> rgb, fg;
  // Output-domain copies when the camera is distorted.
  std::vector<float> oz, ocos;
  std::vector<uint8_t> orgb, ofg;
  // Pointers to the output-domain results of the last Render.
  const float* out_z = nullptr;
  const float* out_cos = nullptr;
  const uint8_t* out_rgb = nullptr;
  const uint8_t* out_fg = nullptr;
};

// Rasterizes and shades `scene` from `view` into `s` (out_* pointers).
// `shade_color` false skips colour.
void RenderViewCore(const ViewCache& view, const SceneTemplate& tmpl, const FrameScene& scene, bool shade_color,
                    RenderScratch* s);

// Per-pod colour gain/offset.
struct ColorVariation {
  float gain[3] = {1, 1, 1};
  float offset[3] = {0, 0, 0};
};
ColorVariation PodColorVariation(uint64_t seed, int pod_id);

// Writes the outputs of the last RenderViewCore (sized to the view's camera).
// Any output may be null. `noise` null: `depth` gets the exact depth.
void WriteColor(const ViewCache& view, const RenderScratch& s, const ColorVariation* variation, ImageRgb8* color);
void WriteTruth(const ViewCache& view, const RenderScratch& s, ImageDepth16* depth, ImageGray8* mask);
// Noisy depth: see DepthNoiseOptions. `stream` selects the random stream
// (seed, frame, pod).
void WriteNoisyDepth(const ViewCache& view, const RenderScratch& s, const DepthNoiseOptions& noise, uint64_t stream,
                     ImageDepth16* depth);

}  // namespace holo::studio
