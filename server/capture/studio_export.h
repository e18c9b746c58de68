// Renders a span of the synthetic studio into a dataset folder (with ground
// truth beside it) and measures what it rendered. Used by holoport-studio and
// the demo.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "common/image.h"
#include "common/status.h"
#include "server/capture/dataset.h"
#include "studio/studio.h"

namespace holo {

struct StudioExportOptions {
  int64_t first_frame = 0;
  int64_t num_frames = 30;
  // Dataset folder to write, or empty to render without writing (timing only).
  std::string out_dir;
  bool ground_truth = true;
  DatasetWriterOptions writer;
  // Frame whose contact sheet is returned (-1: the middle frame).
  int64_t contact_sheet_frame = -1;
};

struct StudioExportSummary {
  int64_t frames = 0;
  int pods = 0;
  int width = 0, height = 0;
  double render_fps = 0;          // frames (all pods + ground truth) per second, rendering only
  double total_seconds = 0;       // including writing
  double foreground_fraction = 0; // mean fraction of pixels in the ground-truth masks
  double depth_valid_fraction = 0;       // noisy depth != 0 where truth is valid
  double depth_abs_error_mm = 0;         // mean |noisy - truth| where both valid
  double depth_median_abs_error_mm = 0;  // median of the same
  double fg_depth_valid_fraction = 0;    // as above, within the ground-truth foreground masks
  double fg_depth_abs_error_mm = 0;         // mean (flying pixels at silhouettes weigh in)
  double fg_depth_median_abs_error_mm = 0;
  size_t mesh_vertices = 0, mesh_triangles = 0;
  ImageRgb8 contact_sheet;
  std::string ToJson() const;
};

// `progress(done, total)` is called after every frame (may be empty).
StatusOr<StudioExportSummary> ExportStudio(SyntheticStudio& studio, const StudioExportOptions& options,
                                           const std::function<void(int64_t, int64_t)>& progress = {});

}  // namespace holo
