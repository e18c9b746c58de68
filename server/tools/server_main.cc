// holoport-server: the capture site. Reads frames from the synthetic studio or
// a dataset, segments, fuses, meshes and textures every frame on the
// concurrent pipeline; exports PLY meshes and per-frame stats. (Streaming to
// viewers comes with the sessions issue.)
#include <cstdio>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "common/file_util.h"
#include "common/image_io.h"
#include "common/visualize.h"
#include "server/capture/dataset.h"
#include "server/pipeline/capture_site.h"
#include "server/record/replay_command.h"
#include "server/studio/studio.h"
#include "server/studio/workloads.h"
#include "server/texture/mesh_renderer.h"
#include "server/texture/novel_view.h"

namespace {

int Fail(const holo::Status& s) {
  std::fprintf(stderr, "holoport-server: %s\n", s.message().c_str());
  return 1;
}

char FrameFileName(char* buf, size_t n, const std::string& dir, int64_t index) {
  std::snprintf(buf, n, "%s/mesh_%06lld.ply", dir.c_str(), static_cast<long long>(index));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "holoport-server: the capture site. Frames from the synthetic studio or a dataset go through\n"
      "colour calibration, segmentation, TSDF fusion, marching cubes, clean-up and texturing, stages\n"
      "running concurrently; every frame's textured mesh can be exported as PLY. Stage timings and\n"
      "progress go to stderr, per-frame stats as JSON lines to --stats (or stdout)."};
  std::string source_spec = "synthetic", workload_name = "S8-QVGA", rig_path, background_spec, export_dir, stats_path;
  std::string masks_name = "segment", snapshot_path;
  int64_t frames = 60;
  double voxel_mm = 0, trunc_voxels = 4, pace = 0;
  size_t decimate = 0, min_component = 200;
  int background_frames = 30, queue = 2;
  bool serial = false, no_texture = false, no_color_calibration = false, quiet = false;
  app.add_option("--source", source_spec, "synthetic (the studio) or dataset:PATH")->capture_default_str();
  app.add_option("-w,--workload", workload_name, "synthetic source: S8-QVGA or S8-VGA")->capture_default_str();
  app.add_option("--rig", rig_path, "synthetic source: render this rig instead of the workload's");
  app.add_option("--background", background_spec,
                 "empty-room frames for segmentation and colour calibration: dataset:PATH "
                 "(default for the synthetic source: the studio's empty room)");
  app.add_option("--masks", masks_name, "segment | truth (synthetic only) | dataset | none")->capture_default_str();
  app.add_option("-n,--frames", frames, "frames to process (-1: until the source ends)")->capture_default_str();
  app.add_option("--voxel-mm", voxel_mm, "TSDF voxel size, mm (default: the workload's, 10 for datasets)");
  app.add_option("--trunc-voxels", trunc_voxels, "TSDF truncation, voxels")->capture_default_str();
  app.add_option("--decimate", decimate, "decimate meshes to this many triangles (0: off)")->capture_default_str();
  app.add_option("--min-component", min_component, "drop mesh fragments with fewer triangles")->capture_default_str();
  app.add_option("--background-frames", background_frames, "empty-room frames to learn from")->capture_default_str();
  app.add_option("--queue", queue, "frames in flight per pipeline hop")->capture_default_str();
  app.add_option("--pace", pace, "pace acquisition like a live camera at this fps (0: as fast as possible)");
  app.add_option("--export", export_dir, "write every frame's textured mesh to DIR/mesh_NNNNNN.ply");
  app.add_option("--snapshot", snapshot_path,
                 "write a PNG of the last frame's textured mesh from a viewpoint no pod has "
                 "(synthetic source: ground truth on the left, ours on the right)");
  app.add_option("--stats", stats_path, "write per-frame stats as JSON lines to this file (default stdout)");
  app.add_flag("--serial", serial, "run the stages one after another on one thread");
  app.add_flag("--no-texture", no_texture, "skip texturing (voxel colours stay)");
  app.add_flag("--no-color-calibration", no_color_calibration, "do not estimate and apply per-pod colour maps");
  app.add_flag("-q,--quiet", quiet, "no progress output");
  // Replay of a recording (docs/recording.md): serves the recorded stream instead of the capture pipeline.
  holo::record::ReplayCommandOptions replay;
  app.add_option("--replay", replay.path, "replay this recording instead of capturing (with --export / --stats)");
  app.add_option("--speed", replay.speed, "--replay: playback speed, 0.25..4")->capture_default_str();
  app.add_flag("--loop", replay.loop, "--replay: start again at the end");
  app.add_option("--start", replay.start_s, "--replay: start at this media time, seconds");
  app.add_option("--replay-seconds", replay.max_wall_s, "--replay: stop after this many seconds (0: at the end)");
  CLI11_PARSE(app, argc, argv);
  if (!replay.path.empty()) {
    replay.export_dir = export_dir;
    replay.stats_path = stats_path;
    replay.quiet = quiet;
    return holo::record::RunReplayCommand(replay);
  }

  auto masks = holo::ParseMaskSource(masks_name);
  if (!masks.ok()) return Fail(masks.status());

  holo::CaptureSiteOptions options;
  options.masks = *masks;
  options.background_frames = background_frames;
  options.color_calibration = !no_color_calibration;
  options.texture = !no_texture;
  options.tsdf.truncation_voxels = static_cast<float>(trunc_voxels);
  options.cleanup.target_triangles = decimate;
  options.cleanup.min_component_triangles = min_component;
  options.pipeline.serial = serial;
  options.pipeline.queue_capacity = queue;
  options.pipeline.pace_fps = pace;
  options.pipeline.max_frames = frames;

  // Sources. The studio is both the frame source and (empty room) the background.
  std::unique_ptr<holo::SyntheticStudio> studio, empty_room;
  std::unique_ptr<holo::DatasetReader> dataset, background_dataset;
  holo::FrameSource* source = nullptr;
  holo::FrameSource* background = nullptr;
  std::string source_name;
  if (source_spec == "synthetic") {
    auto workload = holo::GetWorkload(workload_name);
    if (!workload.ok()) return Fail(workload.status());
    holo::Rig rig = workload->rig;
    if (!rig_path.empty()) {
      auto loaded = holo::LoadRig(rig_path);
      if (!loaded.ok()) return Fail(loaded.status());
      rig = *loaded;
    }
    auto s = holo::SyntheticStudio::Create(rig, workload->studio);
    if (!s.ok()) return Fail(s.status());
    studio = std::move(*s);
    holo::StudioOptions empty = workload->studio;
    empty.empty_room = true;
    auto e = holo::SyntheticStudio::Create(rig, empty);
    if (!e.ok()) return Fail(e.status());
    empty_room = std::move(*e);
    source = studio.get();
    background = empty_room.get();
    options.tsdf.voxel_size = voxel_mm > 0 ? static_cast<float>(voxel_mm * 1e-3) : workload->voxel_size_m;
    source_name = workload->name;
  } else if (source_spec.rfind("dataset:", 0) == 0) {
    auto d = holo::DatasetReader::Open(source_spec.substr(8));
    if (!d.ok()) return Fail(d.status());
    dataset = std::move(*d);
    source = dataset.get();
    options.tsdf.voxel_size = static_cast<float>((voxel_mm > 0 ? voxel_mm : 10.0) * 1e-3);
    source_name = source_spec;
    if (options.masks == holo::MaskSource::kTruth)
      return Fail(holo::InvalidArgument("--masks truth needs --source synthetic"));
  } else {
    return Fail(holo::InvalidArgument("--source must be 'synthetic' or 'dataset:PATH', got '" + source_spec + "'"));
  }
  if (!background_spec.empty()) {
    if (background_spec.rfind("dataset:", 0) != 0)
      return Fail(holo::InvalidArgument("--background must be dataset:PATH, got '" + background_spec + "'"));
    auto d = holo::DatasetReader::Open(background_spec.substr(8));
    if (!d.ok()) return Fail(d.status());
    background_dataset = std::move(*d);
    background = background_dataset.get();
  }
  if (background == nullptr) {
    // A dataset without empty-room frames: segmentation and calibration are impossible.
    if (options.masks == holo::MaskSource::kSegment)
      return Fail(holo::InvalidArgument(
          "--masks segment needs empty-room frames: pass --background dataset:PATH, or use --masks dataset|none"));
    options.color_calibration = false;
  }
  if (!export_dir.empty()) {
    holo::Status s = holo::MakeDirs(export_dir);
    if (!s.ok()) return Fail(s);
  }
  FILE* stats_out = stdout;
  if (!stats_path.empty()) {
    stats_out = std::fopen(stats_path.c_str(), "w");
    if (stats_out == nullptr) return Fail(holo::Unavailable(stats_path + ": cannot open for writing"));
  }

  if (!quiet)
    std::fprintf(stderr, "holoport-server: %s, %zu pods, masks=%s, voxel %.1f mm, %s pipeline; learning background...\n",
                 source_name.c_str(), source->rig().pods.size(), holo::MaskSourceName(options.masks),
                 options.tsdf.voxel_size * 1e3, serial ? "serial" : "concurrent");
  auto site = holo::CaptureSite::Create(source, background, studio.get(), options);
  if (!site.ok()) return Fail(site.status());

  int64_t done = 0;
  holo::Mesh last_mesh;
  int64_t last_frame = -1;
  auto sink = [&](const holo::FrameWork& w) -> holo::Status {
    if (!snapshot_path.empty()) {
      last_mesh = w.mesh;
      last_frame = w.frames.frame_index;
    }
    const auto& t = w.timings;
    std::fprintf(stats_out,
                 "{\"frame\":%lld,\"vertices\":%zu,\"triangles\":%zu,\"acquire_ms\":%.3f,\"segment_ms\":%.3f,"
                 "\"fuse_ms\":%.3f,\"mesh_ms\":%.3f,\"texture_ms\":%.3f,\"latency_ms\":%.3f}\n",
                 static_cast<long long>(w.frames.frame_index), w.mesh.num_vertices(), w.mesh.num_triangles(),
                 t.acquire_ms, t.segment_ms, t.fuse_ms, t.mesh_ms, t.texture_ms, t.latency_ms());
    if (!export_dir.empty()) {
      char path[4096];
      FrameFileName(path, sizeof(path), export_dir, w.frames.frame_index);
      HOLO_RETURN_IF_ERROR(holo::WritePly(path, w.mesh));
    }
    ++done;
    if (!quiet && (done % 30 == 0))
      std::fprintf(stderr,
                   "  frame %lld: %zu triangles; segment %.1f ms, fuse %.1f, mesh %.1f, texture %.1f; latency %.1f ms\n",
                   static_cast<long long>(done), w.mesh.num_triangles(), t.segment_ms, t.fuse_ms, t.mesh_ms,
                   t.texture_ms, t.latency_ms());
    return holo::OkStatus();
  };
  auto stats = (*site)->Run(sink);
  if (stats_out != stdout) std::fclose(stats_out);
  if (!stats.ok()) return Fail(stats.status());
  if (!snapshot_path.empty() && last_frame >= 0) {
    holo::NovelViewOptions nv;
    nv.intrinsics = holo::Intrinsics::FromFov(480, 480, 60.0);
    const holo::NovelView view = holo::MakeNovelViews(nv)[0];
    holo::ImageRgb8 ours, truth;
    holo::Status s = holo::RenderMesh(last_mesh, view.camera, &ours, nullptr, nullptr);
    if (!s.ok()) return Fail(s);
    std::vector<const holo::ImageRgb8*> tiles;
    if (studio) {
      studio->RenderView(last_frame, view.camera, &truth, nullptr, nullptr);
      tiles.push_back(&truth);
    }
    tiles.push_back(&ours);
    s = holo::WriteImageRgb8(snapshot_path, holo::TileImages(tiles, 2));
    if (!s.ok()) return Fail(s);
    if (!quiet) std::fprintf(stderr, "holoport-server: snapshot of frame %lld in %s\n", static_cast<long long>(last_frame), snapshot_path.c_str());
  }
  const holo::StageTimings m = holo::MedianTimings(*stats);
  if (!quiet)
    std::fprintf(stderr,
                 "holoport-server: %lld frames in %.2f s = %.1f fps; median ms: acquire %.1f, segment %.1f, fuse %.1f, "
                 "mesh %.1f, texture %.1f; median latency %.1f ms (%s)%s%s\n",
                 static_cast<long long>(stats->frames), stats->wall_seconds, stats->fps, m.acquire_ms, m.segment_ms,
                 m.fuse_ms, m.mesh_ms, m.texture_ms, holo::MedianLatencyMs(*stats),
                 pace > 0 ? "paced" : "unpaced: includes waiting in queues; use --pace for live latency",
                 export_dir.empty() ? "" : "; meshes in ", export_dir.c_str());
  return 0;
}
