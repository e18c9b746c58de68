// The client side of a session (docs/sessions.md): connect to a site server,
// handshake, subscribe, receive and decode frames into ready-to-use meshes
// and images, send the own audio+pose and head pose, ping for RTT and clock
// offset, and reconnect with exponential backoff when the site goes away.
// Used by the GL viewer (pull API: LatestFrame), the render host and the
// recorder (callbacks; on_raw gives every message's bytes). No GL needed.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/image.h"
#include "common/mesh.h"
#include "common/rig.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::net {

// Content bits of Control.subscribe.
inline constexpr uint32_t kSubscribeGeometry = 1;
inline constexpr uint32_t kSubscribeColor = 2;
inline constexpr uint32_t kSubscribeAudio = 4;
inline constexpr uint32_t kSubscribeAll = 7;  // geometry, colour, audio (what value 0 means on the wire)
// Regions (PROTOCOL.md §4, type 15). Never sent to the site at Welcome: the
// client subscribes to them only when the site announces them (Stats
// "site.regions"), so an older site never sees an unknown content bit.
inline constexpr uint32_t kSubscribeRegions = 8;

// Io threads shared by many clients (a recorder of several sites, the
// load benchmark's hundred viewers). A client without one makes its own.
class NetContext {
 public:
  explicit NetContext(int threads = 1);
  ~NetContext();  // stops and joins (clients using it must be stopped first)
  NetContext(const NetContext&) = delete;
  NetContext& operator=(const NetContext&) = delete;
  struct Impl;
  Impl* impl() { return impl_.get(); }
  // CPU time of the io threads, ms.
  double CpuMs() const;

 private:
  std::unique_ptr<Impl> impl_;
};

struct TlsClientConfig {
  bool enabled = false;
  std::string ca_file;   // PEM file of trusted certificates (e.g. the site's self-signed cert)
  bool verify = true;    // verify the chain and the host name (off only for tests)
};

struct ClientOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 0;
  protocol::Role role = protocol::Role::kViewer;
  std::string token;
  std::string name = "holoport-client";
  // Content sent with Control.subscribe after Welcome (viewers, render hosts, recorders).
  uint32_t subscribe = kSubscribeAll | kSubscribeRegions;
  // Decode MeshFrame → Mesh and ColorFrame → images on the io thread. Off:
  // frames carry only their index, times and sizes (recorders, load tests).
  bool decode = true;
  bool reconnect = true;
  double backoff_initial_s = 0.1;  // first retry delay; doubles up to backoff_max_s
  double backoff_max_s = 5.0;
  double connect_timeout_s = 5.0;  // connect + TLS + Welcome
  double ping_interval_s = 1.0;    // 0: no pings
  // How long a mesh waits for its ColorFrame before it is delivered alone.
  double color_wait_s = 0.05;
  // Control set quality sent after each Welcome when below 10 (10: the site
  // chooses; on a site with quality layers 0..4 keep to the reduced layer).
  int quality = 10;
  size_t max_pending_frames = 4;   // pull queue; the oldest is dropped
  size_t max_pending_audio = 512;  // pull queue; the oldest is dropped
  size_t max_send_queue = 1024;    // messages waiting to be sent; newer ones are dropped beyond
  uint32_t max_message_bytes = 64u << 20;
  protocol::Capabilities capabilities{{protocol::GeometryCodec::kG1, protocol::GeometryCodec::kG3, protocol::GeometryCodec::kG0},
                                      {protocol::ColorCodec::kC1, protocol::ColorCodec::kC0, protocol::ColorCodec::kV1},
                                      {protocol::AudioCodec::kOpusLean, protocol::AudioCodec::kOpus,
                                       protocol::AudioCodec::kPcm16}};
  TlsClientConfig tls;
  // No connection: content messages come from Feed() (an HTTP broadcast
  // player, client/net/broadcast_player.h); the state is kConnected at once.
  bool fed = false;
  Status Check() const;
};

struct DecodedImage {
  uint16_t pod_id = 0;
  ImageRgb8 image;
  ImageGray8 mask;
};

// One video frame: the mesh and (if subscribed and published) the pods' images.
struct ReceivedFrame {
  int64_t frame_index = -1;
  int64_t capture_time_us = 0;   // site clock
  int64_t received_us = 0;       // this machine's wall clock (net::WallUs)
  double latency_ms = 0;         // capture → received, corrected by the ping clock offset
  // False when the capture time cannot be on a wall clock (0, or more than a
  // day from this machine's: a synthetic recording's stream time played
  // over HTTP); latency_ms then means nothing and is left 0.
  bool latency_known = true;
  size_t wire_bytes = 0;         // payload bytes of its messages
  bool has_mesh = false;
  bool has_color = false;
  Mesh mesh;                     // decoded (ClientOptions::decode)
  std::vector<DecodedImage> images;
};

// One Regions report as received (PROTOCOL.md §4 Regions).
struct ReceivedRegions {
  protocol::Regions regions;
  int64_t capture_time_us = 0;  // of the frame the report is about (site clock)
  int64_t received_us = 0;      // this machine's wall clock (net::WallUs)
};

// One reassembled message as received (unfragmented header + payload).
struct RawMessage {
  protocol::Header header;
  std::vector<uint8_t> payload;
  int64_t received_us = 0;
};

enum class ClientState { kConnecting, kConnected, kBackoff, kRefused, kStopped };
const char* ClientStateName(ClientState s);

struct ClientCallbacks {
  // All run on an io thread; keep them short (copy and hand over).
  std::function<void(const ReceivedFrame&)> on_frame;
  std::function<void(const protocol::AudioPose&, uint32_t stream_id)> on_audio;
  std::function<void(const Rig&)> on_rig;
  std::function<void(const ReceivedRegions&)> on_regions;
  std::function<void(const RawMessage&)> on_raw;  // every message after Welcome (recorders)
  std::function<void(ClientState, const Status&)> on_state;
};

struct ClientStats {
  uint64_t connects = 0;          // Welcomes received
  uint64_t connect_failures = 0;  // attempts that did not reach Welcome
  uint64_t frames_received = 0;
  uint64_t frames_dropped_local = 0;  // pull queue overflow (the application did not poll)
  uint64_t audio_received = 0;
  uint64_t regions_received = 0;  // Regions messages (one per frame of a site with regions)
  uint64_t messages_received = 0;
  uint64_t bytes_received = 0;
  uint64_t decode_errors = 0;
  uint64_t color_images_waiting = 0;  // V1 pod images skipped while a stream waited for a keyframe
  uint64_t keyframe_requests = 0;     // Control kRequestKeyFrame sent (V1)
  // Quality layers: the layer the site says this viewer receives (0 = full),
  // how many it publishes (1: no layers), and the changes it announced.
  int layer = 0;
  int num_layers = 1;
  int layer_step = 1;  // the layer carries every layer_step-th frame of the site
  uint64_t layer_changes = 0;
  uint64_t sends_dropped = 0;     // not connected or send queue full
  int64_t last_frame_index = -1;
  double rtt_ms = -1;
  double rtt_min_ms = -1;
  int64_t clock_offset_us = 0;    // site clock − local clock, from the lowest-RTT ping
  double mesh_decode_ms = 0;      // total
  double color_decode_ms = 0;     // total
};

class SiteClient {
 public:
  // Validates the options and starts connecting in the background.
  static StatusOr<std::unique_ptr<SiteClient>> Start(ClientOptions options, ClientCallbacks callbacks = {},
                                                     NetContext* context = nullptr);
  ~SiteClient();  // Stop()
  SiteClient(const SiteClient&) = delete;
  SiteClient& operator=(const SiteClient&) = delete;
  void Stop();

  ClientState state() const;
  // Why the last connection ended (OK while connected); on refusal, the
  // server's reason and message ("refused: BAD_TOKEN: ...").
  Status status() const;
  std::optional<protocol::Refuse> refusal() const;
  std::optional<protocol::Welcome> welcome() const;
  std::optional<Rig> rig() const;
  // Blocks until Welcome (true), a refusal or the timeout (false).
  bool WaitConnected(double timeout_s);

  // Pull API. PollFrame: the oldest waiting frame; LatestFrame: the newest
  // (older ones are discarded: a render loop wants only the freshest).
  bool PollFrame(ReceivedFrame* out);
  bool LatestFrame(ReceivedFrame* out);
  bool WaitFrame(ReceivedFrame* out, double timeout_s);
  bool PollAudio(protocol::AudioPose* out, uint32_t* stream_id = nullptr);
  // The newest Regions report (false before the first).
  bool LatestRegions(ReceivedRegions* out) const;

  // Sending (any thread; dropped and counted while not connected).
  // An Opus frame goes out in the layout the site negotiated: lean (codec 3,
  // pose quantized) or classic (codec 2; a lean frame without a pose then
  // carries the last pose sent).
  void SendAudioPose(const protocol::AudioPose& audio);
  void SendClientPose(const protocol::ClientPose& pose);
  void SendControl(const protocol::Control& control);
  void Subscribe(uint32_t content_bits);
  void Unsubscribe(uint32_t content_bits);
  // Control set quality 0..10 (clamped), kept and sent again after every
  // reconnection; on a site with quality layers it caps the layer
  // (PROTOCOL.md §4 Stats).
  void SetQuality(int level);
  void Pause();
  void Resume();
  void SetLoop(bool loop);  // replays: start again at the end (or not)
  void Seek(int64_t media_time_us);
  void SetSpeed(float speed);

  ClientStats stats() const;

  // ClientOptions::fed: one whole content message (Rig, MeshFrame,
  // ColorFrame, AudioPose, Stats) for the same decode and delivery path as
  // a site's; untrusted (decoded and checked there). Ignored otherwise.
  void Feed(RawMessage message);

  struct Impl;

 private:
  explicit SiteClient(std::shared_ptr<Impl> impl);
  std::shared_ptr<Impl> impl_;
};

}  // namespace holo::net
