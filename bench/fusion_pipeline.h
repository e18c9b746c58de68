// Whole-pipeline figures for `holoport-bench fusion`: our segmentation (not
// ground-truth masks), fusion, clean-up and texturing running concurrently
// on the capture pipeline, judged against the studio's ground truth.
#pragma once

#include "bench.h"

namespace holo::bench {

struct PipelineBenchOptions {
  int frames = 60;        // frames through the pipeline (throughput run)
  int eval_every = 10;    // keep every n-th frame's mesh and masks for scoring
  bool novel_views = true;
  std::string png_dir;    // if set: novel views (truth | ours) written here
  // Where frames come from: "synthetic" (the studio renders while the
  // pipeline runs: its CPU counts as acquire), "prerendered" (the same frames
  // rendered into memory before the run: acquire is a copy, as with cameras
  // that deliver frames), or "dataset:DIR" (a studio export of the same
  // workload on disk: acquire decodes PNGs), or "stereo" (depth from
  // PatchMatch on the studio's IR pairs as holoport-server --depth stereo
  // makes it, depth filter off unless depth_filter is set; the same frames
  // are also run on the studio's direct depth and the two sites' meshes
  // compared: "compare":"stereo_vs_direct"). The background is always the
  // studio's empty room; scoring always uses the studio's ground truth.
  std::string source = "synthetic";
  // Texturer clustering cell, mm (< 0: the capture site's default) and transfer mode.
  double texture_cluster_mm = -1;
  int texture_transfer = -1;
  // Segmenter overrides (< 0: the capture site's defaults; seg_edge_band:
  // SegmenterOptions::depth_edge_band_px, by default
  // kStereoSegmentEdgeBandPx with stereo depth and 0 otherwise).
  int seg_iterations = -1, seg_downsample = -1, seg_edge_band = -1;
  double seg_grid_px = -1;
  // --pipeline-source stereo: PatchMatchOptions::edge_shift_px (< 0: its default).
  int stereo_edge_shift = -1;
  // --pipeline-source stereo: StereoRoiOptions::row_spans (the regions as
  // row spans around the person, or their bounding boxes).
  bool stereo_roi_spans = true;
  // --pipeline-source stereo: StereoRoiOptions::search_with_sgbm.
  bool stereo_search_sgbm = true;
  // --pipeline-source stereo: PatchMatchOptions::temporal_still (< 0: its default).
  double stereo_still = -1;
  // TsdfOptions::behind_band override (< 0: the default).
  double behind_band = -1;
  // TsdfOptions::behind_noise_sigmas override (< 0: the default).
  double behind_sigmas = -1;
  // Frames of the serial run that measures CPU-ms per stage (0: skip it).
  int cpu_frames = 20;
  // Frames of the run that scores the stream mesh against the full mesh
  // (every eval_every-th is scored; 0: skip it).
  int stream_frames = 60;
  // Depth filter radius override (< 0: the capture site's default, 0: off)
  // and full meshes from the volume as fused, not smoothed.
  int depth_filter = -1;
  bool raw_full_mesh = false;
};

// Prints JSON lines: ms per stage (segment, fuse, mesh, texture, total),
// fps, cpu_ms per frame of the concurrent run and the fps two cores could
// sustain at that cost, cpu_ms per stage (serial run), latency_ms (paced
// run), mask_iou, chamfer_mm, completeness, the stream mesh's
// mean_distance_mm to the full mesh and back ("mode":"stream_mesh"), and
// novel_view_psnr_db / novel_view_ssim (4 viewpoints no pod has), all with
// "mode":"pipeline". Returns a process exit code.
int RunPipelineFigures(const BenchArgs& args, const PipelineBenchOptions& options);

}  // namespace holo::bench
