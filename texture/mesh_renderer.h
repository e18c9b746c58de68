// A small CPU z-buffer rasterizer for triangle meshes: depth maps for the
// texturer's visibility test, and colour renders of textured meshes for
// novel-view evaluation and debugging. Not for untrusted meshes beyond
// Mesh::Validate (RenderMesh checks it).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "common/camera.h"
#include "common/image.h"
#include "common/mesh.h"
#include "common/status.h"

namespace holo {

struct MeshRenderOptions {
  // Colour of pixels no triangle covers.
  std::array<uint8_t, 3> background = {0, 0, 0};
  // Skip triangles seen from behind (clockwise on screen). Off by default:
  // reconstructed meshes may be open, and the nearest surface is what a camera sees.
  bool cull_back_faces = false;
  // Triangles with a vertex nearer than this (camera z, metres) are dropped
  // (no near-plane clipping).
  float near_m = 0.05f;
  // Colour of covered pixels when the mesh has no per-vertex colours.
  std::array<uint8_t, 3> default_color = {200, 200, 200};
};

// Reusable z-buffer rasterizer. Pixel centres are at integer coordinates
// (Intrinsics convention); a pixel is covered when its centre lies inside the
// projected triangle (top-left fill rule, so shared edges are covered once).
// Depth is interpolated perspective-correctly (1/z linear on screen).
// Distorted cameras: vertices are projected with distortion and triangles are
// rasterized as straight-edged on the distorted image, which is accurate for
// triangles a few pixels wide. Buffers are kept from call to call.
class MeshRasterizer {
 public:

  // Rasterizes `triangles` over `positions` (world coordinates) seen by
  // `camera`. `want_attributes` also records the triangle id and perspective-
  // correct barycentrics per pixel (needed for colour, not for depth).
  // Indices must be in range (the caller validates).
  void Rasterize(const std::vector<Eigen::Vector3f>& positions, const std::vector<std::array<uint32_t, 3>>& triangles,
                 const CameraModel& camera, bool want_attributes, bool cull_back_faces = false, float near_m = 0.05f);

  int width() const { return width_; }
  int height() const { return height_; }
  // Inverse camera depth 1/z (1/metres) per pixel, row-major; 0 where
  // nothing is drawn. (Inverse depth: the z-test needs no division, and it
  // is what interpolates linearly on screen.)
  const std::vector<float>& inv_z() const { return iz_buf_; }
  // With `want_attributes`: triangle index (-1 = none) and the barycentric
  // weights of its 2nd and 3rd vertices per pixel.
  const std::vector<int32_t>& triangle_ids() const { return tri_; }
  const std::vector<float>& bary1() const { return b1_; }
  const std::vector<float>& bary2() const { return b2_; }
  // Largest 1/z over the projected vertices (those past the near plane), 0 if none.
  float max_inv_z() const { return max_iz_; }
  // Inclusive pixel box holding every drawn pixel; empty (x0 > x1) if none.
  int box_x0() const { return box_[0]; }
  int box_y0() const { return box_[1]; }
  int box_x1() const { return box_[2]; }
  int box_y1() const { return box_[3]; }

 private:
  int width_ = 0, height_ = 0;
  // Projected vertex: pixel x, y in 1/256 px (8 bytes, so the first pass
  // over the triangles gathers as little as possible) and, separately, 1/z;
  // iz = 0 (and x = y = 0) when behind the near plane or too far off screen
  // (its triangles are dropped).
  struct ScreenXY {
    int32_t x, y;
  };
  std::vector<ScreenXY> sv_;
  std::vector<float> siz_;
  std::vector<uint32_t> survivors_;  // triangles left by the branch-free first pass
  std::vector<float> iz_buf_, b1_, b2_;
  std::vector<int32_t> tri_;
  int box_[4] = {0, 0, -1, -1};
  float max_iz_ = 0;
};

// Renders `mesh` (per-vertex colours Gouraud-interpolated, perspective-correct)
// from `camera`. Outputs are resized to the camera's resolution; any may be
// null. `depth`: camera z in millimetres (rounded, 0 where nothing is drawn or
// beyond 65.535 m); `mask`: 255 where the mesh covers the pixel. Returns
// InvalidArgument for bad intrinsics or options, DataLoss from Mesh::Validate.
Status RenderMesh(const Mesh& mesh, const CameraModel& camera, ImageRgb8* color, ImageDepth16* depth,
                  ImageGray8* mask, const MeshRenderOptions& options);
// Same with default options (black background).
Status RenderMesh(const Mesh& mesh, const CameraModel& camera, ImageRgb8* color, ImageDepth16* depth,
                  ImageGray8* mask);

}  // namespace holo
