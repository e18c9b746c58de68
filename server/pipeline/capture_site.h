// The capture site: composes the real stages on the pipeline scheduler.
//
//   acquire  FrameSource::Next, then the per-pod colour calibration
//   segment  Segmenter (background learned at start-up), or ground-truth /
//            dataset masks, or none
//   fuse     TsdfVolume::Integrate of the masked depth (fresh volume per frame)
//   mesh     marching cubes + CleanupMesh (fragments, optional decimation)
//            — or, with `temporal`, both by TemporalFusion (server/temporal/:
//            the previous volume tracked non-rigidly and fused over time);
//            with `stream_mesh`, the compact stream mesh (StreamMesher:
//            coarser marching cubes + simplification to a triangle budget)
//            instead, and the full mesh only when `full_mesh` asks for it
//   texture  Texturer (Holoportation per-vertex colours)
//   encode   optional, the caller's (the session publisher's G1 + C1)
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "common/frame_source.h"
#include "common/rig.h"
#include "common/status.h"
#include "server/fusion/mesh_cleanup.h"
#include "server/fusion/depth_filter.h"
#include "server/fusion/stream_mesh.h"
#include "server/fusion/visual_hull.h"
#include "server/fusion/tsdf.h"
#include "server/pipeline/pipeline.h"
#include "server/segment/color_calibration.h"
#include "server/segment/segmenter.h"
#include "server/temporal/temporal_fusion.h"
#include "studio/studio.h"
#include "texture/texturer.h"

namespace holo {

enum class MaskSource {
  kSegment,  // our segmentation, background learned from empty-room frames
  kTruth,    // the studio's exact masks (synthetic source only; for evaluation)
  kDataset,  // masks stored with the frames (dataset source)
  kNone,     // fuse every valid depth pixel
};
// "segment" | "truth" | "dataset" | "none".
StatusOr<MaskSource> ParseMaskSource(const std::string& name);
const char* MaskSourceName(MaskSource m);

struct CaptureSiteOptions {
  MaskSource masks = MaskSource::kSegment;
  // Empty-room frame sets used to learn the background and the colour calibration.
  int background_frames = 30;
  // Estimate a per-pod colour mapping to pod 0 from the empty room and apply it.
  bool color_calibration = true;
  // One mean-field update instead of the segmenter's default two: on S8-QVGA
  // (20 frames scored through the pipeline) mask IoU 0.9682 → 0.9687,
  // Chamfer 6.484 → 6.491 mm, PSNR 18.892 → 18.890 dB, for ~3 CPU-ms less
  // per frame (docs/texturing.md, "Pipeline speed").
  SegmenterOptions segment = [] {
    SegmenterOptions o;
    o.crf_iterations = 1;
    return o;
  }();
  // Edge-preserving smoothing of each pod's depth within its mask before
  // fusion (server/fusion/depth_filter.h; radius 0 = off). Not used by the
  // visual hull, which reads no depth.
  DepthFilterOptions depth_filter;
  TsdfOptions tsdf;
  // Full-resolution meshes (the published mesh without `stream_mesh`, and
  // `full_mesh`) are extracted from the fused volume smoothed on its own
  // grid (TsdfVolume::SmoothInto). Not for temporal fusion, whose volume
  // carries its own history.
  bool smooth_full_mesh = true;
  MeshCleanupOptions cleanup;
  // Fuse + mesh by TemporalFusion (docs/temporal.md) instead of a fresh
  // volume per frame. Its `tsdf` and `cleanup` are replaced by the ones
  // above; the rest (graph, tracker, weight cap, reset policy) is used as is.
  bool temporal = false;
  TemporalFusionOptions temporal_options;
  // Reconstruct from the masks alone, as colour-only pods would
  // (server/fusion/visual_hull.h), instead of fusing depth; the volume
  // (`tsdf`'s voxel size and truncation) holds the hull's distance field and
  // everything after it runs unchanged. Not with `temporal`; needs masks.
  bool hull = false;
  VisualHullOptions hull_options;
  // Publish the compact stream mesh (server/fusion/stream_mesh.h) as
  // FrameWork::mesh. With `full_mesh` the full-resolution mesh is also made
  // (FrameWork::full_mesh, textured too: export, recording of full quality).
  bool stream_mesh = false;
  StreamMeshOptions stream;
  // With `stream_mesh`: also keep the grid the stream mesh is extracted from
  // (FrameWork::stream_field), for the G3 geometry codec.
  bool stream_field = false;
  bool full_mesh = false;
  bool texture = true;
  TextureOptions texture_options;
  PipelineOptions pipeline;
  Status Check() const;
  // temporal_options with tsdf and cleanup taken from above.
  TemporalFusionOptions TemporalOptions() const;
};

class CaptureSite {
 public:
  // `source` delivers the frames (borrowed for the site's lifetime).
  // `background` delivers empty-room frames for MaskSource::kSegment and
  // colour calibration (borrowed; read only in Create; may be null otherwise).
  // `studio` is needed for MaskSource::kTruth (borrowed; may be null otherwise).
  static StatusOr<std::unique_ptr<CaptureSite>> Create(FrameSource* source, FrameSource* background,
                                                       SyntheticStudio* studio, CaptureSiteOptions options);
  ~CaptureSite();

  // Runs the pipeline; `sink` sees every finished frame in order (its mesh
  // is textured, its frames carry the masks used).
  // `encode` (optional) runs as its own stage between texture and sink.
  StatusOr<PipelineStats> Run(std::function<Status(const FrameWork&)> sink,
                              std::function<Status(FrameWork&)> encode = {});
  void Stop();

  const Rig& rig() const { return rig_; }
  const ColorCalibration* color_calibration() const { return calibration_ ? calibration_.get() : nullptr; }

 private:
  CaptureSite() = default;
  PipelineStages MakeStages(std::function<Status(const FrameWork&)> sink, std::function<Status(FrameWork&)> encode);
  // The full-resolution mesh of volume_ (smoothed with smooth_full_mesh).
  Status ExtractFullMesh(Mesh* out);

  Rig rig_;
  CaptureSiteOptions options_;
  FrameSource* source_ = nullptr;
  SyntheticStudio* studio_ = nullptr;
  std::unique_ptr<ColorCalibration> calibration_;
  std::unique_ptr<Segmenter> segmenter_;
  std::unique_ptr<DepthFilter> depth_filter_;
  std::unique_ptr<TsdfVolume> volume_;
  std::unique_ptr<TsdfVolume> smoothed_;  // smooth_full_mesh
  std::unique_ptr<TemporalFusion> temporal_;
  std::unique_ptr<StreamMesher> stream_;
  std::unique_ptr<VisualHull> hull_;
  int64_t next_sequence_ = 0;  // acquire: the source's next frame set
  std::unique_ptr<Texturer> texturer_;
  std::unique_ptr<Pipeline> pipeline_;
};

}  // namespace holo
