// The site as a pod hub: pods (holoport-pod, one process per camera, on this
// machine or others) connect to the hub's port with role `pod`, a pod token
// and their calibration; the hub estimates each pod's clock offset with
// Ping/Pong, decodes their frames (depth D1, colour C1), groups them into
// frame sets by capture time (FrameGrouper) and hands the sets to the
// capture pipeline as a FrameSource. Missing pods are allowed: their slot
// holds an empty frame (depth 0 everywhere), which fusion skips.
//
// Handshake (PROTOCOL.md §3.1): pod → Hello (role pod, pod token), pod →
// Rig (exactly its own pod's calibration), hub → Welcome or Refuse (BAD_TOKEN,
// ROLE_NOT_ALLOWED, BAD_CALIBRATION with the field that disagrees). A pod
// that reconnects (restarted, or its link came back) takes its slot again; a
// second connection for a pod id replaces the first. A malformed message, a
// frame of another pod, or a frame whose size disagrees with the calibration
// closes that pod's connection only.
//
// Threads: one accept thread, one thread per pod connection (it decodes
// that pod's frames, so decoding runs in parallel across pods); Next() runs
// on the pipeline's acquire thread.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "common/frame_source.h"
#include "common/log.h"
#include "common/rig.h"
#include "common/status.h"
#include "protocol/messages.h"
#include "server/pods/clock_sync.h"
#include "server/pods/frame_grouper.h"
#include "server/pods/socket_io.h"

namespace holo::pods {

struct PodHubOptions {
  // Where pods connect: host ("" = all interfaces) and port (0 = any free port).
  std::string host;
  uint16_t port = 0;
  // The pods' access token (required, compared in constant time).
  std::string pod_token;
  GrouperOptions grouping;
  // Ping period per pod, ms: the offset estimate follows drift at this rate.
  int ping_interval_ms = 100;
  // Hello + calibration must arrive within this, ms.
  int handshake_timeout_ms = 3000;
  // A pod silent this long is closed, ms (a pod sends frames at its rate
  // and answers pings).
  int idle_timeout_ms = 3000;
  // Connections at once (handshakes included); more are closed at accept.
  // 0: twice the rig's pods + 8.
  size_t max_connections = 0;
  // Frame sets waiting for the pipeline; when it falls behind, the oldest
  // waiting set is dropped (a live site never queues up latency).
  size_t output_sets = 2;
  // Calibration agreement with the rig: intrinsics (fx, fy, cx, cy) in
  // pixels, distortion coefficients, translation in mm, rotation in degrees.
  // Image sizes must match exactly.
  double max_intrinsics_px = 0.5;
  double max_distortion = 1e-3;
  double max_translation_mm = 2.0;
  double max_rotation_deg = 0.2;
  protocol::Limits limits;
  Status Check() const;
};

// One pod's counters (a snapshot).
struct PodCounters {
  int pod_id = 0;
  std::string name;
  bool connected = false;
  std::string peer;              // "address:port" of the current (or last) connection
  uint64_t connections = 0;      // accepted handshakes (1 + reconnects)
  uint64_t received = 0;         // PodFrames received and decoded
  uint64_t late = 0;             // arrived after their set had left
  uint64_t duplicates = 0;       // a second frame for the same set
  uint64_t dropped = 0;          // received but never fused: late, duplicate, no clock offset yet, or the
                                 // pipeline fell behind and its set was dropped
  uint64_t bytes = 0;            // PodFrame payload bytes
  double offset_ms = 0;          // pod clock − site clock (estimate)
  double rtt_ms = 0;             // RTT of the ping the estimate uses
  double jitter_ms = 0;          // smoothed |change| of capture → arrival transit time (RFC 3550 style)
  double decode_cpu_ms = 0;      // CPU time decoding this pod's frames (its connection thread)
  std::string last_error;        // why its last connection closed
};

struct HubCounters {
  uint64_t accepted = 0;         // TCP connections
  uint64_t refused = 0;          // handshakes refused (token, role, calibration)
  uint64_t violations = 0;       // connections closed for a malformed message
  uint64_t sets_released = 0;    // frame sets the grouper released
  uint64_t sets_complete = 0;    // ... with every expected pod
  uint64_t sets_taken = 0;       // ... taken by the pipeline (Next)
  uint64_t sets_dropped = 0;     // ... dropped because the pipeline fell behind
};

// What the hub knows of a released frame set (for benchmarks and logs).
struct SetInfo {
  int64_t index = 0;             // sets released so far (0, 1, 2, ...)
  int64_t time_us = 0;           // capture time, site clock (system clock, µs since the epoch)
  int64_t released_us = 0;       // when the grouper released it, site clock
  int present = 0;
  bool complete = false;
  int64_t spread_us = 0;         // sync error: max − min capture time of its frames
  uint64_t pods_mask = 0;        // bit i: rig pod i present
};

class PodHub final : public FrameSource {
 public:
  // Starts listening. `log` receives connection events and refusals (null: the
  // log, common/log.h, refusals and failures as warnings).
  static StatusOr<std::unique_ptr<PodHub>> Start(const Rig& rig, PodHubOptions options,
                                                 std::function<void(const std::string&)> log = {});
  ~PodHub() override;  // Stop()
  PodHub(const PodHub&) = delete;
  PodHub& operator=(const PodHub&) = delete;

  uint16_t port() const { return port_; }

  // FrameSource. Next blocks until a set is released, filling `out` with one
  // frame per rig pod (missing pods: empty frames of the calibrated size,
  // timestamp 0; present ones: capture time on the site clock). OutOfRange
  // after Stop().
  const Rig& rig() const override { return rig_; }
  Status Next(RgbdFrameSet* out) override;
  int64_t num_frames() const override { return -1; }
  Status Seek(int64_t index) override;
  // Skips without waiting: a live source drops what it cannot deliver.
  Status Skip(int64_t n) override;

  // Called (on a pod thread, outside the hub's locks) for every released set.
  void SetOnSet(std::function<void(const SetInfo&)> fn);

  std::vector<PodCounters> Pods() const;
  HubCounters counters() const;
  // Sets Next() has delivered; the info of the last one.
  SetInfo last_set() const;

  // Closes the listener and every pod, wakes Next(). Idempotent.
  void Stop();

 private:
  struct PodState;
  struct Conn;
  PodHub(const Rig& rig, PodHubOptions options, std::function<void(const std::string&)> log);
  void AcceptLoop();
  void Serve(std::shared_ptr<Conn> conn);
  Status Handshake(Conn& conn, int* pod_index);
  Status HandleFrame(int pod, const protocol::PodFrame& f, int64_t arrival_us);
  void ReleaseReady(int64_t now_us);  // hub lock held
  // Through the hook when one is set, else the log at `level`.
  void Log(const std::string& line, spdlog::level::level_enum level = spdlog::level::info);

  Rig rig_;
  PodHubOptions options_;
  std::function<void(const std::string&)> log_;
  std::function<void(const SetInfo&)> on_set_;
  Socket listener_;
  uint16_t port_ = 0;
  std::atomic<bool> stop_{false};
  std::thread accept_thread_;

  mutable std::mutex mu_;  // everything below
  std::condition_variable cv_;
  std::vector<std::unique_ptr<PodState>> pods_;
  std::vector<std::shared_ptr<Conn>> conns_;
  std::vector<std::pair<uint64_t, std::thread>> threads_;  // by connection id
  std::vector<uint64_t> finished_;  // connections whose thread has ended (joined by the accept loop)
  FrameGrouper grouper_;
  std::deque<std::pair<SetInfo, GroupedSet>> ready_;
  std::vector<SetInfo> released_info_;  // released since the last callback round
  HubCounters counters_;
  SetInfo last_set_;
  uint64_t next_conn_id_ = 1;
};

// One JSON object (one line, no newline) per pod / for the hub / per set,
// as the server's stats output prints them (docs/capture.md).
std::string PodCountersJson(const PodCounters& c);
std::string HubCountersJson(const HubCounters& c);
std::string SetInfoJson(const SetInfo& s);

// Checks a pod's calibration against the rig's pod of the same id: OK, or
// InvalidArgument naming the field and both values ("pod 3 (pod-3):
// depth.fx 530 differs from the rig's 525 by more than 0.5 px").
Status CheckPodCalibration(const Rig& rig, const PodCalibration& pod, const PodHubOptions& options, int* index);

}  // namespace holo::pods
