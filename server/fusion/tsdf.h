// Multi-pod TSDF fusion on sparse voxel blocks, and marching-cubes meshing.
//
// Integrate() takes one synchronized frame set: every pod's (masked) depth is
// fused into 8³-voxel blocks that are allocated only where masked depth lands
// (the truncation band around each measured point). Each block is then
// integrated by projecting its voxels into every pod that can see it
// (projective signed distance along the camera z axis, as in KinectFusion and
// Open3D), with a running weighted average, so integrating into a volume that
// already holds data is a proper temporal update. ExtractMesh() runs marching
// cubes over the blocks with shared edge vertices.
//
// Threading: Integrate and ExtractMesh use options.threads threads (a
// persistent pool owned by the volume). A volume is not safe for concurrent
// calls from several threads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "common/mesh.h"
#include "common/rgbd.h"
#include "common/rig.h"
#include "common/sdf_grid.h"
#include "common/status.h"
#include "server/fusion/voxel_blocks.h"

namespace holo {

struct TsdfOptions {
  // Edge length of one voxel, metres.
  float voxel_size = 0.005f;
  // Truncation distance, in voxels (Open3D's sdf_trunc = this · voxel_size).
  float truncation_voxels = 4.0f;
  // Observations behind the measured surface count down to
  //     behind(d) = behind_band · truncation + behind_noise_sigmas · σ(d),
  //     σ(d) = depth_noise_at_1m_mm · d²   (d: the pixel's depth, metres),
  // clamped to −1; deeper ones are dropped (behind_band 1 and no noise term:
  // dropped beyond one truncation distance, as KinectFusion and Open3D do).
  // Dropping them while the ones in front are only clamped at +1 biases the
  // average outward wherever depth noise is comparable to the truncation:
  // on the studio (σ ≈ 19 mm at 2.5 m, 32 mm truncation at S8-QVGA) the
  // surface sat 2.8 mm inside the person with band 1. A band that follows the
  // sensor's noise at each pixel's depth removes that bias where the noise is
  // large and adds nothing where it is small (exact depth: σ = 0), which a
  // fixed multiple of the truncation cannot do: a deep fixed band grows
  // flaps at sharp corners of clean depth (docs/fusion.md has the figures).
  // Only voxels the truncation band's blocks reach are updated.
  float behind_band = 1.25f;
  float behind_noise_sigmas = 1.25f;
  // The depth sensor's axial noise at 1 m, millimetres, growing with z²
  // (the site's sensor model, as SegmenterOptions::depth_noise_at_1m_m and
  // DepthFilterOptions::sigma_at_1m_mm). 0: exact depth.
  float depth_noise_at_1m_mm = 3.0f;
  // Depth beyond this is ignored, metres.
  float max_depth_m = 5.0f;
  // Depth nearer than this is ignored, metres.
  float min_depth_m = 0.1f;
  // Ignore observations behind the surface (negative distance) made through
  // a pixel on a depth edge: a pixel with a 4-neighbour that has no usable
  // depth (masked, invalid) or differs by more than the truncation distance.
  // With nearest-pixel lookup such pixels otherwise mark the space just
  // behind a silhouette as inside, which grows flaps at object edges.
  bool ignore_behind_depth_edges = false;
  // Blocks are allocated only around pixels with at least this many
  // 4-neighbours whose depth is within the truncation distance of theirs
  // (0 = every usable pixel). Isolated flying pixels then allocate nothing:
  // on the studio they would allocate ~60 % of the blocks, all of it junk
  // (small blobs the clean-up removes) and time. Such pixels still update
  // blocks that their neighbours' bands allocated.
  int allocation_min_support = 2;
  // Marching cubes uses a cube only if every corner has at least this
  // accumulated weight (one observation = weight 1).
  float min_weight = 1.0f;
  // Marching cubes skips cubes with a corner that every view saw as free
  // space beyond the truncation distance (tsdf = +1): such a cube cannot hold
  // the surface, and skipping it removes spurious sheets where views disagree.
  bool skip_truncated_cubes = true;
  // Per-voxel colour (weighted mean of the pods' colour in the truncation
  // band) and per-vertex mesh colour interpolated from it. Off: Integrate
  // fuses geometry only (voxel colours stay 0) and ExtractMesh leaves the
  // mesh's colours empty — for callers that colour the mesh themselves
  // (the capture site when its texture stage runs: the texturer replaces
  // every vertex colour). Geometry and normals are the same either way.
  bool integrate_color = true;
  // Worker threads; 0 = std::thread::hardware_concurrency().
  int threads = 0;

  // OK, or InvalidArgument naming the field: "voxel_size must be > 0, got -1".
  Status Check() const;
};

// Counters of the last Integrate / ExtractMesh call (for benchmarks and logs).
struct TsdfStats {
  size_t blocks_touched = 0;       // blocks the last frame's depth landed in
  size_t blocks_allocated = 0;     // of those, newly allocated
  size_t block_views = 0;          // (block, pod) pairs integrated
  size_t block_views_skipped = 0;  // pairs skipped: outside the image, no valid depth, or occluded
  size_t block_views_free = 0;     // of the integrated pairs, those wholly in free space (no projection needed)
  size_t sub_blocks_projected = 0; // 4³ sub-blocks projected voxel by voxel (the rest culled or free space)
  size_t mesh_blocks = 0;          // blocks that could hold a surface during meshing
  // Wall time of Integrate's phases, ms: depth preparation and block
  // collection (parallel over pods), block allocation (serial), voxel
  // integration (parallel over blocks).
  double prepare_ms = 0, allocate_ms = 0, integrate_ms = 0;
};

class TsdfVolume {
 public:
  // `options` must pass Check() (HOLO_CHECK otherwise; use Create for
  // untrusted values).
  explicit TsdfVolume(TsdfOptions options);
  static StatusOr<std::unique_ptr<TsdfVolume>> Create(TsdfOptions options);
  ~TsdfVolume();
  TsdfVolume(const TsdfVolume&) = delete;
  TsdfVolume& operator=(const TsdfVolume&) = delete;

  const TsdfOptions& options() const { return options_; }

  // Empties the volume but keeps its memory for the next frame, so a
  // steady-state frame loop allocates nothing.
  void Reset();

  // Fuses every pod's depth. Only pixels whose mask is nonzero are used when
  // the frame has a mask (empty mask = all pixels). Colour comes from the
  // pod's colour camera (which may differ from the depth camera). Errors
  // (InvalidArgument, naming the pod): pod count differs from the rig, an
  // image size differs from the calibration, a bad rig. The volume is
  // unchanged on error.
  Status Integrate(const Rig& rig, const RgbdFrameSet& frames);

  // Marching cubes over all blocks: vertices shared between triangles (one
  // per crossed voxel edge, no duplicate positions), triangles
  // counter-clockwise seen from outside (free space), normals from the TSDF
  // gradient, per-vertex colour interpolated from the voxels. Reuses `out`'s
  // buffers. Cubes whose corners are not all observed (min_weight) are skipped.
  void ExtractMesh(Mesh* out) const;

  // The same field on a grid `step` times coarser: coarse voxel c (reset
  // first) holds the weighted mean TSDF value and colour of the fine voxels
  // step·c … step·c + step − 1 on each axis (a box filter: noise averages
  // out, and the mean of a linear field is its value at the box centre), and
  // the mean weight of those observed; unobserved where none is. The box
  // centre sits (step − 1)/2 fine voxels above coarse voxel c's own position,
  // so a mesh extracted from `coarse` must be shifted by DownsampleOffset(step)
  // to sit on the fine volume's surface. `coarse` must have voxel_size =
  // step · voxel_size and the same truncation in metres (truncation_voxels /
  // step); InvalidArgument otherwise. Used for the capture site's stream
  // mesh (server/fusion/stream_mesh.h).
  Status DownsampleInto(int step, TsdfVolume* coarse) const;
  // The same field smoothed on the same grid: every observed voxel of `out`
  // (reset first; same voxel size and truncation, InvalidArgument
  // otherwise) holds the weighted mean TSDF of its observed 3×3×3
  // neighbours, with the binomial kernel [1 2 1] on each axis; weights,
  // colours and unobserved voxels are copied as they are. What is left of
  // the depth noise after the depth filter (server/fusion/depth_filter.h)
  // folds the full-resolution mesh at the scale of one voxel. Voxels at +1
  // (free space beyond the truncation) are smoothed too: next to the
  // surface they drop below +1, so cubes that marching cubes skipped for
  // one noisy +1 corner (skip_truncated_cubes) are meshed again. Measured on
  // the S8-QVGA pipeline (docs/fusion.md, "Depth filter and smoothing"):
  // full mesh 110 k → 84 k triangles, Chamfer to the truth 5.42 → 5.36 mm;
  // keeping the +1 voxels as they were gave 5.46 mm. The capture site's
  // full-resolution meshes (export, recording) are extracted from it.
  Status SmoothInto(TsdfVolume* out) const;
  // The field as a dense box of samples (common/sdf_grid.h) for the G3
  // geometry codec: the box of the blocks holding a voxel behind the
  // surface (tsdf < 0), one voxel wider on every side (every cube marching
  // cubes could mesh lies in it), signed
  // distances in metres (tsdf · truncation), NaN where the weight is below
  // min_weight — exactly the voxels marching cubes would use. With no
  // blocks, one unobserved sample. `out`'s buffer is reused.
  void ExportGrid(SdfGrid* out) const;
  // World offset (metres, the same on every axis) of DownsampleInto's coarse grid.
  float DownsampleOffset(int step) const { return 0.5f * static_cast<float>(step - 1) * options_.voxel_size; }

  size_t num_blocks() const { return blocks_.size(); }
  const TsdfStats& stats() const { return stats_; }

  // The block storage, for inspection, tests and (later) temporal fusion.
  const VoxelBlockMap& blocks() const { return blocks_; }
  VoxelBlockMap& mutable_blocks() { return blocks_; }

  // TSDF value (in [-1, 1]) and weight of the voxel at global voxel index
  // (x, y, z); weight 0 if its block is not allocated.
  void VoxelAt(int64_t x, int64_t y, int64_t z, float* tsdf, float* weight) const;

 // Implementation details, defined in tsdf_internal.h.
  struct PodView;
  struct Scratch;
  struct RowMasks;

 private:

  TsdfOptions options_;
  VoxelBlockMap blocks_;
  std::unique_ptr<Scratch> scratch_;  // per-frame buffers reused across calls
  mutable TsdfStats stats_;
};

}  // namespace holo
