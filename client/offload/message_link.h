// A blocking, message-level TCP link between a render host and a thin client
// (PROTOCOL.md framing: FrameParser + MessageAssembler on receive, whole
// unfragmented messages on send). Sends are thread-safe; one thread reads.
// Close() from any thread wakes a blocked Read().
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "common/status.h"
#include "protocol/messages.h"

namespace holo::offload {

class MessageLink {
 public:
  // Takes ownership of a connected socket descriptor.
  MessageLink(int fd, protocol::Limits limits);
  ~MessageLink();
  MessageLink(const MessageLink&) = delete;
  MessageLink& operator=(const MessageLink&) = delete;

  // Connects to host:port (name resolution through Asio), waiting at most timeout_s.
  static StatusOr<std::unique_ptr<MessageLink>> Connect(const std::string& host, uint16_t port, double timeout_s,
                                                        protocol::Limits limits = {});

  Status Send(const protocol::Payload& payload, uint32_t stream_id = 0, int64_t capture_time_us = 0);
  // The next whole message; Unavailable when the peer closed, on timeout
  // ("no message for N s") or after Close(); DataLoss for malformed bytes.
  StatusOr<protocol::Message> Read(double timeout_s);
  void Close();
  bool closed() const { return closed_.load(); }
  uint64_t bytes_sent() const { return bytes_sent_.load(); }
  uint64_t bytes_received() const { return bytes_received_.load(); }
  const std::string& peer() const { return peer_; }

 private:
  int fd_;
  std::string peer_;
  std::mutex send_mu_;
  std::atomic<bool> closed_{false};
  std::atomic<uint64_t> bytes_sent_{0}, bytes_received_{0};
  uint32_t sequence_ = 0;
  protocol::FrameParser parser_;
  protocol::MessageAssembler assembler_;
};

}  // namespace holo::offload
