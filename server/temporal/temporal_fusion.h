// Temporally consistent fusion (issue 4): instead of fusing every frame into
// a fresh TSDF volume, keep the previous frame's fused volume (the
// reference), track its surface non-rigidly into the new frame
// (NonrigidTracker on an ED graph), warp the reference volume into the live
// frame, and fuse the new observation into it (TsdfVolume::Integrate adds to
// the carried running averages). Regions where tracking fails are reset to
// the new observation. Policy (docs/temporal.md):
//
//  * Per frame: the graph is rebuilt on the reference surface (nodes every
//    `graph.node_spacing_m`), so the reference is always the last output —
//    there is no long-lived canonical key volume to drift from. Nodes start
//    at the previous frame's displacement (constant velocity); nodes that
//    moved less than `snap_still_m` are set to the identity afterwards.
//  * Only reference blocks holding (or next to) the cleaned reference mesh
//    are carried.
//  * Carried weights are capped at `max_weight`, so a voxel's value is an
//    exponential average over roughly max_weight / (views per frame) frames.
//  * Region reset: reference blocks skinned mostly (> ½) to failed nodes
//    (high residual, seen-through or outside a silhouette, stretched graph
//    edges = topology change) are dropped before fusing: that region shows
//    the new observation only.
//  * Visual hull: carried blocks that project outside a pod's silhouette are
//    dropped (free space by the masks).
//  * Tracking lost (more than `lost_node_fraction` of the nodes failed, or
//    fewer than `lost_min_associated` of the model points found a
//    correspondence, e.g. a frame of garbage depth): the frame is not fused;
//    the reference mesh is output again (the picture holds) and the reference
//    is tracked into the next frame. After `max_lost_frames` lost frames in a
//    row the reference is replaced by the frame's per-frame fusion (full
//    reset, a new key frame).
//
// Not thread-safe; one instance per stream.
#pragma once

#include <memory>
#include <vector>

#include "common/mesh.h"
#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"
#include "server/fusion/mesh_cleanup.h"
#include "server/fusion/tsdf.h"
#include "server/temporal/deformation_graph.h"
#include "server/temporal/feature_matcher.h"
#include "server/temporal/nonrigid_tracker.h"

namespace holo {

struct TemporalFusionOptions {
  TsdfOptions tsdf;
  MeshCleanupOptions cleanup;
  DeformationGraphOptions graph;
  TrackerOptions tracker;
  // Colour features for the tracker's sparse term (matched only when
  // tracker.SparseOn(rig): by resolution unless tracker.use_sparse is set).
  FeatureMatchOptions features;
  // false: plain per-frame fusion (the baseline), same code path otherwise.
  bool temporal = true;
  // Cap of a carried voxel weight (one pod's observation = 1): a voxel seen
  // by ≈ 3 pods averages over ≈ 20 frames. 60 since the fourth pass (was 30:
  // 60 is better on S8-QVGA and S8-VGA in flicker, Chamfer and the dropped
  // pod's kept surface, docs/temporal.md).
  float max_weight = 60.0f;
  // Model points tracked per frame (vertices of the reference mesh, evenly strided).
  int track_points = 3000;
  // At least this many model points per graph node (more points are taken
  // when the graph has more nodes than track_points / this, e.g. two people
  // and a crate at S8-VGA): with too few data residuals per node (12
  // parameters each) the tracker fits the sensor noise (docs/temporal.md).
  // 0 = off.
  float min_points_per_node = 7.0f;
  // Model points are taken only where the reference voxel's weight is at
  // least this (one pod's observation = 1), e.g. 2: not surface that a
  // single pod saw once (flying pixels, double surfaces of the first
  // per-frame fusion; S8-VGA flicker ratio 0.512 → 0.507, docs/temporal.md).
  // 0 = all.
  float min_track_weight = 2.0f;
  // Normals of the tracked model points: the gradient of the reference TSDF
  // box-filtered over (2r+1)³ voxels with central differences r voxels apart,
  // instead of the mesh vertex normal (one-voxel differences of a volume that
  // is a single frame's fusion in the first frames, so noisy). The data term
  // is point-to-plane along this normal. 0 = the mesh normals.
  int track_normal_radius_voxels = 2;
  // Start each node at the displacement of the nearest node of the last
  // tracked frame (constant-velocity prediction).
  bool predict_motion = true;
  // Nodes that moved less than this (translation, metres; and ‖A − I‖ <
  // 10 × this / 1 m) are set to the identity, so still regions are copied,
  // not re-sampled (0 = off).
  float snap_still_m = 0.002f;
  bool reset_failed_regions = true;
  bool hull_carving = true;
  float lost_node_fraction = 0.5f;
  // Also lost when fewer than this share of the model points find a
  // correspondence in any pod (garbage depth associates almost nothing).
  float lost_min_associated = 0.25f;
  int max_lost_frames = 2;

  Status Check() const;
};

struct TemporalFrameStats {
  // Wall time, ms: tracking; warping the reference into the live frame;
  // fusing the observation; marching cubes + clean-up; all.
  double track_ms = 0, warp_ms = 0, fuse_ms = 0, mesh_ms = 0, total_ms = 0;
  double features_ms = 0;    // colour features (detect + match; part of track_ms)
  size_t feature_pairs = 0;  // correspondences handed to the tracker
  bool tracked = false;      // a reference existed and was tracked
  bool lost = false;         // tracking lost: frame not fused, reference output again
  bool full_reset = false;   // reference replaced by this frame's per-frame fusion
  bool region_reset = false; // some reference blocks dropped because their nodes failed
  int nodes = 0, failed_nodes = 0;
  size_t carried_blocks = 0, reset_blocks = 0, hull_blocks = 0;
  TrackResult track;
};

class TemporalFusion {
 public:
  static StatusOr<std::unique_ptr<TemporalFusion>> Create(TemporalFusionOptions options);
  ~TemporalFusion();

  const TemporalFusionOptions& options() const { return options_; }

  // Fuses one frame set (masked depth as for TsdfVolume::Integrate) and
  // writes the cleaned mesh of the live frame to `out`. Errors
  // (InvalidArgument) leave the state as before the call.
  Status Process(const Rig& rig, const RgbdFrameSet& frames, Mesh* out, TemporalFrameStats* stats);

  // Forgets the reference (the next frame starts from scratch).
  void Reset();

  // The graph of the last tracked frame (nodes, parameters), for tests.
  const DeformationGraph& graph() const { return graph_; }
  const TsdfVolume& reference_volume() const { return *reference_; }
  // The model points and normals tracked in the last frame (on the
  // reference surface, before the warp), for tests.
  const std::vector<Eigen::Vector3f>& tracked_points() const { return points_; }
  const std::vector<Eigen::Vector3f>& tracked_normals() const { return normals_; }

  struct Impl;

 private:
  explicit TemporalFusion(TemporalFusionOptions options);
  Status FusePerFrame(const Rig& rig, const RgbdFrameSet& frames, TsdfVolume* volume, Mesh* out,
                      TemporalFrameStats* stats);
  // Replaces normals_ of points_ by box-filtered reference TSDF gradients
  // (track_normal_radius_voxels).
  void SmoothTrackNormals();
  void WarpReference(const Rig& rig, const RgbdFrameSet& frames, const TrackResult& track, TemporalFrameStats* stats);

  TemporalFusionOptions options_;
  std::unique_ptr<TsdfVolume> reference_, live_;
  Mesh reference_mesh_;
  bool has_reference_ = false;
  int lost_frames_ = 0;
  DeformationGraph graph_;
  std::unique_ptr<NonrigidTracker> tracker_;
  std::unique_ptr<FeatureMatcher> matcher_;
  std::vector<FeatureCorrespondence> pairs_;
  // The previous Process() call fused its frame (so the matcher's previous
  // features belong to the reference).
  bool prev_fused_ = false;
  std::unique_ptr<Impl> impl_;
  std::vector<Eigen::Vector3f> points_, normals_;
  // Last tracked frame: warped node positions and their displacements.
  std::vector<Eigen::Vector3f> prev_node_pos_, prev_node_disp_;
};

}  // namespace holo
