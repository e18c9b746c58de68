// Stage 5 of the capture pipeline: per-vertex colour from all pods, after
// Holoportation (Orts-Escolano et al., UIST 2016, "Color texturing"). See
// docs/texturing.md for the algorithm, the defaults and measured figures.
//
// For every vertex and every pod the texturer keeps the pod's colour sample
// only if
//   * the vertex faces the pod (n·v > 0) and projects inside its colour image,
//   * it is visible: its depth is within `visibility_tolerance_m` of the depth
//     map rasterized from the mesh itself (not the noisy sensor depth), so a
//     thin occluder hides what lies behind it,
//   * it is not near a depth discontinuity of that rasterized depth map:
//     farther than `discontinuity_radius_m` (converted to pixels at the
//     vertex's depth) from any pixel whose neighbour's depth jumps by more
//     than `discontinuity_jump_m` (silhouettes included), and
//   * if the frame carries a foreground mask, it falls inside it.
// The kept samples are weighted by max(0, n·v)^α. Where views disagree,
// multi-level majority voting keeps the largest cluster of mutually agreeing
// colours (threshold `vote_threshold` doubled at each of `voting_levels`
// levels); without a majority at any level the sample from the view whose
// image is locally the smoothest (minimum colour variance) wins. Vertices no
// view observes take the average of observed neighbours (propagated over the
// mesh); components never observed fall back to the minimum-variance view
// among all views they face, ignoring the visibility tests.
//
// The per-pod colour images are only read, never modified, so they stay
// available for projective texturing by clients.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "common/mesh.h"
#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"
#include "texture/mesh_renderer.h"

namespace holo {

class WorkerPool;

struct TextureOptions {
  // Exponent α of the view weight max(0, n·v)^α.
  float alpha = 2.0f;
  // Assumed reconstruction error, metres: a vertex closer than this (measured
  // on the image at the vertex's depth) to a depth discontinuity of a view is
  // not coloured from that view.
  float discontinuity_radius_m = 0.01f;
  // When every view that sees a vertex is near a discontinuity, use them
  // anyway (instead of leaving the vertex to neighbour filling). Matters at
  // low resolution, where thin limbs are only a few pixels wide in every view.
  bool discontinuity_fallback = true;
  // Depth jump between 4-neighbouring pixels of a rasterized depth map that
  // counts as a discontinuity, metres. Covered/uncovered neighbours always do.
  float discontinuity_jump_m = 0.05f;
  // A vertex is visible in a view when its camera z is at most this much
  // behind the rasterized depth at its pixel, metres.
  float visibility_tolerance_m = 0.015f;
  // Multi-level majority voting: colours agree at level k when their RGB
  // distance (0..441) is ≤ vote_threshold·2^k, k = 0 .. voting_levels − 1.
  // 0 levels: plain weighted average of the kept views.
  int voting_levels = 3;
  float vote_threshold = 24.0f;
  // Rounds of neighbour propagation for vertices no view observes.
  int fill_iterations = 64;
  // Rasterize only front faces for visibility: exact for closed meshes
  // (the nearest surface along a ray is front-facing) and half the work.
  bool cull_back_faces = true;
  // Switches for ablations and baselines (all on = Holoportation).
  bool visibility_test = true;
  bool discontinuity_test = true;
  // Off: every view that projects inside the image counts with weight 1,
  // facing or not (with the tests above off, this is the naive average).
  bool normal_weighting = true;
  // Use RgbdFrame::mask when present.
  bool use_masks = true;
  // A view whose mask has background within this many pixels (chessboard)
  // of the vertex's pixel is not used: segmentation edges are often a pixel
  // or two off and paint the room onto the person. A vertex that only such
  // views see is filled from its observed neighbours. 0 = off.
  int mask_edge_px = 2;
  // Use the SSE2 paths (four pods per vector) where they apply: undistorted
  // colour cameras on an SSE2 build. Off: the scalar reference path. Both
  // give the same results (tested); this switch exists for that test.
  bool vectorize = true;
  // Worker threads (0 = hardware concurrency).
  int threads = 0;
  // Texturing on a simplified mesh (0 = off: every vertex is textured
  // against the mesh itself). If > 0, the mesh's vertices are clustered on a
  // grid of this cell size (metres), separately per dominant normal
  // direction (so the two sides of a thin part never merge); the cluster
  // means form a coarse mesh that is rasterized for visibility and textured
  // as above, and every vertex then takes a distance-weighted mean of the
  // colours of its cluster and the clusters adjacent to it in the coarse
  // mesh. For a mesh much finer than the pods' pixels (a TSDF mesh at QVGA)
  // this is several times cheaper for nearly the same colours.
  float cluster_size_m = 0.0f;
  // With clustering: 0 = each vertex takes its cluster's colour; 1 = the
  // distance-weighted mean over its cluster and the adjacent ones; 2 = the
  // coarse mesh is only used for visibility (rasterized depth maps and
  // discontinuities), every vertex is coloured itself.
  int cluster_transfer = 1;

  // OK, or InvalidArgument naming the field and value.
  Status Check() const;
};

// What the last Apply did, for logs and benchmarks.
struct TextureStats {
  size_t num_vertices = 0;
  size_t observed = 0;           // ≥ 1 view kept
  size_t edge_only = 0;          // only views near a discontinuity (discontinuity_fallback)
  size_t voted = 0;              // views disagreed; a majority cluster decided
  size_t min_variance = 0;       // no majority at any level: minimum-variance view
  size_t filled_from_neighbours = 0;
  size_t fallback = 0;           // never observed: minimum-variance facing view, tests ignored
  size_t uncoloured = 0;         // no view at all (left grey)
  size_t coarse_vertices = 0, coarse_triangles = 0;  // with cluster_size_m > 0
  double ms_cluster = 0, ms_raster = 0, ms_sample = 0, ms_fill = 0, ms_transfer = 0, ms_total = 0;
};

class Texturer {
 public:
  // `rig` must pass Rig::Check and `options` TextureOptions::Check; Apply
  // reports violations as InvalidArgument.
  Texturer(const Rig& rig, TextureOptions options);
  ~Texturer();
  Texturer(const Texturer&) = delete;
  Texturer& operator=(const Texturer&) = delete;

  // Sets `mesh->colors` (one RGB per vertex) from `frames` (one frame per pod
  // of the rig, in rig order; frames[i].color in pod i's colour camera at its
  // resolution; frames[i].mask empty or at the depth camera's resolution).
  // Uses `mesh->normals` when present (one per vertex), else area-weighted
  // face normals computed internally (the mesh's normals are not changed).
  // Buffers are reused: after the first call with a given mesh size and rig no
  // heap allocation happens. Errors: InvalidArgument (bad options/rig, pod
  // count or image size mismatch, null mesh), DataLoss (Mesh::Validate).
  Status Apply(const RgbdFrameSet& frames, Mesh* mesh);

  const TextureStats& stats() const { return stats_; }
  const TextureOptions& options() const { return options_; }
  // Rasterized inverse depth of the last Apply in pod `pod`'s colour camera
  // (1/z, 1/metres, 0 where empty), for debugging.
  const std::vector<float>& RasterInverseDepth(int pod) const;

 private:
  struct PodState;
  struct ThreadScratch;
  void PreparePod(int pod, const Mesh& mesh);
  void DiscontinuityMap(int pod);
  void RasterizeAllPods(const Mesh& mesh);
  void ColorVertices(const RgbdFrameSet& frames, const Mesh& mesh, const std::vector<Eigen::Vector3f>& normals,
                     size_t begin, size_t end, ThreadScratch* scratch);
  void FillUnobserved(const RgbdFrameSet& frames, Mesh* mesh, const std::vector<Eigen::Vector3f>& normals);
  // Raster, sampling and filling of `mesh` (normals: one per vertex).
  // `visibility_mesh` (null: `mesh`) is what is rasterized for visibility.
  void TextureMesh(const RgbdFrameSet& frames, Mesh* mesh, const std::vector<Eigen::Vector3f>& normals,
                   const Mesh* visibility_mesh = nullptr);
  // Builds coarse_ and cluster_of_ from `mesh`.
  void BuildClusters(const Mesh& mesh, const std::vector<Eigen::Vector3f>& normals);
  // Colours of `mesh` from coarse_'s colours.
  void TransferColors(Mesh* mesh);
  void BuildAdjacency(const Mesh& mesh);
  // The same lists, but only for vertices whose state_ is kUnset (the only
  // ones FillUnobserved reads; the others get empty lists). Same neighbour
  // order per vertex as BuildAdjacency.
  void BuildUnsetAdjacency(const Mesh& mesh);
  // The CSR lists of every vertex (`only_unset` false) or of the unset ones.
  void FillAdjacency(const Mesh& mesh, bool only_unset);

  Rig rig_;
  TextureOptions options_;
  Status init_status_;
  int threads_ = 1;
  std::unique_ptr<WorkerPool> pool_;
  std::vector<std::unique_ptr<PodState>> pods_;
  struct PodSimd;
  std::vector<PodSimd> pod_simd_;  // pods in groups of 4 (SSE2 builds, undistorted pods)
  bool simd_pods_ = false;
  // RasterizeAllPods: projected vertices (per group of four pods and vertex:
  // x[4], y[4] in 1/256 px as int32, 1/z[4]) and the per-thread largest 1/z per pod.
  std::vector<float> screen_, max_iz_lanes_;
  std::vector<std::unique_ptr<ThreadScratch>> scratch_;
  std::vector<Eigen::Vector3f> normals_;  // when the mesh has none
  std::vector<uint8_t> state_;            // per vertex: how it was coloured
  std::vector<std::array<float, 3>> accum_;
  std::vector<uint32_t> adj_offsets_, adj_;  // vertex adjacency (CSR), built when needed
  std::vector<uint32_t> frontier_, next_frontier_;
  bool adjacency_built_ = false;
  // Clustering (cluster_size_m > 0).
  Mesh coarse_;
  std::vector<uint32_t> cluster_of_;     // per vertex of the input mesh
  std::vector<uint64_t> hash_keys_;      // open addressing: cell key, ~0 = empty
  std::vector<uint32_t> hash_values_;
  std::vector<uint32_t> cluster_count_;
  TextureStats stats_;
};

}  // namespace holo
