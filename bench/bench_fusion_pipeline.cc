#include <algorithm>
#include <cstdio>
#include <map>
#include <memory>
#include <vector>

#include "common/file_util.h"
#include "common/metrics/image_metrics.h"
#include "common/metrics/mesh_distance.h"
#include "fusion_pipeline.h"
#include "server/pipeline/capture_site.h"
#include "server/studio/studio.h"
#include "server/studio/workloads.h"
#include "server/texture/novel_view.h"

namespace holo::bench {
namespace {

struct Kept {
  int64_t frame = 0;
  Mesh mesh;
  std::vector<ImageGray8> masks;
};

void Progress(const BenchArgs& args, const char* what) {
  if (!args.json) std::fprintf(stderr, "fusion pipeline: %s\n", what);
}

}  // namespace

int RunPipelineFigures(const BenchArgs& args, const PipelineBenchOptions& options) {
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) {
    std::fprintf(stderr, "fusion: %s\n", workload.status().message().c_str());
    return 2;
  }
  const std::string& wl = workload->name;
  CaptureSiteOptions site_options;
  site_options.masks = MaskSource::kSegment;
  site_options.tsdf.voxel_size = workload->voxel_size_m;
  site_options.pipeline.max_frames = options.frames;

  auto make_site = [&](StudioOptions studio_options, std::unique_ptr<SyntheticStudio>* studio,
                       std::unique_ptr<SyntheticStudio>* empty) -> StatusOr<std::unique_ptr<CaptureSite>> {
    HOLO_ASSIGN_OR_RETURN(*studio, SyntheticStudio::Create(workload->rig, studio_options));
    studio_options.empty_room = true;
    HOLO_ASSIGN_OR_RETURN(*empty, SyntheticStudio::Create(workload->rig, studio_options));
    return CaptureSite::Create(studio->get(), empty->get(), nullptr, site_options);
  };

  // 1. Throughput: as fast as the stages go. The sink keeps a few frames for scoring.
  Progress(args, "learning the background, then the throughput run");
  std::unique_ptr<SyntheticStudio> studio, empty;
  auto site = make_site(workload->studio, &studio, &empty);
  if (!site.ok()) {
    std::fprintf(stderr, "fusion: %s\n", site.status().message().c_str());
    return 1;
  }
  std::vector<Kept> kept;
  auto stats = (*site)->Run([&](const FrameWork& w) -> Status {
    if (w.sequence % options.eval_every == options.eval_every / 2) {
      Kept k;
      k.frame = w.frames.frame_index;
      k.mesh = w.mesh;
      for (const auto& f : w.frames.frames) k.masks.push_back(f.mask);
      kept.push_back(std::move(k));
    }
    return OkStatus();
  });
  if (!stats.ok()) {
    std::fprintf(stderr, "fusion: pipeline: %s\n", stats.status().message().c_str());
    return 1;
  }
  std::vector<double> total;
  for (const auto& t : stats->per_frame)
    total.push_back(t.acquire_ms + t.segment_ms + t.fuse_ms + t.mesh_ms + t.texture_ms);
  const StageTimings med = MedianTimings(*stats);
  auto q = [](const char* stage) { return std::map<std::string, std::string>{{"stage", stage}, {"mode", "pipeline"}}; };
  EmitFigure("fusion", wl, "ms", med.acquire_ms, "ms", q("acquire"));
  EmitFigure("fusion", wl, "ms", med.segment_ms, "ms", q("segment"));
  EmitFigure("fusion", wl, "ms", med.fuse_ms, "ms", q("fuse"));
  EmitFigure("fusion", wl, "ms", med.mesh_ms, "ms", q("mesh"));
  EmitFigure("fusion", wl, "ms", med.texture_ms, "ms", q("texture"));
  EmitFigure("fusion", wl, "ms", Median(total), "ms", q("total"));
  EmitFigure("fusion", wl, "fps", stats->fps, "1/s", {{"mode", "pipeline"}, {"frames", std::to_string(stats->frames)}});
  // The slowest stage bounds throughput.
  const std::pair<double, const char*> stages[] = {{med.acquire_ms, "acquire"},
                                                   {med.segment_ms, "segment"},
                                                   {med.fuse_ms + med.mesh_ms, "fuse+mesh"},
                                                   {med.texture_ms, "texture"}};
  const auto* slowest = &stages[0];
  for (const auto& s : stages)
    if (s.first > slowest->first) slowest = &s;
  if (!args.json)
    std::fprintf(stderr, "fusion pipeline: %.1f fps, bottleneck stage %s (%.1f ms)\n", stats->fps, slowest->second,
                 slowest->first);

  // 2. Latency: paced like a live camera a little below the measured rate, so
  // queues stay short and latency is what a viewer would see.
  const double pace = std::min(workload->studio.fps, 0.85 * stats->fps);
  if (pace > 0.5) {
    Progress(args, "paced run for latency");
    std::unique_ptr<SyntheticStudio> s2, e2;
    site_options.pipeline.pace_fps = pace;
    site_options.pipeline.max_frames = std::min(options.frames, 45);
    auto paced = make_site(workload->studio, &s2, &e2);
    if (paced.ok()) {
      auto ps = (*paced)->Run([](const FrameWork&) { return OkStatus(); });
      if (ps.ok())
        EmitFigure("fusion", wl, "latency_ms", MedianLatencyMs(*ps), "ms",
                   {{"mode", "pipeline"}, {"pace_fps", std::to_string(static_cast<int>(pace + 0.5))}});
    }
  }

  // 3. Quality of the kept frames against ground truth.
  if (!options.png_dir.empty()) {
    if (Status s = MakeDirs(options.png_dir); !s.ok()) {
      std::fprintf(stderr, "fusion: %s\n", s.message().c_str());
      return 1;
    }
  }
  Progress(args, "scoring kept frames against ground truth");
  std::vector<double> iou, chamfer, completeness, psnr, ssim;
  RgbdFrameSet truth_frames;
  StudioGroundTruth gt;
  const auto views = MakeNovelViews(NovelViewOptions{});
  for (const auto& k : kept) {
    studio->RenderFrame(k.frame, &truth_frames, &gt);
    for (size_t p = 0; p < k.masks.size() && p < gt.mask.size(); ++p) {
      auto m = metrics::CompareMasks(k.masks[p], gt.mask[p]);
      if (m.ok()) iou.push_back(m->iou);
    }
    auto d = metrics::ComputeMeshDistance(k.mesh, gt.foreground_mesh);
    if (d.ok()) {
      chamfer.push_back(d->chamfer_mm);
      completeness.push_back(d->completeness);
    }
    if (options.novel_views) {
      for (size_t v = 0; v < views.size(); ++v) {
        const std::string prefix =
            options.png_dir.empty() ? "" : options.png_dir + "/" + wl + "_f" + std::to_string(k.frame) + "_v" + std::to_string(v);
        auto score = ScoreNovelView(*studio, k.frame, k.mesh, views[v], prefix);
        if (score.ok()) {
          psnr.push_back(score->psnr_db);
          ssim.push_back(score->ssim);
        } else {
          std::fprintf(stderr, "fusion: novel view %zu of frame %lld: %s\n", v, static_cast<long long>(k.frame),
                       score.status().message().c_str());
        }
      }
    }
  }
  const std::map<std::string, std::string> pq = {{"mode", "pipeline"}, {"frames_scored", std::to_string(kept.size())}};
  EmitFigure("fusion", wl, "mask_iou", Mean(iou), "fraction", pq);
  EmitFigure("fusion", wl, "chamfer_mm", Mean(chamfer), "mm", pq);
  EmitFigure("fusion", wl, "completeness", Mean(completeness), "fraction", pq);
  if (options.novel_views) {
    EmitFigure("fusion", wl, "novel_view_psnr_db", Mean(psnr), "dB", {{"mode", "pipeline"}, {"views", "4"}});
    EmitFigure("fusion", wl, "novel_view_ssim", Mean(ssim), "fraction", {{"mode", "pipeline"}, {"views", "4"}});
  }
  return 0;
}

}  // namespace holo::bench
