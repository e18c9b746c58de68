// holoport-bench client-pose: head-pose prediction error and offloaded
// rendering with reprojection (docs/prediction.md).
//
// Prediction: every model (none, cv, kalman) at horizons 20/50/100 ms on the
// synthetic generator (looking around and walking, 60 s each at 90 Hz) and
// on the recorded trace tests/data/head/lookaround_72hz.csv:
//   {"metric":"pred_err_deg","model":"cv","horizon_ms":"50","trace":"synthetic",...}
// Reprojection: see RunReprojectionBench below:
//   {"metric":"reproj_psnr_db","mode":"predicted","latency_ms":"50","region":"frame",...}
//   {"metric":"black_border_fraction",...}, reproj_gain_db, rendered_frame_kb, reproj_cpu_ms
//
// Extra options: --part pred|reproj|all (default all); --trace FILE (recorded
// trace, default the sample); tuning of the Kalman model: --jerk_pos X
// --jerk_ang X --accel_tau X --vel_tau X --cv_window X. Reprojection:
// --scene foreground|studio|both, --method none|rotation|plane|depth,
// --filter bilinear|bicubic, --latencies 30,50,80, --margin 0.25,
// --size 640x360, --hfov 90, --quality 90, --distance 2.6, --png DIR;
// --frames N sets the display frames of both scenes (default 120 / 60).
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "bench.h"
#include "client/pose/head_motion.h"
#include "client/pose/predictor.h"
#include "client/pose/trace.h"
#include "client/reproject/offload_sim.h"
#include "common/log.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace {

using holo::pose::PredictorModel;

int RunPrediction(const holo::bench::BenchArgs& args, const holo::pose::PredictorOptions& options,
                  const std::string& trace_path) {
  struct Trace {
    std::string name, kind;
    std::vector<holo::pose::PoseSample> samples;
  };
  std::vector<Trace> traces;
  for (auto kind : {holo::pose::HeadMotionKind::kLookAround, holo::pose::HeadMotionKind::kWalk}) {
    holo::pose::HeadMotionOptions o;
    o.kind = kind;
    o.duration_s = 60;
    o.seed = 7;
    auto samples = holo::pose::GenerateHeadMotion(o);
    if (!samples.ok()) {
      spdlog::error("client-pose: {}", samples.status().ToString());
      return 1;
    }
    traces.push_back({"synthetic", kind == holo::pose::HeadMotionKind::kWalk ? "walk" : "lookaround", *samples});
  }
  auto recorded = holo::pose::ReadHeadTrace(trace_path);
  if (!recorded.ok()) {
    spdlog::error("client-pose: {}", recorded.status().ToString());
    return 1;
  }
  traces.push_back({"recorded", "lookaround", *recorded});
  for (const Trace& t : traces) {
    for (int horizon_ms : {20, 50, 100}) {
      for (PredictorModel m : {PredictorModel::kNone, PredictorModel::kConstantVelocity, PredictorModel::kKalman}) {
        // Judged against what the tracker reports (noise included), as
        // recorded data must be.
        auto e = holo::pose::EvaluatePredictor(m, options, t.samples, t.samples, horizon_ms * 1e-3);
        if (!e.ok()) {
          spdlog::error("client-pose: {}", e.status().ToString());
          return 1;
        }
        const std::string model = holo::pose::PredictorModelName(m);
        std::map<std::string, std::string> q = {{"model", model},
                                                {"horizon_ms", std::to_string(horizon_ms)},
                                                {"trace", t.name},
                                                {"motion", t.kind}};
        q["stat"] = "mean";
        holo::bench::EmitFigure("client-pose", "head-trace", "pred_err_deg", e->mean_deg, "deg", q);
        holo::bench::EmitFigure("client-pose", "head-trace", "pred_err_mm", e->mean_mm, "mm", q);
        q["stat"] = "p95";
        holo::bench::EmitFigure("client-pose", "head-trace", "pred_err_deg", e->p95_deg, "deg", q);
        holo::bench::EmitFigure("client-pose", "head-trace", "pred_err_mm", e->p95_mm, "mm", q);
        if (!args.json) {
          spdlog::info("{:<9} {:<10} {:3} ms {:<6}  {:6.2f} deg (p95 {:6.2f})  {:6.1f} mm (p95 {:6.1f})", t.name,
                       t.kind, horizon_ms, model, e->mean_deg, e->p95_deg, e->mean_mm, e->p95_mm);
        }
      }
    }
  }
  return 0;
}

// Offloaded rendering on the synthetic studio with the recorded head trace
// (client/reproject/offload_sim.h): for display times spread over the trace
// and each simulated host latency L, the modes ideal (zero latency: the
// ceiling), stale, reprojected, predicted (Kalman) and enlarged (FOV margin).
// Scenes: "foreground" — the studio's ground-truth textured foreground mesh
// (people and props) drawn by the CPU mesh renderer on black, as a viewer of
// the received mesh shows it; "studio" — the whole studio (room included)
// from its ground-truth renderer, which fills the frame.
// Options of the reprojection part (holoport-bench client-pose --help).
struct ReprojArgs {
  holo::reproject::OffloadSimOptions o = [] {
    holo::reproject::OffloadSimOptions d;
    d.encode.jpeg_quality = 90;
    return d;
  }();
  std::string size;  // WxH, empty = the default
  std::string filter = "bilinear";  // OffloadSimOptions' default
  std::string latencies;  // comma-separated ms, empty = the default
  double view_distance_m = 2.6;
  std::string scenes = "both", method_name = "plane";
};

int RunReprojectionBench(const holo::bench::BenchArgs& args, const holo::pose::PredictorOptions& predictor_options,
                         const std::string& trace_path, const ReprojArgs& r) {
  using namespace holo::reproject;
  OffloadSimOptions o = r.o;
  o.predictor_options = predictor_options;
  const double view_distance_m = r.view_distance_m;
  const std::string& scenes = r.scenes;
  const std::string& method_name = r.method_name;
  // Display frames per scene (the room renders 3× slower than the person).
  const int fg_frames = args.frames > 0 ? args.frames : 120;
  const int studio_frames = args.frames > 0 ? args.frames : 60;
  if (!r.size.empty() && std::sscanf(r.size.c_str(), "%dx%d", &o.width, &o.height) != 2) {
    spdlog::error("client-pose: --size must be WxH, got {}", r.size);
    return 2;
  }
  o.filter = r.filter == "bilinear" ? ReprojectFilter::kBilinear : ReprojectFilter::kBicubic;
  if (!r.latencies.empty()) {
    o.latencies_ms.clear();
    const std::string& list = r.latencies;
    for (size_t start = 0; start <= list.size();) {
      const size_t comma = std::min(list.find(',', start), list.size());
      o.latencies_ms.push_back(std::atoi(list.substr(start, comma - start).c_str()));
      start = comma + 1;
    }
  }
  if (scenes != "foreground" && scenes != "studio" && scenes != "both") {
    spdlog::error("client-pose: --scene must be foreground, studio or both, got {}", scenes);
    return 2;
  }
  auto method = ParseReprojectMethod(method_name);
  if (!method.ok()) {
    spdlog::error("client-pose: {}", method.status().ToString());
    return 2;
  }
  o.method = *method;
  if (auto s = o.Check(); !s.ok()) {
    spdlog::error("client-pose: {}", s.ToString());
    return 2;
  }
  auto trace = holo::pose::ReadHeadTrace(trace_path);
  if (!trace.ok()) {
    spdlog::error("client-pose: {}", trace.status().ToString());
    return 1;
  }
  auto workload = holo::GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("client-pose: {}", workload.status().ToString());
    return 1;
  }
  holo::StudioOptions studio_options = workload->studio;
  studio_options.threads = 2;
  auto studio = holo::SyntheticStudio::Create(workload->rig, studio_options);
  if (!studio.ok()) {
    spdlog::error("client-pose: {}", studio.status().ToString());
    return 1;
  }
  o.content_fps = workload->studio.fps;
  // The trace's room frame (yaw 0 = +x) is placed `view_distance_m` from the
  // studio's centre on −x, so the viewer faces the people.
  std::vector<holo::pose::PoseSample> samples = *trace;
  for (holo::pose::PoseSample& s : samples) s.position += Eigen::Vector3d(-view_distance_m, 0, 0);

  std::vector<std::string> scene_list;
  if (scenes != "studio") scene_list.push_back("foreground");
  if (scenes != "foreground") scene_list.push_back("studio");
  for (const std::string& scene : scene_list) {
    o.display_frames = scene == "studio" ? studio_frames : fg_frames;
    holo::Mesh mesh;
    int64_t mesh_frame = -1;
    SceneAtFrame scene_at = [&](int64_t frame) -> SceneRenderFn {
      if (scene == "studio") {
        return [&, frame](const holo::CameraModel& cam, holo::ImageRgb8* c, holo::ImageDepth16* d, holo::ImageGray8* m) {
          (*studio)->RenderView(frame, cam, c, d, nullptr);
          if (m) m->Resize(cam.intrinsics.width, cam.intrinsics.height, 255);  // the room covers every pixel
          return holo::OkStatus();
        };
      }
      if (frame != mesh_frame) {
        mesh = (*studio)->ForegroundMesh(frame);
        mesh_frame = frame;
      }
      return MeshSceneRenderer(mesh);
    };
    const double cpu0 = holo::bench::ProcessCpuMs();
    auto results = SimulateOffload(samples, scene_at, o, [&](int done, int total) {
      if (!args.json && done % 20 == 0) spdlog::info("client-pose: {}: {}/{} display frames", scene, done, total);
    });
    if (!results.ok()) {
      spdlog::error("client-pose: {}", results.status().ToString());
      return 1;
    }
    const std::string workload_name = args.workload + "/" + scene;
    for (const OffloadResult& r : *results) {
      std::map<std::string, std::string> q = {{"mode", OffloadModeName(r.mode)},
                                              {"latency_ms", std::to_string(r.latency_ms)},
                                              {"method", r.mode == OffloadMode::kIdeal || r.mode == OffloadMode::kStale
                                                             ? "none"
                                                             : ReprojectMethodName(o.method)},
                                              {"trace", "recorded"},
                                              {"scene", scene},
                                              {"filter", o.filter == ReprojectFilter::kBicubic ? "bicubic" : "bilinear"},
                                              {"size", std::to_string(o.width) + "x" + std::to_string(o.height)},
                                              {"region", "frame"}};
      holo::bench::EmitFigure("client-pose", workload_name, "reproj_psnr_db", r.psnr_db, "dB", q);
      q["region"] = "content";
      holo::bench::EmitFigure("client-pose", workload_name, "reproj_psnr_db", r.psnr_content_db, "dB", q);
      q.erase("region");
      holo::bench::EmitFigure("client-pose", workload_name, "black_border_fraction", r.black_border_fraction, "1", q);
      if (o.method == ReprojectMethod::kDepth) {
        holo::bench::EmitFigure("client-pose", workload_name, "hole_fraction", r.hole_fraction, "1", q);
      }
      holo::bench::EmitFigure("client-pose", workload_name, "rendered_frame_kb", r.wire_bytes / 1024.0, "KiB", q);
      holo::bench::EmitFigure("client-pose", workload_name, "reproj_cpu_ms", r.reproject_cpu_ms, "ms", q);
      if (!args.json) {
        spdlog::info(
            "{:<10} L={:3} ms {:<11} PSNR {:6.2f} dB (content {:6.2f})  border {:.4f}  {:6.1f} KiB  reproject {:.1f} "
            "ms",
            scene, r.latency_ms, OffloadModeName(r.mode), r.psnr_db, r.psnr_content_db, r.black_border_fraction,
            r.wire_bytes / 1024.0, r.reproject_cpu_ms);
      }
    }
    // Paired per-frame gains (same display frames): mean ± standard error.
    auto gain = [&](int latency, OffloadMode from, OffloadMode to) {
      const OffloadResult *a = nullptr, *b = nullptr;
      for (const OffloadResult& r : *results) {
        if (r.latency_ms == latency && r.mode == from) a = &r;
        if (r.latency_ms == latency && r.mode == to) b = &r;
      }
      if (!a || !b || a->frame_psnr_db.size() != b->frame_psnr_db.size() || a->frame_psnr_db.size() < 2) return;
      const size_t n = a->frame_psnr_db.size();
      double sum = 0, sum2 = 0;
      int better = 0;
      for (size_t i = 0; i < n; ++i) {
        const double d = b->frame_psnr_db[i] - a->frame_psnr_db[i];
        sum += d;
        sum2 += d * d;
        better += d > 0;
      }
      const double mean = sum / n;
      const double se = std::sqrt(std::max(0.0, sum2 / n - mean * mean) / (n - 1));
      std::map<std::string, std::string> q = {{"from", OffloadModeName(from)}, {"to", OffloadModeName(to)},
                                              {"latency_ms", std::to_string(latency)}, {"scene", scene},
                                              {"method", ReprojectMethodName(o.method)}};
      holo::bench::EmitFigure("client-pose", workload_name, "reproj_gain_db", mean, "dB", q);
      holo::bench::EmitFigure("client-pose", workload_name, "reproj_gain_se_db", se, "dB", q);
      holo::bench::EmitFigure("client-pose", workload_name, "reproj_gain_frames_better", static_cast<double>(better) / n,
                              "1", q);
      if (!args.json) {
        spdlog::info("{:<10} L={:3} ms {} → {}: {:+.2f} ± {:.2f} dB (better in {} of {} frames)", scene, latency,
                     OffloadModeName(from), OffloadModeName(to), mean, se, better, n);
      }
    };
    for (int latency : o.latencies_ms) {
      gain(latency, OffloadMode::kStale, OffloadMode::kReprojected);
      gain(latency, OffloadMode::kReprojected, OffloadMode::kPredicted);
      gain(latency, OffloadMode::kPredicted, OffloadMode::kEnlarged);
    }
    if (!args.json) {
      spdlog::info("client-pose: {}: {:.1f} s CPU for {} display frames", scene,
                   (holo::bench::ProcessCpuMs() - cpu0) * 1e-3, o.display_frames);
    }
  }
  return 0;
}

struct ClientPoseArgs {
  std::string part = "all";
  std::string trace_path = std::string(HOLO_SOURCE_DIR) + "/tests/data/head/lookaround_72hz.csv";
  holo::pose::PredictorOptions options;
  ReprojArgs reproj;
};

int RunClientPoseBench(const holo::bench::BenchArgs& args, const ClientPoseArgs& c) {
  const std::string& part = c.part;
  const std::string& trace_path = c.trace_path;
  const holo::pose::PredictorOptions& options = c.options;
  if (part != "pred" && part != "reproj" && part != "all") {
    spdlog::error("client-pose: --part must be pred, reproj or all, got {}", part);
    return 2;
  }
  if (auto s = options.Check(); !s.ok()) {
    spdlog::error("client-pose: {}", s.ToString());
    return 2;
  }
  if (part != "reproj") {
    if (int rc = RunPrediction(args, options, trace_path); rc != 0) return rc;
  }
  if (part != "pred") return RunReprojectionBench(args, options, trace_path, c.reproj);
  return 0;
}

}  // namespace

holo::bench::BenchFn SetupClientPose(CLI::App& app) {
  holo::bench::DropCommonOptions(app, {"--repeats"});  // this benchmark does not read them
  auto c = std::make_shared<ClientPoseArgs>();
  app.add_option("--part", c->part, "pred (prediction), reproj (reprojection) or all")
      ->capture_default_str()
      ->check(CLI::IsMember({"pred", "reproj", "all"}));
  app.add_option("--trace", c->trace_path, "head trace CSV")->capture_default_str();
  app.add_option("--jerk_pos", c->options.position_jerk_psd, "predictor: position jerk PSD");
  app.add_option("--jerk_ang", c->options.angle_jerk_psd, "predictor: angle jerk PSD");
  app.add_option("--accel_tau", c->options.accel_tau_s, "predictor: acceleration time constant, s");
  app.add_option("--vel_tau", c->options.velocity_tau_s, "predictor: velocity time constant, s");
  app.add_option("--cv_window", c->options.window_s, "predictor: constant-velocity window, s");
  ReprojArgs& r = c->reproj;
  app.add_option("--size", r.size, "reprojection: display size WxH");
  app.add_option("--hfov", r.o.hfov_deg, "reprojection: horizontal field of view, degrees")->capture_default_str();
  app.add_option("--margin", r.o.margin, "reprojection: rendered margin")->capture_default_str();
  app.add_option("--scene", r.scenes, "reprojection: foreground, studio or both")
      ->capture_default_str()
      ->check(CLI::IsMember({"foreground", "studio", "both"}));
  app.add_option("--method", r.method_name, "reprojection method")->capture_default_str();
  app.add_option("--filter", r.filter, "reprojection filter: bilinear or bicubic")
      ->capture_default_str()
      ->check(CLI::IsMember({"bilinear", "bicubic"}));
  app.add_option("--quality", r.o.encode.jpeg_quality, "reprojection: JPEG quality")->capture_default_str();
  app.add_option("--distance", r.view_distance_m, "reprojection: viewing distance, m")->capture_default_str();
  app.add_option("--png", r.o.png_dir, "reprojection: write images here");
  app.add_option("--latencies", r.latencies, "reprojection: latencies, comma-separated ms");
  return [c](const holo::bench::BenchArgs& args) { return RunClientPoseBench(args, *c); };
}

HOLO_REGISTER_BENCH_OPTIONS(
    "client-pose",
    "head-pose prediction error (pred_err_deg/mm) and reprojection PSNR (reproj_psnr_db) for the thin client",
    SetupClientPose);
