#include "server/capture/studio_export.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/clock.h"
#include "common/visualize.h"

namespace holo {

std::string StudioExportSummary::ToJson() const {
  nlohmann::ordered_json j;
  j["frames"] = frames;
  j["pods"] = pods;
  j["width"] = width;
  j["height"] = height;
  j["render_fps"] = render_fps;
  j["total_seconds"] = total_seconds;
  j["foreground_fraction"] = foreground_fraction;
  j["depth_valid_fraction"] = depth_valid_fraction;
  j["depth_abs_error_mm"] = depth_abs_error_mm;
  j["depth_median_abs_error_mm"] = depth_median_abs_error_mm;
  j["fg_depth_valid_fraction"] = fg_depth_valid_fraction;
  j["fg_depth_abs_error_mm"] = fg_depth_abs_error_mm;
  j["fg_depth_median_abs_error_mm"] = fg_depth_median_abs_error_mm;
  j["mesh_vertices"] = mesh_vertices;
  j["mesh_triangles"] = mesh_triangles;
  return j.dump();
}

StatusOr<StudioExportSummary> ExportStudio(SyntheticStudio& studio, const StudioExportOptions& options,
                                           const std::function<void(int64_t, int64_t)>& progress) {
  if (options.num_frames <= 0) return InvalidArgument("num_frames must be > 0, got " + std::to_string(options.num_frames));
  if (options.first_frame < 0) return InvalidArgument("first_frame must be >= 0, got " + std::to_string(options.first_frame));
  std::unique_ptr<DatasetWriter> writer;
  if (!options.out_dir.empty()) {
    HOLO_ASSIGN_OR_RETURN(writer, DatasetWriter::Create(options.out_dir, studio.rig(), options.writer));
  }
  StudioExportSummary summary;
  summary.pods = static_cast<int>(studio.rig().pods.size());
  summary.width = studio.rig().pods[0].depth.width;
  summary.height = studio.rig().pods[0].depth.height;
  const int64_t sheet_frame =
      options.contact_sheet_frame >= 0 ? options.contact_sheet_frame : options.first_frame + options.num_frames / 2;

  RgbdFrameSet frames;
  StudioGroundTruth gt;
  double render_s = 0, fg_sum = 0;
  double valid_sum = 0, valid_count = 0, err_sum = 0, err_count = 0;
  double fg_valid = 0, fg_count = 0, fg_err_sum = 0, fg_err_count = 0;
  std::vector<uint32_t> err_hist(200, 0);  // |error| histogram, 0.5 mm bins, for the median
  std::vector<uint32_t> fg_err_hist(200, 0);
  Stopwatch total;
  for (int64_t i = 0; i < options.num_frames; ++i) {
    const int64_t f = options.first_frame + i;
    Stopwatch sw;
    studio.RenderFrame(f, &frames, &gt);
    render_s += sw.ElapsedMs() * 1e-3;
    for (size_t p = 0; p < frames.frames.size(); ++p) {
      const auto& noisy = frames.frames[p].depth;
      const auto& truth = gt.depth[p];
      const auto& mask = gt.mask[p];
      size_t fg = 0;
      for (size_t k = 0; k < truth.num_pixels(); ++k) {
        fg += mask.data()[k] != 0;
        const uint16_t t = truth.data()[k], n = noisy.data()[k];
        if (t == 0) continue;
        valid_count += 1;
        if (n == 0) continue;
        valid_sum += 1;
        const double e = std::abs(static_cast<double>(n) - t);
        err_sum += e;
        err_count += 1;
        err_hist[std::min<size_t>(err_hist.size() - 1, static_cast<size_t>(e * 2))]++;
      }
      for (size_t k = 0; k < truth.num_pixels(); ++k) {
        if (mask.data()[k] == 0 || truth.data()[k] == 0) continue;
        fg_count += 1;
        if (noisy.data()[k] == 0) continue;
        fg_valid += 1;
        const double e = std::abs(static_cast<double>(noisy.data()[k]) - truth.data()[k]);
        fg_err_sum += e;
        fg_err_hist[std::min<size_t>(fg_err_hist.size() - 1, static_cast<size_t>(e * 2))]++;
        fg_err_count += 1;
      }
      fg_sum += static_cast<double>(fg) / static_cast<double>(std::max<size_t>(1, truth.num_pixels()));
    }
    if (writer) {
      HOLO_RETURN_IF_ERROR(writer->Write(frames));
      if (options.ground_truth)
        HOLO_RETURN_IF_ERROR(writer->WriteGroundTruth(f, gt.depth, gt.mask, &gt.foreground_mesh));
    }
    if (f == sheet_frame) {
      RgbdFrameSet with_masks = frames;
      for (size_t p = 0; p < with_masks.frames.size(); ++p) with_masks.frames[p].mask = gt.mask[p];
      summary.contact_sheet = MakeContactSheet(with_masks, 4, true);
    }
    summary.mesh_vertices = gt.foreground_mesh.num_vertices();
    summary.mesh_triangles = gt.foreground_mesh.num_triangles();
    if (progress) progress(i + 1, options.num_frames);
  }
  if (writer) HOLO_RETURN_IF_ERROR(writer->Close());
  summary.frames = options.num_frames;
  summary.render_fps = render_s > 0 ? static_cast<double>(options.num_frames) / render_s : 0;
  summary.total_seconds = total.ElapsedMs() * 1e-3;
  summary.foreground_fraction = fg_sum / static_cast<double>(options.num_frames * std::max(1, summary.pods));
  summary.depth_valid_fraction = valid_count > 0 ? valid_sum / valid_count : 0;
  summary.depth_abs_error_mm = err_count > 0 ? err_sum / err_count : 0;
  summary.fg_depth_valid_fraction = fg_count > 0 ? fg_valid / fg_count : 0;
  summary.fg_depth_abs_error_mm = fg_err_count > 0 ? fg_err_sum / fg_err_count : 0;
  auto median = [](const std::vector<uint32_t>& hist, double count) {
    double acc = 0;
    for (size_t b = 0; b < hist.size(); ++b) {
      acc += hist[b];
      if (acc >= count / 2) return static_cast<double>(b) * 0.5 + 0.25;
    }
    return 0.0;
  };
  summary.depth_median_abs_error_mm = median(err_hist, err_count);
  summary.fg_depth_median_abs_error_mm = median(fg_err_hist, fg_err_count);
  return summary;
}

}  // namespace holo
