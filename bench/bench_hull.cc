// holoport-bench hull: the visual hull of the pods' masks (colour-only
// pods, server/fusion/visual_hull.h) against TSDF fusion of their depth
// (the peer, same frames, same masks, same threads), with 4, 6 and 8 pods of
// the workload's rig.
//
// Per method (hull | tsdf) and pods: chamfer_mm and completeness of the
// cleaned mesh against the studio's ground-truth foreground mesh,
// novel_view_psnr_db of the textured mesh from 4 cameras no pod has,
// reconstruct_ms / reconstruct_cpu_ms (hull carving or fusion, plus marching
// cubes and clean-up; median over frames) and fps = 1000 / reconstruct_ms.
// Masks are the studio's true ones, so the figures compare the two
// reconstructions, not the segmentation; content "truth" for the masks, the
// reconstructions are the site's own.
//
// Options: --pods 4,6,8  --hull-voxel-mm 16 (the hull; TSDF at the
// workload's voxel)  --threads 2  --png-dir DIR (novel views).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "bench.h"
#include "common/clock.h"
#include "common/log.h"
#include "common/metrics/mesh_distance.h"
#include "server/fusion/mesh_cleanup.h"
#include "server/fusion/tsdf.h"
#include "server/fusion/visual_hull.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#include "texture/novel_view.h"
#include "texture/texturer.h"

namespace holo::bench {
namespace {

struct HullBenchOptions {
  std::vector<int> pods = {4, 6, 8};
  double hull_voxel_mm = 16.0;
  int threads = 2;
  std::string png_dir;
};

// k pods spread evenly over the rig's n.
std::vector<size_t> PickPods(size_t n, size_t k) {
  std::vector<size_t> out;
  for (size_t i = 0; i < k; ++i) out.push_back((i * n) / k);
  return out;
}

int RunHullBench(const BenchArgs& args, const HullBenchOptions& o) {
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("hull: {}", workload.status().ToString());
    return 2;
  }
  for (int k : o.pods)
    if (static_cast<size_t>(k) > workload->rig.pods.size()) {
      spdlog::error("hull: --pods {} but the rig has {} pods", k, workload->rig.pods.size());
      return 2;
    }
  const int frames = args.frames > 0 ? args.frames : 4;
  const std::string& wl = args.workload;
  SyntheticStudio studio(workload->rig, workload->studio);
  NovelViewOptions nvo;
  const std::vector<NovelView> views = MakeNovelViews(nvo);

  for (const int pods : o.pods) {
    const auto k = static_cast<size_t>(pods);
    const std::vector<size_t> chosen = PickPods(workload->rig.pods.size(), k);
    Rig rig = workload->rig;
    rig.pods.clear();
    for (size_t p : chosen) {
      rig.pods.push_back(workload->rig.pods[p]);
      rig.pods.back().id = static_cast<int>(rig.pods.size() - 1);
    }
    for (const bool is_hull : {true, false}) {
      const std::string method = is_hull ? "hull" : "tsdf";
      TsdfOptions to;
      to.voxel_size = is_hull ? static_cast<float>(o.hull_voxel_mm * 1e-3) : workload->voxel_size_m;
      to.truncation_voxels = is_hull ? 2.0f : 4.0f;
      to.integrate_color = false;
      to.threads = o.threads;
      TsdfVolume volume(to);
      VisualHullOptions ho;
      ho.threads = o.threads;
      ho.min_views = std::min<int>(3, static_cast<int>(k));
      VisualHull hull(ho);
      TextureOptions texo;
      Texturer texturer(rig, texo);
      std::vector<double> ms, cpu_ms, chamfer, completeness, psnr, distance_ms, fill_ms;
      for (int f = 0; f < frames; ++f) {
        const int64_t frame = 10 + 23 * static_cast<int64_t>(f);
        RgbdFrameSet all, fs;
        StudioGroundTruth gt;
        studio.RenderFrame(frame, &all, &gt);
        fs.frame_index = all.frame_index;
        for (size_t i = 0; i < chosen.size(); ++i) {
          fs.frames.push_back(all.frames[chosen[i]]);
          fs.frames.back().pod_id = static_cast<int>(i);
          fs.frames.back().mask = gt.mask[chosen[i]];
        }
        Mesh mesh;
        const double cpu0 = ProcessCpuMs();
        const auto t0 = std::chrono::steady_clock::now();
        Status st = is_hull ? hull.Build(rig, fs, &volume)
                                                  : (volume.Reset(), volume.Integrate(rig, fs));
        if (st.ok()) {
          volume.ExtractMesh(&mesh);
          st = CleanupMesh(MeshCleanupOptions{}, &mesh);
        }
        ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        cpu_ms.push_back(ProcessCpuMs() - cpu0);
        if (is_hull) {
          distance_ms.push_back(hull.stats().distance_ms);
          fill_ms.push_back(hull.stats().fill_ms);
        }
        if (!st.ok()) {
          spdlog::error("hull: {} with {} pods, frame {}: {}", method, k, frame, st.ToString());
          return 1;
        }
        auto d = metrics::ComputeMeshDistance(mesh, gt.foreground_mesh);
        if (d.ok()) {
          chamfer.push_back(d->chamfer_mm);
          completeness.push_back(d->completeness);
        }
        if (Status ts = texturer.Apply(fs, &mesh); !ts.ok()) {
          spdlog::warn("hull: texturing {} with {} pods, frame {}: {}", method, k, frame, ts.ToString());
        } else {
          for (size_t v = 0; v < views.size(); ++v) {
            const std::string prefix = o.png_dir.empty() ? ""
                                                         : o.png_dir + "/" + method + "_pods" + std::to_string(k) + "_f" +
                                                               std::to_string(frame) + "_v" + std::to_string(v);
            auto score = ScoreNovelView(studio, frame, mesh, views[v], prefix);
            if (score.ok()) psnr.push_back(score->psnr_db);
            else spdlog::warn("hull: novel view {}: {}", v, score.status().ToString());
          }
        }
        if (!args.json)
          spdlog::info("hull: {} with {} pods, frame {}: {} triangles, {:.1f} ms, chamfer {:.2f} mm", method, k, frame,
                       mesh.num_triangles(), ms.back(), chamfer.empty() ? 0.0 : chamfer.back());
      }
      const std::map<std::string, std::string> q = {{"method", method},
                                                    {"pods", std::to_string(k)},
                                                    {"voxel_mm", std::to_string(static_cast<int>(std::lround(to.voxel_size * 1000)))},
                                                    {"masks", "truth"},
                                                    {"content", "truth"},  // reconstructed from the studio's true masks
                                                    {"frames", std::to_string(frames)},
                                                    {"threads", std::to_string(o.threads)}};
      EmitFigure("hull", wl, "chamfer_mm", Mean(chamfer), "mm", q);
      EmitFigure("hull", wl, "completeness", Mean(completeness), "fraction", q);
      if (!psnr.empty()) EmitFigure("hull", wl, "novel_view_psnr_db", Mean(psnr), "dB", q);
      EmitFigure("hull", wl, "reconstruct_ms", Median(ms), "ms", q);
      EmitFigure("hull", wl, "reconstruct_cpu_ms", Median(cpu_ms), "ms", q);
      EmitFigure("hull", wl, "fps", 1000.0 / std::max(1e-9, Median(ms)), "1/s", q);
      if (!distance_ms.empty()) {
        EmitFigure("hull", wl, "stage_ms", Median(distance_ms), "ms", [&] {
          auto s = q;
          s["stage"] = "distance_transforms";
          return s;
        }());
        EmitFigure("hull", wl, "stage_ms", Median(fill_ms), "ms", [&] {
          auto s = q;
          s["stage"] = "blocks_and_field";
          return s;
        }());
      }
    }
  }
  return 0;
}

BenchFn SetupHull(CLI::App& app) {
  auto o = std::make_shared<HullBenchOptions>();
  DropCommonOptions(app, {"--repeats"});  // this benchmark does not read them
  app.add_option("--pods", o->pods, "pod counts to compare, comma separated (pods spread over the rig)")
      ->delimiter(',')
      ->check(CLI::Range(2, 64))
      ->capture_default_str();
  app.add_option("--hull-voxel-mm", o->hull_voxel_mm, "voxel of the visual hull, mm (TSDF: the workload's)")
      ->check(CLI::Range(2.0, 100.0))
      ->capture_default_str();
  app.add_option("--threads", o->threads, "threads of the hull and the fusion")->check(CLI::Range(1, 64))->capture_default_str();
  app.add_option("--png-dir", o->png_dir, "write the novel views (truth left, ours right) to this directory");
  return [o](const BenchArgs& args) { return RunHullBench(args, *o); };
}

}  // namespace

HOLO_REGISTER_BENCH_OPTIONS("hull",
                            "visual hull of the pods' masks (colour-only pods) vs TSDF fusion of their depth, 4/6/8 "
                            "pods: Chamfer, completeness, novel-view PSNR, ms per frame",
                            SetupHull);

}  // namespace holo::bench
