// holoport-pod's loop as a library (so tests and benchmarks run the same
// code): produce this pod's frames at the camera rate, stamp them with the
// pod's clock, compress them (depth D2 or D1, colour C1) and hand them to a
// PodClient.
//
// Frames come from the synthetic studio rendering only this pod (the
// studio's content, noise and colour variation depend on the pod id, not on
// the other pods) or from a dataset folder (this pod's images). With depth
// "stereo" a studio pod is an active-stereo pod: its depth is not the
// studio's depth-sensor model but PatchMatch on its own IR pair
// (docs/stereo.md), computed in the pod, so the site receives depth as from
// any pod and needs no stereo of its own. The camera is triggered at
// wall-clock slots k / fps (as pods on a shared trigger are); a slot the pod
// cannot make in time is skipped. The pod's clock is the system clock plus a
// simulated offset and drift (--clock-offset-ms, --clock-drift-ppm), to test
// the site's offset estimation.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"
#include "server/stereo/patchmatch.h"

namespace holo::pods {

struct PodRunOptions {
  std::string site = "127.0.0.1:7100";  // the site's pod port, HOST:PORT
  std::string token;
  int pod_id = -1;                      // id in the rig (required)
  std::string workload = "S8-QVGA";     // synthetic source: content and rig
  std::string rig_path;                 // a rig file instead of the workload's
  std::string dataset;                  // a dataset folder instead of the studio
  double fps = 30;
  int64_t frames = -1;                  // stop after this many slots (-1: until stopped)
  int prerender = 0;                    // studio: render this many frames first and loop them (0: render live)
  std::string depth = "direct";         // studio: "direct" (its depth-sensor model) or "stereo" (PatchMatch on the IR pair)
  int stereo_threads = 1;               // depth stereo: PatchMatch threads (0: every core)
  std::string stereo_roi = "on";        // depth stereo: "on" (match around the person, stereo_roi.h) or "off"
  std::string stereo_search = "sgbm";    // depth stereo: whole pairs due searched with "sgbm" first, or "patchmatch" whole
  std::string stereo_temporal = "on";   // depth stereo: "on" (regions start from the last planes) or "off"
  double stereo_still = PatchMatchOptions{}.temporal_still;  // depth stereo: PatchMatchOptions::temporal_still (0: off)
  std::string stereo_dense_pass = "on";  // depth stereo: "on" (PatchMatchOptions::final_window_step) or "off"
  double clock_offset_ms = 0;           // simulated pod clock: offset against the system clock
  double clock_drift_ppm = 0;           // ... and drift (parts per million)
  int jpeg_quality = 60;                // colour C1 quality (60: ~24 KB per QVGA frame; depth D2 ~70 KB, D1 ~85 KB)
  std::string depth_codec = "d2";       // "d2" (PROTOCOL.md §8.2) or "d1" (§8.1)
  int zstd_level = 1;                   // depth D1 level
  int queue_frames = 3;                 // frames waiting for the link
  std::string stats_path;               // JSON lines of the pod's counters, once a second ("-": stdout)
  bool quiet = false;
  Status Check() const;
};

// This pod's frames by trigger slot: the studio (direct or stereo depth,
// rendered live or pre-rendered and looped) or a dataset (looped). RunPod's
// producer, also for tests that need a pod's frames without a socket.
class PodFrames {
 public:
  virtual ~PodFrames() = default;
  // The frame of trigger slot `slot` (>= 0).
  virtual Status Get(int64_t slot, RgbdFrame* out) = 0;
  // The pod's calibration (what it sends the site).
  const PodCalibration& calibration() const { return calibration_; }

 protected:
  PodCalibration calibration_;
};

// The producer `options` name (pod id, workload or rig or dataset, depth,
// prerender; the options must pass Check()). Pre-rendering (and, with depth
// stereo, matching) happens here; `log` gets progress lines, may be empty.
StatusOr<std::unique_ptr<PodFrames>> OpenPodFrames(const PodRunOptions& options,
                                                   const std::function<void(const std::string&)>& log);

// Runs until `stop` becomes true, `frames` are done, or the site refuses the
// pod. Returns the refusal (InvalidArgument with the site's reason) or a
// set-up error; OK otherwise.
Status RunPod(const PodRunOptions& options, const std::atomic<bool>& stop);

}  // namespace holo::pods
