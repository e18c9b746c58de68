// holoport-bench client-offload: networked render offload over loopback
// (docs/offload.md). In one process: a site server publishing the synthetic
// studio's ground-truth foreground mesh, a render host (client/offload)
// subscribed to it, and a thin client playing the sample head trace in real
// time at 60 Hz with a simulated network delay L on receive (30/50/80 ms).
// Every 4th displayed image is compared with the ground truth: the mesh the
// host drew, rendered at the true display-time pose. Configurations:
//   stale        — host without prediction, margin 0; the image as received
//   reprojected  — the same images, reprojected (plane) to the display pose
//   predicted    — host with Kalman prediction, margin 0, reprojected
//   enlarged     — host with Kalman prediction, margin 0.25, reprojected
// and, with --sim, SimulateOffload on the same trace segment at the measured
// mean pose→photon latency for comparison with `client-pose`.
//
// Options (after --): --latencies 30,50,80  --frames 120  --size 640x360
//   --trace FILE  --trace-start 5  --sample-every 4  --renderer cpu|gl|auto  --no-sim
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "bench.h"
#include "client/offload/render_host.h"
#include "client/offload/thin_client.h"
#include "client/pose/trace.h"
#include "client/reproject/offload_sim.h"
#include "common/log.h"
#include "common/metrics/image_metrics.h"
#include "net/session_server.h"
#include "net/wire_message.h"
#include "server/net/site_publisher.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace {

// One quality layer: the render host measured here takes every frame of the
// full layer; the layer policy (docs/sessions.md) is not what this measures.
holo::net::SitePublisherOptions FullLayerOnly() {
  holo::net::SitePublisherOptions o;
  o.reduced.enabled = false;
  return o;
}

using namespace holo;

struct ConfigResult {
  std::string mode;
  int latency = 0;
  std::vector<double> psnr, psnr_content, border;
  offload::ThinClientResult thin;
  double host_render_ms = 0, host_horizon_ms = 0;
  std::string renderer;
};

// Options (holoport-bench client-offload --help).
struct OffloadArgs {
  std::string latencies = "30,50,80";
  std::string size = "640x360";
  std::string trace_path = std::string(HOLO_SOURCE_DIR) + "/tests/data/head/lookaround_72hz.csv";
  double trace_start = 5.0;
  int sample_every = 4;
  std::string renderer = "cpu";
  bool sim = true;
};

int RunClientOffloadBench(const bench::BenchArgs& args, const OffloadArgs& o) {
  std::vector<int> latencies;
  {
    std::stringstream ss(o.latencies);
    std::string tok;
    while (std::getline(ss, tok, ',')) latencies.push_back(std::atoi(tok.c_str()));
  }
  int frames = args.frames > 0 ? args.frames : 120;
  int width = 640, height = 360;
  const int sample_every = std::max(1, o.sample_every);
  const double trace_start = o.trace_start, view_distance = 2.6;
  const bool sim = o.sim;
  const std::string& trace_path = o.trace_path;
  if (std::sscanf(o.size.c_str(), "%dx%d", &width, &height) != 2) {
    spdlog::error("client-offload: --size must be WxH");
    return 2;
  }
  auto parsed_renderer = offload::ParseHostRenderer(o.renderer);
  if (!parsed_renderer.ok()) {
    spdlog::error("client-offload: {}", parsed_renderer.status().ToString());
    return 2;
  }
  const offload::HostRenderer renderer = *parsed_renderer;
  for (int l : latencies) {
    if (l < 0 || l > 1000) {
      spdlog::error("client-offload: latencies must be 0..1000 ms");
      return 2;
    }
  }
  auto trace = pose::ReadHeadTrace(trace_path);
  if (!trace.ok()) {
    spdlog::error("client-offload: {}", trace.status().ToString());
    return 1;
  }
  for (pose::PoseSample& s : *trace) s.position += Eigen::Vector3d(-view_distance, 0, 0);
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("client-offload: {}", workload.status().ToString());
    return 1;
  }
  StudioOptions so = workload->studio;
  so.threads = 2;
  auto studio = SyntheticStudio::Create(workload->rig, so);
  if (!studio.ok()) {
    spdlog::error("client-offload: {}", studio.status().ToString());
    return 1;
  }
  const Mesh content = (*studio)->ForegroundMesh(0);

  // The site: publishes the same content frame at 10 Hz (the figures isolate head motion).
  net::ServerConfig sc;
  sc.publisher_token = "bench-pub";
  sc.viewer_token = "bench-view";
  sc.ping_interval_s = 0.2;
  auto server = net::Server::Start(sc);
  if (!server.ok()) {
    spdlog::error("client-offload: site: {}", server.status().ToString());
    return 1;
  }
  std::atomic<bool> stop{false};
  std::thread publisher([&] {
    net::SitePublisher pub(server->get(), FullLayerOnly());
    for (int64_t idx = 0; !stop; ++idx) {
      net::PublishTimings t;
      (void)pub.Publish(idx, net::WallUs(), content, {}, &t);
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  });

  const double cpu0 = bench::ProcessCpuMs();
  const auto wall0 = std::chrono::steady_clock::now();
  const reproject::FieldOfView fov = reproject::FieldOfView::FromHorizontalDeg(90.0, double(width) / height);
  struct HostConfig {
    const char* name;
    pose::PredictorModel model;
    double margin;
  };
  const HostConfig configs[] = {{"reprojected", pose::PredictorModel::kNone, 0.0},
                                {"predicted", pose::PredictorModel::kKalman, 0.0},
                                {"enlarged", pose::PredictorModel::kKalman, 0.25}};
  std::vector<ConfigResult> results;
  int rc = 0;
  for (int latency : latencies) {
    for (const HostConfig& hc : configs) {
      offload::RenderHostOptions ho;
      ho.site.port = (*server)->port();
      ho.site.token = sc.viewer_token;
      ho.margin = hc.margin;
      ho.predictor = hc.model;
      ho.width = width;
      ho.renderer = renderer;
      ho.log = [](const std::string&) {};
      auto host = offload::RenderHost::Start(ho);
      if (!host.ok() || !(*host)->site()->WaitConnected(5.0)) {
        spdlog::error("client-offload: render host did not start");
        rc = 1;
        break;
      }
      while ((*host)->stats().site_frames == 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
      offload::ThinClientOptions to;
      to.port = (*host)->port();
      to.token = sc.viewer_token;
      to.width = width;
      to.height = height;
      to.frames = frames;
      to.trace = *trace;
      to.trace_start_s = trace_start - 0.5;  // 0.5 s of warm-up before the measured frames
      to.receive_delay_ms = latency;
      const bool base = hc.model == pose::PredictorModel::kNone;
      to.keep_stale = base;
      struct Kept {
        pose::PoseSample pose;
        std::shared_ptr<const Mesh> mesh;  // what the host drew (taken at display: the host keeps 16)
        ImageRgb8 shown, stale;
        double border;
      };
      std::vector<Kept> kept;
      const int warmup = 30;
      to.frames = frames + warmup;
      offload::RenderHost* host_ptr = host->get();
      auto thin = offload::RunThinClient(to, [&](const offload::DisplayedFrame& d) {
        if (d.index >= warmup && (d.index - warmup) % sample_every == 0) {
          kept.push_back({d.true_pose, host_ptr->MeshForFrame(d.frame_index), d.shown, d.stale, d.black_border_fraction});
        }
      });
      const offload::RenderHostStats hs = (*host)->stats();
      ConfigResult r;
      r.mode = hc.name;
      r.latency = latency;
      if (!hs.clients.empty()) {
        r.host_render_ms = hs.clients[0].render_ms;
        r.host_horizon_ms = hs.clients[0].horizon_ms;
        r.renderer = hs.clients[0].renderer.substr(0, hs.clients[0].renderer.find(' '));
      }
      if (!thin.ok()) {
        spdlog::error("client-offload: thin client: {}", thin.status().ToString());
        rc = 1;
        break;
      }
      r.thin = *thin;
      ConfigResult stale;
      stale.mode = "stale";
      stale.latency = latency;
      stale.thin = *thin;
      reproject::RenderedView truth;
      for (const Kept& k : kept) {
        if (!k.mesh) continue;
        if (!reproject::RenderAtPose(reproject::MeshSceneRenderer(*k.mesh), k.pose.ToPose(), fov, width, height, &truth).ok()) continue;
        auto add = [&](ConfigResult& cr, const ImageRgb8& shown, double border) {
          ImageGray8 content_mask(width, height);
          for (size_t i = 0; i < content_mask.num_pixels(); ++i) {
            const uint8_t* c = shown.data() + 3 * i;
            const uint8_t* t = truth.color.data() + 3 * i;
            content_mask.data()[i] = (c[0] | c[1] | c[2] | t[0] | t[1] | t[2]) ? 255 : 0;
          }
          auto p = metrics::ComputePsnr(shown, truth.color);
          auto pc = metrics::ComputePsnr(shown, truth.color, &content_mask);
          if (p.ok()) cr.psnr.push_back(*p);
          if (pc.ok()) cr.psnr_content.push_back(*pc);
          cr.border.push_back(border);
        };
        add(r, k.shown, k.border);
        if (base) add(stale, k.stale, 0.0);
      }
      (*host)->Stop();
      if (base) results.push_back(stale);
      results.push_back(r);
      if (!args.json) {
        spdlog::info("client-offload: L={} ms {}: {} frames compared, pose->photon {:.1f} ms", latency, hc.name,
                     r.psnr.size(), thin->mean_pose_to_photon_ms);
      }
    }
    if (rc) break;
  }
  stop = true;
  publisher.join();
  (*server)->Stop();
  if (rc) return rc;

  const double net_cpu_ms = bench::ProcessCpuMs() - cpu0;
  const double net_wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  const std::string wl = args.workload + "/foreground";
  const std::string size = std::to_string(width) + "x" + std::to_string(height);
  std::map<int, double> measured_latency;  // mean pose→photon per L (base run)
  for (const ConfigResult& r : results) {
    std::map<std::string, std::string> q = {{"mode", r.mode},         {"latency_ms", std::to_string(r.latency)},
                                            {"path", "network"},      {"scene", "foreground"},
                                            {"size", size},           {"trace", "recorded"},
                                            {"method", r.mode == "stale" ? "none" : "plane"}, {"region", "frame"},
                                            {"renderer", r.renderer}};
    bench::EmitFigure("client-offload", wl, "reproj_psnr_db", bench::Mean(r.psnr), "dB", q);
    q["region"] = "content";
    bench::EmitFigure("client-offload", wl, "reproj_psnr_db", bench::Mean(r.psnr_content), "dB", q);
    q.erase("region");
    bench::EmitFigure("client-offload", wl, "black_border_fraction", bench::Mean(r.border), "1", q);
    bench::EmitFigure("client-offload", wl, "compared_frames", static_cast<double>(r.psnr.size()), "1", q);
    if (r.mode != "stale") {
      bench::EmitFigure("client-offload", wl, "pose_to_photon_ms", r.thin.mean_pose_to_photon_ms, "ms", q);
      bench::EmitFigure("client-offload", wl, "pose_to_photon_p95_ms", r.thin.p95_pose_to_photon_ms, "ms", q);
      bench::EmitFigure("client-offload", wl, "display_fps", r.thin.fps, "1/s", q);
      bench::EmitFigure("client-offload", wl, "image_fps", r.thin.received_fps, "1/s", q);
      bench::EmitFigure("client-offload", wl, "rendered_frame_kb", r.thin.mean_frame_bytes / 1024.0, "KiB", q);
      bench::EmitFigure("client-offload", wl, "reproj_ms", r.thin.mean_reproject_ms, "ms", q);
      bench::EmitFigure("client-offload", wl, "host_render_ms", r.host_render_ms, "ms", q);
      bench::EmitFigure("client-offload", wl, "host_horizon_ms", r.host_horizon_ms, "ms", q);
    }
    if (r.mode == "reprojected") measured_latency[r.latency] = r.thin.mean_pose_to_photon_ms;
    if (!args.json) {
      spdlog::info(
          "network L={:3} {:<11} PSNR {:6.2f} dB (content {:6.2f}) border {:.4f}  pose->photon {:.1f} ms  {} fps, "
          "{:.1f} images/s, {:.1f} KiB",
          r.latency, r.mode, bench::Mean(r.psnr), bench::Mean(r.psnr_content), bench::Mean(r.border),
          r.thin.mean_pose_to_photon_ms, static_cast<int>(std::lround(r.thin.fps)), r.thin.received_fps,
          r.thin.mean_frame_bytes / 1024.0);
    }
  }
  bench::EmitFigure("client-offload", wl, "network_cpu_ms", net_cpu_ms, "ms", {{"path", "network"}});
  bench::EmitFigure("client-offload", wl, "network_wall_s", net_wall_s, "s", {{"path", "network"}});

  if (sim) {
    // The simulation on the same trace segment at the latency the network path measured.
    std::vector<pose::PoseSample> segment;
    const int64_t t0 = trace->front().time_us + static_cast<int64_t>((trace_start - 1.0) * 1e6);
    const int64_t t1 = trace->front().time_us + static_cast<int64_t>((trace_start + frames / 60.0) * 1e6);
    for (const pose::PoseSample& s : *trace) {
      if (s.time_us >= t0 && s.time_us <= t1) segment.push_back(s);
    }
    reproject::OffloadSimOptions o;
    o.width = width;
    o.height = height;
    o.latencies_ms.clear();
    for (int l : latencies) o.latencies_ms.push_back(static_cast<int>(std::lround(measured_latency[l])));
    o.display_frames = std::max(2, frames / sample_every);
    o.modes = {reproject::OffloadMode::kStale, reproject::OffloadMode::kReprojected, reproject::OffloadMode::kPredicted,
               reproject::OffloadMode::kEnlarged};
    auto sim_results = reproject::SimulateOffload(
        segment, [&](int64_t) { return reproject::MeshSceneRenderer(content); }, o);
    if (!sim_results.ok()) {
      spdlog::error("client-offload: simulation: {}", sim_results.status().ToString());
      return 1;
    }
    for (size_t k = 0; k < sim_results->size(); ++k) {
      const reproject::OffloadResult& r = (*sim_results)[k];
      const int net_latency = latencies[k / o.modes.size()];
      std::map<std::string, std::string> q = {{"mode", reproject::OffloadModeName(r.mode)},
                                              {"latency_ms", std::to_string(net_latency)},
                                              {"sim_latency_ms", std::to_string(r.latency_ms)},
                                              {"path", "simulation"}, {"scene", "foreground"}, {"size", size},
                                              {"trace", "recorded"}, {"region", "frame"}};
      bench::EmitFigure("client-offload", wl, "reproj_psnr_db", r.psnr_db, "dB", q);
      q["region"] = "content";
      bench::EmitFigure("client-offload", wl, "reproj_psnr_db", r.psnr_content_db, "dB", q);
      q.erase("region");
      bench::EmitFigure("client-offload", wl, "black_border_fraction", r.black_border_fraction, "1", q);
      if (!args.json) {
        spdlog::info("simulation L={:3} (at {} ms) {:<11} PSNR {:6.2f} dB (content {:6.2f}) border {:.4f}", net_latency,
                     r.latency_ms, reproject::OffloadModeName(r.mode), r.psnr_db, r.psnr_content_db,
                     r.black_border_fraction);
      }
    }
  }
  return 0;
}

}  // namespace

bench::BenchFn SetupClientOffload(CLI::App& app) {
  bench::DropCommonOptions(app, {"--repeats"});  // this benchmark does not read them
  auto o = std::make_shared<OffloadArgs>();
  app.add_option("--latencies", o->latencies, "network latencies, comma-separated ms (0..1000)")->capture_default_str();
  app.add_option("--size", o->size, "display size WxH")->capture_default_str();
  app.add_option("--trace", o->trace_path, "head trace CSV")->capture_default_str();
  app.add_option("--trace-start", o->trace_start, "start in the trace, s")->capture_default_str();
  app.add_option("--sample-every", o->sample_every, "evaluate every N frames")->capture_default_str();
  app.add_option("--renderer", o->renderer, "host renderer: cpu, gl or auto")->capture_default_str();
  app.add_flag("--no-sim{false}", o->sim, "skip the simulation at the measured latency");
  return [o](const bench::BenchArgs& args) { return RunClientOffloadBench(args, *o); };
}

HOLO_REGISTER_BENCH_OPTIONS("client-offload",
                            "networked render offload over loopback: PSNR stale/reprojected/predicted/enlarged vs "
                            "ground truth, black border, pose->photon latency (and the simulation at the measured latency)",
                            SetupClientOffload);
