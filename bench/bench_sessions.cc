// holoport-bench sessions --workload S8-QVGA [--json] [--frames N] [--viewers=N] [--seconds=S]
//                         [--server-threads=N] [--client-threads=N]
//
// One-to-many broadcast on loopback: an in-process session server (its own
// io threads) fans a 30 fps stream out to N normal viewers (SiteClient, no
// decoding, on a shared client io thread), one slow viewer (reads at 1/10 of
// the stream's byte rate), one stalled viewer (never reads) and one "mid" viewer
// reading at 60 % of the full layer's byte rate: with --layers 2 (default) the
// site also publishes the reduced layer, and the mid viewer shows a layer switch.
//
// Content: N frames (default 30) of the workload pre-encoded once, then looped:
// the studio's ground-truth foreground mesh per frame (G1, colours) and the 8
// pods' colour images with the exact masks (C1), i.e. S8-QVGA-sized frames
// without the capture pipeline's cost (which holoport-server measures).
//
// Figures: viewers_held (normal viewers at >= 29 fps over the measured window),
// delivered_fraction per class (normal, slow, stalled), publish_to_received_p50_ms and
// publish_to_received_p99_ms (publish time, stamped as the capture time on the
// wire: the content is made before the run, so nothing is captured → message reassembled
// at the viewer), cpu_per_viewer_pct (server io + publisher threads' CPU per
// wall second, per viewer), plus the machine load and the clients' CPU.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <time.h>

#include <CLI/CLI.hpp>

#include "bench.h"
#include "client/net/raw_peer.h"
#include "common/clock.h"
#include "common/log.h"
#include "common/quantile.h"
#include "net/session_server.h"
#include "net/site_client.h"
#include "protocol/color_codec.h"
#include "protocol/geometry_codec.h"
#include "server/net/site_publisher.h"
#include "server/pipeline/capture_site.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::bench {
namespace {

using Clock = std::chrono::steady_clock;

struct SessionsOptions {
  int viewers = 100;
  int seconds = 20;
  int server_threads = 2;
  int client_threads = 1;
  std::string content = "truth";
  int layers = 2;
};

std::string LoadAverage() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

struct Content {
  std::vector<std::vector<uint8_t>> geometry;
  std::vector<protocol::ColorFrame> color;
  size_t vertices = 0;
  double bytes_per_frame = 0;
  // The reduced layer as SitePublisher's defaults make it (coarser G1 step,
  // lower C1 quality; published every n-th frame). holoport-server now codes
  // its reduced layer as G3 + V1 by default (a quarter of these bytes); the
  // fan-out's cost per byte is what this bench measures.
  std::vector<std::vector<uint8_t>> reduced_geometry;
  std::vector<protocol::ColorFrame> reduced_color;
  double reduced_bytes_per_frame = 0;
};

// Encodes one frame into both layers of `c`.
Status AddFrame(const Mesh& mesh, const std::vector<const ImageRgb8*>& images,
                const std::vector<const ImageGray8*>& masks, Content* c) {
  const net::SitePublisherOptions site;  // SitePublisher's defaults (holoport-server's full layer)
  for (int layer = 0; layer < 2; ++layer) {
    const net::LayerEncodeOptions lo = net::EncodeOptionsOfLayer(site, layer);
    protocol::GeometryEncodeOptions g = lo.geometry;
    const protocol::ColorEncodeOptions& co = lo.color;
    g.colors = !mesh.colors.empty();
    std::vector<uint8_t> blob;
    HOLO_RETURN_IF_ERROR(protocol::EncodeGeometry(mesh, g, &blob));
    double bytes = static_cast<double>(blob.size());
    protocol::ColorFrame cf;
    cf.codec = protocol::ColorCodec::kC1;
    for (size_t p = 0; p < images.size(); ++p) {
      protocol::PodImage pi;
      pi.pod_id = static_cast<uint16_t>(p);
      HOLO_RETURN_IF_ERROR(protocol::EncodeColor(*images[p], *masks[p], co, &pi.data));
      bytes += static_cast<double>(pi.data.size());
      cf.images.push_back(std::move(pi));
    }
    (layer == 0 ? c->bytes_per_frame : c->reduced_bytes_per_frame) += bytes;
    (layer == 0 ? c->geometry : c->reduced_geometry).push_back(std::move(blob));
    (layer == 0 ? c->color : c->reduced_color).push_back(std::move(cf));
  }
  c->vertices = mesh.num_vertices();
  return OkStatus();
}

StatusOr<Content> PrepareContent(const Workload& wl, int frames) {
  Content c;
  SyntheticStudio studio(wl.rig, wl.studio);
  RgbdFrameSet fs;
  StudioGroundTruth gt;
  for (int f = 0; f < frames; ++f) {
    studio.RenderFrame(f, &fs, &gt);
    std::vector<const ImageRgb8*> images;
    std::vector<const ImageGray8*> masks;
    for (size_t p = 0; p < fs.frames.size() && p < gt.mask.size(); ++p) {
      images.push_back(&fs.frames[p].color);
      masks.push_back(&gt.mask[p]);
    }
    HOLO_RETURN_IF_ERROR(AddFrame(gt.foreground_mesh, images, masks, &c));
  }
  c.bytes_per_frame /= frames;
  c.reduced_bytes_per_frame /= frames;
  return c;
}

// The capture site's own output: fused, meshed and textured frames (exact
// masks, to keep the preparation short), encoded like holoport-server does.
StatusOr<Content> PrepareFusedContent(const Workload& wl, int frames) {
  Content c;
  HOLO_ASSIGN_OR_RETURN(auto studio, SyntheticStudio::Create(wl.rig, wl.studio));
  CaptureSiteOptions o;
  o.masks = MaskSource::kTruth;
  o.color_calibration = false;
  o.tsdf.voxel_size = wl.voxel_size_m;
  o.pipeline.max_frames = frames;
  // What holoport-server --listen publishes by default: the compact stream
  // mesh, without vertex colours (the viewer colours it from the images).
  o.stream_mesh = true;
  o.stream.max_triangles = wl.stream_triangles;
  o.texture = false;
  o.tsdf.integrate_color = false;
  HOLO_ASSIGN_OR_RETURN(auto site, CaptureSite::Create(studio.get(), nullptr, studio.get(), o));
  auto sink = [&](const FrameWork& w) -> Status {
    std::vector<const ImageRgb8*> images;
    std::vector<const ImageGray8*> masks;
    for (const auto& f : w.frames.frames) {
      if (f.mask.width() != f.color.width() || f.mask.height() != f.color.height()) continue;
      images.push_back(&f.color);
      masks.push_back(&f.mask);
    }
    HOLO_RETURN_IF_ERROR(AddFrame(w.mesh, images, masks, &c));
    spdlog::info("  fused frame {}/{}: {} vertices", c.geometry.size(), frames, w.mesh.num_vertices());
    return OkStatus();
  };
  HOLO_ASSIGN_OR_RETURN(auto stats, site->Run(sink));
  (void)stats;
  if (c.geometry.empty()) return Internal("the capture site produced no frames");
  c.bytes_per_frame /= static_cast<double>(c.geometry.size());
  c.reduced_bytes_per_frame /= static_cast<double>(c.geometry.size());
  return c;
}

int RunSessions(const BenchArgs& args, const SessionsOptions& o) {
  const int num_viewers = std::max(1, o.viewers);
  const int seconds = std::max(4, o.seconds);
  const int server_threads = std::max(1, o.server_threads);
  const int client_threads = std::max(1, o.client_threads);
  const std::string content_kind = o.content;
  const int content_frames = args.frames > 0 ? args.frames : (content_kind == "truth" ? 30 : 8);
  const double fps = 30.0;
  auto wl = GetWorkload(args.workload);
  if (!wl.ok()) {
    spdlog::error("sessions: {}", wl.status().ToString());
    return 2;
  }
  spdlog::info("sessions: load average before: {}", LoadAverage());
  spdlog::info("sessions: pre-encoding {} {} frames ({} mesh G1 + 8 pods C1)...", content_frames, args.workload,
               content_kind == "truth" ? "ground-truth" : "fused");
  auto content = content_kind == "truth" ? PrepareContent(*wl, content_frames) : PrepareFusedContent(*wl, content_frames);
  if (!content.ok()) {
    spdlog::error("sessions: {}", content.status().ToString());
    return 1;
  }
  spdlog::info("sessions: {} vertices, {:.1f} KB per frame ({:.1f} Mbit/s per viewer)", content->vertices,
               content->bytes_per_frame / 1024, content->bytes_per_frame * 8 * fps / 1e6);

  net::ServerConfig cfg;
  cfg.name = "bench-site";
  cfg.publisher_token = "bench-pub";
  cfg.viewer_token = "bench-view";
  cfg.max_viewers = num_viewers + 8;
  cfg.max_pending = num_viewers + 8;
  cfg.threads = server_threads;
  cfg.idle_timeout_s = 3600;
  std::atomic<int> log_lines{0};
  net::ServerHooks hooks;
  hooks.log = [&log_lines](const std::string&) { ++log_lines; };  // 100 welcomes: not interesting here
  auto server = net::Server::Start(cfg, hooks);
  if (!server.ok()) {
    spdlog::error("sessions: {}", server.status().ToString());
    return 1;
  }
  const uint16_t port = (*server)->port();
  const net::SitePublisherOptions site;  // SitePublisher's defaults (holoport-server's full layer)
  const int divisor = site.reduced.frame_divisor;
  if (o.layers > 1) (*server)->SetLayers(2);

  // Normal viewers.
  struct ViewerCount {
    std::atomic<int64_t> frames{0};
    std::atomic<int64_t> last_index{-1};
    std::atomic<int64_t> out_of_order{0};
  };
  std::vector<ViewerCount> counts(num_viewers);
  std::mutex lat_mu;
  std::vector<double> latencies;
  std::atomic<bool> measuring{false};
  net::NetContext ctx(client_threads);
  std::vector<std::unique_ptr<net::SiteClient>> viewers;
  for (int i = 0; i < num_viewers; ++i) {
    net::ClientOptions o;
    o.port = port;
    o.token = "bench-view";
    o.name = "normal" + std::to_string(i);
    o.decode = false;
    o.subscribe = net::kSubscribeGeometry | net::kSubscribeColor;
    o.connect_timeout_s = 30;
    net::ClientCallbacks cb;
    ViewerCount* vc = &counts[i];
    cb.on_frame = [vc, &lat_mu, &latencies, &measuring](const net::ReceivedFrame& f) {
      ++vc->frames;
      if (f.frame_index <= vc->last_index) ++vc->out_of_order;
      vc->last_index = f.frame_index;
      if (measuring) {
        std::lock_guard<std::mutex> l(lat_mu);
        latencies.push_back(f.latency_ms);
      }
    };
    auto c = net::SiteClient::Start(o, cb, &ctx);
    if (!c.ok()) {
      spdlog::error("sessions: {}", c.status().ToString());
      return 1;
    }
    viewers.push_back(std::move(*c));
  }
  for (auto& v : viewers)
    if (!v->WaitConnected(30)) {
      spdlog::error("sessions: a viewer did not connect: {}", v->status().ToString());
      return 1;
    }
  // 1/10 of the stream's byte rate, per 10 ms slice.
  const size_t slow_budget = static_cast<size_t>(content->bytes_per_frame * fps / 10 / 100);
  // Raw-socket viewers of geometry and colour, reading `bytes_per_10ms` every 10 ms (0: never).
  net::RawViewerOptions ro;
  ro.port = port;
  ro.token = "bench-view";
  ro.subscribe = net::kSubscribeGeometry | net::kSubscribeColor;
  ro.receive_buffer = 64 << 10;
  ro.welcome_timeout_s = 10.0;
  ro.name = "slow";
  ro.bytes_per_10ms = std::max<size_t>(512, slow_budget);
  auto slow_viewer = net::RawViewer::Start(ro);
  ro.name = "stalled";
  ro.bytes_per_10ms = 0;
  auto stalled_viewer = net::RawViewer::Start(ro);
  // A viewer whose link carries 60 % of the full stream: more than the
  // reduced layer needs, less than the full one.
  ro.name = "mid";
  ro.bytes_per_10ms = static_cast<size_t>(content->bytes_per_frame * fps * 0.6 / 100);
  auto mid_viewer = net::RawViewer::Start(ro);
  if (!slow_viewer.ok() || !stalled_viewer.ok() || !mid_viewer.ok()) {
    spdlog::error("sessions: slow/stalled/mid viewer: {} {} {}", slow_viewer.status().ToString(),
                  stalled_viewer.status().ToString(), mid_viewer.status().ToString());
    return 1;
  }
  const net::RawViewer& slow = **slow_viewer;
  const net::RawViewer& stalled = **stalled_viewer;
  const net::RawViewer& mid = **mid_viewer;
  while ((*server)->num_subscribed(net::kContentGeometry) < static_cast<size_t>(num_viewers + 3))
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  spdlog::info("sessions: {} normal + 1 slow + 1 stalled viewers connected; streaming {} s at {:.0f} fps", num_viewers,
               seconds, fps);

  // Publisher: one encode per frame (MakeVideoFrame copies the pre-encoded
  // blobs into the wire buffer once), shared by every viewer.
  const double warmup_s = 2.0;
  std::atomic<int64_t> published{0}, published_reduced{0};
  std::atomic<int64_t> published_at_window_start{0};
  double publisher_cpu_ms = 0;
  std::thread publisher([&] {
    const double cpu0 = holo::ThreadCpuTimeMs();
    const auto start = Clock::now();
    const int64_t total = static_cast<int64_t>(seconds * fps);
    for (int64_t i = 0; i < total; ++i) {
      const size_t k = static_cast<size_t>(i % static_cast<int64_t>(content->geometry.size()));
      const int64_t now = net::WallUs();
      (*server)->PublishVideo(net::MakeVideoFrame(i, now, protocol::GeometryCodec::kG1, content->geometry[k],
                                                  &content->color[k], cfg.fragment_bytes));
      ++published;
      // The reduced layer as SitePublisher does it: only while someone gets it, every n-th frame.
      if (o.layers > 1 && i % divisor == 0 && (*server)->ViewersOnLayer(1) > 0) {
        (*server)->PublishVideo(net::MakeVideoFrame(i, now, protocol::GeometryCodec::kG1,
                                                    content->reduced_geometry[k], &content->reduced_color[k],
                                                    cfg.fragment_bytes, net::kSiteStreamId, 1, true));
        ++published_reduced;
      }
      std::this_thread::sleep_until(start + std::chrono::microseconds(static_cast<int64_t>((i + 1) * 1e6 / fps)));
    }
    publisher_cpu_ms = holo::ThreadCpuTimeMs() - cpu0;
  });

  // Window: after the warm-up until the end of publishing.
  std::this_thread::sleep_for(std::chrono::milliseconds(static_cast<int>(warmup_s * 1000)));
  std::vector<int64_t> frames0(num_viewers);
  for (int i = 0; i < num_viewers; ++i) frames0[i] = counts[i].frames;
  const int64_t slow0 = slow.meshes();
  const int64_t stalled0 = stalled.meshes();
  const int64_t mid0 = mid.meshes();
  const size_t mid_lat0 = mid.mesh_latencies_ms().size();
  const int64_t reduced0 = published_reduced.load();
  published_at_window_start = published.load();
  const double server_cpu0 = (*server)->IoCpuMs();
  const double client_cpu0 = ctx.CpuMs();
  const double proc_cpu0 = ProcessCpuMs();
  const auto t0 = Clock::now();
  measuring = true;
  for (int s = 0; s < seconds - static_cast<int>(warmup_s); s += 5) {
    std::this_thread::sleep_for(std::chrono::seconds(std::min(5, seconds - static_cast<int>(warmup_s) - s)));
    int64_t sum = 0;
    for (int i = 0; i < num_viewers; ++i) sum += counts[i].frames - frames0[i];
    const double el = std::chrono::duration<double>(Clock::now() - t0).count();
    spdlog::info("  {:.0f} s: published {}, mean {:.1f} fps per normal viewer, server io CPU {:.0f}%, load {}",
                 el + warmup_s, published.load(), sum / el / num_viewers,
                 ((*server)->IoCpuMs() - server_cpu0) / (el * 10), LoadAverage());
  }
  publisher.join();
  const double window_s = std::chrono::duration<double>(Clock::now() - t0).count();
  const double server_cpu_ms = (*server)->IoCpuMs() - server_cpu0;
  const double client_cpu_ms = ctx.CpuMs() - client_cpu0;
  const double proc_cpu_ms = ProcessCpuMs() - proc_cpu0;
  // Let in-flight frames arrive (the window's frames were published before now).
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  measuring = false;
  const int64_t window_published = published.load() - published_at_window_start.load();

  int held = 0;
  std::vector<double> fractions, fps_list;
  int64_t out_of_order = 0;
  for (int i = 0; i < num_viewers; ++i) {
    const int64_t got = counts[i].frames - frames0[i];
    const double f = static_cast<double>(got) / window_s;
    fps_list.push_back(f);
    // The window's start and end fall between frames: ±1 frame of slack.
    if (got + 1 >= static_cast<int64_t>(29.0 * window_s)) ++held;
    fractions.push_back(std::min(1.0, static_cast<double>(got) / static_cast<double>(window_published)));
    out_of_order += counts[i].out_of_order;
  }
  const double slow_fraction = static_cast<double>(slow.meshes() - slow0) / static_cast<double>(window_published);
  const double stalled_fraction =
      static_cast<double>(stalled.meshes() - stalled0) / static_cast<double>(window_published);
  const double mid_fraction = static_cast<double>(mid.meshes() - mid0) / static_cast<double>(window_published);
  std::vector<double> mid_lat = mid.mesh_latencies_ms();
  mid_lat.erase(mid_lat.begin(), mid_lat.begin() + static_cast<std::ptrdiff_t>(std::min(mid_lat0, mid_lat.size())));
  net::SessionStats mid_stats;
  uint64_t dropped_normal = 0, dropped_slow = 0, dropped_stalled = 0, bytes_sent = 0;
  for (const auto& s : (*server)->Sessions()) {
    bytes_sent += s.bytes_sent;
    if (s.client_name == "mid") mid_stats = s;
    if (s.client_name == "mid") continue;
    if (s.client_name == "slow") dropped_slow = s.video_frames_dropped;
    else if (s.client_name == "stalled") dropped_stalled = s.video_frames_dropped;
    else dropped_normal += s.video_frames_dropped;
  }
  std::vector<double> lat;
  {
    std::lock_guard<std::mutex> l(lat_mu);
    lat = latencies;
  }
  const double server_total_cpu_ms = server_cpu_ms + publisher_cpu_ms * (window_s / seconds);
  const double cpu_pct_per_viewer = server_total_cpu_ms / (window_s * 1e3) * 100.0 / (num_viewers + 3);

  const std::string w = args.workload;
  const std::map<std::string, std::string> q{{"viewers", std::to_string(num_viewers)},
                                             {"fps", "30"},
                                             {"content", content_kind == "truth" ? "studio-ground-truth-G1+C1-looped" : "fused-G1+C1-looped"},
                                             {"server_threads", std::to_string(server_threads)},
                                             {"layers", std::to_string(o.layers)}};
  auto with = [&](std::map<std::string, std::string> extra) {
    extra.insert(q.begin(), q.end());
    return extra;
  };
  EmitFigure("sessions", w, "viewers_held", held, "viewers", with({{"of", std::to_string(num_viewers)}}));
  EmitFigure("sessions", w, "delivered_fraction", Mean(fractions), "1", with({{"class", "normal"}}));
  EmitFigure("sessions", w, "delivered_fraction", *std::min_element(fractions.begin(), fractions.end()), "1",
             with({{"class", "normal"}, {"stat", "min"}}));
  EmitFigure("sessions", w, "delivered_fraction", slow_fraction, "1", with({{"class", "slow"}}));
  EmitFigure("sessions", w, "delivered_fraction", stalled_fraction, "1", with({{"class", "stalled"}}));
  // The viewer between the layers: what it gets, how late, on which layer.
  EmitFigure("sessions", w, "delivered_fraction", mid_fraction, "1", with({{"class", "mid"}}));
  EmitFigure("sessions", w, "fps_per_viewer", mid_fraction * fps, "1/s", with({{"class", "mid"}}));
  EmitFigure("sessions", w, "publish_to_received_p50_ms", Quantile(mid_lat, 0.5), "ms", with({{"class", "mid"}}));
  EmitFigure("sessions", w, "publish_to_received_p99_ms", Quantile(mid_lat, 0.99), "ms", with({{"class", "mid"}}));
  EmitFigure("sessions", w, "frames_dropped", static_cast<double>(mid_stats.video_frames_dropped), "frames",
             with({{"class", "mid"}}));
  EmitFigure("sessions", w, "layer_switches", static_cast<double>(mid_stats.layer_switches), "",
             with({{"class", "mid"}}));
  EmitFigure("sessions", w, "layer", static_cast<double>(mid_stats.layer), "", with({{"class", "mid"}}));
  EmitFigure("sessions", w, "reduced_frames_published",
             static_cast<double>(published_reduced.load() - reduced0), "frames",
             with({{"of", std::to_string(window_published)}}));
  EmitFigure("sessions", w, "frame_bytes", content->reduced_bytes_per_frame, "B", with({{"layer", "reduced"}}));
  EmitFigure("sessions", w, "frames_dropped", static_cast<double>(dropped_normal), "frames",
             with({{"class", "normal"}, {"stat", "sum"}}));
  EmitFigure("sessions", w, "frames_dropped", static_cast<double>(dropped_slow), "frames", with({{"class", "slow"}}));
  EmitFigure("sessions", w, "frames_dropped", static_cast<double>(dropped_stalled), "frames",
             with({{"class", "stalled"}}));
  EmitFigure("sessions", w, "fps_per_viewer", Median(fps_list), "1/s", with({{"class", "normal"}, {"stat", "median"}}));
  EmitFigure("sessions", w, "fps_per_viewer", *std::min_element(fps_list.begin(), fps_list.end()), "1/s",
             with({{"class", "normal"}, {"stat", "min"}}));
  EmitFigure("sessions", w, "publish_to_received_p50_ms", Quantile(lat, 0.5), "ms", with({{"class", "normal"}}));
  EmitFigure("sessions", w, "publish_to_received_p99_ms", Quantile(lat, 0.99), "ms", with({{"class", "normal"}}));
  EmitFigure("sessions", w, "cpu_per_viewer_pct", cpu_pct_per_viewer, "%",
             with({{"stage", "server"}, {"note", "io threads + publisher, per wall second"}}));
  EmitFigure("sessions", w, "cpu_pct", server_total_cpu_ms / (window_s * 10), "%", with({{"stage", "server"}}));
  EmitFigure("sessions", w, "cpu_pct", client_cpu_ms / (window_s * 10), "%", with({{"stage", "viewers"}}));
  EmitFigure("sessions", w, "cpu_pct", proc_cpu_ms / (window_s * 10), "%", with({{"stage", "process"}}));
  EmitFigure("sessions", w, "frame_bytes", content->bytes_per_frame, "B", with({{"vertices", std::to_string(content->vertices)}}));
  EmitFigure("sessions", w, "out_of_order_frames", static_cast<double>(out_of_order), "frames", with({{"class", "normal"}}));
  EmitFigure("sessions", w, "server_send_rate", static_cast<double>(bytes_sent) * 8 / 1e6 / (seconds + 2.0), "Mbit/s",
             with({{"note", "all viewers, whole run incl. warm-up"}}));
  EmitFigure("sessions", w, "window_s", window_s, "s", with({}));
  spdlog::info("sessions: load average after: {} (2 cores shared)", LoadAverage());

  return 0;
}

BenchFn SetupSessions(CLI::App& app) {
  DropCommonOptions(app, {"--repeats"});  // this benchmark does not read them
  auto o = std::make_shared<SessionsOptions>();
  app.add_option("--viewers", o->viewers, "viewers on loopback")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--layers", o->layers,
                 "2: the site also publishes the reduced layer (as holoport-server does by default), 1: full only")
      ->capture_default_str()
      ->check(CLI::Range(1, 2));
  app.add_option("--seconds", o->seconds, "seconds of broadcast (at least 4)")->capture_default_str();
  app.add_option("--server-threads", o->server_threads, "session server threads")->capture_default_str();
  app.add_option("--client-threads", o->client_threads, "threads of the viewers' client side")->capture_default_str();
  app.add_option("--content", o->content, "what is broadcast: truth (ground-truth meshes) or fused")
      ->capture_default_str()
      ->check(CLI::IsMember({"truth", "fused"}));
  return [o](const BenchArgs& args) { return RunSessions(args, *o); };
}

HOLO_REGISTER_BENCH_OPTIONS("sessions",
                            "broadcast fan-out on loopback: N viewers + slow + stalled at 30 fps (viewers_held, "
                            "delivered_fraction, latency, cpu_per_viewer_pct)",
                            SetupSessions);

}  // namespace
}  // namespace holo::bench
