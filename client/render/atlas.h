// Projective texturing baked once per mesh into a texture atlas, on the CPU.
//
// The renderer's projective shaders blend the pods' images per displayed
// pixel: on a CPU GL (llvmpipe) that is the whole cost of a frame, and it is
// paid again whenever the head moves, although the colours change only when
// a new mesh (or new pod images) arrives. The bake does the same blending
// once per mesh, for a few texels per triangle, and the frame then draws the
// mesh with one bilinear texture fetch per pixel.
//
// Layout: every triangle has its own square cell of (L+1)×(L+1) texels
// (L = `texels_per_edge`). Its corners sit on texel centres: corner 0 at
// cell texel (0, 0), corner 1 at (L, 0), corner 2 at (0, L); texel (i, j)
// is the surface point with barycentrics (1 − i/L − j/L, i/L, j/L). Texels
// with i + j ≤ L lie on the triangle; the row i + j = L + 1 just past its
// third edge is filled too (the triangle's plane extended), since bilinear
// sampling near that edge reads it. A bilinear fetch anywhere on the
// triangle therefore reads only its own cell: no gutters, no bleeding from
// other triangles, and along a shared edge both cells hold colours of the
// same surface points, so seams stay invisible.
//
// Each texel's colour is the renderer's fragment colour without the
// view-dependent term: pod i's weight is the interpolation of the corners'
// max(0, n·d_i)^α (0 where the pod selection did not keep pod i at that
// corner), times visibility in the pod's flagged depth map (camera z within
// the tolerance; near a discontinuity the weight is scaled by
// `discontinuity_weight`), the colour a bilinear fetch of the pod's image
// premultiplied by its mask weight, and the mean mask weight fades to the
// per-vertex colour below `min_mask_confidence` (renderer.h). β (the
// view-dependent term) is left out: a baked colour cannot depend on the
// viewer; on the studio it gained at most 0.1 dB (docs/viewer.md).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "common/camera.h"
#include "common/status.h"

namespace holo {
class WorkerPool;
}

namespace holo::render {

struct AtlasBakeOptions {
  int texels_per_edge = 8;  // L: cell of (L+1)² texels per triangle, 1..16 (ProjectiveOptions' default)
  // Texels along a triangle's edge per pixel of that edge in its most
  // heavily weighted pod's image (at least 1, at most L): a triangle smaller
  // than a pod pixel needs no more than its corners. 0 = always L.
  float texels_per_pod_pixel = 1.0f;
  // A triangle is baked without the pods whose summed corner weight is below
  // this fraction of its strongest pod's (0 = every pod the selection kept).
  // Fused S8-QVGA frame 40 (626 k samples with 0): 0.1 takes 8.5 % fewer
  // for no PSNR change (−0.0004 dB); 0.25 20 % fewer for −0.002 dB on fused
  // but −0.1 dB on the studio's exact mesh; 0.5 38 % fewer for −0.02 dB.
  float min_pod_weight = 0.1f;
  int max_width = 2048;     // atlas width limit (texels); the height grows
  int max_height = 16384;   // fewer texels per edge for meshes needing more; refuse them at L = 1
  float alpha = 2.0f;       // exponent of the facing term
  float visibility_tolerance_m = 0.015f;
  float discontinuity_weight = 0.001f;
  float min_mask_confidence = 0.5f;  // 0 = never fade to the vertex colour
  // Sample eight texels at a time with AVX2 where the CPU has it (pods
  // without lens distortion); the same sums as the portable loop, bit for
  // bit. false: the portable loop (for tests and comparison).
  bool vectorized = true;
  Status Check() const;
};

// One pod as the bake sees it (all borrowed; sizes are the camera's).
struct AtlasPod {
  const CameraModel* camera = nullptr;
  // Flagged depth (camera z; negative near a discontinuity; 0 = empty),
  // width × height, row-major.
  const float* flagged_z = nullptr;
  // Colour premultiplied by the mask weight, alpha = the weight (255 with no
  // masks), RGBA8, width × height.
  const uint8_t* rgba = nullptr;
};

struct AtlasMeshInput {
  const std::vector<Eigen::Vector3f>* positions = nullptr;
  const std::vector<Eigen::Vector3f>* normals = nullptr;      // per vertex, any length > 0
  const std::vector<std::array<uint8_t, 3>>* colors = nullptr;  // per vertex, or null/empty: grey 180
  const std::vector<std::array<uint32_t, 3>>* triangles = nullptr;
  // Pods kept per vertex and per triangle (bit i = pod i), as the renderer's
  // pod selection chose them; a triangle is baked from its pods only.
  const std::vector<uint16_t>* vertex_pods = nullptr;
  const std::vector<uint16_t>* triangle_pods = nullptr;
};

struct Atlas {
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;  // width × height × 4 (alpha 255 on baked texels)
  // Texture coordinates (normalized, texel centres) of every triangle corner,
  // 3 per triangle in triangle order.
  std::vector<std::array<float, 2>> uv;
  size_t texels_baked = 0;  // texels computed (cells' used part)
  size_t samples = 0;       // pod samples taken (texel × pod)
  int texels_per_edge = 0;  // L used: the options', halved until the cells fit max_height
};

// A pod's world-to-image map as one 3×4 matrix: rows u·z, v·z, z for a camera
// without lens distortion; camera coordinates (then Distort via
// CameraModel::ProjectCamera) for one with it. Shared by the bake and the
// renderer's pod selection.
Eigen::Matrix<float, 3, 4> PodProjection(const CameraModel& camera);

// Bakes `mesh` from `pods`. `pool` (optional) runs the triangles in
// parallel; the result does not depend on the thread count.
Status BakeAtlas(const AtlasMeshInput& mesh, const std::vector<AtlasPod>& pods, const AtlasBakeOptions& options,
                 WorkerPool* pool, Atlas* out);

}  // namespace holo::render
