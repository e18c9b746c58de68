// holoport-pod: one RGB-D pod as its own process (docs/capture.md). It
// renders its own view of the synthetic studio (or reads its images from a
// dataset folder), with the studio's depth or, as an active-stereo pod
// (--depth stereo), depth matched from its own IR pair; stamps every frame
// with its own clock, compresses it and streams it to a site started with
// `holoport-server --pods PORT`.
#include <CLI/CLI.hpp>

#include <atomic>
#include <csignal>
#include <cstdio>

#include "common/log.h"
#include "server/pods/pod_runner.h"

namespace {
std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }
}  // namespace

int main(int argc, char** argv) {
  holo::pods::PodRunOptions o;
  CLI::App app{"holoport-pod: one RGB-D pod streaming its frames to a site's pod port (holoport-server --pods)"};
  holo::AddLogLevelOption(app);
  app.add_option("--site", o.site, "the site's pod port, HOST:PORT")->capture_default_str();
  app.add_option("--token", o.token, "the site's pod token (holoport-server --pod-token); required");
  app.add_option("--pod", o.pod_id, "this pod's id in the rig; required");
  app.add_option("-w,--workload", o.workload, "synthetic source: S8-QVGA or S8-VGA (content and rig)")
      ->capture_default_str();
  app.add_option("--rig", o.rig_path, "synthetic source: this rig file instead of the workload's");
  app.add_option("--dataset", o.dataset, "read this pod's frames from a dataset folder (looped) instead of the studio");
  app.add_option("--fps", o.fps, "camera rate; frames are triggered at wall-clock slots k/fps")->capture_default_str();
  app.add_option("-n,--frames", o.frames, "stop after this many frames (-1: until interrupted)")->capture_default_str();
  app.add_option("--prerender", o.prerender,
                 "studio: render this many frames first (with --depth stereo: and match them) and loop them "
                 "(0: render live)")
      ->capture_default_str();
  app.add_option("--depth", o.depth,
                 "studio: direct (the studio's depth-sensor model) or stereo (an active-stereo pod: PatchMatch on "
                 "its own IR pair, ~0.25 s of CPU per QVGA frame; docs/stereo.md); not with --dataset")
      ->check(CLI::IsMember({"direct", "stereo"}))
      ->capture_default_str();
  app.add_option("--stereo-threads", o.stereo_threads, "--depth stereo: PatchMatch threads (0: every core)")
      ->capture_default_str();
  app.add_option("--stereo-dense-pass", o.stereo_dense_pass,
                 "--depth stereo: on (a last pass with a window of adjacent pixels: a closer fused person for "
                 "~1.2x the matching CPU; docs/stereo.md) or off")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  app.add_option("--stereo-still", o.stereo_still,
                 "--depth stereo: a region's pixels whose window (and their match's) changed since the previous frame by at most K times the camera's noise level keep their planes unvisited (0: off; 1.0: the site's masks, mesh and view as good, its CPU not measurably lower yet; docs/stereo.md)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  app.add_option("--stereo-temporal", o.stereo_temporal,
                 "--depth stereo: on (a region starts from the previous frame's planes instead of a half-resolution "
                 "pass: ~0.77x the CPU and a closer fused mesh; whole pairs run the full algorithm; docs/stereo.md) "
                 "or off")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  app.add_option("--stereo-search", o.stereo_search,
                 "--depth stereo: where a pod's whole pair is due (every 15 frames, the first, when the person reaches the region's edge, nobody found): sgbm (search it with OpenCV's SGBM, ~1/20 of PatchMatch's CPU, then PatchMatch only around the person found; no depth elsewhere on those frames) or patchmatch (the whole pair through PatchMatch); docs/stereo.md")
      ->check(CLI::IsMember({"sgbm", "patchmatch"}))
      ->capture_default_str();
  app.add_option("--stereo-roi", o.stereo_roi,
                 "--depth stereo: on (match the IR pair only around the person, from the previous frame's stereo "
                 "depth, the whole pair every 15 frames and when the person reaches the region's edge "
                 "(see --stereo-search); docs/stereo.md) or off (every pair whole)")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  app.add_option("--clock-offset-ms", o.clock_offset_ms, "simulate a pod clock offset from the system clock, ms")
      ->capture_default_str();
  app.add_option("--clock-drift-ppm", o.clock_drift_ppm, "simulate a pod clock drift, parts per million")
      ->capture_default_str();
  app.add_option("--jpeg-quality", o.jpeg_quality, "colour (C1 JPEG) quality 1..100")->capture_default_str();
  app.add_option("--depth-codec", o.depth_codec, "depth codec: d2 (plane prediction + context-modelled rANS) or d1 (zstd)")
      ->check(CLI::IsMember({"d1", "d2"}))
      ->capture_default_str();
  app.add_option("--zstd-level", o.zstd_level, "depth (D1) zstd level 1..19")->capture_default_str();
  app.add_option("--queue", o.queue_frames, "frames waiting for the link; when full the oldest is dropped")
      ->capture_default_str();
  app.add_option("--stats", o.stats_path, "write the pod's counters as JSON lines once a second to this file (- = stdout)");
  app.add_flag("-q,--quiet", o.quiet, "no progress output");
  CLI11_PARSE(app, argc, argv);
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  const holo::Status s = holo::pods::RunPod(o, g_stop);
  if (!s.ok()) {
    spdlog::error("holoport-pod: {}", s.ToString());
    return s.code() == holo::StatusCode::kInvalidArgument ? 2 : 1;
  }
  return 0;
}
