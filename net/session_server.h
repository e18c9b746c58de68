// The session server: an asynchronous TCP (optionally TLS) server on Asio
// that accepts publishers, viewers, render hosts and recorders, runs the
// handshake of PROTOCOL.md §3, and fans the site's published frames out to
// every viewer without re-encoding (docs/sessions.md).
//
// Threads: one io_context run by `config.threads` threads; each connection
// is serialised by a strand. Publishing (PublishVideo / PublishAudio) is
// called from the capture pipeline's thread and never blocks on a viewer:
// it appends a shared pointer to each viewer's bounded queue under a short
// per-viewer lock.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "common/rig.h"
#include "common/status.h"
#include "net/layer_control.h"
#include "net/server_config.h"
#include "net/wire_message.h"
#include "protocol/messages.h"

namespace holo::net {

// A viewer's playback control (pause, resume, seek, speed, key frame,
// quality), forwarded to whatever produces the stream (a replay engine).
// Called on an io thread: implementations must be thread-safe and quick.
struct ControlEvent {
  uint64_t session_id = 0;
  std::string client_name;
  protocol::Role role = protocol::Role::kViewer;
  protocol::Control control;
};
class StreamControlSink {
 public:
  virtual ~StreamControlSink() = default;
  virtual void OnControl(const ControlEvent& event) = 0;
};

// Per-connection counters (a snapshot).
struct SessionStats {
  uint64_t session_id = 0;
  protocol::Role role = protocol::Role::kViewer;
  std::string client_name;
  std::string peer;                   // "address:port"
  uint32_t subscription = 0;          // content bits
  int quality = 10;                   // last Control set-quality (0..10)
  uint64_t video_frames_queued = 0;   // frames offered to this viewer
  uint64_t video_frames_sent = 0;     // frames completely written to the socket
  uint64_t video_frames_dropped = 0;  // whole frames dropped because the viewer fell behind
  uint64_t audio_sent = 0;            // AudioPose messages written
  uint64_t messages_received = 0;
  uint64_t bytes_sent = 0;
  uint64_t bytes_received = 0;
  size_t queue_video = 0;             // frames waiting (not counting one in flight)
  size_t queue_priority = 0;          // small messages waiting
  double rtt_ms = -1;                 // last ping round trip (-1: none yet)
  double rtt_min_ms = -1;
  // Quality layers (net/layer_control.h): the layer this viewer receives,
  // the one it is being moved to, switches so far, why the target last
  // changed, and the throughput its socket took while busy (-1: not known).
  int layer = 0, target_layer = 0;
  uint64_t layer_switches = 0, layer_switches_down = 0;
  std::string layer_reason;
  double throughput_mbps = -1;
};

struct ServerCounters {
  uint64_t accepted = 0;              // TCP connections accepted
  uint64_t welcomed = 0;
  uint64_t refused = 0;               // Refuse sent
  uint64_t rejected_pending = 0;      // closed at accept: too many handshakes in progress
  uint64_t violations = 0;            // closed for a protocol violation
  uint64_t handshake_timeouts = 0;
  uint64_t idle_timeouts = 0;
  uint64_t priority_overflows = 0;    // viewers closed because audio/control could not be queued
  uint64_t video_frames_published = 0;
  uint64_t audio_published = 0;       // AudioPose messages published (in-process + relayed)
  uint64_t audio_relayed = 0;         // AudioPose messages received from publisher connections
  uint64_t controls_forwarded = 0;
  // Viewers welcomed plus Control kRequestKeyFrame received: a publisher of
  // inter-frame colour (V1) sends a key frame when this count grows.
  uint64_t keyframe_requests = 0;
  // The same per quality layer (welcomes count for layer 0; a viewer moved
  // to a layer counts for it), and layer switches of all viewers.
  std::array<uint64_t, kMaxLayers> layer_keyframe_requests{};
  uint64_t layer_switches = 0;
};

struct ServerHooks {
  // Log lines (refusals with their reason, violations, timeouts). Default: the
  // log (common/log.h), refusals and failures as warnings.
  std::function<void(const std::string&)> log;
  // Pause/seek/speed/key frame/quality from viewers; may be null.
  StreamControlSink* control = nullptr;
  // Every AudioPose received from a publisher connection (after validation),
  // e.g. for local playback or a recorder; called on an io thread.
  std::function<void(uint64_t session_id, const protocol::AudioPose&)> on_audio;
};

class Server {
 public:
  // Validates the config, binds, listens and starts the io threads.
  static StatusOr<std::unique_ptr<Server>> Start(const ServerConfig& config, ServerHooks hooks = {});
  ~Server();  // Stop()
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  uint16_t port() const;
  const ServerConfig& config() const;

  // The codecs this site publishes in; a client whose Hello lists neither
  // is refused with NO_COMMON_CODEC. Default G1, C1.
  // (These are the full layer's, told in Welcome; every layer uses them
  // unless SetLayerCodecs says otherwise.)
  void SetPublishedCodecs(protocol::GeometryCodec geometry, protocol::ColorCodec color);
  // The codecs of layer `layer` (1..kMaxLayers-1) where they differ from the
  // full layer's. A viewer is only ever moved to the layers whose codecs its
  // Hello lists (every frame names its codec, so one that does decodes the
  // new layer's frames without a new handshake); the others keep the layers
  // above them.
  void SetLayerCodecs(int layer, protocol::GeometryCodec geometry, protocol::ColorCodec color);
  // The rig, sent to every viewer after Welcome and to all viewers now.
  void SetRig(const Rig& rig);
  // The same with an already encoded Rig message (a replay sends the
  // recorded bytes unchanged). `message->type` must be kRig.
  void SetRigMessage(WireMessagePtr message);

  // This site publishes Regions (PROTOCOL.md §4, type 15): every viewer,
  // now and at each Welcome after the Rig, gets a Stats message
  // {"site.regions": num_regions}; viewers that know Regions subscribe to
  // them (content bit 8) when they see it. Regions then go out with
  // PublishPriority to those subscribers only.
  void AnnounceRegions(size_t num_regions);

  // Fan-out (any thread, never blocks on a viewer). Video frames go to every
  // viewer subscribed to geometry or colour; a viewer whose queue is full
  // loses its oldest waiting frame.
  void PublishVideo(VideoFramePtr frame);
  // An AudioPose of one of the site's own participants (stream id ≥ 256).
  void PublishAudio(const protocol::AudioPose& audio, uint32_t stream_id);
  // Any small message to every viewer subscribed to its content (priority queue).
  void PublishPriority(WireMessagePtr message);

  // Quality layers (docs/sessions.md): the site publishes each frame once
  // per layer (VideoFrame::layer, 0 = full); each viewer gets one layer,
  // moved by its queue, drops and throughput (config().layers). Default 1.
  // Viewers hear of their layer through Stats (protocol::kLayerKey).
  void SetLayers(int num_layers);
  // A layer that carries every `step`-th frame (default 1), told to viewers.
  void SetLayerFrameStep(int layer, int step);
  int num_layers() const;
  // Viewers receiving `layer` or being moved to it: a publisher encodes a
  // reduced layer only while this is > 0.
  size_t ViewersOnLayer(int layer) const;
  // The layer's published bitrate over the last seconds, Mbit/s.
  double LayerMbps(int layer) const;

  size_t num_viewers() const;      // after Welcome: viewers, render hosts, recorders
  size_t num_publishers() const;
  // Viewers subscribed to at least one of `content_bits`.
  size_t num_subscribed(uint32_t content_bits) const;
  std::vector<SessionStats> Sessions() const;
  ServerCounters counters() const;
  // CPU time of the io threads, ms (thread CPU clocks): the server's own cost.
  double IoCpuMs() const;

  // Closes the listener and every connection, joins the threads. Idempotent.
  void Stop();

  class Impl;

 private:
  explicit Server(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Compares two secrets in time independent of where they differ (SHA-256 of
// both, then CRYPTO_memcmp), so lengths do not leak either.
bool TokensEqual(const std::string& a, const std::string& b);

}  // namespace holo::net
