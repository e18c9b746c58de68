// Shared pieces of the session tests (tests/net, tests/client, tests/record):
// a loopback server config with short timeouts, starting a server on a port
// that may still be taken, encoded frames of a procedural mesh, waiting for a
// condition, capturing log lines.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "net/session_server.h"
#include "protocol/color_codec.h"
#include "protocol/geometry_codec.h"
#include "protocol/test_meshes.h"

namespace holo::test {

inline net::ServerConfig LoopbackConfig(uint16_t port = 0) {
  net::ServerConfig c;
  c.name = "test-site";
  c.host = "127.0.0.1";
  c.port = port;
  c.publisher_token = "pub-secret";
  c.viewer_token = "view-secret";
  c.handshake_timeout_s = 2.0;
  c.idle_timeout_s = 10.0;
  c.ping_interval_s = 0.05;
  c.threads = 2;
  return c;
}

// Starts a server, retrying every 100 ms for up to 5 s while its port (of a
// site just stopped) is not free yet.
inline StatusOr<std::unique_ptr<net::Server>> StartServerRetrying(const net::ServerConfig& config,
                                                                  const net::ServerHooks& hooks = {}) {
  auto server = net::Server::Start(config, hooks);
  for (int i = 0; i < 50 && !server.ok(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    server = net::Server::Start(config, hooks);
  }
  return server;
}

// Polls `pred` every 5 ms until it holds or `timeout_s` passes.
inline bool Eventually(const std::function<bool()>& pred, double timeout_s = 5.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::microseconds(static_cast<int64_t>(timeout_s * 1e6));
  while (std::chrono::steady_clock::now() < end) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return pred();
}

struct EncodedContent {
  std::vector<uint8_t> geometry;     // G1 blob
  protocol::ColorFrame color;        // two C1 images
  size_t vertices = 0;
};

inline EncodedContent MakeContent(int rows = 40, int cols = 60) {
  EncodedContent c;
  const Mesh m = NoisySphere(rows, cols);
  protocol::GeometryEncodeOptions g;
  HOLO_CHECK(protocol::EncodeGeometry(m, g, &c.geometry).ok());
  Mesh decoded;
  HOLO_CHECK(protocol::DecodeGeometry(c.geometry, &decoded).ok());
  c.vertices = decoded.num_vertices();
  c.color.codec = protocol::ColorCodec::kC1;
  for (uint16_t pod = 0; pod < 2; ++pod) {
    ImageRgb8 img;
    ImageGray8 mask;
    MaskedImage(160, 120, &img, &mask, pod + 1);
    protocol::PodImage pi;
    pi.pod_id = pod;
    HOLO_CHECK(protocol::EncodeColor(img, mask, {}, &pi.data).ok());
    c.color.images.push_back(std::move(pi));
  }
  return c;
}

// Log lines captured from a server (thread-safe).
struct LogCapture {
  std::mutex mu;
  std::vector<std::string> lines;
  std::function<void(const std::string&)> Hook() {
    return [this](const std::string& s) {
      std::lock_guard<std::mutex> l(mu);
      lines.push_back(s);
    };
  }
  bool Contains(const std::string& needle) {
    std::lock_guard<std::mutex> l(mu);
    for (const auto& s : lines)
      if (s.find(needle) != std::string::npos) return true;
    return false;
  }
};

}  // namespace holo::test
