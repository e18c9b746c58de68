// The viewer's OpenGL 3.3 core renderer (needs a current context from
// gl_context.h). It draws the remote site's mesh
//   * with its per-vertex colours (Gouraud), or
//   * with projective texturing from the pods' colour images, blended per
//     fragment with Holoportation-style weights: for pod i,
//       w_i = V_i · max(0, n·d_i)^α · ((1 + d_i·d_eye) / 2)^β
//     where n is the surface normal, d_i the unit direction from the surface
//     point to pod i, d_eye the direction to the viewer (the view-dependent
//     term; weights are computed per vertex and interpolated), and V_i the
//     visibility per fragment from pod i's depth map, rendered from the mesh
//     in a pre-pass (one layer of a texture array per pod). Samples near a
//     depth discontinuity of that map (within `discontinuity_radius_m` at
//     the texel's depth) are used only when no clean sample exists. With no
//     sample at all the vertex colour is used.
//     By default (ProjectiveOptions::bake) the same blending, without the
//     view-dependent term, runs once per mesh on the CPU into a texture atlas
//     (atlas.h), and each frame draws the mesh with one texture fetch per
//     pixel.
// The remote mesh can be placed in the local room by a similarity transform
// (the miniature mode), and composited against the local site's mesh: that
// mesh is drawn first (in colour, or depth only for see-through AR) so it
// occludes the remote people wherever it is nearer.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "common/camera.h"
#include "common/image.h"
#include "common/mesh.h"
#include "common/rig.h"
#include "common/status.h"

namespace holo {
class MeshRasterizer;
class WorkerPool;
}

namespace holo::render {

enum class ColorMode { kVertexColor, kProjective };
const char* ColorModeName(ColorMode m);

struct ProjectiveOptions {
  float alpha = 2.0f;  // exponent of the normal term max(0, n·d_i)
  float beta = 2.0f;   // exponent of the view-dependent term ((1 + d_i·d_eye)/2)
  // (β = 0: 25.1 dB on exact geometry, 19.3 dB with 16 mm geometry error;
  // β = 2: 25.0 / 19.4; β = 8: 24.7 / 19.3 — docs/viewer.md)
  // A point is visible from a pod when its camera z is at most this much
  // behind the pod's depth map.
  float visibility_tolerance_m = 0.015f;
  // Discontinuity test in the pod depth maps: jump between the centre and a
  // neighbour at the radius (or an empty neighbour), metres.
  float discontinuity_jump_m = 0.05f;
  float discontinuity_radius_m = 0.01f;
  // Weight factor of a sample near such a discontinuity (Holoportation's
  // dilated discontinuity map down-weights them): small, so that they count
  // only where no clean sample exists.
  float discontinuity_weight = 0.001f;
  // Skip back faces when rendering the pods' depth maps. Off: a fused
  // mesh is not reliably closed and consistently oriented (folds of the
  // noisy surface), and a culled fold leaves a hole in a pod's depth map
  // through which hidden surface takes that pod's colour.
  bool cull_back_faces = false;
  // Pods' foreground masks (SetPodImages with masks): a texel outside its
  // pod's mask never contributes (a decoded C1 image is black there), and
  // texels near the mask's edge are down-weighted, since a segmentation edge
  // misaligned by a pixel or two paints background onto the person: the
  // weight is 1 from `mask_erode_px + mask_feather_px` pixels inside the edge
  // (chessboard distance; 1 = a mask pixel next to the background), falls
  // linearly to 0 at `mask_erode_px`, and never below `edge_floor_weight`
  // inside the mask (so a point only seen near an edge still takes colour).
  bool use_masks = true;
  float mask_erode_px = 2.0f;
  float mask_feather_px = 2.0f;
  float edge_floor_weight = 0.02f;
  // Below this mean mask weight of a fragment's samples the colour fades to
  // the mesh's per-vertex colour (0 = never).
  float min_mask_confidence = 0.5f;
  // Pod selection, once per mesh (Renderer::SelectPods): each vertex keeps
  // the `pods_per_vertex` pods with the largest view-independent weight
  // (visible in the pod's depth map, facing it, inside its mask; edge
  // samples down-weighted) and gives the others weight 0; each triangle is
  // textured from the pods its vertices keep, at most
  // `max_pods_per_triangle` of them (the largest summed weights; a pod
  // dropped there makes a small seam, counted in SelectionStats). Weights
  // stay continuous across triangles, since a pod's weight on an edge
  // depends only on the edge's vertices. The fragment shader then loops
  // over a triangle's few pods instead of all of them. 0 = every pod
  // everywhere (one draw call, the renderer before selection existed).
  int pods_per_vertex = 3;
  int max_pods_per_triangle = 4;
  // The pods' visibility maps (depth and discontinuity flags, once per mesh)
  // from the CPU rasterizer (texture/mesh_renderer.h) and uploaded, or
  // rendered by GL as before. On llvmpipe the CPU path is several times
  // cheaper (8 small draws of the whole mesh cost GL more than the CPU's
  // triangle setup); the maps are the same up to the rasterizers' rounding.
  bool gpu_visibility = false;
  // Bake the blended colours once per mesh into a texture atlas on the CPU
  // (client/render/atlas.h: the same weights without the view-dependent
  // term β), then draw each frame with one texture fetch per pixel: the
  // per-frame cost no longer depends on the pods, and it is paid once per
  // mesh, not once per displayed frame. Off: blend per fragment as above
  // (with β). `bake_texels_per_edge`: atlas texels along a triangle's edge
  // (its cell holds (L+1)² texels). A mesh too large for the atlas is drawn
  // per fragment. 8: with VGA pod images (S8-VGA) a triangle spans more
  // than 4 pod pixels, and 4 texels per edge lost 1.7 dB against per-fragment
  // blending on the exact mesh (8: 0.6 dB, at 1.3× the bake time; with
  // S8-QVGA pods no triangle asks for more than 4, so nothing changes). A
  // mesh whose atlas would exceed GL's texture size at L is baked at L/2,
  // L/4, … before it falls back to per-fragment blending.
  bool bake = true;
  int bake_texels_per_edge = 8;
  // Fewer texels for triangles small in their pods' images: texels along an
  // edge per pod pixel of that edge (1..bake_texels_per_edge; 0 = always
  // bake_texels_per_edge). AtlasBakeOptions::texels_per_pod_pixel.
  float bake_texels_per_pod_pixel = 1.0f;
  Status Check() const;
  // The renderer as it was before masks and edge weights (for before/after
  // comparisons): masks ignored, back faces culled in the pods' depth maps.
  // (RenderSettings::Legacy() gives the old view settings too.)
  static ProjectiveOptions Legacy();
};

struct RenderSettings {
  ColorMode mode = ColorMode::kProjective;
  std::array<uint8_t, 3> background = {24, 26, 30};
  // local_from_remote (similarity; identity = the remote room as it is).
  Eigen::Matrix4f local_from_remote = Eigen::Matrix4f::Identity();
  // Local-site mesh (SetLocalMesh): draw it for occlusion; in colour when
  // `show_local`, depth only (see-through AR) otherwise.
  bool composite_local = false;
  bool show_local = true;
  ProjectiveOptions projective;
  // Skip the remote mesh's back faces (counter-clockwise = front, as
  // holo::Mesh promises). Off by default: on the live fused stream culling
  // opened most of the black speckles and holes a viewer saw (folds of the
  // noisy fused surface face away from the viewer; behind them is
  // background), +0.7 dB novel-view PSNR without it (docs/viewer.md). On
  // for exactly closed meshes (the studio's truth), where it saves time.
  bool cull_back_faces = false;
  // Projective mode: lay down depth first so each pixel is textured once.
  // Pays off without culling (fused S8-QVGA, 20 k triangles, 960×540: 124
  // → 90 CPU-ms per frame; docs/viewer.md).
  bool depth_prepass = true;
  float near_m = 0.02f;
  float far_m = 100.0f;
  // The settings as they were before issue 17 (back faces culled, no depth
  // pre-pass, ProjectiveOptions::Legacy), for before/after comparisons.
  static RenderSettings Legacy();
};

// Pixel rectangle of the bound framebuffer, origin bottom-left (GL convention).
struct Viewport {
  int x = 0, y = 0, width = 0, height = 0;
};

// A framebuffer object with an RGBA8 colour and a 24-bit depth renderbuffer.
class OffscreenTarget {
 public:
  ~OffscreenTarget();
  static StatusOr<std::unique_ptr<OffscreenTarget>> Create(int width, int height);
  void Bind() const;
  int width() const { return width_; }
  int height() const { return height_; }
  // Reads the whole target (rows top to bottom) into `out`.
  Status ReadRgb(ImageRgb8* out) const;

 private:
  OffscreenTarget() = default;
  unsigned fbo_ = 0, color_ = 0, depth_ = 0;
  int width_ = 0, height_ = 0;
};

// Reads `vp` of the bound read framebuffer, rows top to bottom.
Status ReadViewportRgb(const Viewport& vp, ImageRgb8* out);

class Renderer {
 public:
  // A multiple of 4 (weights travel as vec4 varyings).
  static constexpr int kMaxPods = 16;
  ~Renderer();
  // Compiles the shaders; a 3.3 core context must be current.
  static StatusOr<std::unique_ptr<Renderer>> Create();

  // The remote mesh (remote world coordinates). Normals are computed when the
  // mesh has none; missing colours are grey. DataLoss from Mesh::Validate.
  Status SetRemoteMesh(const Mesh& mesh);
  // The pods' colour images (one per pod of `rig`, in rig order, each the
  // size of that pod's colour camera), for projective texturing. Up to
  // kMaxPods pods.
  Status SetPodImages(const Rig& rig, const std::vector<const ImageRgb8*>& images);
  // The same with the pods' foreground masks (one per image, same size,
  // nonzero = foreground; as the C1 colour codec decodes them), used by
  // projective texturing when ProjectiveOptions::use_masks. An empty `masks`
  // means none (every texel of the images is usable).
  Status SetPodImages(const Rig& rig, const std::vector<const ImageRgb8*>& images,
                      const std::vector<const ImageGray8*>& masks);
  // Local-site geometry (local world coordinates) for compositing; an empty
  // mesh clears it.
  Status SetLocalMesh(const Mesh& mesh);

  // Renders the pods' visibility depth maps and their discontinuity flags
  // now (otherwise the first projective Render after a new mesh or rig, or
  // with other discontinuity options, does it).
  Status UpdateVisibility(const ProjectiveOptions& options = {});

  // Bakes the projective colours into the atlas now (ProjectiveOptions::bake;
  // otherwise the first baked Render after a new mesh, new pod images or
  // other options does it, after UpdateVisibility and the pod selection).
  Status UpdateAtlas(const ProjectiveOptions& options = {});

  // Draws into `vp` of the bound draw framebuffer as seen by `camera` (local
  // world coordinates; its intrinsics should match vp's size).
  Status Render(const CameraModel& camera, const RenderSettings& settings, const Viewport& vp);

  size_t remote_triangles() const { return remote_.index_count / 3; }
  size_t local_triangles() const { return local_.index_count / 3; }
  bool has_pod_images() const { return num_pods_ > 0; }

  // Depth map (camera z, metres; 0 = nothing) of pod `i` from the last
  // visibility pass, for tests and debugging.
  Status ReadPodDepth(int i, ImageFloat* out);

  // What the last pod selection produced (ProjectiveOptions::pods_per_vertex).
  struct SelectionStats {
    size_t draws = 0;              // draw calls (distinct pod sets) per projective frame
    double mean_pods = 0;          // mean pods per triangle (slots the fragment shader loops over)
    size_t capped_triangles = 0;   // triangles whose vertices kept more than max_pods_per_triangle pods
    size_t uncoloured_triangles = 0;  // no pod sees any of their vertices: per-vertex colour
    double select_ms = 0;          // wall time of the selection (readback + choice + index upload)
    double select_cpu_ms = 0;      // CPU time of the calling thread in it (pods run on a pool: not all CPU)
  };
  const SelectionStats& selection_stats() const { return selection_stats_; }
  // Per triangle of the last selection: the pods it is textured from (bit i =
  // pod i; empty before a selection or with pods_per_vertex 0).
  const std::vector<uint16_t>& triangle_pods() const { return triangle_pods_; }

  // What the last atlas bake produced (ProjectiveOptions::bake).
  struct AtlasStats {
    int width = 0, height = 0;  // atlas texels
    size_t texels = 0;          // texels baked
    size_t samples = 0;         // pod samples taken (texel × pod in view)
    double bake_ms = 0;         // wall time of the bake and its upload
    bool fallback = false;      // the mesh did not fit: drawn per fragment
    int texels_per_edge = 0;    // L used: bake_texels_per_edge, halved until the atlas fits
  };
  const AtlasStats& atlas_stats() const { return atlas_stats_; }

 private:
  struct GpuMesh {
    unsigned vao = 0, vbo = 0, ibo = 0;
    size_t index_count = 0;
    size_t vbo_bytes = 0, ibo_bytes = 0;
  };
  Renderer() = default;
  Status Init();
  // `normals` (optional) receives the normals uploaded (computed when the
  // mesh has none).
  Status Upload(const Mesh& mesh, GpuMesh* gpu, std::vector<Eigen::Vector3f>* normals = nullptr);
  void Draw(const GpuMesh& gpu) const;
  void FreeMesh(GpuMesh* gpu);
  // Scissor box {x, y, w, h} of pod image pixels the remote mesh can cover;
  // left unchanged (whole image) when it cannot be bounded.
  void PodBox(const CameraModel& cam, int box[4]) const;
  // The program for `slots` pod slots (0 = per-vertex colour), built on
  // first use.
  StatusOr<unsigned> DrawProgram(int slots);
  // Chooses the pods of every vertex and triangle and orders the remote
  // mesh's triangles into one range per pod set (see ProjectiveOptions).
  Status SelectPods(const ProjectiveOptions& options);
  // Makes the pods' images premultiplied RGBA (alpha = the texel's mask
  // weight, see ProjectiveOptions) for `options` in pod_rgba_ (copied to GL
  // by SyncPodTexturesToGpu when per-fragment blending needs them).
  void MakePodRgba(const ProjectiveOptions& options);
  // Makes sure pod_flagged_z_ holds the flagged depth maps of the last
  // visibility pass (reads the GL maps back once when GL made them).
  Status FlaggedDepthOnCpu();
  // Whether the visibility maps, the uploaded pod textures and the pod
  // selection (and on top of them the atlas) are current for `options`.
  bool VisibilityCurrent(const ProjectiveOptions& options) const;
  bool TexturesCurrent(const ProjectiveOptions& options) const;
  bool SelectionCurrent(const ProjectiveOptions& options) const;
  bool AtlasCurrent(const ProjectiveOptions& options) const;
  // Checks `options` and brings the visibility maps, pod textures and pod
  // selection up to date: what both projective paths need first.
  Status PreparePods(const ProjectiveOptions& options);

  std::array<unsigned, kMaxPods + 1> draw_programs_{};
  unsigned depth_program_ = 0, edge_program_ = 0, empty_vao_ = 0;
  // Per-vertex pod bits of the remote mesh (attribute 3).
  unsigned remote_pods_vbo_ = 0;
  size_t remote_pods_vbo_bytes_ = 0;
  // The CPU visibility path: one rasterizer per pod, and the maps of the
  // last pass (camera z; flagged: negated near a discontinuity; 0 = empty),
  // pod image size each.
  std::vector<std::unique_ptr<MeshRasterizer>> pod_rasters_;
  std::vector<std::vector<float>> pod_raw_z_, pod_flagged_z_;
  bool flagged_on_cpu_ = false;  // pod_flagged_z_ matches the last visibility pass
  // Options of the last visibility pass (GL or CPU maps, back faces culled).
  bool vis_gpu_ = false, vis_cull_ = false;
  Status UpdateVisibilityCpu(const ProjectiveOptions& options);
  // CPU copy of the remote mesh (normals computed when missing) for the
  // pod selection, in the order the mesh came.
  std::vector<Eigen::Vector3f> remote_positions_, remote_normals_;
  std::vector<std::array<uint32_t, 3>> remote_triangles_;
  std::vector<std::array<uint8_t, 3>> remote_colors_;  // empty = none
  // The last pod selection per vertex and per triangle (mesh order; bit i =
  // pod i), for the atlas bake.
  std::vector<uint16_t> vertex_pods_, triangle_pods_;
  // The baked atlas (ProjectiveOptions::bake): texture, one vertex per
  // triangle corner (position, atlas coordinate), and what it was baked with.
  unsigned atlas_tex_ = 0, baked_program_ = 0;
  GpuMesh baked_;
  size_t baked_vertices_ = 0;
  bool atlas_dirty_ = true;
  int atlas_texels_ = -1;
  float atlas_tol_ = -1, atlas_edge_ = -1, atlas_conf_ = -1, atlas_density_ = -1;
  AtlasStats atlas_stats_;
  // Threads for the per-mesh CPU work (visibility maps, pod selection, atlas
  // bake), as many as the machine has.
  std::unique_ptr<WorkerPool> pool_;
  // One draw call per pod set: the pods (rig order) and the index range.
  struct PodSet {
    std::array<int, kMaxPods> pods{};
    int num_pods = 0;
    size_t first_index = 0, index_count = 0;
  };
  std::vector<PodSet> pod_sets_;
  bool selection_dirty_ = true;
  int sel_per_vertex_ = -1, sel_per_triangle_ = -1;
  float sel_alpha_ = -1;
  SelectionStats selection_stats_;
  // Mask weight (alpha) of every pod texel as uploaded; empty = no masks.
  std::vector<std::vector<uint8_t>> pod_alpha_;
  // Every pod's image as uploaded (RGBA premultiplied by the mask weight).
  std::vector<std::vector<uint8_t>> pod_rgba_;
  GpuMesh remote_, local_;
  Eigen::Vector3f remote_min_ = Eigen::Vector3f::Constant(1e30f), remote_max_ = Eigen::Vector3f::Constant(-1e30f);
  // The remote mesh carries per-vertex colours (a live site streaming pod
  // images sends none: then the images' colour is used even where only mask
  // edges saw a point, rather than a colourless fallback).
  bool remote_has_colors_ = true;
  // Pods: colour and depth texture arrays (one layer per pod, max size).
  // pod_raw_tex_: camera z per texel; pod_depth_tex_: the same, negated
  // near discontinuities.
  unsigned pod_color_tex_ = 0, pod_depth_tex_ = 0, pod_raw_tex_ = 0, pod_depth_rb_ = 0, pod_fbo_ = 0;
  // The CPU maps (pod_rgba_; pod_raw_z_ / pod_flagged_z_ of a CPU visibility
  // pass) changed since they were last copied into the texture arrays. Only
  // the per-fragment path reads the arrays: the baked path never pays the
  // copies (about 7 MB per mesh at S8-QVGA through llvmpipe).
  bool color_tex_stale_ = false, depth_tex_stale_ = false;
  Status SyncPodTexturesToGpu();
  float edge_jump_m_ = -1, edge_radius_m_ = -1;
  int num_pods_ = 0, array_width_ = 0, array_height_ = 0;
  std::vector<CameraModel> pod_cameras_;
  bool visibility_dirty_ = true;
  // CPU copies of the last pod images and masks (masks empty = none), and
  // the mask options the uploaded texture was built with.
  std::vector<ImageRgb8> pod_images_;
  std::vector<ImageGray8> pod_masks_;
  std::vector<uint8_t> rgba_scratch_;
  std::vector<uint8_t> dist_scratch_;
  bool tex_use_masks_ = false;
  float tex_erode_ = -1, tex_feather_ = -1, tex_floor_ = -1;
  bool textures_dirty_ = true;
};

}  // namespace holo::render
