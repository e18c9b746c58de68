// A simulation of offloaded rendering with a thin client, for measurement
// and tests: a head trace drives display times; a simulated render host
// gets each pose `latency` late, renders (optionally at a predicted pose,
// optionally into an enlarged FOV), sends the image through the wire form
// (RenderedFrame: JPEG + LZ4 depth) and the thin client reprojects it to the
// pose at display time. Every displayed image is compared with the truth:
// the same scene content rendered at the display-time pose.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "client/pose/head_pose.h"
#include "client/pose/predictor.h"
#include "client/reproject/rendered_view.h"
#include "client/reproject/reproject.h"

namespace holo::reproject {

enum class OffloadMode {
  kIdeal,        // rendered at the true display pose (zero latency): the ceiling (JPEG only)
  kStale,        // rendered at the pose sampled `latency` earlier, shown as is
  kReprojected,  // the same image reprojected to the display pose
  kPredicted,    // rendered at the predicted display pose, reprojected
  kEnlarged,     // as predicted, rendered with an enlarged FOV
};
const char* OffloadModeName(OffloadMode m);  // "ideal", "stale", "reprojected", "predicted", "enlarged"

struct OffloadSimOptions {
  // Display (one eye): resolution and horizontal FOV, degrees (square pixels).
  int width = 640;
  int height = 360;
  double hfov_deg = 90.0;
  // Enlarged mode: FOV tangents × (1 + margin), same pixel density.
  double margin = 0.25;
  // Host latencies to simulate (pose sampled → image displayed), ms.
  std::vector<int> latencies_ms = {30, 50, 80};
  // Display frames, evenly spread over the trace after `warmup_s`.
  int display_frames = 120;
  double warmup_s = 1.0;
  std::vector<OffloadMode> modes = {OffloadMode::kIdeal, OffloadMode::kStale, OffloadMode::kReprojected,
                                    OffloadMode::kPredicted, OffloadMode::kEnlarged};
  ReprojectMethod method = ReprojectMethod::kPlane;
  ReprojectFilter filter = ReprojectFilter::kBilinear;
  pose::PredictorModel predictor = pose::PredictorModel::kKalman;
  pose::PredictorOptions predictor_options;
  FrameEncodeOptions encode;
  // Scene content rate: display time t shows content frame floor(t · fps)
  // (the same for host and truth: the figures isolate head motion).
  double content_fps = 30.0;
  // If set, PNGs of every `png_every`-th display frame (truth and each mode).
  std::string png_dir;
  int png_every = 20;
  Status Check() const;
};

struct OffloadResult {
  int latency_ms = 0;
  OffloadMode mode = OffloadMode::kStale;
  int frames = 0;
  // Means over the display frames.
  double psnr_db = 0;          // whole frame vs truth
  double psnr_content_db = 0;  // pixels where truth or display has content (non-black)
  double black_border_fraction = 0;
  double hole_fraction = 0;
  double wire_bytes = 0;       // RenderedFrame payload
  double reproject_cpu_ms = 0; // median thread CPU time of Reproject
  std::vector<double> frame_psnr_db;  // per display frame (for paired comparisons)
};

// The scene to render for content frame `frame`.
using SceneAtFrame = std::function<SceneRenderFn(int64_t frame)>;

// Runs the simulation over `trace` (world-frame eye poses, time-ordered;
// at least warm-up + 0.1 s long). `progress(done, total)` is called per
// display frame if set. Results: one per latency × mode, in that order.
StatusOr<std::vector<OffloadResult>> SimulateOffload(const std::vector<pose::PoseSample>& trace,
                                                     const SceneAtFrame& scene, const OffloadSimOptions& options,
                                                     const std::function<void(int, int)>& progress = {});

}  // namespace holo::reproject
