// holoport-server: the capture site. Reads frames from the synthetic studio or
// a dataset, segments, fuses, meshes and textures every frame on the
// concurrent pipeline; exports PLY meshes and per-frame stats. With --listen
// (or --net-config) it is also a session server: every frame is encoded once
// (G1 mesh + C1 pod images) and fanned out to viewers, render hosts and
// recorders; participants' audio+pose is relayed (docs/sessions.md).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <mutex>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "common/clock.h"
#include "common/file_util.h"
#include "common/image_io.h"
#include "common/log.h"
#include "common/visualize.h"
#include "net/server_config.h"
#include "net/session_server.h"
#include "server/capture/dataset.h"
#include "server/capture/prerendered.h"
#include "server/net/site_publisher.h"
#include "server/pipeline/capture_site.h"
#include "server/pods/pod_hub.h"
#include "server/record/replay_command.h"
#include "server/regions/regions.h"
#include "server/stereo/stereo_depth.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#include "texture/mesh_renderer.h"
#include "texture/novel_view.h"
#include "server/voice/site_voice.h"

namespace {

int Fail(const holo::Status& s) {
  spdlog::error("holoport-server: {}", s.message());
  return 1;
}

char FrameFileName(char* buf, size_t n, const std::string& dir, int64_t index) {
  std::snprintf(buf, n, "%s/mesh_%06lld.ply", dir.c_str(), static_cast<long long>(index));
  return 0;
}

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

// Per-viewer counters summed for the stats lines and stderr.
struct NetSummary {
  size_t viewers = 0;
  size_t on_reduced = 0;  // viewers receiving the reduced quality layer
  uint64_t sent = 0, dropped = 0, bytes = 0;
  size_t max_queue = 0;
  double rtt_ms_max = -1;
};
NetSummary Summarize(const holo::net::Server& server) {
  NetSummary n;
  for (const auto& s : server.Sessions()) {
    if (s.role == holo::protocol::Role::kPublisher) continue;
    ++n.viewers;
    if (s.layer > 0) ++n.on_reduced;
    n.sent += s.video_frames_sent;
    n.dropped += s.video_frames_dropped;
    n.bytes += s.bytes_sent;
    n.max_queue = std::max(n.max_queue, s.queue_video);
    n.rtt_ms_max = std::max(n.rtt_ms_max, s.rtt_ms);
  }
  return n;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "holoport-server: the capture site. Frames from the synthetic studio or a dataset go through\n"
      "colour calibration, segmentation, TSDF fusion, marching cubes, clean-up and texturing, stages\n"
      "running concurrently; every frame's textured mesh can be exported as PLY. Stage timings and\n"
      "progress go to stderr, per-frame stats as JSON lines to --stats (or stdout)."};
  holo::AddLogLevelOption(app);
  std::string source_spec = "synthetic", workload_name = "S8-QVGA", rig_path, background_spec, export_dir, stats_path;
  std::string masks_name = "segment", snapshot_path;
  int64_t frames = 60;
  double voxel_mm = 0, trunc_voxels = 4, pace = 0;
  size_t decimate = 0, min_component = 200;
  int background_frames = 30, queue = 2;
  bool serial = false, no_texture = false, no_color_calibration = false, quiet = false, temporal = false;
  int prerender = 0, stream_step = holo::StreamMeshOptions{}.step, max_in_flight = 2;
  bool keep_late = false;
  size_t stream_triangles = holo::StreamMeshOptions{}.max_triangles;
  app.add_option("--source", source_spec, "synthetic (the studio) or dataset:PATH")->capture_default_str();
  app.add_option("-w,--workload", workload_name, "synthetic source: S8-QVGA or S8-VGA")->capture_default_str();
  app.add_option("--rig", rig_path, "synthetic source: render this rig instead of the workload's");
  app.add_option("--background", background_spec,
                 "empty-room frames for segmentation and colour calibration: dataset:PATH "
                 "(default for the synthetic source: the studio's empty room)");
  app.add_option("--masks", masks_name, "segment | truth (synthetic only) | dataset | none")->capture_default_str();
  std::string depth_mode = "direct";
  app.add_option("--depth", depth_mode, "synthetic source: direct (the studio's depth sensor model) or stereo "
                 "(PatchMatch on each pod's IR pair, docs/stereo.md); not with --pods, where each pod makes its "
                 "depth (holoport-pod --depth stereo)")->check(CLI::IsMember({"direct", "stereo"}))
      ->capture_default_str();
  std::string stereo_roi = "on";
  app.add_option("--stereo-roi", stereo_roi,
                 "--depth stereo: on (match each pod's pair only around the person, from the previous frame's "
                 "stereo depth, the whole pair every 15 frames and when the person reaches the region's edge "
                 "(see --stereo-search); docs/stereo.md) or off (every pair whole)")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  std::string stereo_search = "sgbm";
  app.add_option("--stereo-search", stereo_search,
                 "--depth stereo: where a pod's whole pair is due (every 15 frames, the first, when the person reaches the region's edge, nobody found): sgbm (search it with OpenCV's SGBM, ~1/20 of PatchMatch's CPU, then PatchMatch only around the person found; no depth elsewhere on those frames) or patchmatch (the whole pair through PatchMatch); docs/stereo.md")
      ->check(CLI::IsMember({"sgbm", "patchmatch"}))
      ->capture_default_str();
  std::string stereo_temporal = "on";
  app.add_option("--stereo-temporal", stereo_temporal,
                 "--depth stereo: on (each pod's matcher starts a region from its planes of the previous frame instead "
                 "of a half-resolution pass: ~0.77x the CPU and a closer fused mesh; whole pairs still run the full "
                 "algorithm; docs/stereo.md) or off")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  double stereo_still = holo::PatchMatchOptions{}.temporal_still;
  app.add_option("--stereo-still", stereo_still,
                 "--depth stereo: a region's pixels whose window (and their match's) changed since the previous frame by at most K times the camera's noise level keep their planes unvisited (0: off; 1.0: the site's masks, mesh and view as good, its CPU not measurably lower yet; docs/stereo.md)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  std::string stereo_dense_pass = "on";
  app.add_option("--stereo-dense-pass", stereo_dense_pass,
                 "--depth stereo: on (a last pass moves each pixel's depth in a window of adjacent pixels, taking "
                 "away the sparse window's bias on a rounded body: fused person ~1.7 mm closer for ~1.2x the "
                 "matching CPU; docs/stereo.md) or off")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  std::string reconstruct = "tsdf";
  app.add_option("--reconstruct", reconstruct,
                 "tsdf (fuse the pods' depth) or hull (the visual hull of the pods' masks alone, as colour-only "
                 "pods would give; docs/visual_hull.md)")
      ->check(CLI::IsMember({"tsdf", "hull"}))
      ->capture_default_str();
  app.add_option("-n,--frames", frames, "frames to process (-1: until the source ends)")->capture_default_str();
  app.add_option("--voxel-mm", voxel_mm, "TSDF voxel size, mm (default: the workload's, 10 for datasets)");
  app.add_option("--trunc-voxels", trunc_voxels, "TSDF truncation, voxels")->capture_default_str();
  app.add_option("--decimate", decimate, "decimate meshes to this many triangles (0: off)")->capture_default_str();
  app.add_option("--min-component", min_component, "drop mesh fragments with fewer triangles")->capture_default_str();
  app.add_option("--background-frames", background_frames, "empty-room frames to learn from")->capture_default_str();
  app.add_option("--queue", queue, "frames in flight per pipeline hop")->capture_default_str();
  app.add_option("--pace", pace, "pace acquisition like a live camera at this fps (0: as fast as possible)");
  app.add_flag("--keep-late", keep_late,
               "with --pace: take every frame however late (latency grows when the site cannot keep up) instead "
               "of skipping to the newest camera frame");
  app.add_option("--max-in-flight", max_in_flight,
                 "frames in the pipeline at once (0: as many as the queues hold); on a CPU-bound site the latency is "
                 "about this many frame times (docs/live.md)")
      ->capture_default_str()
      ->check(CLI::Range(0, 256));
  app.add_option("--prerender", prerender,
                 "synthetic source: render this many frame sets into memory first and loop them forward and back "
                 "forever (-n counts on), so acquisition costs a copy as with cameras, not the studio's rendering "
                 "(with --depth stereo: and its PatchMatch, as pods that match their own pairs; 0: render while "
                 "running)")
      ->check(CLI::Range(0, 3000));
  int depth_filter_radius = holo::DepthFilterOptions{}.radius;
  app.add_option("--depth-filter", depth_filter_radius,
                 "smooth each pod's depth within its mask over a (2R+1)² window before fusion, keeping depth "
                 "edges (0: off; server/fusion/depth_filter.h; with --depth stereo 0 unless given)")
      ->capture_default_str()
      ->check(CLI::Range(0, 4));
  int segment_edge_band = 0;
  app.add_option("--segment-edge-band", segment_edge_band,
                 "segmentation: within this many pixels of a depth edge colour decides, not depth (stereo depth "
                 "spreads a surface's depth past its edge; docs/stereo.md; with --depth stereo " +
                     std::to_string(holo::kStereoSegmentEdgeBandPx) +
                     " unless given; give it for a --pods site of stereo pods)")
      ->capture_default_str()
      ->check(CLI::Range(0, 32));
  double depth_noise_mm = holo::TsdfOptions{}.depth_noise_at_1m_mm;
  app.add_option("--depth-noise-mm", depth_noise_mm,
                 "the depth sensor's axial noise at 1 m, mm, growing with z² (the studio's: 3): sets the "
                 "segmenter's noise floor, the depth filter's range and how deep behind the measured surface "
                 "fusion counts an observation (1.25 truncations + 1.25 σ)")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 50.0));
  bool raw_full_mesh = false;
  app.add_flag("--raw-full-mesh", raw_full_mesh,
               "extract full-resolution meshes (--export, --stream-step 1) from the fused volume as it is, not "
               "smoothed on its grid");
  app.add_option("--stream-step", stream_step,
                 "the published mesh: marching cubes over every N-th voxel of the fused volume (1: full resolution)")
      ->capture_default_str()
      ->check(CLI::Range(1, 4));
  app.add_option("--stream-triangles", stream_triangles,
                 "the published mesh: simplify to at most this many triangles (0: no budget; default: the "
                 "synthetic workload's, 10000 per person, else 10000); --stream-step 1 --stream-triangles 0 "
                 "publishes the full mesh");
  app.add_option("--export", export_dir,
                 "write every frame's full-resolution textured mesh to DIR/mesh_NNNNNN.ply");
  app.add_option("--snapshot", snapshot_path,
                 "write a PNG of the last frame's textured mesh from a viewpoint no pod has "
                 "(synthetic source: ground truth on the left, ours on the right)");
  app.add_option("--stats", stats_path, "write per-frame stats as JSON lines to this file (default stdout)");
  app.add_flag("--serial", serial, "run the stages one after another on one thread");
  app.add_flag("--no-texture", no_texture, "skip texturing (voxel colours stay)");
  app.add_flag("--temporal", temporal,
               "fuse over time: track the previous volume non-rigidly and fuse into it (docs/temporal.md)");
  app.add_flag("--no-color-calibration", no_color_calibration, "do not estimate and apply per-pod colour maps");
  app.add_flag("-q,--quiet", quiet, "no progress output");
  // Replay of a recording (docs/recording.md): serves the recorded stream instead of the capture pipeline.
  holo::record::ReplayCommandOptions replay;
  app.add_option("--replay", replay.path, "replay this recording instead of capturing: to viewers with --listen HOST:PORT --viewer-token T "
                 "(they can pause, resume, seek, change speed), else to --export / --stats");
  app.add_option("--speed", replay.speed, "--replay: playback speed, 0.25..4")->capture_default_str();
  app.add_flag("--loop", replay.loop, "--replay: start again at the end");
  app.add_option("--start", replay.start_s, "--replay: start at this media time, seconds");
  app.add_option("--replay-seconds", replay.max_wall_s, "--replay: stop after this many seconds (0: at the end)");
  std::string listen_spec, net_config_path, publisher_token, viewer_token;
  bool truth_mesh = false, no_color_stream = false, mesh_colors = false;
  double position_step_mm = holo::net::kSitePositionStepMm;
  int jpeg_quality = holo::net::kSiteJpegQuality;
  std::string color_codec = "c1", geometry_codec = "g1";
  double g3_step_mm = 2.0;
  int video_crf = holo::net::kSiteVideoCrf;
  std::string video_preset;
  int truth_loop = 0;
  app.add_option("--listen", listen_spec,
                 "stream to viewers: listen on HOST:PORT (default: off, no networking; overrides the "
                 "config's listen)");
  app.add_option("--net-config", net_config_path,
                 "session server config, YAML: tokens, limits, timeouts, TLS (docs/sessions.md)");
  app.add_option("--publisher-token", publisher_token,
                 "token participants need to publish audio+pose (default: env HOLO_PUBLISHER_TOKEN or the config)");
  app.add_option("--viewer-token", viewer_token,
                 "token viewers, render hosts and recorders need (default: env HOLO_VIEWER_TOKEN or the config)");
  app.add_flag("--truth-mesh", truth_mesh,
               "synthetic source: stream the studio's ground-truth meshes and exact-mask pod images instead of "
               "running the capture pipeline (a valid 30 fps stream; paced at --pace, default 30)");
  app.add_option("--truth-loop", truth_loop,
                 "with --truth-mesh: render this many frames up front and loop them (frame indices keep "
                 "counting), so that the studio's rendering does not limit the rate (0: render live)")
      ->check(CLI::Range(0, 3000));
  app.add_flag("--no-color-stream", no_color_stream, "stream meshes only (no C1 pod images)");
  app.add_option("--position-step-mm", position_step_mm,
                 "G1 position quantisation of the streamed mesh, mm (error <= step * 0.87)")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 100.0));
  app.add_option("--geometry-codec", geometry_codec,
                 "codec of the streamed mesh: g1 (the mesh: connectivity and quantized positions) or g3 (the "
                 "distance samples the stream mesh is extracted from; the viewer runs marching cubes: about a "
                 "third of G1's bytes, no vertex colours; needs the stream mesh)")
      ->capture_default_str()
      ->check(CLI::IsMember({"g1", "g3"}));
  app.add_option("--g3-step-mm", g3_step_mm, "g3: quantization of a vertex along its grid edge, mm (error <= step / 2)")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 16.0));
  app.add_option("--jpeg-quality", jpeg_quality, "C1 JPEG quality of the streamed pod images, 1..100")
      ->capture_default_str()
      ->check(CLI::Range(1, 100));
  app.add_option("--color-codec", color_codec,
                 "codec of the streamed pod images: c1 (per-frame JPEG, every frame decodes alone) or v1 (per-pod "
                 "inter-frame video, x264 4:4:4: fewer bytes; key frames every 2 s and when a viewer joins or asks)")
      ->capture_default_str()
      ->check(CLI::IsMember({"c1", "v1"}));
  app.add_option("--video-crf", video_crf,
                 "v1: x264 constant-quality factor 0..51 (lower: more bytes, better picture; -1: the codec's own "
                 "default, 24)")
      ->capture_default_str()
      ->check(CLI::Range(-1, 51));
  app.add_option("--video-preset", video_preset,
                 "v1: x264 speed preset, ultrafast..veryslow (default veryfast; ultrafast: ~0.75x the encode CPU, "
                 "~1.6x the bytes)");
  int layers = 2;
  holo::net::ReducedLayerOptions reduced;
  app.add_option("--layers", layers,
                 "quality layers: 2 = full + reduced (each encoded once; a viewer that falls behind is moved to the "
                 "reduced one and back when its link allows; the reduced one is encoded only while someone gets it), "
                 "1 = the full layer only")
      ->capture_default_str()
      ->check(CLI::Range(1, 2));
  app.add_option("--reduced-step-scale", reduced.position_step_scale,
                 "reduced layer: G1 position step x this")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 16.0));
  app.add_option("--reduced-jpeg-quality", reduced.jpeg_quality, "reduced layer: C1 JPEG quality 1..100")
      ->capture_default_str()
      ->check(CLI::Range(1, 100));
  app.add_option("--reduced-crf-offset", reduced.crf_offset, "reduced layer, v1: CRF of the full layer + this")
      ->capture_default_str()
      ->check(CLI::Range(0, 51));
  app.add_option("--reduced-rate-divisor", reduced.frame_divisor,
                 "reduced layer: every n-th frame (2: 30 fps -> 15)")
      ->capture_default_str()
      ->check(CLI::Range(1, 8));
  // The reduced layer is for links that cannot take the full one: by
  // default its codecs are the ones with the fewest bytes (G3 + V1: 1.1-1.4
  // against 4.8 Mbit/s for G1 + C1 at S8-QVGA, 15 fps, docs/sessions.md),
  // while the full layer keeps G1 + C1's lower CPU.
  std::string reduced_geometry_codec = "auto", reduced_color_codec = "v1";
  app.add_option("--reduced-geometry-codec", reduced_geometry_codec,
                 "reduced layer's geometry codec: auto (g3 when the site streams the stream mesh, else as "
                 "--geometry-codec), same (as --geometry-codec), g1 or g3 (g3 needs the stream mesh); viewers that "
                 "do not decode it stay on the full layer")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "same", "g1", "g3"}));
  app.add_option("--reduced-color-codec", reduced_color_codec,
                 "reduced layer's colour codec: same (as --color-codec), c1 or v1 (v1 at the full layer's "
                 "--video-crf + --reduced-crf-offset); viewers that do not decode it stay on the full layer")
      ->capture_default_str()
      ->check(CLI::IsMember({"same", "c1", "v1"}));
  app.add_flag("--mesh-colors", mesh_colors,
               "texture the streamed mesh per vertex and send the colours in it even when the pods' images are "
               "streamed (by default the viewer colours the mesh from the images, as Holoportation does: the "
               "colours would cost ~8 bits per triangle and the texture stage ~8 CPU-ms per frame)");
  std::string pods_spec, pod_token;
  double pod_tolerance_ms = 12, pod_timeout_ms = 60;
  bool pod_set_stats = false;
  app.add_option("--pods", pods_spec,
                 "take the frames from pod processes (holoport-pod) connecting to [HOST:]PORT instead of the "
                 "local source; the workload / --rig gives the rig they must match, its empty room the background; "
                 "direct and stereo pods (holoport-pod --depth) alike");
  app.add_option("--pod-token", pod_token, "--pods: the token pods must present");
  app.add_option("--pod-tolerance-ms", pod_tolerance_ms, "--pods: frames within this of each other form one set")
      ->capture_default_str();
  app.add_option("--pod-timeout-ms", pod_timeout_ms,
                 "--pods: a set missing a connected pod leaves this long after its capture time")
      ->capture_default_str();
  app.add_flag("--pod-set-stats", pod_set_stats, "--pods: one stats line per frame set the hub releases");
  std::string voice_spec = "off";
  app.add_option("--voice", voice_spec,
                 "publish the voice of the person the pods capture, 20 ms Opus frames stamped on the pictures' "
                 "capture clock with their head pose: off, synthetic (the studio's person says a syllable at each "
                 "footstep and the ball knocks when it bounces, in step with the picture; needs the synthetic "
                 "source and --pace or --truth-mesh), mic or mic:DEVICE, or a WAV file (looped)")
      ->capture_default_str();
  std::string regions_path;
  app.add_option("--regions", regions_path,
                 "active regions: a YAML file of named boxes and spheres in the site's world frame; every frame the "
                 "site reports which ones its reconstruction occupies (enter, stay, leave, volume) to viewers, "
                 "recordings and --stats (docs/regions.md)");
  CLI11_PARSE(app, argc, argv);
  if (!replay.path.empty()) {
    replay.export_dir = export_dir;
    replay.stats_path = stats_path;
    replay.quiet = quiet;
    replay.listen = listen_spec;
    replay.net_config = net_config_path;
    replay.viewer_token = viewer_token;
    replay.publisher_token = publisher_token;
    return holo::record::RunReplayCommand(replay);
  }
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);

  // Session server (optional).
  std::unique_ptr<holo::net::Server> server;
  if (!listen_spec.empty() || !net_config_path.empty()) {
    holo::net::ServerConfig net;
    if (!net_config_path.empty()) {
      auto c = holo::net::LoadServerConfig(net_config_path);
      if (!c.ok()) return Fail(c.status());
      net = *c;
    } else {
      net.host = "0.0.0.0";
    }
    if (!listen_spec.empty()) {
      holo::Status st = holo::net::ParseHostPort(listen_spec, &net.host, &net.port);
      if (!st.ok()) return Fail(st.WithContext("--listen"));
    }
    if (publisher_token.empty() && std::getenv("HOLO_PUBLISHER_TOKEN")) publisher_token = std::getenv("HOLO_PUBLISHER_TOKEN");
    if (viewer_token.empty() && std::getenv("HOLO_VIEWER_TOKEN")) viewer_token = std::getenv("HOLO_VIEWER_TOKEN");
    if (!publisher_token.empty()) net.publisher_token = publisher_token;
    if (!viewer_token.empty()) net.viewer_token = viewer_token;
    if (net.publisher_token.empty() || net.viewer_token.empty())
      return Fail(holo::InvalidArgument(
          "streaming needs a publisher and a viewer token: --publisher-token/--viewer-token, the env "
          "variables HOLO_PUBLISHER_TOKEN/HOLO_VIEWER_TOKEN, or publisher_token/viewer_token in --net-config"));
    holo::net::ServerHooks hooks;
    if (quiet) hooks.log = [](const std::string&) {};
    auto srv = holo::net::Server::Start(net, hooks);
    if (!srv.ok()) return Fail(srv.status());
    server = std::move(*srv);
    if (!quiet)
      spdlog::info("holoport-server: session server '{}' on {}:{}{}, max {} viewers", net.name, net.host,
                   server->port(), net.tls.enabled ? " (TLS)" : "", net.max_viewers);
  }
  // Active regions: tracked on every frame's mesh (the encode stage when
  // streaming, else the sink), published at once on the priority queue to
  // the viewers that subscribed to them.
  std::unique_ptr<holo::regions::RegionTracker> region_tracker;
  if (!regions_path.empty()) {
    auto rc = holo::regions::LoadRegionsConfig(regions_path);
    if (!rc.ok()) return Fail(rc.status().WithContext("--regions"));
    region_tracker = std::make_unique<holo::regions::RegionTracker>(std::move(*rc));
    if (server) server->AnnounceRegions(region_tracker->config().regions.size());
    if (!quiet)
      spdlog::info("holoport-server: {} active regions from {}", region_tracker->config().regions.size(),
                   regions_path);
  }
  std::vector<std::string> region_event_lines;  // JSON lines of enter/leave events for the stats output
  std::mutex region_event_mu;
  auto track_regions = [&](int64_t frame, int64_t capture_wall_us, const holo::Mesh& mesh,
                           holo::StageTimings* t) {
    if (!region_tracker) return;
    holo::Stopwatch sw;
    const double cpu0 = holo::ThreadCpuTimeMs();
    const holo::protocol::Regions& report = region_tracker->Update(frame, mesh.positions);
    t->regions_ms = sw.ElapsedMs();
    t->regions_cpu_ms = holo::ThreadCpuTimeMs() - cpu0;
    if (server) {
      holo::protocol::Header h;
      h.stream_id = holo::net::kSiteStreamId;
      h.sequence = static_cast<uint32_t>(frame);
      h.capture_time_us = capture_wall_us;
      server->PublishPriority(holo::net::MakeWireMessage(h, report, server->config().fragment_bytes));
    }
    for (const auto& g : report.regions) {
      if (g.state != holo::protocol::RegionState::kEnter && g.state != holo::protocol::RegionState::kLeave) continue;
      nlohmann::ordered_json j;
      j["region_event"] = holo::protocol::RegionStateName(g.state);
      j["region"] = g.name;
      j["frame"] = frame;
      j["occupied_litres"] = g.occupied_litres;
      j["capture_us"] = capture_wall_us;
      std::lock_guard<std::mutex> l(region_event_mu);
      region_event_lines.push_back(j.dump());
    }
  };
  // Writes the events noted since the last call (the sink's thread).
  auto region_event_output = [&](FILE* out) {
    std::vector<std::string> lines;
    {
      std::lock_guard<std::mutex> l(region_event_mu);
      lines.swap(region_event_lines);
    }
    for (const auto& line : lines) std::fprintf(out, "%s\n", line.c_str());
  };

  holo::net::SitePublisherOptions publish_options;
  publish_options.color = !no_color_stream;
  publish_options.geometry.position_step_m = static_cast<float>(position_step_mm * 1e-3);
  publish_options.color_options.jpeg_quality = jpeg_quality;
  if (reduced_geometry_codec == "auto") reduced_geometry_codec = truth_mesh || stream_step < 2 ? "same" : "g3";
  if (geometry_codec == "g3") publish_options.geometry.codec = holo::protocol::GeometryCodec::kG3;
  if (color_codec == "v1") publish_options.color_options.codec = holo::protocol::ColorCodec::kV1;
  publish_options.reduced = reduced;
  publish_options.reduced.enabled = layers > 1;
  if (reduced_geometry_codec != "same")
    publish_options.reduced.geometry_codec =
        reduced_geometry_codec == "g3" ? holo::protocol::GeometryCodec::kG3 : holo::protocol::GeometryCodec::kG1;
  if (reduced_color_codec != "same")
    publish_options.reduced.color_codec =
        reduced_color_codec == "v1" ? holo::protocol::ColorCodec::kV1 : holo::protocol::ColorCodec::kC1;
  if (holo::net::PublisherNeedsField(publish_options)) {
    if (truth_mesh || stream_step < 2)
      return Fail(holo::InvalidArgument(std::string(geometry_codec == "g3" ? "--geometry-codec" : "--reduced-geometry-codec") +
                                        " g3 needs the stream mesh (--stream-step 2..4, not --truth-mesh)"));
    publish_options.surface.position_step_m = static_cast<float>(g3_step_mm * 1e-3);
    if (holo::Status st = publish_options.surface.Check(); !st.ok()) return Fail(st.WithContext("--g3-step-mm"));
  }
  if (color_codec == "v1" || (publish_options.reduced.enabled && publish_options.reduced.color_codec ==
                                                                       holo::protocol::ColorCodec::kV1)) {
    publish_options.video.crf = video_crf;
    publish_options.video.preset = video_preset;
    if (holo::Status st = publish_options.video.Check(); !st.ok()) return Fail(st.WithContext("--video-crf"));
  }
  std::unique_ptr<holo::net::SitePublisher> publisher;
  if (server) publisher = std::make_unique<holo::net::SitePublisher>(server.get(), publish_options);

  auto masks = holo::ParseMaskSource(masks_name);
  if (!masks.ok()) return Fail(masks.status());

  holo::CaptureSiteOptions options;
  options.masks = *masks;
  options.background_frames = background_frames;
  options.color_calibration = !no_color_calibration;
  // Colour travels in the pods' images when they are streamed; per-vertex
  // colours are made only when something uses them (export, --mesh-colors,
  // a mesh-only stream, or no streaming at all).
  const bool streaming = !listen_spec.empty() || !net_config_path.empty();
  const bool vertex_colors = !streaming || no_color_stream || mesh_colors || !export_dir.empty();
  options.texture = !no_texture && vertex_colors;
  if (!vertex_colors) options.tsdf.integrate_color = false;
  options.tsdf.truncation_voxels = static_cast<float>(trunc_voxels);
  options.cleanup.target_triangles = decimate;
  options.cleanup.min_component_triangles = min_component;
  options.temporal = temporal;
  options.pipeline.serial = serial;
  options.pipeline.queue_capacity = queue;
  options.pipeline.pace_fps = pace;
  // A live site behaves like cameras: a frame the pipeline cannot take in
  // time is skipped (counted), and few frames are in flight, so latency
  // stays bounded when the machine cannot keep up.
  options.pipeline.drop_late_frames = pace > 0 && !keep_late;
  options.pipeline.max_in_flight = max_in_flight;
  options.pipeline.max_frames = frames;
  // A live site runs for hours: the summary's medians are over the newest
  // 9000–18000 frames (5–10 minutes at 30 fps) instead of keeping every frame.
  options.pipeline.keep_frame_timings = 9000;
  // The synthetic source's workload: its rig, studio, voxel and stream budget.
  std::optional<holo::Workload> workload;
  if (source_spec == "synthetic") {
    auto w = holo::GetWorkload(workload_name);
    if (!w.ok()) return Fail(w.status());
    workload = std::move(*w);
    if (app.count("--stream-triangles") == 0) stream_triangles = workload->stream_triangles;
  }
  options.stream_mesh = stream_step > 1 || stream_triangles > 0;
  options.stream.step = stream_step;
  options.stream.max_triangles = stream_triangles;
  options.stream_field = options.stream_mesh && holo::net::PublisherNeedsField(publish_options);
  // With G3 the viewers mesh the grid themselves (every marching-cubes
  // triangle, ~22 k at S8-QVGA): simplifying the site's own copy of the
  // stream mesh (regions, stats) to the budget would be work no one sees.
  // (With G3 on the reduced layer only, the full layer's G1 needs it.)
  if (options.stream_field && geometry_codec == "g3") options.stream.max_triangles = 0;
  options.full_mesh = !export_dir.empty();
  options.depth_filter.radius = depth_filter_radius;
  // PatchMatch's depth is already smooth within each plane's window, and its
  // errors are correlated over it: the filter made the stereo person fused
  // 0.5 mm farther from the truth (docs/stereo.md, "A dense last pass"), so
  // --depth stereo leaves it off unless asked for.
  if (depth_mode == "stereo" && app.count("--depth-filter") == 0) options.depth_filter.radius = 0;
  options.segment.depth_edge_band_px = segment_edge_band;
  if (depth_mode == "stereo" && app.count("--segment-edge-band") == 0)
    options.segment.depth_edge_band_px = holo::kStereoSegmentEdgeBandPx;
  options.depth_filter.sigma_at_1m_mm = static_cast<float>(depth_noise_mm);
  options.segment.depth_noise_at_1m_m = static_cast<float>(depth_noise_mm * 1e-3);
  options.tsdf.depth_noise_at_1m_mm = static_cast<float>(depth_noise_mm);
  options.smooth_full_mesh = !raw_full_mesh;

  // Sources. The studio is both the frame source and (empty room) the background.
  std::unique_ptr<holo::SyntheticStudio> studio, empty_room;
  std::unique_ptr<holo::DatasetReader> dataset, background_dataset;
  std::unique_ptr<holo::PrerenderedSource> prerendered;
  holo::FrameSource* source = nullptr;
  holo::FrameSource* background = nullptr;
  std::string source_name;
  if (workload) {
    holo::Rig rig = workload->rig;
    if (!rig_path.empty()) {
      auto loaded = holo::LoadRig(rig_path);
      if (!loaded.ok()) return Fail(loaded.status());
      rig = *loaded;
    }
    auto s = holo::SyntheticStudio::Create(rig, workload->studio);
    if (!s.ok()) return Fail(s.status());
    studio = std::move(*s);
    holo::StudioOptions empty = workload->studio;
    empty.empty_room = true;
    auto e = holo::SyntheticStudio::Create(rig, empty);
    if (!e.ok()) return Fail(e.status());
    empty_room = std::move(*e);
    source = studio.get();
    if (prerender > 0 && options.masks == holo::MaskSource::kTruth)
      return Fail(holo::InvalidArgument("--prerender cannot be combined with --masks truth (the studio renders the masks)"));
    background = empty_room.get();
    options.tsdf.voxel_size = voxel_mm > 0 ? static_cast<float>(voxel_mm * 1e-3) : workload->voxel_size_m;
    source_name = workload->name;
  } else if (source_spec.rfind("dataset:", 0) == 0) {
    auto d = holo::DatasetReader::Open(source_spec.substr(8));
    if (!d.ok()) return Fail(d.status());
    dataset = std::move(*d);
    source = dataset.get();
    options.tsdf.voxel_size = static_cast<float>((voxel_mm > 0 ? voxel_mm : 10.0) * 1e-3);
    source_name = source_spec;
    if (options.masks == holo::MaskSource::kTruth)
      return Fail(holo::InvalidArgument("--masks truth needs --source synthetic"));
  } else {
    return Fail(holo::InvalidArgument("--source must be 'synthetic' or 'dataset:PATH', got '" + source_spec + "'"));
  }
  if (reconstruct == "hull") {
    options.hull = true;
    // Carved straight at the stream mesh's resolution: a hull has no depth
    // noise for the stream mesh's box filter to average.
    if (options.stream_mesh && options.stream.step > 1) {
      options.tsdf.voxel_size *= static_cast<float>(options.stream.step);
      options.tsdf.truncation_voxels /= static_cast<float>(options.stream.step);
      options.stream.step = 1;
    }
  }
  // Stereo depth: the studio's IR pairs through PatchMatch replace its depth.
  std::unique_ptr<holo::FrameSource> stereo_source;
  if (depth_mode == "stereo") {
    // Pods send depth, whichever way they made it: a stereo pod matches its
    // own IR pair, and its calibration (depth and colour cameras, poses) is
    // checked like any pod's. A stereo source here would never be read.
    if (!pods_spec.empty())
      return Fail(holo::InvalidArgument(
          "--depth stereo is the local synthetic source's; with --pods each pod makes its depth: start the pods "
          "with holoport-pod --depth stereo (a --pods site takes stereo and direct pods alike)"));
    if (!studio) return Fail(holo::InvalidArgument("--depth stereo needs --source synthetic"));
    holo::StereoDepthOptions sdo;
    sdo.roi.enabled = stereo_roi == "on";
    sdo.roi.search_with_sgbm = stereo_search == "sgbm";
    sdo.patchmatch.temporal = stereo_temporal == "on";
    sdo.patchmatch.temporal_still = static_cast<float>(stereo_still);
    if (stereo_dense_pass == "off") sdo.patchmatch.final_window_step = 0;
    auto st = holo::StereoStudioSource::Create(studio.get(), sdo);
    if (!st.ok()) return Fail(st.status());
    stereo_source = std::move(*st);
    source = stereo_source.get();
  }
  // Frame sets made before the run and looped: the run costs a copy per
  // frame, as with cameras (with --depth stereo: as with pods that match
  // their own pairs; frames 0, 1, ... in order, so regions and last planes
  // work as live, ~0.3 s each).
  if (prerender > 0 && studio) {
    if (!quiet)
      spdlog::info("holoport-server: pre-rendering {} frame sets of {}{}...", prerender, source_name,
                   depth_mode == "stereo" ? " with stereo depth" : "");
    auto pr = holo::PrerenderedSource::Record(*source, prerender, /*loop=*/true, quiet);
    if (!pr.ok()) return Fail(pr.status());
    prerendered = std::move(*pr);
    source = prerendered.get();
  }
  // Pods over the network replace the local source (the rig stays: pods must match it).
  std::unique_ptr<holo::pods::PodHub> pod_hub;
  FILE* pod_stats = nullptr;  // set below, with the stats output
  if (!pods_spec.empty()) {
    holo::pods::PodHubOptions ho;
    holo::Status st = holo::pods::ParseHostPort(pods_spec, &ho.host, &ho.port);
    if (!st.ok()) return Fail(st.WithContext("--pods"));
    if (pod_token.empty()) return Fail(holo::InvalidArgument("--pods needs --pod-token (the token pods present)"));
    if (truth_mesh) return Fail(holo::InvalidArgument("--pods cannot be combined with --truth-mesh"));
    if (options.masks == holo::MaskSource::kTruth) return Fail(holo::InvalidArgument("--pods cannot use --masks truth"));
    ho.pod_token = pod_token;
    ho.grouping.tolerance_us = static_cast<int64_t>(pod_tolerance_ms * 1000);
    ho.grouping.timeout_us = static_cast<int64_t>(pod_timeout_ms * 1000);
    auto hub = holo::pods::PodHub::Start(source->rig(), ho, [quiet](const std::string& line) {
      if (!quiet) spdlog::info("holoport-server: pods: {}", line);
    });
    if (!hub.ok()) return Fail(hub.status());
    pod_hub = std::move(*hub);
    if (!quiet)
      spdlog::info("holoport-server: waiting for {} pods on port {}", source->rig().pods.size(), pod_hub->port());
    source = pod_hub.get();
    source_name = "pods:" + std::to_string(pod_hub->port());
    // The hub paces the site: sets leave when the pods deliver them.
    options.pipeline.pace_fps = 0;
    options.pipeline.drop_late_frames = false;
  }
  if (!background_spec.empty()) {
    if (background_spec.rfind("dataset:", 0) != 0)
      return Fail(holo::InvalidArgument("--background must be dataset:PATH, got '" + background_spec + "'"));
    auto d = holo::DatasetReader::Open(background_spec.substr(8));
    if (!d.ok()) return Fail(d.status());
    background_dataset = std::move(*d);
    background = background_dataset.get();
  }
  if (background == nullptr) {
    // A dataset without empty-room frames: segmentation and calibration are impossible.
    if (options.masks == holo::MaskSource::kSegment)
      return Fail(holo::InvalidArgument(
          "--masks segment needs empty-room frames: pass --background dataset:PATH, or use --masks dataset|none"));
    options.color_calibration = false;
  }
  if (!export_dir.empty()) {
    holo::Status s = holo::MakeDirs(export_dir);
    if (!s.ok()) return Fail(s);
  }
  FILE* stats_out = stdout;
  if (!stats_path.empty()) {
    stats_out = std::fopen(stats_path.c_str(), "w");
    if (stats_out == nullptr) return Fail(holo::Unavailable(stats_path + ": cannot open for writing"));
  }

  if (server) server->SetRig(source->rig());

  // The site's voice (--voice): published as stream 2, on the capture clock.
  // The camera timeline (pacing origin, frame → studio frame) tells the
  // synthetic voice what the cameras see at each instant.
  std::atomic<int64_t> capture_start_us{0};  // pipeline clock (RealClock); 0: not capturing yet
  double capture_period_us = pace > 0 ? 1e6 / pace : 1e6 / 30.0;
  std::function<int64_t(int64_t)> content_frame = [&](int64_t k) {
    if (truth_mesh) return truth_loop > 0 ? k % truth_loop : k;
    return prerendered ? prerendered->ContentFrame(k) : k;
  };
  std::unique_ptr<holo::voice::SiteVoice> site_voice;
  if (voice_spec != "off") {
    if (!server) return Fail(holo::InvalidArgument("--voice needs --listen or --net-config (the voice goes to viewers)"));
    holo::voice::SiteVoiceOptions vo;
    vo.source = voice_spec;
    holo::voice::StudioTimeFn studio_time;
    // The stereo source renders the studio's frame k as its frame k, so it keeps the camera timeline.
    const bool camera_timeline = studio && !pod_hub && (truth_mesh || pace > 0);
    if (voice_spec == "synthetic" && !camera_timeline)
      return Fail(holo::InvalidArgument(
          "--voice synthetic needs the synthetic studio as the frame source, paced like cameras (--pace FPS, or "
          "--truth-mesh): the syllables follow what the cameras see"));
    if (camera_timeline) {
      const double studio_fps = studio->options().fps;
      studio_time = [&, studio_fps](int64_t t_us) {
        const int64_t start = capture_start_us.load();
        if (start == 0 || t_us < start) return std::numeric_limits<double>::quiet_NaN();
        const double x = static_cast<double>(t_us - start) / capture_period_us;
        const auto k = static_cast<int64_t>(std::floor(x));
        const double f = x - static_cast<double>(k);
        const auto a = static_cast<double>(content_frame(k)), b = static_cast<double>(content_frame(k + 1));
        // Between camera frames the motion goes on (a loop starting over jumps).
        const double frame = std::abs(b - a) <= 1.0 ? a + f * (b - a) : a;
        return frame / studio_fps;
      };
    }  // else no camera timeline (pods, datasets): the voice is published from the start
    holo::net::Server* srv = server.get();
    auto v = holo::voice::SiteVoice::Start(vo, studio.get(), studio_time, [srv](const holo::protocol::AudioPose& a) {
      srv->PublishAudio(a, holo::net::kSiteVoiceStreamId);
    });
    if (!v.ok()) return Fail(v.status());
    site_voice = std::move(*v);
    if (!quiet) spdlog::info("holoport-server: voice: {}", site_voice->stats().description);
  }
  options.pipeline.on_start = [&](int64_t start_us) { capture_start_us = start_us; };
  pod_stats = stats_out;
  // Pod counters once a second (and per released set with --pod-set-stats).
  std::atomic<bool> pod_stats_done{false};
  std::thread pod_stats_thread;
  auto pod_lines = [&] {
    for (const auto& c : pod_hub->Pods()) std::fprintf(pod_stats, "%s\n", holo::pods::PodCountersJson(c).c_str());
    std::fprintf(pod_stats, "%s\n", holo::pods::HubCountersJson(pod_hub->counters()).c_str());
    std::fflush(pod_stats);
  };
  if (pod_hub) {
    if (pod_set_stats)
      pod_hub->SetOnSet([&](const holo::pods::SetInfo& i) {
        std::fprintf(pod_stats, "%s\n", holo::pods::SetInfoJson(i).c_str());
      });
    pod_stats_thread = std::thread([&] {
      while (!pod_stats_done) {
        for (int i = 0; i < 20 && !pod_stats_done; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(50));
        pod_lines();
      }
    });
  }
  struct PodStatsJoin {
    std::atomic<bool>* done;
    std::thread* t;
    ~PodStatsJoin() {
      *done = true;
      if (t->joinable()) t->join();
    }
  } pod_stats_join{&pod_stats_done, &pod_stats_thread};

  // Network stats line every 30 frames and a summary at the end.
  auto net_line = [&](int64_t frame) {
    if (!server) return;
    const NetSummary n = Summarize(*server);
    const holo::net::ServerCounters c = server->counters();
    nlohmann::ordered_json j;
    j["net"] = true;
    j["frame"] = frame;
    j["viewers"] = n.viewers;
    j["frames_sent"] = n.sent;
    j["frames_dropped"] = n.dropped;
    j["bytes_sent"] = n.bytes;
    j["max_queue"] = n.max_queue;
    j["rtt_ms_max"] = n.rtt_ms_max;
    j["refused"] = c.refused;
    j["violations"] = c.violations;
    j["audio_relayed"] = c.audio_relayed;
    j["keyframe_requests"] = c.keyframe_requests;
    if (server->num_layers() > 1) {
      j["viewers_reduced"] = n.on_reduced;
      j["layer_switches"] = c.layer_switches;
      j["layer0_mbps"] = server->LayerMbps(0);
      j["layer1_mbps"] = server->LayerMbps(1);
    }
    if (site_voice) {
      const holo::voice::SiteVoiceStats vs = site_voice->stats();
      j["voice_frames"] = vs.frames;
      j["voice_cpu_ms"] = vs.cpu_ms;
      j["voice_late_frames"] = vs.late_frames;
    }
    j["io_cpu_ms"] = server->IoCpuMs();
    std::fprintf(stats_out, "%s\n", j.dump().c_str());
    std::fflush(stats_out);
  };

  if (truth_mesh) {
    // Fast path: the studio's exact meshes and masks, no reconstruction.
    if (!studio) return Fail(holo::InvalidArgument("--truth-mesh needs --source synthetic"));
    const double fps = pace > 0 ? pace : 30.0;
    if (!quiet)
      spdlog::info("holoport-server: streaming the studio's ground truth ({}) at {:.0f} fps{}", source_name, fps,
                   frames < 0 ? " until interrupted" : "");
    holo::RgbdFrameSet fs;
    holo::StudioGroundTruth gt;
    // Pre-rendered loop: meshes, colour images and exact masks.
    struct Prerendered {
      holo::Mesh mesh;
      std::vector<holo::ImageRgb8> color;
      std::vector<holo::ImageGray8> mask;
    };
    std::vector<Prerendered> loop(static_cast<size_t>(truth_loop));
    for (int k = 0; k < truth_loop && !g_stop; ++k) {
      if (no_color_stream) {
        loop[k].mesh = studio->ForegroundMesh(k);
        continue;
      }
      studio->RenderFrame(k, &fs, &gt);
      loop[k].mesh = std::move(gt.foreground_mesh);
      for (size_t p = 0; p < fs.frames.size() && p < gt.mask.size(); ++p) {
        loop[k].color.push_back(fs.frames[p].color);
        loop[k].mask.push_back(gt.mask[p]);
      }
      if (!quiet && (k + 1) % 10 == 0) spdlog::info("  pre-rendered {}/{} frames", k + 1, truth_loop);
    }
    const auto start = std::chrono::steady_clock::now();
    capture_period_us = 1e6 / fps;
    capture_start_us = holo::RealClock::Instance().NowUs();
    int64_t late = 0;
    std::vector<double> render_ms, geom_ms, color_ms, pub_ms;
    int64_t i = 0;
    for (; (frames < 0 || i < frames) && !g_stop; ++i) {
      const auto due = start + std::chrono::microseconds(static_cast<int64_t>(i * 1e6 / fps));
      if (std::chrono::steady_clock::now() > due + std::chrono::milliseconds(5)) ++late;
      std::this_thread::sleep_until(due);
      // The frame of this slot, even when taken late (what the voice is in step with).
      const int64_t capture_us =
          holo::net::WallUs() -
          std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now() - due).count();
      holo::Stopwatch sw;
      std::vector<holo::net::PodColor> pods;
      holo::Mesh mesh;
      if (truth_loop > 0) {
        const Prerendered& pr = loop[static_cast<size_t>(i % truth_loop)];
        mesh = pr.mesh;
        for (size_t p = 0; p < pr.color.size(); ++p) pods.push_back({static_cast<uint16_t>(p), &pr.color[p], &pr.mask[p]});
      } else if (no_color_stream) {
        mesh = studio->ForegroundMesh(i);
      } else {
        studio->RenderFrame(i, &fs, &gt);
        mesh = std::move(gt.foreground_mesh);
        for (size_t p = 0; p < fs.frames.size() && p < gt.mask.size(); ++p)
          pods.push_back({static_cast<uint16_t>(p), &fs.frames[p].color, &gt.mask[p]});
      }
      const double r_ms = sw.ElapsedMs();
      holo::StageTimings rt;
      track_regions(i, capture_us, mesh, &rt);
      holo::net::PublishTimings pt;
      if (publisher) {
        holo::Status st = publisher->Publish(i, capture_us, mesh, pods, &pt);
        if (!st.ok()) return Fail(st);
      } else {
        // No server: encode anyway so the timings mean the same.
        holo::net::SitePublisherOptions o = publish_options;
        std::vector<uint8_t> blob;
        holo::Stopwatch g;
        holo::Status st = holo::protocol::EncodeGeometry(mesh, o.geometry, &blob);
        if (!st.ok()) return Fail(st);
        pt.geometry_ms = g.ElapsedMs();
        pt.geometry_bytes = blob.size();
      }
      render_ms.push_back(r_ms);
      geom_ms.push_back(pt.geometry_ms);
      color_ms.push_back(pt.color_ms);
      pub_ms.push_back(pt.publish_ms);
      nlohmann::ordered_json j;
      j["frame"] = i;
      j["vertices"] = mesh.num_vertices();
      j["triangles"] = mesh.num_triangles();
      j["truth_render_ms"] = r_ms;
      j["encode_geometry_ms"] = pt.geometry_ms;
      j["encode_color_ms"] = pt.color_ms;
      j["publish_ms"] = pt.publish_ms;
      j["geometry_bytes"] = pt.geometry_bytes;
      j["color_bytes"] = pt.color_bytes;
      if (pt.reduced) j["reduced_bytes"] = pt.reduced_bytes;
      j["viewers"] = pt.viewers;
      if (region_tracker) {
        j["regions_ms"] = rt.regions_ms;
        j["regions_cpu_ms"] = rt.regions_cpu_ms;
      }
      std::fprintf(stats_out, "%s\n", j.dump().c_str());
      region_event_output(stats_out);
      if ((i + 1) % 30 == 0) {
        net_line(i);
        if (!quiet)
          spdlog::info(
              "  frame {}: {} vertices, {:.1f} KB; render {:.1f} ms, encode G1 {:.1f}, C1 {:.1f}, publish {:.2f}; {} "
              "viewers",
              i + 1, mesh.num_vertices(), (pt.geometry_bytes + pt.color_bytes) / 1024.0, r_ms, pt.geometry_ms,
              pt.color_ms, pt.publish_ms, pt.viewers);
      }
    }
    net_line(i);
    if (stats_out != stdout) std::fclose(stats_out);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    auto med = [](std::vector<double> v) {
      if (v.empty()) return 0.0;
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      return v[v.size() / 2];
    };
    if (!quiet) {
      spdlog::info(
          "holoport-server: {} frames in {:.2f} s = {:.1f} fps ({} late); median ms: truth render {:.1f}, "
          "encode G1 {:.1f}, C1 {:.1f}, publish {:.2f}",
          i, wall, i / std::max(wall, 1e-9), late, med(render_ms), med(geom_ms), med(color_ms), med(pub_ms));
      if (server) {
        const NetSummary n = Summarize(*server);
        spdlog::info("holoport-server: {} viewers at the end; {} frames sent, {} dropped; io CPU {:.0f} ms", n.viewers,
                     n.sent, n.dropped, server->IoCpuMs());
      }
    }
    return 0;
  }

  if (!quiet)
    spdlog::info("holoport-server: {}, {} pods, masks={}, voxel {:.1f} mm, {} pipeline; learning background...",
                 source_name, source->rig().pods.size(), holo::MaskSourceName(options.masks),
                 options.tsdf.voxel_size * 1e3, serial ? "serial" : "concurrent");
  auto site = holo::CaptureSite::Create(source, background, studio.get(), options);
  if (!site.ok()) return Fail(site.status());

  int64_t done = 0;
  holo::Mesh last_mesh;
  int64_t last_frame = -1;
  // Encode stage (own thread): G1 + C1 of the frame into the work item.
  std::function<holo::Status(holo::FrameWork&)> encode;
  if (publisher) {
    encode = [&](holo::FrameWork& w) -> holo::Status {
      if (!w.encoded) w.encoded = std::make_shared<holo::net::EncodedFrame>();
      auto* e = static_cast<holo::net::EncodedFrame*>(w.encoded.get());
      // Capture time on the wall clock: now minus the time since acquisition.
      const int64_t capture_us = holo::net::WallUs() - (holo::RealClock::Instance().NowUs() - w.timings.acquired_us);
      // Regions first: their events go out before the frame is encoded.
      track_regions(w.frames.frame_index, capture_us, w.mesh, &w.timings);
      std::vector<holo::net::PodColor> pods;
      for (const auto& f : w.frames.frames)
        pods.push_back({static_cast<uint16_t>(f.pod_id), &f.color, &f.mask});
      return publisher->Encode(w.frames.frame_index, capture_us, w.mesh, pods, e,
                               options.stream_field ? &w.stream_field : nullptr);
    };
  }
  double cpu_window = holo::ProcessCpuTimeMs();
  std::vector<double> region_cpu_ms;  // per frame (sink thread)
  auto sink = [&](const holo::FrameWork& w) -> holo::Status {
    holo::StageTimings regions_t;
    if (!publisher) {  // no encode stage: regions here (no viewers to tell, only the stats)
      track_regions(w.frames.frame_index,
                    holo::net::WallUs() - (holo::RealClock::Instance().NowUs() - w.timings.acquired_us), w.mesh,
                    &regions_t);
    } else {
      regions_t = w.timings;
    }
    if (region_tracker) region_cpu_ms.push_back(regions_t.regions_cpu_ms);
    if (!snapshot_path.empty()) {
      last_mesh = w.mesh;
      last_frame = w.frames.frame_index;
    }
    const auto& t = w.timings;
    holo::net::PublishTimings pt;
    if (publisher && w.encoded) {
      auto* e = static_cast<holo::net::EncodedFrame*>(w.encoded.get());
      publisher->PublishEncoded(e);
      pt = e->timings;
    }
    nlohmann::ordered_json j;
    j["frame"] = w.frames.frame_index;
    j["vertices"] = w.mesh.num_vertices();
    j["triangles"] = w.mesh.num_triangles();
    j["full_triangles"] = w.full_mesh.num_triangles();
    j["acquire_ms"] = t.acquire_ms;
    j["segment_ms"] = t.segment_ms;
    j["fuse_ms"] = t.fuse_ms;
    j["mesh_ms"] = t.mesh_ms;
    j["simplify_ms"] = t.simplify_ms;
    j["texture_ms"] = t.texture_ms;
    j["encode_ms"] = t.encode_ms;
    j["latency_ms"] = t.latency_ms();
    j["encoded_latency_ms"] = t.encoded_latency_ms();
    if (region_tracker) {
      j["regions_ms"] = regions_t.regions_ms;
      j["regions_cpu_ms"] = regions_t.regions_cpu_ms;
    }
    if (serial) {  // CPU of each stage (one at a time: the process's CPU while it ran)
      j["acquire_cpu_ms"] = t.acquire_cpu_ms;
      j["segment_cpu_ms"] = t.segment_cpu_ms;
      j["fuse_cpu_ms"] = t.fuse_cpu_ms;
      j["mesh_cpu_ms"] = t.mesh_cpu_ms;
      j["simplify_cpu_ms"] = t.simplify_cpu_ms;
      j["texture_cpu_ms"] = t.texture_cpu_ms;
      j["encode_cpu_ms"] = t.encode_cpu_ms;
    }
    if (publisher) {
      j["encode_geometry_ms"] = pt.geometry_ms;
      j["encode_color_ms"] = pt.color_ms;
      j["encode_geometry_cpu_ms"] = pt.geometry_cpu_ms;
      j["encode_color_cpu_ms"] = pt.color_cpu_ms;
      j["publish_ms"] = pt.publish_ms;
      j["geometry_bytes"] = pt.geometry_bytes;
      j["color_bytes"] = pt.color_bytes;
      j["color_keyframe"] = pt.color_keyframe;
      if (pt.geometry_fallback) j["geometry_fallback"] = true;  // G3 frame sent as G1
      if (pt.reduced) {
        j["reduced_bytes"] = pt.reduced_bytes;
        j["reduced_ms"] = pt.reduced_ms;
        j["reduced_cpu_ms"] = pt.reduced_cpu_ms;
      }
      j["viewers"] = pt.viewers;
    }
    std::fprintf(stats_out, "%s\n", j.dump().c_str());
    region_event_output(stats_out);
    if (pod_hub) {
      // Pod capture (site clock) → textured (and encoded) mesh.
      int64_t capture = 0;
      int present = 0;
      for (const auto& f : w.frames.frames)
        if (f.timestamp_us != 0) {
          capture = capture == 0 ? f.timestamp_us : std::min(capture, f.timestamp_us);
          ++present;
        }
      nlohmann::ordered_json pj;
      pj["pod_frame"] = w.frames.frame_index;
      pj["pods_present"] = present;
      pj["capture_us"] = capture;
      pj["capture_latency_ms"] = capture ? static_cast<double>(holo::net::WallUs() - capture) * 1e-3 : -1.0;
      std::fprintf(stats_out, "%s\n", pj.dump().c_str());
    }
    if (!export_dir.empty()) {
      char path[4096];
      FrameFileName(path, sizeof(path), export_dir, w.frames.frame_index);
      HOLO_RETURN_IF_ERROR(holo::WritePly(path, w.full_mesh.empty() ? w.mesh : w.full_mesh));
    }
    ++done;
    if (done % 30 == 0) {
      net_line(w.frames.frame_index);
      // Whole-process CPU per frame over the last 30 frames (all stages, encode and network).
      const double now_cpu = holo::ProcessCpuTimeMs();
      nlohmann::ordered_json site_line;
      site_line["site"] = true;
      site_line["frame"] = w.frames.frame_index;
      site_line["cpu_ms_per_frame"] = (now_cpu - cpu_window) / 30.0;
      std::fprintf(stats_out, "%s\n", site_line.dump().c_str());
      std::fflush(stats_out);
      if (!quiet)
        spdlog::info(
            "  frame {}: {} triangles; segment {:.1f} ms, fuse {:.1f}, mesh {:.1f}, simplify {:.1f}, texture {:.1f}, "
            "encode {:.1f} (G1 {} B, C1 {} B); latency {:.1f} ms; {:.1f} CPU-ms per frame; {} viewers",
            done, w.mesh.num_triangles(), t.segment_ms, t.fuse_ms, t.mesh_ms, t.simplify_ms, t.texture_ms, t.encode_ms,
            pt.geometry_bytes, pt.color_bytes, t.encoded_latency_ms(), (now_cpu - cpu_window) / 30.0, pt.viewers);
      cpu_window = now_cpu;
    }
    return holo::OkStatus();
  };
  // Ctrl-C / SIGTERM: stop the pipeline (from a watcher thread; signal
  // handlers may only set a flag).
  std::atomic<bool> run_done{false};
  std::thread watcher([&] {
    while (!run_done && !g_stop) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (g_stop) {
      (*site)->Stop();
      if (pod_hub) pod_hub->Stop();  // wakes an acquire waiting for pods
    }
  });
  auto stats = (*site)->Run(sink, encode);
  run_done = true;
  watcher.join();
  if (server) net_line(-1);
  if (pod_hub) {
    pod_stats_done = true;
    if (pod_stats_thread.joinable()) pod_stats_thread.join();
    pod_hub->Stop();
    pod_lines();
  }
  if (stats_out != stdout) std::fclose(stats_out);
  if (!stats.ok()) return Fail(stats.status());
  if (!snapshot_path.empty() && last_frame >= 0) {
    holo::NovelViewOptions nv;
    nv.intrinsics = holo::Intrinsics::FromFov(480, 480, 60.0);
    const holo::NovelView view = holo::MakeNovelViews(nv)[0];
    holo::ImageRgb8 ours, truth;
    holo::Status s = holo::RenderMesh(last_mesh, view.camera, &ours, nullptr, nullptr);
    if (!s.ok()) return Fail(s);
    std::vector<const holo::ImageRgb8*> tiles;
    if (studio) {
      studio->RenderView(prerendered ? prerendered->ContentFrame(last_frame) : last_frame, view.camera, &truth,
                         nullptr, nullptr);
      tiles.push_back(&truth);
    }
    tiles.push_back(&ours);
    s = holo::WriteImageRgb8(snapshot_path, holo::TileImages(tiles, 2));
    if (!s.ok()) return Fail(s);
    if (!quiet) spdlog::info("holoport-server: snapshot of frame {} in {}", last_frame, snapshot_path);
  }
  const holo::StageTimings m = holo::MedianTimings(*stats);
  if (!quiet && region_tracker && !region_cpu_ms.empty()) {
    std::vector<double> v = region_cpu_ms;
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    spdlog::info("holoport-server: active regions: {} events, median {:.3f} CPU-ms per frame over {} regions",
                 region_tracker->events(), v[v.size() / 2], region_tracker->config().regions.size());
  }
  if (!quiet)
    spdlog::info(
        "holoport-server: {} frames in {:.2f} s = {:.1f} fps ({} camera frames skipped), {:.1f} CPU-ms per frame; "
        "median ms: acquire {:.1f}, "
        "segment {:.1f}, fuse {:.1f}, mesh {:.1f}, simplify {:.1f}, texture {:.1f}, encode {:.1f}; median latency "
        "{:.1f} ms "
        "({}){}{}",
        stats->frames, stats->wall_seconds, stats->fps, stats->dropped_frames,
        stats->frames > 0 ? stats->cpu_ms / static_cast<double>(stats->frames) : 0.0, m.acquire_ms, m.segment_ms,
        m.fuse_ms, m.mesh_ms, m.simplify_ms, m.texture_ms, m.encode_ms, holo::MedianLatencyMs(*stats),
        pace > 0 ? "paced" : "unpaced: includes waiting in queues; use --pace for live latency",
        export_dir.empty() ? "" : "; meshes in ", export_dir);
  return 0;
}
