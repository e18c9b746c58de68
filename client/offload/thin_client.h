// The thin client of networked render offload (docs/offload.md): connects to
// a render host (Hello with role thin client), sends its head pose at display
// rate, receives RenderedFrames, decodes each and reprojects the newest one
// to the newest pose at every display tick. Pose source: a head trace
// (recorded or synthetic), played in real time from `trace_start_s`.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "client/pose/head_pose.h"
#include "client/reproject/rendered_view.h"
#include "client/reproject/reproject.h"
#include "common/image.h"
#include "common/status.h"

namespace holo::offload {

struct ThinClientOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 0;
  std::string token;
  std::string name = "thin-client";
  int width = 640, height = 360;  // display (one eye)
  double hfov_deg = 90.0;
  double rate_hz = 60.0;          // display and pose rate
  int frames = 120;               // display frames to show (after the first received image)
  double max_wait_s = 10.0;       // give up if no image arrives for this long
  std::vector<pose::PoseSample> trace;  // world-frame eye poses (required)
  double trace_start_s = 1.0;     // trace time at the first tick (the trace loops)
  reproject::ReprojectMethod method = reproject::ReprojectMethod::kPlane;
  // Simulated network latency: a received frame becomes usable this much later.
  double receive_delay_ms = 0;
  // Both eyes (the render host must run with --stereo too): RenderedFrames on
  // stream 1 (left) and 2 (right), each reprojected to its eye, the eyes
  // ±ipd/2 along the head's x axis. PNGs are side by side (left | right).
  bool stereo = false;
  double ipd_m = 0.064;
  bool keep_stale = false;        // also produce the stale image (no reprojection) per display
  std::string out_dir;            // PNGs (every png_every-th display) + stats.json
  int png_every = 10;
  Status Check() const;
};

// One display tick.
struct DisplayedFrame {
  int index = 0;
  int64_t display_us = 0;         // trace clock
  pose::PoseSample true_pose;     // the pose at display (what the truth is rendered at); stereo: the left eye's
  pose::PoseSample true_pose_right;  // stereo: the right eye's pose at display
  int64_t frame_index = -1;       // site content frame the host rendered
  int64_t pose_time_us = 0;       // the pose sample the host's prediction started from
  reproject::RenderedView source; // the received image (decoded)
  ImageRgb8 shown;                // reprojected to true_pose
  ImageRgb8 stale;
  reproject::RenderedView source_right;  // stereo (empty until a right image arrived)
  ImageRgb8 shown_right;                // keep_stale: the received image cropped to the display FOV
  double black_border_fraction = 0;
  double reproject_ms = 0;
  double pose_to_photon_ms = 0;   // display time (= the pose shown: this tick's) − pose_time_us
};

struct ThinClientResult {
  int displayed = 0;
  int frames_received = 0;
  int frames_used = 0;            // distinct received frames shown
  double fps = 0;                 // displayed frames per second
  double received_fps = 0;
  double mean_pose_to_photon_ms = 0, p95_pose_to_photon_ms = 0;
  double mean_reproject_ms = 0;
  double mean_black_border = 0;
  double mean_frame_bytes = 0;
  uint64_t bytes_received = 0;
  double duration_s = 0;
};

// Runs until `frames` display ticks have shown an image. `on_display` (if
// set) sees every tick that showed an image.
StatusOr<ThinClientResult> RunThinClient(const ThinClientOptions& options,
                                         const std::function<void(const DisplayedFrame&)>& on_display = {});

}  // namespace holo::offload
