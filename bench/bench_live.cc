// holoport-bench live: the product end to end on this machine.
//
//   holoport-bench live --workload S8-QVGA|S8-VGA [--content fused|temporal|truth] [--seconds S] [--json]
//
// A site (holoport-server, its own process) runs the real capture pipeline
// on pre-rendered pod frames paced like cameras at 30 fps (the studio's
// rendering is not the site's work): segmentation, fusion (per frame, or
// temporal), the stream mesh, texturing, G1 + C1 encoding, the session
// server. On loopback, in this process: one viewer that decodes *and
// renders* (headless GL, projective texturing at --width × --height, a
// slowly orbiting camera) and --decoders viewers that only decode, each
// with its own io thread. Everything shares the machine's cores, as a
// two-party call on one box would.
//
// Before the live run, a serial run of the same site (one stage at a time)
// gives the CPU-ms of each stage. After it, frames kept by the rendering
// viewer are scored against the studio's ground truth: Chamfer distance of
// the decoded mesh, and PSNR/SSIM of the viewer's render from cameras no pod
// has. The kept frames show the same studio frames in every run (those
// nearest to --quality-frames points spread over the looped content), so
// runs compare picture for picture.
//
// Figures (JSON lines, every one with "content"): site_fps, site_cpu_ms per
// stage (serial run) and total (live run: the site process's CPU per
// published frame), viewer_fps per viewer kind (new frames decoded /
// displayed per second, not redraws), latency_p50_ms / latency_p99_ms
// from the pods' acquisition to decoded and to displayed ("at"), mbps per
// viewer, the rendering viewer's viewer_received_fps and viewer_decode_ms
// per received frame (geometry, color), triangles, chamfer_mm and
// novel_view_psnr_db / novel_view_ssim at the viewer. The site also publishes its person's voice (--voice synthetic:
// syllables at footsteps, knocks at ball bounces, stamped on the pictures'
// capture clock); every viewer plays it in sync with the pictures
// (client/net/site_av_sync.h) and av_offset_ms (p1, p50, p99: voice playout
// minus picture display for the same capture instant, positive = voice late)
// is reported per viewer kind, with the sync delay given to each stream.
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <netinet/in.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bench.h"
#include "bench_process.h"
#include "client/net/av_sync_cli.h"
#include "client/net/site_av_sync.h"
#include "client/render/gl_context.h"
#include "client/render/renderer.h"
#include "common/clock.h"
#include "common/log.h"
#include "common/metrics/image_metrics.h"
#include "common/metrics/mesh_distance.h"
#include "common/pose.h"
#include "net/site_client.h"
#include "net/wire_message.h"
#include "server/capture/prerendered.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#include "texture/novel_view.h"

namespace holo::bench {
namespace {

constexpr char kLivePublisherToken[] = "live-bench-publisher";
constexpr char kLiveViewerToken[] = "live-bench-viewer";

struct LiveOptions {
  std::string content = "fused";  // fused | temporal | truth
  double seconds = 20;
  double warmup_s = 4;
  int decoders = 4;
  bool render = true;
  int viewer_quality = 10;  // the rendering viewer's Control set quality (0..4: the reduced layer)
  int width = 960, height = 540;
  std::string color = "projective";  // rendering viewer: projective | projective-fragment
  int prerender = 60;
  int serial_frames = 30;
  int quality_frames = 6;
  std::string site_binary;
  std::string keep_dir;  // keep the site's logs here
  std::vector<std::string> site_args;  // passed on to holoport-server
  std::string voice = "synthetic";     // the site's --voice
  double delay_voice_ms = 0, delay_picture_ms = 0;  // injected at every viewer
  audio::AvSyncOptions sync;                         // the viewers' lip sync bounds
  std::string av_trace;                              // CSV of every offset measured (renderer, decoder 0)
};

// A child process with stdout and stderr sent to files.
struct Child {
  pid_t pid = -1;
  static StatusOr<Child> Spawn(const std::vector<std::string>& argv, const std::string& log_path) {
    const pid_t pid = SpawnLogged(argv, log_path);
    if (pid < 0) return Unavailable("fork failed");
    Child c;
    c.pid = pid;
    return c;
  }
  bool Running() const {
    if (pid <= 0) return false;
    int status = 0;
    return waitpid(pid, &status, WNOHANG) == 0;
  }
  // SIGTERM, then SIGKILL after `grace_s`; returns the exit status.
  int Stop(double grace_s = 10) {
    const int status = StopProcess(pid, SIGTERM, grace_s);
    pid = -1;
    return status;
  }
  // Waits for a normal exit (the serial run ends by itself).
  int Wait() {
    int status = 0;
    if (pid > 0) waitpid(pid, &status, 0);
    pid = -1;
    return status;
  }
};

std::vector<std::string> SiteArgs(const LiveOptions& o, const std::string& workload, uint16_t port,
                                  const std::string& stats, bool serial) {
  std::vector<std::string> a = {o.site_binary, "--source", "synthetic", "--workload", workload, "--listen",
                                "127.0.0.1:" + std::to_string(port), "--publisher-token", kLivePublisherToken,
                                "--viewer-token", kLiveViewerToken, "--stats", stats, "--pace", "30"};
  a.insert(a.end(), o.site_args.begin(), o.site_args.end());
  if (!serial) a.insert(a.end(), {"--voice", o.voice});
  if (o.content == "truth") {
    a.insert(a.end(), {"--truth-mesh", "--truth-loop", std::to_string(o.prerender), "-n", "-1"});
    return a;
  }
  a.insert(a.end(), {"--prerender", std::to_string(serial ? o.serial_frames : o.prerender)});
  if (o.content == "temporal") a.push_back("--temporal");
  if (serial) {
    a.insert(a.end(), {"--serial", "-n", std::to_string(o.serial_frames)});
  } else {
    a.insert(a.end(), {"-n", "-1"});
  }
  return a;
}

// What a viewer saw of one frame.
struct FrameRecord {
  int64_t frame_index = 0;
  double latency_decoded_ms = 0;
  double latency_displayed_ms = -1;
  int64_t at_us = 0;  // when decoded (decoders) or displayed (renderer)
};

struct ViewerLog {
  std::mutex mu;
  std::vector<FrameRecord> frames;
  uint64_t bytes_at_start = 0, bytes_at_end = 0;
};

struct KeptFrame {
  int64_t frame_index = 0;
  Mesh mesh;
  std::vector<net::DecodedImage> images;
};

// Hands a received frame's pod images to the renderer with the decoder's
// masks, as holoport-client does (C1/V1 images are black outside them);
// without masks when any is missing or of another size. Unavailable when a
// pod's image is missing.
Status SetDecodedPodImages(render::Renderer* renderer, const Rig& rig, const std::vector<net::DecodedImage>& decoded) {
  std::vector<const ImageRgb8*> images(rig.pods.size(), nullptr);
  std::vector<const ImageGray8*> masks(rig.pods.size(), nullptr);
  bool all_masks = true;
  for (const auto& d : decoded) {
    if (d.pod_id >= images.size()) continue;
    images[d.pod_id] = &d.image;
    masks[d.pod_id] = &d.mask;
    all_masks = all_masks && d.mask.width() == d.image.width() && d.mask.height() == d.image.height();
  }
  for (const auto* p : images) {
    if (!p) return Unavailable("a pod's image is missing");
  }
  return renderer->SetPodImages(rig, images, all_masks ? masks : std::vector<const ImageGray8*>{});
}

StatusOr<std::unique_ptr<net::SiteClient>> StartViewer(uint16_t port, const std::string& name,
                                                       net::ClientCallbacks cb, int quality = 10) {
  net::ClientOptions o;
  o.quality = quality;
  o.port = port;
  o.token = kLiveViewerToken;
  o.name = name;
  o.subscribe = net::kSubscribeAll;
  o.decode = true;
  o.backoff_initial_s = 0.2;
  o.backoff_max_s = 1.0;
  o.connect_timeout_s = 60;
  return net::SiteClient::Start(o, std::move(cb));
}

// The orbiting viewer camera at time t (a head that moves).
CameraModel ViewerCamera(int width, int height, double t) {
  const float a = static_cast<float>(0.6 + 0.25 * std::sin(0.5 * t));
  CameraModel c;
  c.intrinsics = Intrinsics::FromFov(width, height, 60.0);
  c.world_from_camera = LookAt(Eigen::Vector3f(2.2f * std::cos(a), 2.2f * std::sin(a), 1.5f), Eigen::Vector3f(0, 0, 1.0f));
  return c;
}

int Run(const BenchArgs& args, LiveOptions o) {
  if (args.frames > 0) o.seconds = args.frames / 30.0;
  if (o.site_binary.empty()) o.site_binary = SelfDir() + "/holoport-server";
  if (access(o.site_binary.c_str(), X_OK) != 0) {
    spdlog::error("live: site program {} not found (build holoport-server or pass --site)", o.site_binary);
    return 2;
  }
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("live: {}", workload.status().ToString());
    return 2;
  }
  const std::string& wl = workload->name;
  // The figures' content says what the site made: --temporal given through
  // --site-arg is temporal content (the figures would say "fused" otherwise).
  const bool temporal_arg = o.content != "temporal" &&
                            std::find(o.site_args.begin(), o.site_args.end(), "--temporal") != o.site_args.end();
  if (temporal_arg && o.content == "truth") {
    spdlog::error("live: --site-arg=--temporal with --content truth: the site streams the studio's meshes, nothing "
                  "is fused");
    return 2;
  }
  if (temporal_arg) spdlog::warn("live: --site-arg=--temporal: the figures say content temporal (--content temporal)");
  const std::string content = temporal_arg ? "temporal" : o.content;
  auto progress = [&](const std::string& s) {
    if (!args.json) spdlog::info("live: {}", s);
  };
  std::string dir = o.keep_dir;
  if (dir.empty()) {
    char tmpl[] = "/tmp/holoport-live-XXXXXX";
    if (!mkdtemp(tmpl)) {
      spdlog::error("live: cannot make a temporary directory");
      return 1;
    }
    dir = tmpl;
  } else {
    std::string cmd = "mkdir -p '" + dir + "'";
    if (std::system(cmd.c_str()) != 0) return 1;
  }
  auto emit = [&](const std::string& metric, double value, const std::string& unit,
                  std::map<std::string, std::string> q = {}) {
    q["content"] = content;
    EmitFigure("live", wl, metric, value, unit, q);
  };

  // 1. Serial run: CPU-ms per stage, one stage at a time.
  if (o.serial_frames > 0 && content != "truth") {
    progress("serial run of the site (" + std::to_string(o.serial_frames) + " frames) for CPU per stage");
    const uint16_t port = FreeTcpPort();
    const std::string stats = dir + "/serial_stats.jsonl";
    auto child = Child::Spawn(SiteArgs(o, wl, port, stats, /*serial=*/true), dir + "/serial_site.log");
    if (!child.ok()) {
      spdlog::error("live: {}", child.status().ToString());
      return 1;
    }
    const int st = child->Wait();
    if (!WIFEXITED(st) || WEXITSTATUS(st) != 0) {
      spdlog::error("live: the serial site run failed (see {}/serial_site.log)", dir);
      return 1;
    }
    std::map<std::string, std::vector<double>> cpu;
    for (const auto& j : ReadJsonLines(stats)) {
      if (!j.contains("triangles") || !j.contains("segment_cpu_ms")) continue;
      double total = 0;
      for (const char* stage : {"acquire", "segment", "fuse", "mesh", "simplify", "texture", "encode_geometry",
                                "encode_color"}) {
        const std::string key = std::string(stage) + "_cpu_ms";
        const double v = j.value(key, 0.0);
        cpu[stage].push_back(v);
        total += v;
      }
      cpu["total"].push_back(total);
    }
    if (cpu["total"].size() < 4) {
      spdlog::error("live: the serial site run gave {} frames", cpu["total"].size());
      return 1;
    }
    // The first frames warm caches and allocate: drop them.
    for (auto& [stage, v] : cpu) {
      v.erase(v.begin(), v.begin() + std::min<size_t>(3, v.size() / 4));
      emit("site_cpu_ms", Median(v), "ms", {{"stage", stage}, {"run", "serial"}});
    }
  }

  // 2. The live run.
  const uint16_t port = FreeTcpPort();
  const std::string stats_path = dir + "/site_stats.jsonl";
  progress("starting the site (" + content + ", " + wl + ") on port " + std::to_string(port));
  auto site = Child::Spawn(SiteArgs(o, wl, port, stats_path, /*serial=*/false), dir + "/site.log");
  if (!site.ok()) {
    spdlog::error("live: {}", site.status().ToString());
    return 1;
  }
  struct Guard {
    Child* c;
    ~Guard() {
      if (c->pid > 0) c->Stop(5);
    }
  } guard{&*site};

  std::atomic<bool> measuring{false}, stop{false};
  // Every viewer plays the site's voice and shows (or, decoding only, takes)
  // its pictures in sync with it.
  auto sync_options = [&] {
    net::SiteAvSyncOptions so;
    so.sync = o.sync;
    so.sync.keep_trace = !o.av_trace.empty();
    so.voice.inject_delay_ms = o.delay_voice_ms;
    so.inject_picture_delay_ms = o.delay_picture_ms;
    return so;
  };
  std::vector<std::unique_ptr<ViewerLog>> logs;
  std::vector<std::unique_ptr<net::SiteClient>> decoders;
  std::vector<std::unique_ptr<net::SiteAvSync>> decoder_syncs;
  std::vector<std::thread> decoder_threads;
  struct Joiner {
    std::atomic<bool>* stop;
    std::vector<std::thread>* threads;
    ~Joiner() {
      *stop = true;
      for (auto& t : *threads)
        if (t.joinable()) t.join();
    }
  } decoder_joiner{&stop, &decoder_threads};
  for (int i = 0; i < o.decoders; ++i) {
    logs.push_back(std::make_unique<ViewerLog>());
    auto c = StartViewer(port, "decoder-" + std::to_string(i), {});
    if (!c.ok()) {
      spdlog::error("live: {}", c.status().ToString());
      return 1;
    }
    auto sy = net::SiteAvSync::Start(c->get(), sync_options());
    if (!sy.ok()) {
      spdlog::error("live: {}", sy.status().ToString());
      return 1;
    }
    decoders.push_back(std::move(*c));
    decoder_syncs.push_back(std::move(*sy));
    // A decoding viewer shows a picture the moment it is decoded and due.
    decoder_threads.emplace_back([log = logs.back().get(), sync = decoder_syncs.back().get(), &measuring, &stop] {
      net::ReceivedFrame f;
      while (!stop) {
        int64_t ready = 0;
        if (!sync->NextFrame(&f, 0.1, &ready)) continue;
        const int64_t now = net::WallUs();
        sync->Displayed(f, now, now);
        if (!measuring || !f.has_mesh) continue;
        FrameRecord r;
        r.frame_index = f.frame_index;
        r.at_us = now;
        // Decoded (taken from the client), before any hold for the voice.
        r.latency_decoded_ms = f.latency_ms + static_cast<double>(ready - f.received_us) * 1e-3;
        std::lock_guard<std::mutex> l(log->mu);
        log->frames.push_back(r);
      }
    });
  }
  ViewerLog render_log;
  std::unique_ptr<net::SiteClient> render_client;
  std::vector<KeptFrame> kept;
  // The studio frame a frame index shows (the site loops its pre-rendered
  // frames forward and back; the truth stream loops forward).
  auto content_frame = [&](int64_t k) {
    return content == "truth" ? k % o.prerender : LoopContent(k, o.prerender);
  };
  struct QualitySlot {
    int64_t target = 0;
    int64_t distance = std::numeric_limits<int64_t>::max();
    KeptFrame frame;
  };
  std::vector<QualitySlot> slots(static_cast<size_t>(std::max(0, o.quality_frames)));
  for (size_t i = 0; i < slots.size(); ++i) {
    slots[i].target = static_cast<int64_t>((2 * i + 1) * static_cast<size_t>(o.prerender) / (2 * slots.size()));
  }
  std::vector<double> render_ms, render_cpu_ms;
  double render_thread_cpu_ms = 0;
  Status render_status;
  std::atomic<int64_t> render_frames_seen{0};
  std::thread render_thread;
  // The GL objects live on the render thread; quality scoring happens there too, after the run.
  std::mutex kept_mu;
  std::unique_ptr<net::SiteAvSync> render_sync;
  if (o.render) {
    auto c = StartViewer(port, "renderer", {}, o.viewer_quality);
    if (!c.ok()) {
      spdlog::error("live: {}", c.status().ToString());
      return 1;
    }
    render_client = std::move(*c);
    auto sy = net::SiteAvSync::Start(render_client.get(), sync_options());
    if (!sy.ok()) {
      spdlog::error("live: {}", sy.status().ToString());
      return 1;
    }
    render_sync = std::move(*sy);
    render_thread = std::thread([&] {
      auto ctx = render::CreateHeadlessContext();
      if (!ctx.ok()) {
        render_status = ctx.status();
        return;
      }
      auto renderer = render::Renderer::Create();
      auto target = render::OffscreenTarget::Create(o.width, o.height);
      if (!renderer.ok() || !target.ok()) {
        render_status = !renderer.ok() ? renderer.status() : target.status();
        return;
      }
      (*target)->Bind();
      render::RenderSettings settings;
      settings.mode = render::ColorMode::kProjective;
      settings.projective.bake = o.color == "projective";
      const auto t0 = std::chrono::steady_clock::now();
      net::ReceivedFrame rf;
      while (!stop) {
        // The newest picture due now (held while its voice is later).
        if (!render_sync->NextFrame(&rf, 0.1)) continue;
        if (!rf.has_mesh || rf.mesh.positions.empty()) continue;
        const double cpu0 = holo::ThreadCpuTimeMs();
        const auto r0 = std::chrono::steady_clock::now();
        const int64_t render_start = net::WallUs();
        auto rig = render_client->rig();
        Status s = (*renderer)->SetRemoteMesh(rf.mesh);
        if (s.ok() && rig && rf.has_color) {
          const Status pods = SetDecodedPodImages(renderer->get(), *rig, rf.images);
          if (pods.code() != StatusCode::kUnavailable) s = pods;  // a frame without every pod: keep the last images
        }
        if (!s.ok()) {
          render_status = s;
          return;
        }
        const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        const render::Viewport vp{0, 0, o.width, o.height};
        s = (*renderer)->Render(ViewerCamera(o.width, o.height, t), settings, vp);
        if (!s.ok()) {
          render_status = s;
          return;
        }
        render::FinishGl();
        const int64_t shown = net::WallUs();
        render_sync->Displayed(rf, render_start, shown);
        ++render_frames_seen;
        if (!measuring) continue;
        render_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - r0).count());
        render_cpu_ms.push_back(holo::ThreadCpuTimeMs() - cpu0);
        FrameRecord r;
        r.frame_index = rf.frame_index;
        r.at_us = shown;
        r.latency_decoded_ms = rf.latency_ms;
        r.latency_displayed_ms = rf.latency_ms + static_cast<double>(shown - rf.received_us) * 1e-3;
        {
          std::lock_guard<std::mutex> l(render_log.mu);
          render_log.frames.push_back(r);
        }
        if (rf.has_color) {
          // Each slot keeps the rendered frame whose studio frame is nearest
          // its target (the first one at the target stays).
          const int64_t c = content_frame(rf.frame_index);
          for (QualitySlot& slot : slots) {
            const int64_t d = std::abs(c - slot.target);
            if (d >= slot.distance) continue;
            std::lock_guard<std::mutex> l(kept_mu);
            slot.distance = d;
            slot.frame = {rf.frame_index, rf.mesh, rf.images};
          }
        }
      }
      render_thread_cpu_ms = holo::ThreadCpuTimeMs();
    });
  }

  // Wait until every viewer has frames (the site pre-renders and learns its background first).
  progress("waiting for the site's first frames");
  const auto start_wait = std::chrono::steady_clock::now();
  for (;;) {
    bool all = true;
    for (auto& d : decoders) all = all && d->stats().frames_received > 0;
    if (render_client) all = all && render_frames_seen > 0;
    if (all) break;
    if (!site->Running()) {
      spdlog::error("live: the site exited early (see {}/site.log)", dir);
      stop = true;
      if (render_thread.joinable()) render_thread.join();
      return 1;
    }
    if (!render_status.ok()) break;
    if (std::chrono::steady_clock::now() - start_wait > std::chrono::seconds(180)) {
      spdlog::error("live: no frames after 180 s (see {}/site.log)", dir);
      stop = true;
      if (render_thread.joinable()) render_thread.join();
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  std::this_thread::sleep_for(std::chrono::duration<double>(o.warmup_s));
  progress("measuring for " + std::to_string(o.seconds) + " s");
  // Frames the site has published so far (its per-frame stats lines).
  auto count_site_frames = [&] {
    int64_t n = 0;
    for (const auto& j : ReadJsonLines(stats_path)) n += j.contains("triangles");
    return n;
  };
  const int64_t site_frames0 = count_site_frames();
  const double site_cpu0 = ProcessCpuMsOf(site->pid);
  const double self_cpu0 = ProcessCpuMs();
  std::vector<uint64_t> bytes0;
  for (auto& d : decoders) bytes0.push_back(d->stats().bytes_received);
  const net::ClientStats render_stats0 = render_client ? render_client->stats() : net::ClientStats{};
  const auto w0 = std::chrono::steady_clock::now();
  for (auto& sy : decoder_syncs) sy->sync().ResetStats();
  if (render_sync) render_sync->sync().ResetStats();
  measuring = true;
  std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
  measuring = false;
  std::vector<audio::AvSyncStats> dec_av;
  for (auto& sy : decoder_syncs) dec_av.push_back(sy->stats());
  if (!o.av_trace.empty()) {
    std::ofstream csv(o.av_trace);
    csv << "viewer,display_s,capture_s,stream,picture_delay_ms,hold_ms,voice_delay_ms,voice_natural_ms,"
           "voice_target_ms,offset_ms\n";
    const int64_t t0 = net::WallUs() - static_cast<int64_t>(o.seconds * 1e6);
    auto dump = [&](const char* viewer, const net::SiteAvSync& sy) {
      for (const auto& p : sy.sync().trace())
        csv << viewer << ',' << (p.display_us - t0) / 1e6 << ',' << (p.capture_us - t0) / 1e6 << ',' << p.stream << ','
            << p.picture_delay_ms << ',' << p.hold_ms << ',' << p.voice_delay_ms << ',' << p.voice_natural_ms << ','
            << p.voice_target_ms << ',' << p.offset_ms << '\n';
    };
    if (render_sync) dump("render", *render_sync);
    if (!decoder_syncs.empty()) dump("decode", *decoder_syncs.front());
    if (!csv) spdlog::error("live: could not write {}", o.av_trace);
  }
  const audio::AvSyncStats render_av = render_sync ? render_sync->stats() : audio::AvSyncStats{};
  std::vector<net::RemoteVoicesStats> voice_stats;
  for (auto& sy : decoder_syncs) voice_stats.push_back(sy->voice_stats());
  if (render_sync) voice_stats.push_back(render_sync->voice_stats());
  const double window_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
  const double site_cpu1 = ProcessCpuMsOf(site->pid);
  const double self_cpu1 = ProcessCpuMs();
  const int64_t site_frames1 = count_site_frames();
  std::vector<uint64_t> bytes1;
  for (auto& d : decoders) bytes1.push_back(d->stats().bytes_received);
  const net::ClientStats render_stats1 = render_client ? render_client->stats() : net::ClientStats{};

  // Site figures.
  const double site_frames = static_cast<double>(site_frames1 - site_frames0);
  emit("site_fps", site_frames / window_s, "1/s");
  if (site_frames > 0) emit("site_cpu_ms", (site_cpu1 - site_cpu0) / site_frames, "ms", {{"stage", "total"}, {"run", "live"}});
  std::vector<double> tris, latency_site, geometry_bytes, color_bytes;
  for (const auto& j : ReadJsonLines(stats_path)) {
    if (!j.contains("triangles")) continue;
    tris.push_back(j.value("triangles", 0.0));
    latency_site.push_back(j.value("encoded_latency_ms", j.value("latency_ms", 0.0)));
    geometry_bytes.push_back(j.value("geometry_bytes", 0.0));
    color_bytes.push_back(j.value("color_bytes", 0.0));
  }
  // The site's voice thread (synthesis, Opus, publishing): CPU per 20 ms frame.
  {
    double voice_cpu = 0, voice_frames = 0;
    for (const auto& j : ReadJsonLines(stats_path)) {
      if (!j.contains("voice_cpu_ms")) continue;
      voice_cpu = j.value("voice_cpu_ms", 0.0);
      voice_frames = j.value("voice_frames", 0.0);
    }
    if (voice_frames > 0)
      emit("site_voice_cpu_ms", voice_cpu / voice_frames, "ms",
           {{"per", "20 ms voice frame"}, {"frames", std::to_string(static_cast<int64_t>(voice_frames))}});
  }
  emit("triangles", Median(tris), "count");
  emit("geometry_bytes", Median(geometry_bytes), "B");
  emit("color_bytes", Median(color_bytes), "B");
  if (content != "truth") emit("site_latency_ms", Median(latency_site), "ms", {{"at", "encoded"}});

  // Viewer figures.
  std::vector<double> dec_fps, mbps;
  std::vector<float> dec_lat;
  for (size_t i = 0; i < decoders.size(); ++i) {
    std::lock_guard<std::mutex> l(logs[i]->mu);
    dec_fps.push_back(static_cast<double>(logs[i]->frames.size()) / window_s);
    for (const auto& r : logs[i]->frames) dec_lat.push_back(static_cast<float>(r.latency_decoded_ms));
    mbps.push_back(static_cast<double>(bytes1[i] - bytes0[i]) * 8.0 / (window_s * 1e6));
  }
  if (!decoders.empty()) {
    emit("viewer_fps", Median(dec_fps), "1/s", {{"viewer", "decode"}, {"of", std::to_string(decoders.size())}});
    emit("viewer_fps_min", *std::min_element(dec_fps.begin(), dec_fps.end()), "1/s", {{"viewer", "decode"}});
    emit("latency_p50_ms", metrics::Percentile(dec_lat, 50), "ms", {{"at", "decoded"}, {"viewer", "decode"}});
    emit("latency_p99_ms", metrics::Percentile(dec_lat, 99), "ms", {{"at", "decoded"}, {"viewer", "decode"}});
    emit("mbps", Median(mbps), "Mbit/s", {{"viewer", "decode"}});
  }
  // Voice and picture in sync, per viewer kind.
  const std::string sync_state = o.sync.enabled ? "on" : "off";
  auto emit_av = [&](const std::string& viewer, const std::vector<audio::AvSyncStats>& v) {
    int64_t offsets = 0, early = 0, late = 0, pictures = 0, held = 0, capped = 0;
    std::vector<double> p50, voice_delay, picture_hold, unsynced;
    double p99 = -1e9, p1 = 1e9;
    for (const auto& a : v) {
      if (a.offsets == 0) continue;
      offsets += a.offsets;
      early += a.offsets_early;
      late += a.offsets_late;
      pictures += a.pictures;
      held += a.pictures_held;
      capped += a.voice_delay_capped + a.pictures_hold_capped;
      p50.push_back(a.av_offset_ms_p50);
      p99 = std::max(p99, a.av_offset_ms_p99);  // the worst viewer's
      p1 = std::min(p1, a.av_offset_ms_p1);
      voice_delay.push_back(a.voice_sync_delay_ms);
      unsynced.push_back(a.unsynced_offset_ms_p50);
      picture_hold.push_back(a.picture_sync_delay_ms);
    }
    if (offsets == 0) {
      spdlog::warn("live: {} viewers measured no voice/picture offset (no voice played?)", viewer);
      return;
    }
    std::map<std::string, std::string> q = {{"viewer", viewer}, {"sync", sync_state}};
    char bound[64];
    std::snprintf(bound, sizeof bound, "%.0f", o.sync.max_voice_delay_ms);
    q["max_voice_delay_ms"] = bound;
    q["hold_pictures"] = o.sync.hold_pictures ? "on" : "off";
    auto with = [&](std::map<std::string, std::string> extra) {
      extra.insert(q.begin(), q.end());
      return extra;
    };
    emit("av_offset_ms", Median(p50), "ms", with({{"stat", "p50"}}));
    emit("av_offset_ms", p99, "ms", with({{"stat", "p99"}}));
    emit("av_offset_ms", p1, "ms", with({{"stat", "p1"}}));
    // Without sync (computed from the same pictures: the voice's own delay
    // minus the picture's delay without its hold).
    emit("av_offset_unsynced_ms", Median(unsynced), "ms",
         with({{"stat", "p50"}, {"note", "voice natural delay - picture delay without hold"}}));
    emit("av_offsets_outside_bt1359", static_cast<double>(early + late) / static_cast<double>(offsets), "fraction",
         with({{"early_over_45ms", std::to_string(early)}, {"late_over_125ms", std::to_string(late)},
               {"offsets", std::to_string(offsets)}}));
    emit("av_sync_delay_ms", Median(voice_delay), "ms", with({{"stream", "voice"}}));
    emit("av_sync_delay_ms", Median(picture_hold), "ms",
         with({{"stream", "picture"}, {"pictures_held", std::to_string(held)}, {"of", std::to_string(pictures)},
               {"capped", std::to_string(capped)}}));
  };
  if (!decoders.empty()) emit_av("decode", dec_av);
  if (render_sync) emit_av("render", {render_av});
  {
    int64_t frames = 0, concealed = 0, underflows = 0, expands = 0, drops = 0, rebuffers = 0;
    for (const auto& v : voice_stats) {
      frames += v.frames;
      concealed += v.concealed;
      underflows += v.underflows;
      expands += v.sync_expands;
      drops += v.sync_drops;
      rebuffers += v.sync_rebuffers;
    }
    if (!voice_stats.empty())
      emit("voice_frames", static_cast<double>(frames) / static_cast<double>(voice_stats.size()), "count",
           {{"note", "per viewer, whole run"}, {"concealed", std::to_string(concealed)},
            {"underflows", std::to_string(underflows)}, {"sync_expands", std::to_string(expands)},
            {"sync_drops", std::to_string(drops)}, {"sync_rebuffers", std::to_string(rebuffers)}});
  }
  stop = true;
  if (render_thread.joinable()) render_thread.join();
  if (!render_status.ok()) {
    spdlog::error("live: rendering viewer failed: {}", render_status.ToString());
    return 1;
  }
  if (render_client) {
    std::vector<float> lat_shown, lat_dec;
    size_t n = 0;
    {
      std::lock_guard<std::mutex> l(render_log.mu);
      n = render_log.frames.size();
      for (const auto& r : render_log.frames) {
        lat_shown.push_back(static_cast<float>(r.latency_displayed_ms));
        lat_dec.push_back(static_cast<float>(r.latency_decoded_ms));
      }
    }
    const std::string res = std::to_string(o.width) + "x" + std::to_string(o.height);
    emit("viewer_fps", static_cast<double>(n) / window_s, "1/s", {{"viewer", "render"}, {"resolution", res}});
    emit("latency_p50_ms", metrics::Percentile(lat_shown, 50), "ms", {{"at", "displayed"}, {"viewer", "render"}});
    emit("latency_p99_ms", metrics::Percentile(lat_shown, 99), "ms", {{"at", "displayed"}, {"viewer", "render"}});
    emit("latency_p50_ms", metrics::Percentile(lat_dec, 50), "ms", {{"at", "received"}, {"viewer", "render"}});
    emit("render_ms", Median(render_ms), "ms", {{"viewer", "render"}, {"resolution", res}, {"color", o.color}});
    emit("render_cpu_ms", Median(render_cpu_ms), "ms",
         {{"viewer", "render"}, {"resolution", res}, {"thread", "render"}, {"color", o.color}});
    emit("mbps", static_cast<double>(render_stats1.bytes_received - render_stats0.bytes_received) * 8.0 / (window_s * 1e6), "Mbit/s",
         {{"viewer", "render"}});
    // Every received frame is decoded (a video stream cannot skip one), even
    // those the renderer never shows: decoding per received frame, wall ms
    // on the client's network thread.
    const auto received = static_cast<double>(render_stats1.frames_received - render_stats0.frames_received);
    if (received > 0) {
      emit("viewer_received_fps", received / window_s, "1/s",
           {{"viewer", "render"}, {"layer", std::to_string(render_stats1.layer)},
            {"layer_changes", std::to_string(render_stats1.layer_changes - render_stats0.layer_changes)}});
      emit("viewer_decode_ms", (render_stats1.mesh_decode_ms - render_stats0.mesh_decode_ms) / received, "ms",
           {{"viewer", "render"}, {"part", "geometry"}, {"per", "received frame"}});
      emit("viewer_decode_ms", (render_stats1.color_decode_ms - render_stats0.color_decode_ms) / received, "ms",
           {{"viewer", "render"}, {"part", "color"}, {"per", "received frame"}});
    }
  }
  emit("viewers_cpu_ms_per_s", (self_cpu1 - self_cpu0) / window_s, "ms",
       {{"note", "this process: all viewers' io, decoding and GL threads"}});
  guard.c->Stop(10);

  // 3. Quality at the viewer against the studio's ground truth.
  for (QualitySlot& slot : slots) {
    if (slot.distance != std::numeric_limits<int64_t>::max()) kept.push_back(std::move(slot.frame));
  }
  if (!kept.empty()) {
    progress("scoring " + std::to_string(kept.size()) + " decoded frames against the ground truth");
    auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
    if (!studio.ok()) {
      spdlog::error("live: {}", studio.status().ToString());
      return 1;
    }
    std::vector<double> chamfer, psnr, ssim;
    NovelViewOptions nv;
    nv.intrinsics = Intrinsics::FromFov(o.width, o.height, 50.0);
    const std::vector<NovelView> views = MakeNovelViews(nv);
    Status q_status;
    std::thread q([&] {
      auto ctx = render::CreateHeadlessContext();
      if (!ctx.ok()) {
        q_status = ctx.status();
        return;
      }
      auto renderer = render::Renderer::Create();
      auto target = render::OffscreenTarget::Create(o.width, o.height);
      if (!renderer.ok() || !target.ok()) {
        q_status = !renderer.ok() ? renderer.status() : target.status();
        return;
      }
      (*target)->Bind();
      for (const KeptFrame& k : kept) {
        const int64_t f = content_frame(k.frame_index);
        const Mesh truth_mesh = (*studio)->ForegroundMesh(f);
        auto d = metrics::ComputeMeshDistance(k.mesh, truth_mesh);
        if (d.ok()) chamfer.push_back(d->chamfer_mm);
        if (!(*renderer)->SetRemoteMesh(k.mesh).ok() ||
            !SetDecodedPodImages(renderer->get(), workload->rig, k.images).ok())
          continue;
        render::RenderSettings settings;
        settings.mode = render::ColorMode::kProjective;
        settings.projective.bake = o.color == "projective";
        settings.background = {0, 0, 0};
        for (const NovelView& v : views) {
          if (!(*renderer)->Render(v.camera, settings, {0, 0, o.width, o.height}).ok()) continue;
          ImageRgb8 ours, truth;
          ImageGray8 mask;
          if (!(*target)->ReadRgb(&ours).ok()) continue;
          (*studio)->RenderView(f, v.camera, &truth, nullptr, &mask);
          auto p = metrics::ComputePsnr(ours, truth, &mask);
          auto s = metrics::ComputeSsim(ours, truth, &mask);
          if (p.ok()) psnr.push_back(*p);
          if (s.ok()) ssim.push_back(*s);
        }
      }
    });
    q.join();
    if (!q_status.ok()) {
      spdlog::error("live: scoring failed: {}", q_status.ToString());
      return 1;
    }
    if (!chamfer.empty()) emit("chamfer_mm", Median(chamfer), "mm", {{"at", "viewer"}, {"frames", std::to_string(chamfer.size())}});
    if (!psnr.empty()) {
      emit("novel_view_psnr_db", Median(psnr), "dB",
           {{"at", "viewer"}, {"mode", "projective"}, {"color", o.color}, {"views", std::to_string(psnr.size())}});
      emit("novel_view_ssim", Median(ssim), "", {{"at", "viewer"}, {"mode", "projective"}, {"color", o.color}});
    }
  }
  if (o.keep_dir.empty()) {
    std::string cmd = "rm -rf '" + dir + "'";
    if (std::system(cmd.c_str()) != 0) spdlog::warn("live: could not remove {}", dir);
  }
  return 0;
}

// The benchmark's own options (holoport-bench live --help).
BenchFn SetupLive(CLI::App& app) {
  DropCommonOptions(app, {"--repeats"});  // this benchmark does not read them
  auto options = std::make_shared<LiveOptions>();
  {
    LiveOptions& o = *options;
    app.add_option("--content", o.content,
                   "fused (per-frame fusion), temporal (fusion over time) or truth (the studio's meshes)")
        ->check(CLI::IsMember({"fused", "temporal", "truth"}));
    app.add_flag(
        "--temporal", [options](int64_t) { options->content = "temporal"; }, "same as --content temporal");
    app.add_option("--seconds", o.seconds, "measured window, s")->check(CLI::Range(3.0, 3600.0));
    app.add_option("--warmup", o.warmup_s, "seconds after every viewer's first frame before measuring")
        ->check(CLI::Range(0.0, 60.0));
    app.add_option("--decoders", o.decoders, "viewers that only decode")->check(CLI::Range(0, 32));
    app.add_option("--viewer-quality", o.viewer_quality,
                   "the rendering viewer's quality cap 0..10 (Control set quality; 0..4 keep it on the site's "
                   "reduced layer, to measure that layer end to end)")
        ->check(CLI::Range(0, 10));
    app.add_option("--width", o.width, "rendering viewer's width")->check(CLI::Range(64, 4096));
    app.add_option("--height", o.height, "rendering viewer's height")->check(CLI::Range(64, 4096));
    app.add_option("--color", o.color,
                   "rendering viewer: projective (pods' images baked once per mesh into an atlas) or "
                   "projective-fragment (blended per pixel)")
        ->check(CLI::IsMember({"projective", "projective-fragment"}));
    app.add_flag(
        "--no-render", [options](int64_t) { options->render = false; },
        "no rendering viewer (and no novel-view figures)");
    app.add_option("--prerender", o.prerender, "pod frame sets rendered before the run and looped")
        ->check(CLI::Range(2, 600));
    app.add_option("--serial-frames", o.serial_frames, "frames of the serial run that measures CPU per stage (0: skip)")
        ->check(CLI::Range(0, 600));
    app.add_option("--site", o.site_binary, "holoport-server binary (default: next to this program)");
    app.add_option("--keep", o.keep_dir, "keep the site's logs and stats in this directory");
    app.add_option("--voice", o.voice, "the site's voice: synthetic, off, or a WAV file (--voice of holoport-server)");
    net::AddAvSyncOptions(app, &o.sync);
    app.add_option("--av-trace", o.av_trace,
                   "write every voice/picture offset measured by the rendering viewer and the first decoding viewer "
                   "to this CSV (display and capture time, delays, hold, voice target, offset)");
    app.add_option("--delay-voice-ms", o.delay_voice_ms, "hold every voice frame this long at each viewer (test)")
        ->check(CLI::Range(0.0, 10000.0));
    app.add_option("--delay-picture-ms", o.delay_picture_ms, "hold every picture this long at each viewer (test)")
        ->check(CLI::Range(0.0, 10000.0));
    app.add_option("--site-arg", o.site_args,
                   "an extra holoport-server argument (repeatable; e.g. --site-arg=--jpeg-quality --site-arg=70)");
  }
  return [options](const BenchArgs& args) { return Run(args, *options); };
}

}  // namespace

HOLO_REGISTER_BENCH_OPTIONS(
    "live",
    "the product end to end: a site process on paced pod frames, its session server, a rendering "
    "viewer and decoding viewers on loopback; fps, CPU per stage, latency, Mbit/s, quality at the viewer",
    SetupLive);

}  // namespace holo::bench
