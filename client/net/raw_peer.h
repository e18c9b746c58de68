// A blocking TCP peer that speaks raw bytes: for tests and the load
// benchmark (malformed input, half-sent headers, slowloris handshakes, slow
// and stalled viewers). Not for applications: use SiteClient.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
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

}  // namespace holo::net
