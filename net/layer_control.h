// Quality layers: which of a site's layers (0 = full, 1 = reduced, ...) one
// viewer receives, decided from what its connection shows — the send queue,
// dropped frames and the throughput its socket takes — and switched only
// where the viewer can decode without a gap (docs/sessions.md, "Quality
// layers").
//
// The site encodes every frame once per layer (SitePublisher); the session
// server offers each viewer the frames of its layer only. This class is the
// per-viewer policy, free of sockets and clocks (times are passed in, µs of a
// steady clock), so that its decisions are unit-tested exactly.
//
// Down: when a frame is dropped from the viewer's queue, when ≥ 2 frames wait
// for `down_queue_s`, or when the measured throughput of a mostly busy socket
// stays below `down_throughput` × the current layer's bitrate.
// Up: after `up_hold_s` on the lower layer with no queue build-up and a
// measured throughput of at least `up_headroom` × the upper layer's bitrate;
// within `probe_s` of such a probe any backlog ends it.
// A return down within `stable_s` of going up doubles the hold (up to
// `max_up_hold_s`), so a viewer on a link between the two layers probes up
// ever more rarely instead of oscillating; `stable_s` on a layer resets it.
// A switch is decided at once but takes effect at the first *independent*
// frame of the new layer (every part decodes without earlier frames: G1/C1
// always, V1 at a key frame), so the picture never waits on a broken chain.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "common/status.h"

namespace holo::net {

inline constexpr int kMaxLayers = 4;

struct LayerPolicy {
  // Off: every viewer stays on the lowest layer its quality cap allows.
  bool adaptive = true;
  // ≥ 2 frames waiting behind the one in flight for this long → down, s.
  double down_queue_s = 0.25;
  // Bytes in the kernel's send buffer not yet sent count as a backlog too
  // when they would take longer than this to send at the current layer's
  // bitrate, s: a socket buffer hides a slow link from the frame queue.
  double kernel_backlog_s = 0.15;
  // Throughput is judged over a decaying window of this length, s, and only
  // when the socket was busy (blocked on the viewer) for at least
  // `busy_fraction` of it: an idle socket says nothing about its limit.
  double throughput_window_s = 1.0;
  double busy_fraction = 0.5;
  // Busy socket taking less than this × the current layer's bitrate → down.
  double down_throughput = 0.9;
  // Up: time on the lower layer first (doubling after a failed probe, up to
  // max_up_hold_s), and throughput ≥ up_headroom × the upper layer's bitrate.
  double up_hold_s = 2.0;
  double max_up_hold_s = 32.0;
  double up_headroom = 1.3;
  // A layer kept this long without going down resets the hold to up_hold_s.
  double stable_s = 20.0;
  // For this long after a probe up, any backlog (≥ 2 frames waiting) sends
  // the viewer back at once: a failed probe costs a frame or two, not
  // down_queue_s of growing delay.
  double probe_s = 1.0;

  Status Check() const;
};

class LayerController {
 public:
  explicit LayerController(LayerPolicy policy = {});

  // Number of layers the site publishes (1..kMaxLayers); layers beyond it
  // are never chosen.
  void SetNumLayers(int n);
  // The viewer's own cap (Control set quality): never above this layer's
  // quality, i.e. never a layer below `min_layer`.
  void SetMinLayer(int min_layer, int64_t now_us);
  // Control set quality 0..10 → the lowest layer index allowed, for `num_layers`
  // layers: 10..5 allow the full layer of two, 4..0 keep to the reduced one.
  static int MinLayerForQuality(int quality, int num_layers);

  // Observations. `queue_depth`: frames waiting after the enqueue (not the
  // one in flight); `dropped`: the enqueue pushed out a waiting frame.
  void OnEnqueue(int64_t now_us, size_t queue_depth, bool dropped);
  // A finished write of `bytes` that took `write_us` (async_write start to
  // completion): how fast the viewer's socket takes data when it is busy.
  // `unsent_bytes`: what the kernel still holds for the viewer after it
  // (SIOCOUTQ; 0 when unknown).
  void OnWrite(int64_t now_us, size_t bytes, int64_t write_us, size_t unsent_bytes = 0);

  // Re-decides the target layer. `layer_bytes_per_s[i]`: layer i's recent
  // published bitrate (0 = unknown: up to an unknown layer needs only the
  // hold and a calm queue; down never depends on it).
  void Update(int64_t now_us, std::span<const double> layer_bytes_per_s);

  // A frame of `layer` is offered: true when this viewer takes it. At an
  // independent frame of the target layer the switch takes effect (and
  // `*switched` is set); until then the viewer keeps its current layer.
  bool Take(int layer, bool independent, bool* switched);

  int layer() const { return layer_; }
  int target() const { return target_; }
  int num_layers() const { return num_layers_; }
  uint64_t switches() const { return switches_; }
  uint64_t switches_down() const { return switches_down_; }
  // Bytes/s the socket took while busy (-1: not busy enough to tell).
  double throughput_bytes_per_s() const;
  // Why the target last changed ("queue", "drop", "throughput", "probe",
  // "quality"), for logs and stats.
  const std::string& reason() const { return reason_; }
  double up_hold_s() const { return hold_s_; }

 private:
  void Decay(int64_t now_us);
  void SetTarget(int t, int64_t now_us, const char* why);

  LayerPolicy p_;
  int num_layers_ = 1;
  int min_layer_ = 0;
  int layer_ = 0, target_ = 0;
  uint64_t switches_ = 0, switches_down_ = 0;
  std::string reason_;
  // Decaying sums for the throughput estimate.
  double sum_bytes_ = 0, sum_busy_s_ = 0;
  int64_t decay_us_ = -1;
  // Queue: since when ≥ 2 frames wait (-1: not now); last time it did.
  int64_t queue_high_since_us_ = -1, queue_high_last_us_ = -1;
  bool drop_pending_ = false;
  size_t unsent_bytes_ = 0;  // the kernel's, after the last write
  size_t queue_depth_ = 0;   // frames waiting, after the last enqueue
  bool kernel_backlog_ = false;  // the unsent bytes exceed kernel_backlog_s (last Update)
  void NoteBacklog(int64_t now_us, bool high);
  int64_t target_since_us_ = 0;   // when the target last changed
  int64_t last_up_us_ = -1;       // when the target last went up (a probe)
  double hold_s_ = 0;
};

}  // namespace holo::net
