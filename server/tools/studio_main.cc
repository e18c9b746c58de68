// holoport-studio: renders a standard workload of the synthetic studio into a
// dataset folder (with ground truth), writes a contact sheet and a summary.
#include <cstdio>
#include <string>

#include <CLI/CLI.hpp>

#include "common/file_util.h"
#include "common/image_io.h"
#include "common/log.h"
#include "server/capture/studio_export.h"
#include "studio/studio.h"
#include "studio/workloads.h"

int main(int argc, char** argv) {
  CLI::App app{
      "holoport-studio: render the synthetic studio (every pod's colour and depth, with ground truth)\n"
      "into a dataset folder; print and write a summary; optionally write a contact sheet PNG."};
  holo::AddLogLevelOption(app);
  std::string workload_name = "S8-QVGA";
  std::string rig_path, out_dir, sheet_path, summary_path;
  int64_t frames = 30, first = 0;
  int64_t seed = -1;
  int threads = 0;
  bool no_gt = false, empty_room = false, no_noise = false, no_color_variation = false, jpeg = false, quiet = false;
  app.add_option("-w,--workload", workload_name, "standard workload: S8-QVGA or S8-VGA (see docs/workloads.md)")
      ->capture_default_str();
  app.add_option("--rig", rig_path, "use this rig YAML instead of the workload's pods");
  app.add_option("-n,--frames", frames, "number of frames to render")->capture_default_str()->check(CLI::Range(1, 100000));
  app.add_option("--first", first, "first frame index")->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--seed", seed, "random seed (default: the workload's)")->check(CLI::NonNegativeNumber);
  app.add_option("--threads", threads, "render threads (0 = all cores)")->capture_default_str()->check(CLI::Range(0, 256));
  app.add_option("-o,--out", out_dir, "dataset folder to write (must not hold a dataset); omit to only render");
  app.add_option("--contact-sheet", sheet_path, "write a PNG of all pods' colour, depth and mask (middle frame)");
  app.add_option("--summary", summary_path, "write the summary as JSON to this file");
  app.add_flag("--no-ground-truth", no_gt, "do not write ground truth beside the dataset");
  app.add_flag("--empty-room", empty_room, "render the room without people or props (background learning)");
  app.add_flag("--no-noise", no_noise, "depth without the sensor noise model");
  app.add_flag("--no-color-variation", no_color_variation, "identical colour response on every pod");
  app.add_flag("--jpeg", jpeg, "store colour as JPEG instead of PNG");
  app.add_flag("-q,--quiet", quiet, "no progress output");
  CLI11_PARSE(app, argc, argv);

  auto workload = holo::GetWorkload(workload_name);
  if (!workload.ok()) {
    spdlog::error("holoport-studio: {}", workload.status().message());
    return 1;
  }
  holo::Rig rig = workload->rig;
  if (!rig_path.empty()) {
    auto loaded = holo::LoadRig(rig_path);
    if (!loaded.ok()) {
      spdlog::error("holoport-studio: {}", loaded.status().message());
      return 1;
    }
    rig = *loaded;
  }
  holo::StudioOptions options = workload->studio;
  if (seed >= 0) options.seed = static_cast<uint64_t>(seed);
  options.threads = threads;
  options.empty_room = empty_room;
  options.depth_noise = !no_noise;
  options.color_variation = !no_color_variation;
  auto studio = holo::SyntheticStudio::Create(rig, options);
  if (!studio.ok()) {
    spdlog::error("holoport-studio: {}", studio.status().message());
    return 1;
  }

  holo::StudioExportOptions export_options;
  export_options.first_frame = first;
  export_options.num_frames = frames;
  export_options.out_dir = out_dir;
  export_options.ground_truth = !no_gt;
  export_options.writer.color_jpeg = jpeg;
  if (!quiet)
    spdlog::info("holoport-studio: {}, {} pods at {}x{}, frames {}..{}{}{}", workload->name, rig.pods.size(),
                 rig.pods[0].depth.width, rig.pods[0].depth.height, first, first + frames - 1,
                 out_dir.empty() ? "" : " -> ", out_dir);
  auto summary = holo::ExportStudio(**studio, export_options, [&](int64_t done, int64_t total) {
    if (quiet) return;
    if (done == total || done % 10 == 0) spdlog::info("  frame {}/{}", done, total);
  });
  if (!summary.ok()) {
    spdlog::error("holoport-studio: {}", summary.status().message());
    return 1;
  }
  if (!sheet_path.empty()) {
    const holo::Status s = holo::WriteImageRgb8(sheet_path, summary->contact_sheet);
    if (!s.ok()) {
      spdlog::error("holoport-studio: {}", s.message());
      return 1;
    }
  }
  const std::string json = summary->ToJson();
  if (!summary_path.empty()) {
    const holo::Status s = holo::WriteStringToFile(summary_path, json + "\n");
    if (!s.ok()) {
      spdlog::error("holoport-studio: {}", s.message());
      return 1;
    }
  }
  std::printf("%s\n", json.c_str());
  if (!quiet) {
    spdlog::info("rendered {} frames of {} pods at {:.1f} frames/s (render only); foreground {:.1f}% of pixels",
                 summary->frames, summary->pods, summary->render_fps, 100 * summary->foreground_fraction);
    spdlog::info(
        "depth noise: {:.1f}% of true depth valid, mean |error| {:.2f} mm, median {:.2f} mm (foreground: {:.1f}% "
        "valid, "
        "mean |error| {:.2f} mm, median {:.2f} mm)",
        100 * summary->depth_valid_fraction, summary->depth_abs_error_mm, summary->depth_median_abs_error_mm,
        100 * summary->fg_depth_valid_fraction, summary->fg_depth_abs_error_mm, summary->fg_depth_median_abs_error_mm);
    spdlog::info("ground-truth mesh {} vertices, {} triangles", summary->mesh_vertices, summary->mesh_triangles);
    if (!sheet_path.empty()) spdlog::info("contact sheet: {}", sheet_path);
  }
  return 0;
}
