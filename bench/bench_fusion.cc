// holoport-bench fusion: TSDF fusion (server/fusion) of a workload's masked
// depth, timed per stage and scored against the studio's ground truth, and
// the identical input fused by Open3D (bench/peers/open3d_fusion.py) in the
// same run.
//
//   holoport-bench fusion --workload S8-QVGA|S8-VGA [--frames N] [--repeats N] [--json]
//   holoport-bench fusion --dataset DIR [--voxel-mm 10] [--depth-max-m 3] ...
//   options: --no-peer (skip Open3D), --keep DIR (write the peer's input and
//            meshes there and keep them), --decimate N (triangle budget for the
//            decimation figure; 0 = off), --min-weight W (TsdfOptions::min_weight),
//            --behind-band B (TsdfOptions::behind_band)
//
// Stages are computed by functions returning figures (RunOurFusion,
// RunOpen3dPeer) so that segmentation, texturing and the pipeline can add
// their own lines to the same benchmark.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <time.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include <CLI/CLI.hpp>

#include "bench.h"
#include "common/log.h"
#include "common/image_io.h"
#include "common/metrics/mesh_distance.h"
#include "fusion_pipeline.h"
#include "server/capture/importers.h"
#include "server/fusion/mesh_cleanup.h"
#include "server/fusion/tsdf.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::bench {
namespace {

namespace fs = std::filesystem;

double Ms(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}


struct FusionConfig {
  TsdfOptions tsdf;
  MeshCleanupOptions cleanup;
  size_t decimate_to = 30000;  // triangle budget of the decimation figure; 0 = off
  int repeats = 3;
  bool verbose = true;
};

// Writes what the Open3D peer needs for one frame: masked depth and colour PNGs.
Status WritePeerFrame(const std::string& dir, int frame, const RgbdFrameSet& set) {
  char name[32];
  std::snprintf(name, sizeof(name), "frame_%03d", frame);
  const fs::path fdir = fs::path(dir) / name;
  fs::create_directories(fdir);
  ImageWriteOptions fast;
  fast.png_compression = 1;
  for (size_t k = 0; k < set.frames.size(); ++k) {
    const RgbdFrame& f = set.frames[k];
    ImageDepth16 depth = f.depth;
    if (!f.mask.empty())
      for (size_t i = 0; i < depth.num_pixels(); ++i)
        if (f.mask.data()[i] == 0) depth.data()[i] = 0;
    HOLO_RETURN_IF_ERROR(WriteDepth16((fdir / ("pod" + std::to_string(k) + "_depth.png")).string(), depth, fast));
    HOLO_RETURN_IF_ERROR(WriteImageRgb8((fdir / ("pod" + std::to_string(k) + "_color.png")).string(), f.color, fast));
  }
  return OkStatus();
}

Status WritePeerCameras(const std::string& dir, const Rig& rig, int frames) {
  nlohmann::json j;
  j["frames"] = frames;
  for (const PodCalibration& pod : rig.pods) {
    if (!pod.IsRegistered() || pod.depth.HasDistortion())
      return InvalidArgument("the Open3D peer needs registered, undistorted pods; " + pod.name + " is not");
    nlohmann::json p;
    p["width"] = pod.depth.width;
    p["height"] = pod.depth.height;
    p["fx"] = pod.depth.fx;
    p["fy"] = pod.depth.fy;
    p["cx"] = pod.depth.cx;
    p["cy"] = pod.depth.cy;
    const Eigen::Matrix4f e = pod.world_from_depth.inverse().matrix();
    std::vector<double> m;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) m.push_back(e(r, c));
    p["extrinsic"] = m;
    j["pods"].push_back(p);
  }
  std::ofstream f(fs::path(dir) / "cameras.json");
  f << j.dump(1);
  return f ? OkStatus() : Internal("cannot write " + dir + "/cameras.json");
}

// Our fusion of one frame set, `repeats` times: fuse, mesh, clean up.
struct OurFrameResult {
  std::vector<double> fuse_ms, mesh_ms, cleanup_ms;
  std::vector<double> fuse_cpu_ms, mesh_cpu_ms;  // CPU time of all threads (barely changed by other load)
  Mesh raw, cleaned;
  TsdfStats stats;
};

Status FuseFrame(TsdfVolume* vol, const Rig& rig, const RgbdFrameSet& set, const FusionConfig& cfg,
                 OurFrameResult* out) {
  Mesh raw, cleaned;
  for (int r = 0; r < cfg.repeats; ++r) {
    vol->Reset();
    const double c0 = ProcessCpuMs();
    const auto t0 = std::chrono::steady_clock::now();
    HOLO_RETURN_IF_ERROR(vol->Integrate(rig, set));
    const auto t1 = std::chrono::steady_clock::now();
    const double c1 = ProcessCpuMs();
    vol->ExtractMesh(&raw);
    const auto t2 = std::chrono::steady_clock::now();
    const double c2 = ProcessCpuMs();
    out->fuse_cpu_ms.push_back(c1 - c0);
    out->mesh_cpu_ms.push_back(c2 - c1);
    cleaned = raw;  // copy outside the timed region
    const auto t3 = std::chrono::steady_clock::now();
    HOLO_RETURN_IF_ERROR(CleanupMesh(cfg.cleanup, &cleaned));
    const auto t4 = std::chrono::steady_clock::now();
    out->fuse_ms.push_back(Ms(t0, t1));
    out->mesh_ms.push_back(Ms(t1, t2));
    out->cleanup_ms.push_back(Ms(t3, t4));
  }
  out->stats = vol->stats();
  out->raw = std::move(raw);
  out->cleaned = std::move(cleaned);
  return OkStatus();
}

struct PeerResult {
  bool ok = false;
  std::string error;
  std::string version;
  std::vector<double> integrate_ms, extract_ms, total_ms;  // all frames × repeats
  std::vector<Mesh> meshes;                                 // one per frame
};

// Runs bench/peers/open3d_fusion.py on `dir` and reads back its timings and meshes.
PeerResult RunOpen3dPeer(const std::string& dir, const TsdfOptions& o, int repeats) {
  PeerResult r;
  const std::string python = "/usr/bin/python3";
  const std::string script = std::string(HOLO_SOURCE_DIR) + "/bench/peers/open3d_fusion.py";
  if (!fs::exists(python)) {
    r.error = python + " not found";
    return r;
  }
  char cmd[2048];
  std::snprintf(cmd, sizeof(cmd), "OMP_WAIT_POLICY=PASSIVE %s '%s' '%s' --voxel %.6f --trunc %.6f --depth-max %.3f --repeats %d", python.c_str(),
                script.c_str(), dir.c_str(), o.voxel_size, o.voxel_size * o.truncation_voxels, o.max_depth_m, repeats);
  FILE* p = popen(cmd, "r");
  if (!p) {
    r.error = "cannot run " + python;
    return r;
  }
  std::string out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  const int rc = pclose(p);
  nlohmann::json j = nlohmann::json::parse(out, nullptr, false);
  if (j.is_discarded() || !j.is_object()) {
    r.error = "peer exited with status " + std::to_string(rc) + " and no JSON output";
    return r;
  }
  if (j.contains("error")) {
    r.error = j["error"].get<std::string>();
    return r;
  }
  r.version = j.value("open3d_version", "");
  for (const auto& f : j["frames"]) {
    const std::vector<double> in = f["integrate_ms"].get<std::vector<double>>();
    const std::vector<double> ex = f["extract_ms"].get<std::vector<double>>();
    for (size_t i = 0; i < in.size() && i < ex.size(); ++i) {
      r.integrate_ms.push_back(in[i]);
      r.extract_ms.push_back(ex[i]);
      r.total_ms.push_back(in[i] + ex[i]);
    }
    auto mesh = ReadPly(f["ply"].get<std::string>());
    if (!mesh.ok()) {
      r.error = "reading the peer's mesh: " + mesh.status().ToString();
      return r;
    }
    r.meshes.push_back(std::move(mesh).value());
  }
  r.ok = rc == 0;
  if (!r.ok) r.error = "peer exited with status " + std::to_string(rc);
  return r;
}

void EmitPeerMissing(const std::string& workload, const std::string& why) {
  spdlog::warn("fusion: Open3D peer unavailable: {} (install python3-open3d; run with /usr/bin/python3)", why);
  EmitFigure("fusion", workload, "peer_missing", 1, "bool", {{"peer", "open3d"}, {"reason", why}});
}

std::string MakeWorkDir(const std::string& keep) {
  if (!keep.empty()) {
    fs::create_directories(keep);
    return keep;
  }
  const fs::path dir = fs::temp_directory_path() / ("holoport_fusion_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

struct ExtraArgs {
  std::string dataset, keep;
  bool peer = true;
  double voxel_mm = 0, depth_max_m = 0, min_weight = 0, behind_band = 0, behind_sigmas = -1;
  long decimate = -1;
  // Whole-pipeline figures (our segmentation + texturing), see fusion_pipeline.h.
  bool pipeline = true, pipeline_only = false;
  PipelineBenchOptions pipeline_options;
};

// The fusion benchmark's options (holoport-bench fusion --help).
void DeclareOptions(CLI::App& app, ExtraArgs* a) {
  PipelineBenchOptions& p = a->pipeline_options;
  app.add_option("--dataset", a->dataset, "Redwood-style dataset folder (else the synthetic studio)");
  app.add_option("--keep", a->keep, "keep the peer's work folder here");
  app.add_flag("--no-peer{false}", a->peer, "skip the Open3D peer");
  app.add_option("--voxel-mm", a->voxel_mm, "TSDF voxel size, mm (default: the workload's)");
  app.add_option("--depth-max-m", a->depth_max_m, "largest depth integrated, m (default 5)");
  app.add_option("--min-weight", a->min_weight, "TSDF minimum weight to extract");
  app.add_option("--behind-band", a->behind_band,
                 "TSDF: observations behind the surface count this many truncation distances deep (default: "
                 "TsdfOptions'; 1 = the classic drop)")
      ->check(CLI::Range(1.0, 4.0));
  app.add_option("--behind-sigmas", a->behind_sigmas,
                 "TSDF: and this many σ of the sensor's depth noise at each pixel's depth deeper (default: "
                 "TsdfOptions'; 0 = a fixed band)")
      ->check(CLI::Range(0.0, 5.0));
  app.add_option("--decimate", a->decimate, "also decimate to this many triangles");
  app.add_flag("--no-pipeline{false}", a->pipeline, "skip the whole-pipeline figures");
  app.add_flag("--pipeline-only", a->pipeline_only, "only the whole-pipeline figures");
  app.add_option("--pipeline-frames", p.frames, "frames of the pipeline run")->check(CLI::PositiveNumber);
  app.add_option("--png", p.png_dir, "write pipeline images here");
  app.add_option("--texture-cluster-mm", p.texture_cluster_mm, "texture cluster size, mm");
  app.add_option("--texture-transfer", p.texture_transfer, "texture transfer mode");
  app.add_option("--seg-iterations", p.seg_iterations, "segmentation CRF iterations");
  app.add_option("--seg-downsample", p.seg_downsample, "segmentation downsampling");
  app.add_option("--seg-grid-px", p.seg_grid_px, "segmentation grid, px");
  app.add_option("--stereo-edge-shift", p.stereo_edge_shift,
                 "--pipeline-source stereo: PatchMatch's edge pass, window shift px (0: off; default: its default)")
      ->check(CLI::Range(0, 8));
  app.add_option("--stereo-roi-shape", p.stereo_roi_spans,
                 "--pipeline-source stereo: the matched regions as row spans around the person or their bounding "
                 "boxes (spans|box)")
      ->transform(CLI::CheckedTransformer(std::map<std::string, bool>{{"spans", true}, {"box", false}}))
      ->capture_default_str();
  app.add_option("--stereo-search", p.stereo_search_sgbm,
                 "--pipeline-source stereo: whole pairs due searched with SGBM, then PatchMatch around the person "
                 "(sgbm), or through PatchMatch whole (patchmatch)")
      ->transform(CLI::CheckedTransformer(std::map<std::string, bool>{{"sgbm", true}, {"patchmatch", false}}))
      ->capture_default_str();
  app.add_option("--stereo-still", p.stereo_still,
                 "--pipeline-source stereo: PatchMatch leaves alone pixels whose window changed since the last frame "
                 "by at most this times the noise level (0: none; default: its default)")
      ->check(CLI::Range(0.0, 100.0));
  app.add_option("--seg-edge-band", p.seg_edge_band,
                 "segmentation: pixels beside a depth edge where colour decides (default: 3 with --pipeline-source "
                 "stereo, else 0)")
      ->check(CLI::Range(0, 32));
  app.add_option("--eval-every", p.eval_every, "evaluate every N frames")->check(CLI::PositiveNumber);
  app.add_option("--pipeline-source", p.source,
                 "pipeline source: synthetic (the studio renders during the run), prerendered, stereo (PatchMatch "
                 "depth from the studio's IR pairs, as holoport-server --depth stereo; also runs the same frames on "
                 "direct depth and compares the meshes) or dataset:DIR")
      ->capture_default_str();
  app.add_option("--cpu-frames", p.cpu_frames, "frames timed for CPU figures")->check(CLI::NonNegativeNumber);
  app.add_option("--depth-filter", p.depth_filter,
                 "pipeline: depth filter radius (default: the capture site's, 0: off)")
      ->check(CLI::Range(0, 4));
  app.add_flag("--raw-full-mesh", p.raw_full_mesh, "pipeline: full meshes from the fused volume as it is (not smoothed)");
  app.add_option("--stream-frames", p.stream_frames,
                 "frames of the run that scores the stream mesh against the full mesh (0: skip)")
      ->check(CLI::NonNegativeNumber);
}

// Every fusion figure is measured on the site's own reconstruction.
std::map<std::string, std::string> Q(std::initializer_list<std::pair<const std::string, std::string>> q) {
  std::map<std::string, std::string> m = q;
  m["content"] = "fused";
  return m;
}

// ---------------------------------------------------------------------------
// Studio workloads: ground-truth masks, ground-truth mesh.

int RunWorkload(const BenchArgs& args, const ExtraArgs& extra) {
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("fusion: {}", workload.status().ToString());
    return 2;
  }
  auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
  if (!studio.ok()) {
    spdlog::error("fusion: {}", studio.status().ToString());
    return 1;
  }
  const std::string& wl = workload->name;
  FusionConfig cfg;
  cfg.tsdf.voxel_size = extra.voxel_mm > 0 ? static_cast<float>(extra.voxel_mm / 1000) : workload->voxel_size_m;
  cfg.tsdf.max_depth_m = extra.depth_max_m > 0 ? static_cast<float>(extra.depth_max_m) : 5.0f;
  if (extra.min_weight > 0) cfg.tsdf.min_weight = static_cast<float>(extra.min_weight);
  if (extra.behind_band > 0) cfg.tsdf.behind_band = static_cast<float>(extra.behind_band);
  if (extra.behind_sigmas >= 0) cfg.tsdf.behind_noise_sigmas = static_cast<float>(extra.behind_sigmas);
  cfg.repeats = args.repeats;
  if (extra.decimate >= 0) cfg.decimate_to = static_cast<size_t>(extra.decimate);
  const int frames = args.frames > 0 ? args.frames : 10;
  auto vol = TsdfVolume::Create(cfg.tsdf);
  if (!vol.ok()) {
    spdlog::error("fusion: {}", vol.status().ToString());
    return 2;
  }
  const std::string dir = extra.peer ? MakeWorkDir(extra.keep) : "";
  if (extra.peer) {
    if (Status s = WritePeerCameras(dir, workload->rig, frames); !s.ok()) {
      spdlog::error("fusion: {}", s.ToString());
      return 1;
    }
  }

  RgbdFrameSet set;
  StudioGroundTruth gt;
  std::vector<Mesh> truth;
  std::vector<double> fuse_ms, mesh_ms, cleanup_ms, total_ms, decimate_ms, fuse_cpu_ms, mesh_cpu_ms;
  std::vector<double> chamfer, chamfer_raw, completeness, hausdorff, hausdorff95, triangles, blocks;
  std::vector<double> chamfer_decimated;
  metrics::MeshDistanceOptions mdo;
  for (int f = 0; f < frames; ++f) {
    (*studio)->RenderFrame(f, &set, &gt);
    for (size_t k = 0; k < set.frames.size(); ++k) set.frames[k].mask = gt.mask[k];
    truth.push_back(gt.foreground_mesh);
    OurFrameResult r;
    if (Status s = FuseFrame(vol->get(), workload->rig, set, cfg, &r); !s.ok()) {
      spdlog::error("fusion: frame {}: {}", f, s.ToString());
      return 1;
    }
    for (size_t i = 0; i < r.fuse_ms.size(); ++i) {
      fuse_ms.push_back(r.fuse_ms[i]);
      mesh_ms.push_back(r.mesh_ms[i]);
      cleanup_ms.push_back(r.cleanup_ms[i]);
      total_ms.push_back(r.fuse_ms[i] + r.mesh_ms[i] + r.cleanup_ms[i]);
      fuse_cpu_ms.push_back(r.fuse_cpu_ms[i]);
      mesh_cpu_ms.push_back(r.mesh_cpu_ms[i]);
    }
    auto d = metrics::ComputeMeshDistance(r.cleaned, gt.foreground_mesh, mdo);
    auto draw = metrics::ComputeMeshDistance(r.raw, gt.foreground_mesh, mdo);
    if (!d.ok() || !draw.ok()) {
      spdlog::error("fusion: frame {}: no surface: {}", f, (d.ok() ? draw : d).status().ToString().c_str());
      return 1;
    }
    chamfer.push_back(d->chamfer_mm);
    chamfer_raw.push_back(draw->chamfer_mm);
    completeness.push_back(d->completeness);
    hausdorff.push_back(d->hausdorff_mm);
    hausdorff95.push_back(d->hausdorff_percentile_mm);
    triangles.push_back(static_cast<double>(r.cleaned.num_triangles()));
    blocks.push_back(static_cast<double>(r.stats.blocks_touched));
    // Decimation cost and added error, on the first frame (OpenMesh's
    // decimater takes seconds on a 150k-triangle mesh).
    if (cfg.decimate_to > 0 && f == 0) {
      Mesh dec = r.cleaned;
      MeshCleanupOptions co;
      co.min_component_triangles = 0;
      co.target_triangles = cfg.decimate_to;
      const auto t0 = std::chrono::steady_clock::now();
      if (Status s = CleanupMesh(co, &dec); !s.ok()) {
        spdlog::error("fusion: decimation: {}", s.ToString());
        return 1;
      }
      decimate_ms.push_back(Ms(t0, std::chrono::steady_clock::now()));
      auto dd = metrics::ComputeMeshDistance(dec, gt.foreground_mesh, mdo);
      if (dd.ok()) chamfer_decimated.push_back(dd->chamfer_mm);
    }
    if (extra.peer) {
      if (Status s = WritePeerFrame(dir, f, set); !s.ok()) {
        spdlog::error("fusion: {}", s.ToString());
        return 1;
      }
    }
    if (!args.json)
      spdlog::info(
          "fusion {} frame {}: fuse {:.1f} ms, mesh {:.1f} ms, cleanup {:.1f} ms; {} blocks, {} block-views ({} "
          "skipped, {} free), {} triangles; chamfer {:.2f} mm (raw {:.2f}), completeness {:.3f}; cpu fuse {:.1f} mesh "
          "{:.1f} ms; prepare {:.1f} allocate {:.1f} integrate {:.1f} ms",
          wl, f, Median(r.fuse_ms), Median(r.mesh_ms), Median(r.cleanup_ms), r.stats.blocks_touched,
          r.stats.block_views, r.stats.block_views_skipped, r.stats.block_views_free, r.cleaned.num_triangles(),
          d->chamfer_mm, draw->chamfer_mm, d->completeness, Median(r.fuse_cpu_ms), Median(r.mesh_cpu_ms),
          r.stats.prepare_ms, r.stats.allocate_ms, r.stats.integrate_ms);
  }
  const std::string voxel_mm = std::to_string(static_cast<int>(std::lround(cfg.tsdf.voxel_size * 1000)));
  const int threads = (*vol)->options().threads;
  const auto q = [&](const std::string& stage) {
    return Q({{"stage", stage}, {"voxel_mm", voxel_mm}, {"threads", std::to_string(threads)}, {"frames", std::to_string(frames)}});
  };
  EmitFigure("fusion", wl, "ms", Median(fuse_ms), "ms", q("fuse"));
  EmitFigure("fusion", wl, "ms", Median(mesh_ms), "ms", q("mesh"));
  EmitFigure("fusion", wl, "ms", Median(cleanup_ms), "ms", q("cleanup"));
  std::vector<double> fuse_mesh;
  for (size_t i = 0; i < fuse_ms.size(); ++i) fuse_mesh.push_back(fuse_ms[i] + mesh_ms[i]);
  EmitFigure("fusion", wl, "ms", Median(fuse_mesh), "ms", q("fuse_mesh"));
  EmitFigure("fusion", wl, "ms", Median(total_ms), "ms", q("fuse_mesh_cleanup"));
  EmitFigure("fusion", wl, "cpu_ms", Median(fuse_cpu_ms), "ms", q("fuse"));
  EmitFigure("fusion", wl, "cpu_ms", Median(mesh_cpu_ms), "ms", q("mesh"));
  EmitFigure("fusion", wl, "chamfer_mm", Mean(chamfer), "mm",
             Q({{"voxel_mm", voxel_mm}, {"mesh", "cleaned"}, {"behind_band", fmt::format("{:g}", cfg.tsdf.behind_band)},
                {"behind_sigmas", fmt::format("{:g}", cfg.tsdf.behind_noise_sigmas)}}));
  EmitFigure("fusion", wl, "chamfer_mm", Mean(chamfer_raw), "mm", Q({{"voxel_mm", voxel_mm}, {"mesh", "raw"}}));
  EmitFigure("fusion", wl, "completeness", Mean(completeness), "fraction", Q({{"voxel_mm", voxel_mm}, {"threshold_mm", "10"}}));
  EmitFigure("fusion", wl, "hausdorff_mm", Mean(hausdorff), "mm", Q({{"voxel_mm", voxel_mm}}));
  EmitFigure("fusion", wl, "hausdorff95_mm", Mean(hausdorff95), "mm", Q({{"voxel_mm", voxel_mm}}));
  EmitFigure("fusion", wl, "triangles", Mean(triangles), "count", Q({{"mesh", "cleaned"}}));
  EmitFigure("fusion", wl, "blocks", Mean(blocks), "count", Q({{"voxel_mm", voxel_mm}}));
  if (!decimate_ms.empty()) {
    const std::string budget = std::to_string(cfg.decimate_to);
    EmitFigure("fusion", wl, "ms", Median(decimate_ms), "ms", Q({{"stage", "decimate"}, {"target_triangles", budget}}));
    EmitFigure("fusion", wl, "chamfer_mm", Mean(chamfer_decimated), "mm",
               Q({{"mesh", "decimated"}, {"target_triangles", budget}}));
  }

  if (!extra.peer) return 0;
  PeerResult peer = RunOpen3dPeer(dir, cfg.tsdf, cfg.repeats);
  if (!peer.ok) {
    EmitPeerMissing(wl, peer.error);
  } else {
    std::vector<double> peer_chamfer, peer_completeness;
    for (size_t f = 0; f < peer.meshes.size() && f < truth.size(); ++f) {
      auto d = metrics::ComputeMeshDistance(peer.meshes[f], truth[f], mdo);
      if (d.ok()) {
        peer_chamfer.push_back(d->chamfer_mm);
        peer_completeness.push_back(d->completeness);
      }
    }
    const auto pq = [&](const std::string& stage) {
      return Q({{"peer", "open3d"}, {"stage", stage}, {"voxel_mm", voxel_mm}, {"open3d", peer.version}});
    };
    EmitFigure("fusion", wl, "ms", Median(peer.integrate_ms), "ms", pq("fuse"));
    EmitFigure("fusion", wl, "ms", Median(peer.extract_ms), "ms", pq("mesh"));
    EmitFigure("fusion", wl, "ms", Median(peer.total_ms), "ms", pq("fuse_mesh"));
    EmitFigure("fusion", wl, "chamfer_mm", Mean(peer_chamfer), "mm", Q({{"peer", "open3d"}, {"voxel_mm", voxel_mm}, {"mesh", "raw"}}));
    EmitFigure("fusion", wl, "completeness", Mean(peer_completeness), "fraction",
               Q({{"peer", "open3d"}, {"voxel_mm", voxel_mm}, {"threshold_mm", "10"}}));
    EmitFigure("fusion", wl, "speedup_vs_open3d", Median(peer.total_ms) / Median(fuse_mesh), "x",
               Q({{"stage", "fuse_mesh"}, {"voxel_mm", voxel_mm}}));
  }
  if (extra.keep.empty()) fs::remove_all(dir);
  return 0;
}

// ---------------------------------------------------------------------------
// A Redwood-layout folder: frames as pods of a static scene, no masks, no
// ground truth; ours against Open3D.

int RunDataset(const BenchArgs& args, const ExtraArgs& extra) {
  RedwoodImportOptions ro;
  if (!fs::exists(fs::path(extra.dataset) / ro.intrinsic_file) && fs::exists(fs::path(extra.dataset) / "camera_primesense.json"))
    ro.intrinsic_file = "camera_primesense.json";
  auto scene = ImportRedwood(extra.dataset, ro);
  if (!scene.ok()) {
    spdlog::error("fusion: {}", scene.status().ToString());
    return 1;
  }
  if (!scene->has_poses) {
    spdlog::error("fusion: {} has no camera poses (trajectory.log); cannot fuse its frames as pods", extra.dataset);
    return 1;
  }
  const std::string wl = "redwood:" + fs::path(extra.dataset).lexically_normal().filename().string() + ":" +
                         std::to_string(scene->rig.pods.size()) + "pods";
  FusionConfig cfg;
  cfg.tsdf.voxel_size = static_cast<float>((extra.voxel_mm > 0 ? extra.voxel_mm : 10.0) / 1000);
  cfg.tsdf.max_depth_m = static_cast<float>(extra.depth_max_m > 0 ? extra.depth_max_m : 3.0);
  cfg.repeats = args.repeats;
  cfg.cleanup.min_component_triangles = 0;
  auto vol = TsdfVolume::Create(cfg.tsdf);
  if (!vol.ok()) {
    spdlog::error("fusion: {}", vol.status().ToString());
    return 2;
  }
  OurFrameResult r;
  if (Status s = FuseFrame(vol->get(), scene->rig, scene->frames, cfg, &r); !s.ok()) {
    spdlog::error("fusion: {}", s.ToString());
    return 1;
  }
  std::vector<double> fuse_mesh;
  for (size_t i = 0; i < r.fuse_ms.size(); ++i) fuse_mesh.push_back(r.fuse_ms[i] + r.mesh_ms[i]);
  const std::string voxel_mm = std::to_string(static_cast<int>(std::lround(cfg.tsdf.voxel_size * 1000)));
  char depth_max[16];
  std::snprintf(depth_max, sizeof(depth_max), "%.2f", cfg.tsdf.max_depth_m);
  const auto q = [&](const std::string& stage) { return Q({{"stage", stage}, {"voxel_mm", voxel_mm}, {"depth_max_m", depth_max}}); };
  EmitFigure("fusion", wl, "ms", Median(r.fuse_ms), "ms", q("fuse"));
  EmitFigure("fusion", wl, "ms", Median(r.mesh_ms), "ms", q("mesh"));
  EmitFigure("fusion", wl, "ms", Median(fuse_mesh), "ms", q("fuse_mesh"));
  EmitFigure("fusion", wl, "triangles", static_cast<double>(r.raw.num_triangles()), "count", Q({{"mesh", "raw"}}));
  if (!args.json)
    spdlog::info("fusion {}: fuse {:.1f} ms, mesh {:.1f} ms, {} blocks, {} triangles", wl, Median(r.fuse_ms),
                 Median(r.mesh_ms), r.stats.blocks_touched, r.raw.num_triangles());
  if (!extra.peer) return 0;
  const std::string dir = MakeWorkDir(extra.keep);
  if (Status s = WritePeerCameras(dir, scene->rig, 1); !s.ok()) {
    spdlog::error("fusion: {}", s.ToString());
    return 1;
  }
  if (Status s = WritePeerFrame(dir, 0, scene->frames); !s.ok()) {
    spdlog::error("fusion: {}", s.ToString());
    return 1;
  }
  PeerResult peer = RunOpen3dPeer(dir, cfg.tsdf, cfg.repeats);
  if (!peer.ok || peer.meshes.empty()) {
    EmitPeerMissing(wl, peer.ok ? "no mesh" : peer.error);
    return 0;
  }
  const auto pq = [&](const std::string& stage) {
    return Q({{"peer", "open3d"}, {"stage", stage}, {"voxel_mm", voxel_mm}, {"open3d", peer.version}});
  };
  EmitFigure("fusion", wl, "ms", Median(peer.integrate_ms), "ms", pq("fuse"));
  EmitFigure("fusion", wl, "ms", Median(peer.extract_ms), "ms", pq("mesh"));
  EmitFigure("fusion", wl, "ms", Median(peer.total_ms), "ms", pq("fuse_mesh"));
  EmitFigure("fusion", wl, "triangles", static_cast<double>(peer.meshes[0].num_triangles()), "count",
             Q({{"peer", "open3d"}, {"mesh", "raw"}}));
  EmitFigure("fusion", wl, "speedup_vs_open3d", Median(peer.total_ms) / Median(fuse_mesh), "x", Q({{"stage", "fuse_mesh"}}));
  // No ground truth: the distance between the two reconstructions.
  auto d = metrics::ComputeMeshDistance(r.raw, peer.meshes[0]);
  if (d.ok()) {
    EmitFigure("fusion", wl, "chamfer_mm", d->chamfer_mm, "mm", Q({{"reference", "open3d"}, {"voxel_mm", voxel_mm}}));
    EmitFigure("fusion", wl, "hausdorff95_mm", d->hausdorff_percentile_mm, "mm", Q({{"reference", "open3d"}}));
    EmitFigure("fusion", wl, "completeness", d->completeness, "fraction", Q({{"reference", "open3d"}, {"threshold_mm", "10"}}));
  } else {
    spdlog::warn("fusion: mesh distance: {}", d.status().ToString());
  }
  if (extra.keep.empty()) fs::remove_all(dir);
  return 0;
}

int RunFusionBench(const BenchArgs& args, const ExtraArgs& extra) {
  if (!extra.dataset.empty()) return RunDataset(args, extra);
  const int rc = extra.pipeline_only ? 0 : RunWorkload(args, extra);
  if (rc != 0 || !extra.pipeline) return rc;
  PipelineBenchOptions pipeline = extra.pipeline_options;
  if (extra.behind_band > 0) pipeline.behind_band = extra.behind_band;
  if (extra.behind_sigmas >= 0) pipeline.behind_sigmas = extra.behind_sigmas;
  return RunPipelineFigures(args, pipeline);
}

BenchFn SetupFusion(CLI::App& app) {
  auto extra = std::make_shared<ExtraArgs>();
  DeclareOptions(app, extra.get());
  return [extra](const BenchArgs& args) { return RunFusionBench(args, *extra); };
}

HOLO_REGISTER_BENCH_OPTIONS("fusion",
                            "TSDF fusion + marching cubes vs ground truth and Open3D (--dataset DIR for Redwood)",
                            SetupFusion);

}  // namespace
}  // namespace holo::bench
