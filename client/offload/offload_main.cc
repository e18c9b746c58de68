#include "client/offload/offload_main.h"

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>

#include "client/offload/render_host.h"
#include "client/offload/thin_client.h"
#include "client/pose/head_motion.h"
#include "client/pose/trace.h"
#include "common/log.h"
#include "net/server_config.h"

namespace holo::offload {
namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

std::string EnvOr(const char* name, const std::string& fallback) {
  const char* v = std::getenv(name);
  return v ? std::string(v) : fallback;
}

}  // namespace

int RenderHostMain(int argc, char** argv) {
  CLI::App app{"holoport-client --render-host: render a site's stream for thin clients (docs/offload.md)"};
  holo::AddLogLevelOption(app);
  bool render_host = false;
  std::string connect, listen = "127.0.0.1:7300", token, thin_token, predict = "kalman", renderer = "auto";
  RenderHostOptions o;
  double seconds = 0;
  app.add_flag("--render-host", render_host, "run as a render host")->required();
  app.add_option("--connect", connect, "site server HOST:PORT")->required();
  app.add_option("--token", token, "site viewer token (default: env HOLO_VIEWER_TOKEN); also the thin clients' token");
  app.add_option("--thin-token", thin_token, "token thin clients must present (default: --token)");
  app.add_option("--listen", listen, "HOST:PORT for thin clients")->capture_default_str();
  app.add_option("--margin", o.margin, "FOV margin: tangents x (1 + margin)")->capture_default_str();
  app.add_option("--predict", predict, "pose predictor: none, cv, kalman")->capture_default_str();
  app.add_option("--width", o.width, "pixels across the thin client's horizontal FOV")->capture_default_str();
  app.add_option("--quality", o.encode.jpeg_quality, "JPEG quality")->capture_default_str();
  app.add_option("--extra-horizon-ms", o.extra_horizon_ms, "added to the measured prediction horizon")->capture_default_str();
  app.add_flag("--stereo", o.stereo, "render both eyes (streams 1 and 2); default mono");
  app.add_option("--renderer", renderer, "cpu, gl (OpenGL via headless EGL) or auto (gl if available)")->capture_default_str();
  app.add_option("--ipd", o.ipd_m, "--stereo: interpupillary distance, m")->capture_default_str();
  app.add_option("--max-thin-clients", o.max_thin_clients, "thin clients served at once")->capture_default_str();
  app.add_option("--seconds", seconds, "stop after this long (0: until Ctrl-C)")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  if (token.empty()) token = EnvOr("HOLO_VIEWER_TOKEN", "");
  if (token.empty()) {
    spdlog::error("render-host: --token (or env HOLO_VIEWER_TOKEN) is required");
    return 2;
  }
  if (auto s = net::ParseHostPort(connect, &o.site.host, &o.site.port); !s.ok()) {
    spdlog::error("render-host: --connect: {}", s.ToString());
    return 2;
  }
  if (auto s = net::ParseHostPort(listen, &o.listen_host, &o.listen_port); !s.ok()) {
    spdlog::error("render-host: --listen: {}", s.ToString());
    return 2;
  }
  auto model = pose::ParsePredictorModel(predict);
  if (!model.ok()) {
    spdlog::error("render-host: --predict: {}", model.status().ToString());
    return 2;
  }
  o.predictor = *model;
  auto r = ParseHostRenderer(renderer);
  if (!r.ok()) {
    spdlog::error("render-host: --renderer: {}", r.status().ToString());
    return 2;
  }
  o.renderer = *r;
  o.site.token = token;
  o.site.name = "render-host";
  o.token = thin_token;
  auto host = RenderHost::Start(o);
  if (!host.ok()) {
    spdlog::error("render-host: {}", host.status().ToString());
    return 1;
  }
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  const auto t0 = std::chrono::steady_clock::now();
  auto last = t0;
  while (!g_stop) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const auto now = std::chrono::steady_clock::now();
    if (seconds > 0 && now - t0 > std::chrono::duration<double>(seconds)) break;
    if (now - last > std::chrono::seconds(5)) {
      last = now;
      const RenderHostStats s = (*host)->stats();
      spdlog::info("render-host: site frames {} (last {}), thin clients accepted {} refused {}", s.site_frames,
                   s.last_site_frame, s.thin_accepted, s.thin_refused);
      for (const ThinClientStats& c : s.clients) {
        if (!c.open) continue;
        spdlog::info(
            "  thin client {} '{}': poses {}, frames {}, render {:.1f} ms, encode {:.1f} ms, rtt {:.1f} ms, "
            "horizon {:.1f} ms, renderer {}",
            c.id, c.name, c.poses, c.frames_sent, c.render_ms, c.encode_ms, c.rtt_ms, c.horizon_ms, c.renderer);
      }
    }
  }
  (*host)->Stop();
  return 0;
}

int ThinClientMain(int argc, char** argv) {
  CLI::App app{"holoport-client --thin: a thin client of a render host (docs/offload.md)"};
  holo::AddLogLevelOption(app);
  std::string thin, trace_path, method = "plane", motion = "lookaround", size = "640x360";
  ThinClientOptions o;
  bool headless = false;
  double view_distance = 2.6;
  uint64_t seed = 1;
  app.add_option("--thin", thin, "render host HOST:PORT")->required();
  app.add_option("--token", o.token, "render host token (default: env HOLO_VIEWER_TOKEN)");
  app.add_option("--pose-trace", trace_path, "head trace CSV (time_s,x,y,z,yaw,pitch,roll); default: synthetic");
  app.add_option("--motion", motion, "synthetic head motion: lookaround or walk")->capture_default_str();
  app.add_option("--seed", seed, "synthetic head motion seed")->capture_default_str();
  app.add_option("--view-distance", view_distance, "trace origin placed this far on -x from the studio centre (m)")->capture_default_str();
  app.add_option("--trace-start", o.trace_start_s, "trace time at the first display tick (s)")->capture_default_str();
  app.add_flag("--headless", headless, "no window (the only mode: PNGs into --out)");
  app.add_option("--frames", o.frames, "display frames to show")->capture_default_str();
  app.add_option("--out", o.out_dir, "folder for PNGs (every --png-every) and stats.json");
  app.add_option("--png-every", o.png_every, "write every n-th displayed frame")->capture_default_str();
  app.add_option("--size", size, "display size WxH")->capture_default_str();
  app.add_option("--hfov", o.hfov_deg, "horizontal FOV, degrees")->capture_default_str();
  app.add_option("--rate", o.rate_hz, "display and pose rate, Hz")->capture_default_str();
  app.add_option("--method", method, "reprojection: none, rotation, plane, depth")->capture_default_str();
  app.add_option("--recv-delay-ms", o.receive_delay_ms, "simulated network delay on receive, ms")->capture_default_str();
  app.add_flag("--stereo", o.stereo, "show both eyes (the render host must run --stereo); PNGs side by side");
  app.add_option("--ipd", o.ipd_m, "--stereo: interpupillary distance, m")->capture_default_str();
  app.add_option("--name", o.name, "name shown in the render host's log")->capture_default_str();
  for (int i = 1; i < argc; ++i) {  // "--thin --help": help, not a host named --help
    if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") {
      std::printf("%s", app.help().c_str());
      return 0;
    }
  }
  CLI11_PARSE(app, argc, argv);
  if (!headless) spdlog::warn("thin: no window is implemented; running headless");
  if (o.token.empty()) o.token = EnvOr("HOLO_VIEWER_TOKEN", "");
  if (auto s = net::ParseHostPort(thin, &o.host, &o.port); !s.ok()) {
    spdlog::error("thin: --thin: {}", s.ToString());
    return 2;
  }
  if (std::sscanf(size.c_str(), "%dx%d", &o.width, &o.height) != 2) {
    spdlog::error("thin: --size must be WxH, got '{}'", size);
    return 2;
  }
  auto m = reproject::ParseReprojectMethod(method);
  if (!m.ok()) {
    spdlog::error("thin: --method: {}", m.status().ToString());
    return 2;
  }
  o.method = *m;
  if (!trace_path.empty()) {
    auto t = pose::ReadHeadTrace(trace_path);
    if (!t.ok()) {
      spdlog::error("thin: {}", t.status().ToString());
      return 1;
    }
    o.trace = *t;
  } else {
    pose::HeadMotionOptions hm;
    if (motion == "walk") {
      hm.kind = pose::HeadMotionKind::kWalk;
    } else if (motion != "lookaround") {
      spdlog::error("thin: --motion must be lookaround or walk, got '{}'", motion);
      return 2;
    }
    hm.seed = seed;
    hm.duration_s = 60;
    auto t = pose::GenerateHeadMotion(hm);
    if (!t.ok()) {
      spdlog::error("thin: {}", t.status().ToString());
      return 1;
    }
    o.trace = *t;
  }
  for (pose::PoseSample& s : o.trace) s.position += Eigen::Vector3d(-view_distance, 0, 0);
  auto r = RunThinClient(o, [&](const DisplayedFrame& d) {
    if (d.index % 60 == 0) {
      spdlog::info("thin: {}/{} displayed, content frame {}, pose->photon {:.1f} ms, border {:.3f}", d.index, o.frames,
                   d.frame_index, d.pose_to_photon_ms, d.black_border_fraction);
    }
  });
  if (!r.ok()) {
    spdlog::error("thin: {}", r.status().ToString());
    return 1;
  }
  std::printf("thin: %d frames displayed at %.1f fps (%d distinct images, %.1f/s), pose->photon %.1f ms mean (p95 %.1f), "
              "reprojection %.1f ms, border %.4f, %.1f KiB/frame\n",
              r->displayed, r->fps, r->frames_used, r->received_fps, r->mean_pose_to_photon_ms, r->p95_pose_to_photon_ms,
              r->mean_reproject_ms, r->mean_black_border, r->mean_frame_bytes / 1024.0);
  return 0;
}

}  // namespace holo::offload
