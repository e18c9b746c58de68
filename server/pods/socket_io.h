// Blocking TCP for the pod link (pods/hub): a handful of connections, one
// thread each, so plain POSIX sockets with poll() timeouts are enough.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/status.h"
#include "protocol/messages.h"

namespace holo::pods {

// An owned socket descriptor (closed by the destructor).
class Socket {
 public:
  Socket() = default;
  explicit Socket(int fd) : fd_(fd) {}
  ~Socket() { Close(); }
  Socket(Socket&& o) noexcept : fd_(o.fd_) { o.fd_ = -1; }
  Socket& operator=(Socket&& o) noexcept;
  Socket(const Socket&) = delete;
  Socket& operator=(const Socket&) = delete;

  int fd() const { return fd_; }
  bool valid() const { return fd_ >= 0; }
  void Close();
  // Wakes a thread blocked on this socket (shutdown both ways) without closing it.
  void Shutdown();

 private:
  int fd_ = -1;
};

// "HOST:PORT" or ":PORT" / "PORT" (all interfaces). InvalidArgument on a bad spec.
Status ParseHostPort(const std::string& spec, std::string* host, uint16_t* port);

// Listens on `host`:`port` (port 0: any free port). Unavailable on failure.
StatusOr<Socket> Listen(const std::string& host, uint16_t port);
uint16_t LocalPort(const Socket& s);
// Waits up to `timeout_ms` for a connection; OutOfRange on timeout.
StatusOr<Socket> Accept(const Socket& listener, int timeout_ms, std::string* peer);
// Connects with a timeout; Unavailable naming the address on failure.
StatusOr<Socket> Connect(const std::string& host, uint16_t port, int timeout_ms);

// Caps the kernel's send / receive buffer of `s` (bytes; 0 leaves it). A
// live stream keeps latency in its own bounded queue, not in megabytes of
// socket buffer.
void SetBufferSizes(const Socket& s, int send_bytes, int receive_bytes);

// Writes all of `data`; Unavailable when the peer is gone or the write does
// not complete within `timeout_ms`.
Status SendAll(const Socket& s, const uint8_t* data, size_t size, int timeout_ms);

// Reads whole messages from a socket: frames through FrameParser,
// fragments through MessageAssembler (the protocol's limits).
class MessageReader {
 public:
  explicit MessageReader(protocol::Limits limits = {}) : parser_(limits), assembler_(limits, 4) {}
  // Waits up to `timeout_ms` for the next complete message. OutOfRange on
  // timeout; Unavailable when the peer closed; DataLoss / UnsupportedVersion
  // for a malformed stream (the connection must then be closed).
  Status Read(const Socket& s, int timeout_ms, protocol::Message* out);
  // System-clock time (µs) when the recv() that delivered the last bytes of
  // the message Read returned came back: the message's arrival, earlier
  // than the return of Read when the thread was busy in between.
  int64_t arrival_us() const { return arrival_us_; }

 private:
  protocol::FrameParser parser_;
  protocol::MessageAssembler assembler_;
  std::vector<uint8_t> buf_ = std::vector<uint8_t>(64 * 1024);
  int64_t recv_us_ = 0;     // time of the latest recv()
  int64_t arrival_us_ = 0;
};

}  // namespace holo::pods
