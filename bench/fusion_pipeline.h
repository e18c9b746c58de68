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
};

// Prints JSON lines: ms per stage (segment, fuse, mesh, texture, total),
// fps, latency_ms (paced run), mask_iou, chamfer_mm, completeness and
// novel_view_psnr_db / novel_view_ssim (4 viewpoints no pod has), all with
// "mode":"pipeline". Returns a process exit code.
int RunPipelineFigures(const BenchArgs& args, const PipelineBenchOptions& options);

}  // namespace holo::bench
