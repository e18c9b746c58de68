// holoport-bench texture: Holoportation-style per-vertex texturing of the
// studio's ground-truth foreground mesh (colours cleared) from the pods'
// colour images, timed, and scored by novel-view PSNR/SSIM against the
// studio's ground-truth renders from 4 viewpoints no pod has. Runs the same
// for two ablations: "no_discontinuity" (discontinuity test off) and "naive"
// (plain average of every view the vertex projects into: no visibility, no
// discontinuity test, no normal weighting, no voting).
//
// Extra options: --png DIR writes every novel view (ours and truth) of the
// first frame there; --threads N (default 2: the 2-core budget); --fused
// textures the TSDF mesh (fused from the ground-truth-masked depth at the
// workload's voxel size, cleaned up) instead of the ground-truth mesh, as in
// the capture pipeline; --cluster_mm C sets TextureOptions::cluster_size_m;
// --only MODE runs one mode.
#include <chrono>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "bench.h"
#include "common/log.h"
#include "server/fusion/mesh_cleanup.h"
#include "server/fusion/tsdf.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#include "texture/novel_view.h"
#include "texture/texturer.h"

namespace {

using holo::bench::Mean;
using holo::bench::ProcessCpuMs;

struct Mode {
  std::string name;
  holo::TextureOptions options;
};

// The benchmark's own options (holoport-bench texture --help).
struct TextureBenchOptions {
  std::string png_dir;         // write the novel views of the first frame here
  int threads = 2;             // the 2-core budget
  holo::TextureOptions tuned;  // defaults, or as set by the options
  float offset_mm = 0;         // move the mesh along its normals (texturing's tolerance to geometry error)
  bool fused = false;          // texture the TSDF mesh instead of the ground truth
  std::string only;            // one mode
};

int RunTextureBench(const holo::bench::BenchArgs& args, const TextureBenchOptions& o) {
  const std::string& png_dir = o.png_dir;
  const int threads = o.threads;
  const holo::TextureOptions& tuned = o.tuned;
  const float offset_mm = o.offset_mm;
  const bool fused = o.fused;
  const std::string& only = o.only;
  auto workload = holo::GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("texture: {}", workload.status().ToString());
    return 2;
  }
  holo::StudioOptions studio_options = workload->studio;
  // Colour calibration (stage 2) is not this stage's job: judge texturing on
  // consistent pod colours.
  studio_options.color_variation = false;
  auto studio = holo::SyntheticStudio::Create(workload->rig, studio_options);
  if (!studio.ok()) {
    spdlog::error("texture: {}", studio.status().ToString());
    return 1;
  }

  if (holo::Status s = tuned.Check(); !s.ok()) {
    spdlog::error("texture: {}", s.ToString());
    return 2;
  }
  std::vector<Mode> modes(3);
  for (auto& m : modes) m.options = tuned;
  modes[0].name = "holoportation";
  modes[1].name = "no_discontinuity";
  modes[1].options.discontinuity_test = false;
  modes[2].name = "naive";
  modes[2].options.visibility_test = false;
  modes[2].options.discontinuity_test = false;
  modes[2].options.normal_weighting = false;
  modes[2].options.voting_levels = 0;
  for (auto& m : modes) m.options.threads = threads;
  if (!only.empty()) {
    std::erase_if(modes, [&](const Mode& m) { return m.name != only; });
    if (modes.empty()) {
      spdlog::error("texture: --only must be holoportation, no_discontinuity or naive");
      return 2;
    }
  }
  holo::TsdfOptions tsdf_options;
  tsdf_options.voxel_size = workload->voxel_size_m;
  holo::TsdfVolume volume(tsdf_options);

  holo::NovelViewOptions nv;
  nv.intrinsics = workload->rig.pods.front().color;
  const std::vector<holo::NovelView> views = holo::MakeNovelViews(nv);

  // Frames spread over the walk/turn/wave cycles.
  const int num_frames = args.frames > 0 ? args.frames : 4;
  std::vector<int64_t> frame_ids;
  for (int i = 0; i < num_frames; ++i) frame_ids.push_back(static_cast<int64_t>(i) * 67);

  holo::RgbdFrameSet set;
  holo::StudioGroundTruth gt;
  std::map<std::string, std::vector<double>> ms, cpu_ms, psnr, ssim;
  std::map<std::string, std::map<int, std::vector<double>>> psnr_view;
  std::map<std::string, holo::TextureStats> last_stats;
  std::vector<double> albedo_psnr, albedo_ssim;
  size_t num_vertices = 0;
  for (int64_t f : frame_ids) {
    (*studio)->RenderFrame(f, &set, &gt);
    holo::Mesh mesh = gt.foreground_mesh;
    if (fused) {
      // The capture pipeline's mesh: fused from the depth inside the true masks.
      for (size_t p = 0; p < set.frames.size(); ++p) set.frames[p].mask = gt.mask[p];
      volume.Reset();
      holo::Status s = volume.Integrate(workload->rig, set);
      if (s.ok()) {
        volume.ExtractMesh(&mesh);
        s = holo::CleanupMesh(holo::MeshCleanupOptions{}, &mesh);
      }
      if (!s.ok()) {
        spdlog::error("texture: fusing frame {}: {}", f, s.ToString());
        return 1;
      }
    }
    // Simulated reconstruction error: every vertex moved along its normal
    // (positive: an inflated surface, as TSDF meshes of noisy depth tend to be).
    if (offset_mm != 0.0f)
      for (size_t v = 0; v < mesh.num_vertices(); ++v) mesh.positions[v] += 1e-3f * offset_mm * mesh.normals[v].normalized();
    num_vertices = mesh.num_vertices();
    // Reference: the true per-vertex albedo (unlit), the mesh's own colours.
    for (size_t v = 0; v < views.size(); ++v) {
      std::string prefix;
      if (!png_dir.empty() && f == frame_ids.front())
        prefix = png_dir + "/" + workload->name + "_gt_albedo_view" + std::to_string(v);
      auto score = holo::ScoreNovelView(**studio, f, gt.foreground_mesh, views[v], prefix);
      if (score.ok()) albedo_psnr.push_back(score->psnr_db), albedo_ssim.push_back(score->ssim);
    }
    for (const Mode& mode : modes) {
      holo::Texturer texturer(workload->rig, mode.options);
      mesh.colors.clear();
      if (holo::Status s = texturer.Apply(set, &mesh); !s.ok()) {  // warm-up: buffers sized
        spdlog::error("texture: {}", s.ToString());
        return 1;
      }
      for (int r = 0; r < args.repeats; ++r) {
        mesh.colors.clear();
        const double c0 = ProcessCpuMs();
        const auto t0 = std::chrono::steady_clock::now();
        const holo::Status s = texturer.Apply(set, &mesh);
        const double dt = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        cpu_ms[mode.name].push_back(ProcessCpuMs() - c0);
        if (!s.ok()) {
          spdlog::error("texture: {}", s.ToString());
          return 1;
        }
        ms[mode.name].push_back(dt);
      }
      last_stats[mode.name] = texturer.stats();
      for (size_t v = 0; v < views.size(); ++v) {
        std::string prefix;
        if (!png_dir.empty() && f == frame_ids.front())
          prefix = png_dir + "/" + workload->name + "_" + mode.name + "_view" + std::to_string(v);
        auto score = holo::ScoreNovelView(**studio, f, mesh, views[v], prefix);
        if (!score.ok()) {
          spdlog::error("texture: {}", score.status().ToString());
          return 1;
        }
        psnr[mode.name].push_back(score->psnr_db);
        ssim[mode.name].push_back(score->ssim);
        psnr_view[mode.name][static_cast<int>(v)].push_back(score->psnr_db);
      }
      if (!args.json) {
        const holo::TextureStats& st = texturer.stats();
        spdlog::info(
            "texture {} frame {} {:<16} {} vertices (coarse {}): {:.2f} ms (cluster {:.2f} raster {:.2f} sample {:.2f} "
            "fill {:.2f} "
            "transfer {:.2f}), "
            "observed {} edge-only {} voted {} min-variance {} filled {} fallback {}",
            workload->name, f, mode.name, st.num_vertices, st.coarse_vertices, st.ms_total, st.ms_cluster, st.ms_raster,
            st.ms_sample, st.ms_fill, st.ms_transfer, st.observed, st.edge_only, st.voted, st.min_variance,
            st.filled_from_neighbours, st.fallback);
      }
    }
  }

  for (const Mode& mode : modes) {
    std::map<std::string, std::string> q = {{"stage", "texture"},
                                            {"mode", mode.name},
                                            {"threads", std::to_string(threads)},
                                            {"vertices", std::to_string(num_vertices)},
                                            {"frames", std::to_string(frame_ids.size())},
                                            {"color_variation", "0"}};
    if (offset_mm != 0.0f) q["geometry_offset_mm"] = std::to_string(offset_mm);
    if (fused) q["mesh"] = "fused";
    q["content"] = fused ? "fused" : "truth";
    if (mode.options.cluster_size_m > 0) q["cluster_mm"] = std::to_string(1e3f * mode.options.cluster_size_m);
    holo::bench::EmitFigure("texture", workload->name, "ms", holo::bench::Median(ms[mode.name]), "ms", q);
    // CPU time of all threads per frame: what other load on the machine barely changes.
    holo::bench::EmitFigure("texture", workload->name, "cpu_ms", holo::bench::Median(cpu_ms[mode.name]), "ms", q);
    q.erase("stage");
    q["views"] = std::to_string(views.size());
    holo::bench::EmitFigure("texture", workload->name, "novel_view_psnr_db", Mean(psnr[mode.name]), "dB", q);
    holo::bench::EmitFigure("texture", workload->name, "novel_view_ssim", Mean(ssim[mode.name]), "1", q);
    q.erase("views");
    for (size_t v = 0; v < views.size(); ++v) {
      auto qv = q;
      char az[32];
      std::snprintf(az, sizeof az, "%.1f", views[v].azimuth_deg);
      qv["azimuth_deg"] = az;
      holo::bench::EmitFigure("texture", workload->name, "novel_view_psnr_db",
                              Mean(psnr_view[mode.name][static_cast<int>(v)]), "dB", qv);
    }
  }
  const std::map<std::string, std::string> qa = {{"mode", "gt_albedo"}, {"views", std::to_string(views.size())},
                                                 {"frames", std::to_string(frame_ids.size())}};
  holo::bench::EmitFigure("texture", workload->name, "novel_view_psnr_db", Mean(albedo_psnr), "dB", qa);
  holo::bench::EmitFigure("texture", workload->name, "novel_view_ssim", Mean(albedo_ssim), "1", qa);
  return 0;
}

holo::bench::BenchFn SetupTexture(CLI::App& app) {
  auto o = std::make_shared<TextureBenchOptions>();
  app.add_option("--png", o->png_dir, "write the first frame's novel views as PNGs to this directory");
  app.add_option("--threads", o->threads, "texturing threads")->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--alpha", o->tuned.alpha, "TextureOptions::alpha")->capture_default_str();
  app.add_option_function<float>(
      "--radius_mm", [o](float mm) { o->tuned.discontinuity_radius_m = 1e-3f * mm; },
      "discontinuity radius, mm (default 10)");
  app.add_flag(
      "--no_fallback", [o](int64_t) { o->tuned.discontinuity_fallback = false; },
      "no fallback to the views near a discontinuity");
  app.add_option_function<float>(
      "--cluster_mm", [o](float mm) { o->tuned.cluster_size_m = 1e-3f * mm; }, "cluster size, mm (0: off)");
  app.add_option("--cluster_transfer", o->tuned.cluster_transfer, "TextureOptions::cluster_transfer")
      ->capture_default_str();
  app.add_flag("--fused", o->fused, "texture the TSDF mesh fused inside the true masks (not the ground truth)");
  app.add_option("--geometry_offset_mm", o->offset_mm, "move the mesh along its normals by this many mm");
  app.add_option("--only", o->only, "run one mode: holoportation, no_discontinuity or naive");
  return [o](const holo::bench::BenchArgs& args) { return RunTextureBench(args, *o); };
}

}  // namespace

HOLO_REGISTER_BENCH_OPTIONS(
    "texture", "texturing of the ground-truth mesh: ms, novel-view PSNR/SSIM vs naive and no-discontinuity",
    SetupTexture);
