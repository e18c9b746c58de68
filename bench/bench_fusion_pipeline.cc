#include <algorithm>
#include <cstdio>
#include <map>
#include <memory>
#include <vector>

#include "common/file_util.h"
#include "common/image_io.h"
#include "common/log.h"
#include "common/metrics/image_metrics.h"
#include "common/metrics/mesh_distance.h"
#include "common/visualize.h"
#include "fusion_pipeline.h"
#include "server/capture/dataset.h"
#include "server/capture/prerendered.h"
#include "server/pipeline/capture_site.h"
#include "server/stereo/stereo_depth.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#include "texture/novel_view.h"

namespace holo::bench {
namespace {

struct Kept {
  int64_t frame = 0;
  Mesh mesh;
  std::vector<ImageGray8> masks;
  std::vector<ImageDepth16> depth;  // kept only when pictures are written
};

// Our mask against the truth's: white both, red ours only, blue the truth's only.
ImageRgb8 MaskErrors(const ImageGray8& ours, const ImageGray8& truth) {
  ImageRgb8 out(ours.width(), ours.height());
  const bool same_size = truth.width() == ours.width() && truth.height() == ours.height();
  for (int y = 0; y < ours.height(); ++y)
    for (int x = 0; x < ours.width(); ++x) {
      const bool a = ours.at(x, y) != 0, b = same_size && truth.at(x, y) != 0;
      uint8_t* px = &out.at(x, y);
      px[0] = a ? 255 : 0;
      px[1] = a && b ? 255 : 0;
      px[2] = b ? 255 : 0;
    }
  return out;
}

void Progress(const BenchArgs& args, const char* what) {
  if (!args.json) spdlog::info("fusion pipeline: {}", what);
}

std::string SourceName(const std::string& src) { return src.rfind("dataset:", 0) == 0 ? "dataset" : src; }

}  // namespace

int RunPipelineFigures(const BenchArgs& args, const PipelineBenchOptions& options) {
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("fusion: {}", workload.status().message());
    return 2;
  }
  const std::string& wl = workload->name;
  CaptureSiteOptions site_options;
  site_options.masks = MaskSource::kSegment;
  site_options.tsdf.voxel_size = workload->voxel_size_m;
  if (options.behind_band >= 0) site_options.tsdf.behind_band = static_cast<float>(options.behind_band);
  if (options.behind_sigmas >= 0) site_options.tsdf.behind_noise_sigmas = static_cast<float>(options.behind_sigmas);
  if (options.depth_filter >= 0) site_options.depth_filter.radius = options.depth_filter;
  site_options.smooth_full_mesh = !options.raw_full_mesh;
  site_options.pipeline.max_frames = options.frames;
  if (options.texture_cluster_mm >= 0)
    site_options.texture_options.cluster_size_m = static_cast<float>(options.texture_cluster_mm * 1e-3);
  if (options.seg_iterations >= 0) site_options.segment.crf_iterations = options.seg_iterations;
  if (options.seg_downsample >= 0) site_options.segment.downsample = options.seg_downsample;
  if (options.seg_grid_px >= 0) site_options.segment.grid_spatial_px = static_cast<float>(options.seg_grid_px);
  if (options.texture_transfer >= 0) site_options.texture_options.cluster_transfer = options.texture_transfer;

  const std::string& src = options.source;
  if (src != "synthetic" && src != "prerendered" && src != "stereo" && src.rfind("dataset:", 0) != 0) {
    spdlog::error("fusion: --pipeline-source must be synthetic, prerendered, stereo or dataset:DIR, got '{}'", src);
    return 2;
  }
  // Stereo depth as holoport-server --depth stereo makes it: regions around
  // the person, each pod starting from its last planes, the dense last pass,
  // and no depth filter unless one is asked for (docs/stereo.md).
  const bool stereo = src == "stereo";
  const int direct_filter_radius = site_options.depth_filter.radius;
  if (stereo && options.depth_filter < 0) site_options.depth_filter.radius = 0;
  // ... and segmentation's depth-edge band (SegmenterOptions::depth_edge_band_px).
  const int direct_edge_band = site_options.segment.depth_edge_band_px;
  if (options.seg_edge_band >= 0)
    site_options.segment.depth_edge_band_px = options.seg_edge_band;
  else if (stereo)
    site_options.segment.depth_edge_band_px = kStereoSegmentEdgeBandPx;
  StereoDepthOptions stereo_options;
  stereo_options.roi.enabled = true;
  stereo_options.patchmatch.temporal = true;
  if (options.stereo_edge_shift >= 0) stereo_options.patchmatch.edge_shift_px = options.stereo_edge_shift;
  stereo_options.roi.row_spans = options.stereo_roi_spans;
  stereo_options.roi.search_with_sgbm = options.stereo_search_sgbm;
  if (options.stereo_still >= 0) stereo_options.patchmatch.temporal_still = static_cast<float>(options.stereo_still);
  // Frames for the prerendered source, rendered once (untimed).
  auto prerendered = std::make_shared<std::vector<RgbdFrameSet>>();
  if (src == "prerendered") {
    Progress(args, "prerendering the frames into memory");
    auto s = SyntheticStudio::Create(workload->rig, workload->studio);
    if (!s.ok()) {
      spdlog::error("fusion: {}", s.status().message());
      return 1;
    }
    prerendered->resize(static_cast<size_t>(options.frames));
    for (auto& f : *prerendered)
      if (Status st = (*s)->Next(&f); !st.ok()) {
        spdlog::error("fusion: prerendering: {}", st.message());
        return 1;
      }
  }
  // One site: `studio` is the scoring truth (and the source when synthetic).
  struct Site {
    std::unique_ptr<SyntheticStudio> studio, empty;
    std::unique_ptr<FrameSource> source;  // prerendered, stereo or dataset
    std::unique_ptr<CaptureSite> site;
  };
  // `direct`: the studio's own depth whatever the source (the stereo run's peer).
  auto make_site = [&](Site* out, bool direct = false) -> Status {
    StudioOptions studio_options = workload->studio;
    HOLO_ASSIGN_OR_RETURN(out->studio, SyntheticStudio::Create(workload->rig, studio_options));
    studio_options.empty_room = true;
    HOLO_ASSIGN_OR_RETURN(out->empty, SyntheticStudio::Create(workload->rig, studio_options));
    FrameSource* source = out->studio.get();
    if (direct) {
      // the studio renders, as with --pipeline-source synthetic
    } else if (stereo) {
      HOLO_ASSIGN_OR_RETURN(out->source, StereoStudioSource::Create(out->studio.get(), stereo_options));
      source = out->source.get();
    } else if (src == "prerendered") {
      out->source = std::make_unique<PrerenderedSource>(workload->rig, prerendered, /*loop=*/false);
      source = out->source.get();
    } else if (src.rfind("dataset:", 0) == 0) {
      HOLO_ASSIGN_OR_RETURN(auto reader, DatasetReader::Open(src.substr(8)));
      if (reader->rig().pods.size() != workload->rig.pods.size())
        return InvalidArgument("dataset " + src.substr(8) + " has " + std::to_string(reader->rig().pods.size()) +
                               " pods, workload " + wl + " has " + std::to_string(workload->rig.pods.size()));
      out->source = std::move(reader);
      source = out->source.get();
    }
    CaptureSiteOptions so = site_options;
    if (direct) {
      so.depth_filter.radius = direct_filter_radius;
      so.segment.depth_edge_band_px = direct_edge_band;
    }
    HOLO_ASSIGN_OR_RETURN(out->site, CaptureSite::Create(source, out->empty.get(), nullptr, so));
    return OkStatus();
  };

  // 1. Throughput: as fast as the stages go. The sink keeps a few frames for scoring.
  Progress(args, "learning the background, then the throughput run");
  Site main_site;
  Status made = make_site(&main_site);
  std::unique_ptr<SyntheticStudio>& studio = main_site.studio;
  std::unique_ptr<CaptureSite>* site = &main_site.site;
  if (!made.ok()) {
    spdlog::error("fusion: {}", made.message());
    return 1;
  }
  std::vector<Kept> kept;
  auto keep = [&](const FrameWork& w) { return w.sequence % options.eval_every == options.eval_every / 2; };
  auto stats = (*site)->Run([&](const FrameWork& w) -> Status {
    if (keep(w)) {
      Kept k;
      k.frame = w.frames.frame_index;
      k.mesh = w.mesh;
      for (const auto& f : w.frames.frames) {
        k.masks.push_back(f.mask);
        if (!options.png_dir.empty()) k.depth.push_back(f.depth);
      }
      kept.push_back(std::move(k));
    }
    return OkStatus();
  });
  if (!stats.ok()) {
    spdlog::error("fusion: pipeline: {}", stats.status().message());
    return 1;
  }
  std::vector<double> total;
  for (const auto& t : stats->per_frame)
    total.push_back(t.acquire_ms + t.segment_ms + t.fuse_ms + t.mesh_ms + t.texture_ms);
  const StageTimings med = MedianTimings(*stats);
  auto q = [&](const char* stage) {
    return std::map<std::string, std::string>{{"stage", stage}, {"mode", "pipeline"}, {"source", SourceName(src)},
                                              {"content", "fused"}};
  };
  EmitFigure("fusion", wl, "ms", med.acquire_ms, "ms", q("acquire"));
  EmitFigure("fusion", wl, "ms", med.segment_ms, "ms", q("segment"));
  EmitFigure("fusion", wl, "ms", med.fuse_ms, "ms", q("fuse"));
  EmitFigure("fusion", wl, "ms", med.mesh_ms, "ms", q("mesh"));
  EmitFigure("fusion", wl, "ms", med.texture_ms, "ms", q("texture"));
  EmitFigure("fusion", wl, "ms", Median(total), "ms", q("total"));
  EmitFigure("fusion", wl, "fps", stats->fps, "1/s",
             {{"mode", "pipeline"}, {"source", SourceName(src)}, {"frames", std::to_string(stats->frames)}});
  // CPU of all threads per frame in the concurrent run, and the rate two
  // cores could sustain at that cost if nothing else ran (a capacity
  // estimate: the shared machine's wall-clock fps depends on others' load).
  const double cpu_per_frame = stats->frames > 0 ? stats->cpu_ms / static_cast<double>(stats->frames) : 0;
  EmitFigure("fusion", wl, "cpu_ms", cpu_per_frame, "ms", q("total"));
  if (cpu_per_frame > 0)
    EmitFigure("fusion", wl, "fps_capacity_2cores", 2000.0 / cpu_per_frame, "1/s",
               {{"mode", "pipeline"}, {"source", SourceName(src)}, {"estimate", "2 cores / cpu_ms per frame"}});
  // The slowest stage bounds throughput.
  const std::pair<double, const char*> stages[] = {{med.acquire_ms, "acquire"},
                                                   {med.segment_ms, "segment"},
                                                   {med.fuse_ms + med.mesh_ms, "fuse+mesh"},
                                                   {med.texture_ms, "texture"}};
  const auto* slowest = &stages[0];
  for (const auto& s : stages)
    if (s.first > slowest->first) slowest = &s;
  if (!args.json)
    spdlog::info("fusion pipeline: {:.1f} fps, bottleneck stage {} ({:.1f} ms)", stats->fps, slowest->second,
                 slowest->first);

  // 2. CPU per stage: the same stages one at a time (serial mode), process
  // CPU of all threads while each ran.
  if (options.cpu_frames > 0) {
    Progress(args, "serial run for CPU per stage");
    Site cs;
    site_options.pipeline.serial = true;
    site_options.pipeline.max_frames = std::min(options.frames, options.cpu_frames);
    if (Status s = make_site(&cs); s.ok()) {
      auto st = cs.site->Run([](const FrameWork&) { return OkStatus(); });
      if (st.ok()) {
        const StageTimings c = MedianTimings(*st);
        EmitFigure("fusion", wl, "cpu_ms", c.acquire_cpu_ms, "ms", q("acquire_serial"));
        EmitFigure("fusion", wl, "cpu_ms", c.segment_cpu_ms, "ms", q("segment_serial"));
        EmitFigure("fusion", wl, "cpu_ms", c.fuse_cpu_ms, "ms", q("fuse_serial"));
        EmitFigure("fusion", wl, "cpu_ms", c.mesh_cpu_ms, "ms", q("mesh_serial"));
        EmitFigure("fusion", wl, "cpu_ms", c.texture_cpu_ms, "ms", q("texture_serial"));
        const double sum = st->frames > 0 ? st->cpu_ms / static_cast<double>(st->frames) : 0;
        EmitFigure("fusion", wl, "cpu_ms", sum, "ms", q("total_serial"));
        if (!args.json)
          spdlog::info(
              "fusion pipeline: CPU ms per frame (serial): acquire {:.1f} segment {:.1f} fuse {:.1f} mesh {:.1f} "
              "texture {:.1f}; all {:.1f}",
              c.acquire_cpu_ms, c.segment_cpu_ms, c.fuse_cpu_ms, c.mesh_cpu_ms, c.texture_cpu_ms, sum);
      } else {
        spdlog::warn("fusion: serial run: {}", st.status().message());
      }
    } else {
      spdlog::warn("fusion: serial run: {}", s.message());
    }
    site_options.pipeline.serial = false;
  }

  // 3. Latency: paced like a live camera a little below the measured rate, so
  // queues stay short and latency is what a viewer would see.
  const double pace = std::min(workload->studio.fps, 0.85 * stats->fps);
  if (pace > 0.5) {
    Progress(args, "paced run for latency");
    Site ps_site;
    site_options.pipeline.pace_fps = pace;
    site_options.pipeline.max_frames = std::min(options.frames, 45);
    if (make_site(&ps_site).ok()) {
      auto ps = ps_site.site->Run([](const FrameWork&) { return OkStatus(); });
      if (ps.ok())
        EmitFigure("fusion", wl, "latency_ms", MedianLatencyMs(*ps), "ms",
                   {{"mode", "pipeline"},
                    {"source", SourceName(src)},
                    {"pace_fps", std::to_string(static_cast<int>(pace + 0.5))}});
    }
  }

  // 4. The stream mesh a live site publishes (server/fusion/stream_mesh.h)
  // against the full-resolution mesh it exports, on the same frames.
  if (options.stream_frames > 0) {
    Progress(args, "stream mesh against the full mesh");
    Site ss;
    site_options.pipeline.pace_fps = 0;
    site_options.pipeline.max_frames = std::min(options.frames, options.stream_frames);
    site_options.stream_mesh = true;
    site_options.stream.max_triangles = workload->stream_triangles;
    site_options.full_mesh = true;
    site_options.texture = false;  // geometry only; the live site colours from the pods' images
    std::vector<double> to_full, from_full, stream_chamfer, full_chamfer, stream_tris, full_tris;
    Status made_ss = make_site(&ss);
    if (made_ss.ok()) {
      auto st = ss.site->Run([&](const FrameWork& w) -> Status {
        if (w.sequence % options.eval_every != options.eval_every / 2) return OkStatus();
        auto a = metrics::ComputeMeshDistance(w.mesh, w.full_mesh);
        const Mesh truth = ss.studio->ForegroundMesh(w.frames.frame_index);
        auto ts = metrics::ComputeMeshDistance(w.mesh, truth);
        auto tf = metrics::ComputeMeshDistance(w.full_mesh, truth);
        if (a.ok() && ts.ok() && tf.ok()) {
          to_full.push_back(a->accuracy_mm);
          from_full.push_back(a->completeness_distance_mm);
          stream_chamfer.push_back(ts->chamfer_mm);
          full_chamfer.push_back(tf->chamfer_mm);
          stream_tris.push_back(static_cast<double>(w.mesh.num_triangles()));
          full_tris.push_back(static_cast<double>(w.full_mesh.num_triangles()));
        }
        return OkStatus();
      });
      if (!st.ok()) made_ss = st.status();
    }
    if (!made_ss.ok()) {
      spdlog::warn("fusion: stream mesh run: {}", made_ss.message());
    } else if (!to_full.empty()) {
      auto sq = [&](const char* direction, const char* mesh) {
        std::map<std::string, std::string> m = {{"mode", "stream_mesh"}, {"content", "fused"},
                                                {"frames_scored", std::to_string(to_full.size())}};
        if (*direction) m["direction"] = direction;
        if (*mesh) m["mesh"] = mesh;
        return m;
      };
      EmitFigure("fusion", wl, "mean_distance_mm", Mean(to_full), "mm", sq("stream_to_full", ""));
      EmitFigure("fusion", wl, "mean_distance_mm", Mean(from_full), "mm", sq("full_to_stream", ""));
      EmitFigure("fusion", wl, "chamfer_mm", Mean(stream_chamfer), "mm", sq("", "stream"));
      EmitFigure("fusion", wl, "chamfer_mm", Mean(full_chamfer), "mm", sq("", "full"));
      EmitFigure("fusion", wl, "triangles", Mean(stream_tris), "count", sq("", "stream"));
      EmitFigure("fusion", wl, "triangles", Mean(full_tris), "count", sq("", "full"));
      if (!args.json)
        spdlog::info("fusion pipeline: stream mesh {:.0f} triangles, mean distance to the full mesh ({:.0f} "
                     "triangles) {:.2f} mm, back {:.2f} mm; Chamfer to the truth {:.2f} mm (full mesh {:.2f})",
                     Mean(stream_tris), Mean(full_tris), Mean(to_full), Mean(from_full), Mean(stream_chamfer),
                     Mean(full_chamfer));
    }
    site_options.stream_mesh = false;
    site_options.full_mesh = false;
    site_options.texture = true;
  }

  // 5. Stereo only: the same frames through the site on the studio's direct
  // depth (its peer: --pipeline-source synthetic), kept by frame index.
  std::map<int64_t, Kept> direct_kept;  // by frame index
  std::vector<double> direct_iou;
  if (stereo) {
    Progress(args, "the same frames on the studio's direct depth (the stereo run's peer)");
    Site ds;
    site_options.pipeline.pace_fps = 0;
    site_options.pipeline.max_frames = options.frames;
    Status made_ds = make_site(&ds, /*direct=*/true);
    if (made_ds.ok()) {
      // (The sink runs while the studio renders the next frames: scored later.)
      auto st = ds.site->Run([&](const FrameWork& w) -> Status {
        if (!keep(w)) return OkStatus();
        Kept& k = direct_kept[w.frames.frame_index];
        k.frame = w.frames.frame_index;
        k.mesh = w.mesh;
        for (const auto& f : w.frames.frames) k.masks.push_back(f.mask);
        return OkStatus();
      });
      if (!st.ok()) made_ds = st.status();
    }
    if (!made_ds.ok()) {
      spdlog::error("fusion: direct-depth peer run: {}", made_ds.message());
      return 1;
    }
  }

  // 6. Quality of the kept frames against ground truth.
  if (!options.png_dir.empty()) {
    if (Status s = MakeDirs(options.png_dir); !s.ok()) {
      spdlog::error("fusion: {}", s.message());
      return 1;
    }
  }
  Progress(args, "scoring kept frames against ground truth");
  std::vector<double> iou, chamfer, completeness, psnr, ssim;
  std::vector<double> vs_direct, vs_direct_acc, vs_direct_comp, direct_chamfer;
  RgbdFrameSet truth_frames;
  StudioGroundTruth gt;
  const auto views = MakeNovelViews(NovelViewOptions{});
  for (const auto& k : kept) {
    studio->RenderFrame(k.frame, &truth_frames, &gt);
    for (size_t p = 0; p < k.masks.size() && p < gt.mask.size(); ++p) {
      auto m = metrics::CompareMasks(k.masks[p], gt.mask[p]);
      if (m.ok()) iou.push_back(m->iou);
    }
    if (!options.png_dir.empty()) {
      // Per pod: the depth the site fused, and its mask against the truth's.
      std::vector<ImageRgb8> cells;
      for (size_t p = 0; p < k.masks.size() && p < gt.mask.size() && p < k.depth.size(); ++p) {
        cells.push_back(ColorizeDepth(k.depth[p], 1000, 6000));
        cells.push_back(MaskErrors(k.masks[p], gt.mask[p]));
      }
      std::vector<const ImageRgb8*> tiles;
      for (const auto& c : cells) tiles.push_back(&c);
      const std::string path =
          options.png_dir + "/" + wl + "_" + SourceName(src) + "_f" + std::to_string(k.frame) + "_masks.png";
      if (!tiles.empty())
        if (Status s = WriteImageRgb8(path, TileImages(tiles, 4)); !s.ok())
          spdlog::warn("fusion: {}", s.message());
    }
    auto d = metrics::ComputeMeshDistance(k.mesh, gt.foreground_mesh);
    if (d.ok()) {
      chamfer.push_back(d->chamfer_mm);
      completeness.push_back(d->completeness);
    }
    if (auto it = direct_kept.find(k.frame); it != direct_kept.end()) {
      for (size_t p = 0; p < it->second.masks.size() && p < gt.mask.size(); ++p) {
        auto m = metrics::CompareMasks(it->second.masks[p], gt.mask[p]);
        if (m.ok()) direct_iou.push_back(m->iou);
      }
      auto sd = metrics::ComputeMeshDistance(k.mesh, it->second.mesh);
      auto dt = metrics::ComputeMeshDistance(it->second.mesh, gt.foreground_mesh);
      if (sd.ok() && dt.ok()) {
        vs_direct.push_back(sd->chamfer_mm);
        vs_direct_acc.push_back(sd->accuracy_mm);
        vs_direct_comp.push_back(sd->completeness_distance_mm);
        direct_chamfer.push_back(dt->chamfer_mm);
      }
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
          spdlog::warn("fusion: novel view {} of frame {}: {}", v, k.frame, score.status().message());
        }
      }
    }
  }
  const std::map<std::string, std::string> pq = {{"mode", "pipeline"},
                                                 {"source", SourceName(src)},
                                                 {"content", "fused"},
                                                 {"frames_scored", std::to_string(kept.size())}};
  EmitFigure("fusion", wl, "mask_iou", Mean(iou), "fraction", pq);
  EmitFigure("fusion", wl, "chamfer_mm", Mean(chamfer), "mm", pq);
  EmitFigure("fusion", wl, "completeness", Mean(completeness), "fraction", pq);
  if (options.novel_views) {
    auto vq = pq;
    vq["views"] = "4";
    EmitFigure("fusion", wl, "novel_view_psnr_db", Mean(psnr), "dB", vq);
    EmitFigure("fusion", wl, "novel_view_ssim", Mean(ssim), "fraction", vq);
  }
  if (!vs_direct.empty()) {
    // The site's mesh from stereo depth against its mesh from direct depth,
    // each with the site's own masks (issue figure: the fused mesh from
    // stereo within X mm Chamfer of the one from direct depth).
    auto cq = pq;
    cq["frames_scored"] = std::to_string(vs_direct.size());
    cq["compare"] = "stereo_vs_direct";
    cq["masks"] = "site";
    EmitFigure("fusion", wl, "chamfer_mm", Mean(vs_direct), "mm", cq);
    cq["direction"] = "stereo_to_direct";
    EmitFigure("fusion", wl, "mean_distance_mm", Mean(vs_direct_acc), "mm", cq);
    cq["direction"] = "direct_to_stereo";
    EmitFigure("fusion", wl, "mean_distance_mm", Mean(vs_direct_comp), "mm", cq);
    cq.erase("direction");
    cq["compare"] = "direct_vs_truth";
    cq["source"] = "synthetic";
    EmitFigure("fusion", wl, "chamfer_mm", Mean(direct_chamfer), "mm", cq);
    cq.erase("compare");
    EmitFigure("fusion", wl, "mask_iou", Mean(direct_iou), "fraction", cq);
    if (!args.json)
      spdlog::info(
          "fusion pipeline: stereo mesh {:.2f} mm Chamfer from the direct-depth mesh ({:.2f} / {:.2f} mm each way); "
          "to the truth: stereo {:.2f} mm, direct {:.2f} mm; mask IoU stereo {:.3f}, direct {:.3f}",
          Mean(vs_direct), Mean(vs_direct_acc), Mean(vs_direct_comp), Mean(chamfer), Mean(direct_chamfer), Mean(iou),
          Mean(direct_iou));
  }
  return 0;
}

}  // namespace holo::bench
