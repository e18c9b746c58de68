// Configuration of the session server (net/session_server.h): listening address,
// access tokens, limits and timeouts, TLS. Loaded from YAML (docs/sessions.md
// lists every key) and validated; every error names the key.
#pragma once

#include <cstdint>
#include <string>

#include "common/status.h"
#include "net/layer_control.h"

namespace holo::net {

struct TlsServerConfig {
  bool enabled = false;
  std::string cert_file;  // PEM certificate (chain)
  std::string key_file;   // PEM private key
};

struct ServerConfig {
  std::string name = "holoport-site";  // sent in Welcome
  std::string host = "127.0.0.1";      // listening address
  uint16_t port = 0;                   // 0: any free port (tests)
  // Access tokens (1..256 bytes each). Publishers (participants' audio+pose)
  // need `publisher_token`; viewers, render hosts and recorders `viewer_token`.
  std::string publisher_token;
  std::string viewer_token;
  int max_viewers = 128;         // viewers + render hosts + recorders after Welcome
  int max_publishers = 8;        // publisher connections after Welcome
  int max_pending = 64;          // connections still in their handshake
  // Largest message this server accepts from a client (reassembled), bytes.
  uint32_t max_message_bytes = 1u << 20;
  double handshake_timeout_s = 5.0;  // accept → Welcome (TLS handshake included)
  double idle_timeout_s = 30.0;      // no byte received for this long → closed
  double ping_interval_s = 1.0;      // server → client pings for RTT (0: off)
  // Per-viewer send queue: video frames waiting (whole frames; the oldest
  // waiting frame is dropped when a new one does not fit) and small
  // priority messages (audio+pose, pongs, control; overflow closes the
  // viewer, since audio is never dropped silently).
  int queue_video_frames = 3;
  int queue_priority_messages = 1024;
  // Kernel send buffer per connection (SO_SNDBUF), bytes; 0 = the kernel's
  // autotuning. Bytes in it are past the drop policy, so a big buffer hides
  // a slow viewer (and adds latency) before whole frames start to drop.
  int socket_send_buffer = 256 << 10;
  uint32_t fragment_bytes = 64u << 10;  // video messages go out in fragments of this payload size
  int threads = 2;                       // io threads
  TlsServerConfig tls;
  // How viewers are moved between the site's quality layers (YAML section
  // `layers`, keys as the fields; net/layer_control.h).
  LayerPolicy layers;

  Status Check() const;
};

// Parses YAML text (`source` names it in errors). Unknown keys are errors.
StatusOr<ServerConfig> ParseServerConfig(const std::string& yaml_text, const std::string& source = "server config");
StatusOr<ServerConfig> LoadServerConfig(const std::string& path);

// "HOST:PORT" (HOST may be empty → 0.0.0.0; [v6] brackets allowed).
Status ParseHostPort(const std::string& spec, std::string* host, uint16_t* port);

}  // namespace holo::net
