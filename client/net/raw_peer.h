// A blocking TCP peer that speaks raw bytes: for tests and the load
// benchmark (malformed input, half-sent headers, slowloris handshakes, slow
// and stalled viewers). Not for applications: use SiteClient.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "common/status.h"
#include "protocol/messages.h"

namespace holo::net {

class RawPeer {
 public:
  static StatusOr<std::unique_ptr<RawPeer>> Connect(const std::string& host, uint16_t port, double timeout_s = 5.0);
  ~RawPeer();
  RawPeer(const RawPeer&) = delete;
  RawPeer& operator=(const RawPeer&) = delete;

  // Sets the kernel receive buffer (before reading; small = a slow link).
  void SetReceiveBuffer(int bytes);
  Status Send(std::span<const uint8_t> bytes);
  Status SendMessage(const protocol::Payload& payload, protocol::Header header = {});
  Status SendHello(protocol::Role role, const std::string& token, const std::string& name);
  // Reads up to `max` bytes, waiting at most `timeout_s`: the count (0 on timeout);
  // Unavailable when the peer closed or reset the connection.
  StatusOr<size_t> Read(uint8_t* out, size_t max, double timeout_s);
  // Reads frames until one whole message decodes (fragments reassembled);
  // Unavailable on close, DeadlineExceeded-like Unavailable on timeout.
  StatusOr<protocol::Message> ReadMessage(double timeout_s);
  // Reads at most `max_bytes` (one recv, waiting up to `timeout_s`) into the
  // peer's frame parser and appends the frames completed so far to `out`.
  Status ReadFrames(size_t max_bytes, double timeout_s, std::vector<protocol::Frame>* out);
  // Reads and discards until the peer closes (true) or the timeout (false).
  bool WaitClosed(double timeout_s);
  void Close();
  uint64_t bytes_read() const { return bytes_read_; }

 private:
  explicit RawPeer(int fd);
  int fd_ = -1;
  uint64_t bytes_read_ = 0;
  protocol::FrameParser parser_;
  protocol::MessageAssembler assembler_;
};

// A viewer on a RawPeer that reads at a limited rate or not at all, counting
// the whole MeshFrames it gets: the slow and stalled viewers of the fan-out
// test and the sessions benchmark.
struct RawViewerOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 0;
  std::string token;
  std::string name;
  uint32_t subscribe = 1;            // content bits of Control.subscribe (kSubscribeGeometry, …)
  int receive_buffer = 16 << 10;     // kernel receive buffer, bytes (small = a slow link)
  double welcome_timeout_s = 5.0;
  size_t bytes_per_10ms = 0;         // read at most this every 10 ms; 0: never read (stalled)
};

class RawViewer {
 public:
  // Connects, says Hello as a viewer, waits for the Welcome and subscribes;
  // then reads on its own thread unless bytes_per_10ms is 0.
  static StatusOr<std::unique_ptr<RawViewer>> Start(const RawViewerOptions& options);
  ~RawViewer();
  RawViewer(const RawViewer&) = delete;
  RawViewer& operator=(const RawViewer&) = delete;

  // Whole MeshFrames read so far (the last fragment of each).
  int64_t meshes() const { return meshes_; }
  // When each whole MeshFrame was read (steady clock, µs; the first 100 000).
  std::vector<int64_t> mesh_times_us() const;
  // Capture (header time, wall clock) → read, ms, of each whole MeshFrame
  // read (the first 100 000): a viewer on this machine's clock.
  std::vector<double> mesh_latencies_ms() const;
  // Changes the read rate (a viewer started with bytes_per_10ms > 0 only).
  void SetRate(size_t bytes_per_10ms) { budget_ = bytes_per_10ms; }
  // The quality layer the site last announced (Stats "session.layer"), -1: none.
  int layer() const { return layer_; }

 private:
  RawViewer(std::unique_ptr<RawPeer> peer, size_t bytes_per_10ms);
  void Run();

  std::unique_ptr<RawPeer> peer_;
  std::atomic<size_t> budget_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<int64_t> meshes_{0};
  std::atomic<int> layer_{-1};
  mutable std::mutex times_mu_;
  std::vector<int64_t> mesh_times_us_;
  std::vector<double> mesh_latencies_ms_;
};

}  // namespace holo::net
