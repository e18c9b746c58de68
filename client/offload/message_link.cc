#include "client/offload/message_link.h"

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>

#include <asio.hpp>

namespace holo::offload {
namespace {

std::string PeerName(int fd) {
  sockaddr_storage ss{};
  socklen_t len = sizeof(ss);
  if (getpeername(fd, reinterpret_cast<sockaddr*>(&ss), &len) != 0) return "?";
  char host[NI_MAXHOST], serv[NI_MAXSERV];
  if (getnameinfo(reinterpret_cast<sockaddr*>(&ss), len, host, sizeof(host), serv, sizeof(serv),
                  NI_NUMERICHOST | NI_NUMERICSERV) != 0) {
    return "?";
  }
  return std::string(host) + ":" + serv;
}

}  // namespace

MessageLink::MessageLink(int fd, protocol::Limits limits)
    : fd_(fd), peer_(PeerName(fd)), parser_(limits), assembler_(limits, 4) {
  int one = 1;
  setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
}

MessageLink::~MessageLink() {
  Close();
  ::close(fd_);
}

StatusOr<std::unique_ptr<MessageLink>> MessageLink::Connect(const std::string& host, uint16_t port, double timeout_s,
                                                            protocol::Limits limits) {
  asio::io_context io;
  asio::ip::tcp::resolver resolver(io);
  asio::error_code ec;
  auto endpoints = resolver.resolve(host, std::to_string(port), ec);
  if (ec) return Unavailable("resolve " + host + ": " + ec.message());
  std::string last = "no address";
  for (const auto& entry : endpoints) {
    const asio::ip::tcp::endpoint ep = entry.endpoint();
    const int fd = ::socket(ep.protocol().family(), SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (fd < 0) return Unavailable(std::string("socket: ") + std::strerror(errno));
    int rc = ::connect(fd, ep.data(), static_cast<socklen_t>(ep.size()));
    if (rc != 0 && errno == EINPROGRESS) {
      pollfd p{fd, POLLOUT, 0};
      rc = ::poll(&p, 1, static_cast<int>(timeout_s * 1000));
      int err = 0;
      socklen_t len = sizeof(err);
      if (rc == 1 && getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len) == 0 && err == 0) {
        rc = 0;
      } else {
        errno = rc == 0 ? ETIMEDOUT : (err ? err : errno);
        rc = -1;
      }
    }
    if (rc == 0) {
      const int flags = fcntl(fd, F_GETFL);
      fcntl(fd, F_SETFL, flags & ~O_NONBLOCK);
      return std::make_unique<MessageLink>(fd, limits);
    }
    last = std::strerror(errno);
    ::close(fd);
  }
  return Unavailable("connect to " + host + ":" + std::to_string(port) + ": " + last);
}

Status MessageLink::Send(const protocol::Payload& payload, uint32_t stream_id, int64_t capture_time_us) {
  protocol::Header h;
  h.stream_id = stream_id;
  h.capture_time_us = capture_time_us;
  std::lock_guard<std::mutex> lock(send_mu_);
  if (closed_) return Unavailable("link to " + peer_ + " is closed");
  h.sequence = sequence_++;
  const std::vector<uint8_t> bytes = protocol::EncodeMessage(h, payload);
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::send(fd_, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return Unavailable("send to " + peer_ + ": " + std::strerror(errno));
    done += static_cast<size_t>(n);
  }
  bytes_sent_ += bytes.size();
  return OkStatus();
}

StatusOr<protocol::Message> MessageLink::Read(double timeout_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::microseconds(static_cast<int64_t>(timeout_s * 1e6));
  uint8_t buf[65536];
  while (true) {
    protocol::Frame frame;
    while (parser_.Next(&frame)) {
      bool complete = false;
      protocol::Message msg;
      HOLO_RETURN_IF_ERROR(assembler_.Add(std::move(frame), &complete, &msg));
      if (complete) return msg;
    }
    if (closed_) return Unavailable("link to " + peer_ + " closed");
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return Unavailable("no message from " + peer_ + " for " + std::to_string(timeout_s) + " s");
    pollfd p{fd_, POLLIN, 0};
    const int rc = ::poll(&p, 1, static_cast<int>(std::min<int64_t>(left.count(), 100)));
    if (rc < 0 && errno != EINTR) return Unavailable(std::string("poll: ") + std::strerror(errno));
    if (rc <= 0) continue;
    const ssize_t n = ::recv(fd_, buf, sizeof(buf), 0);
    if (n < 0 && (errno == EINTR || errno == EAGAIN)) continue;
    if (n < 0) return Unavailable("receive from " + peer_ + ": " + std::strerror(errno));
    if (n == 0) return Unavailable(peer_ + " closed the connection");
    bytes_received_ += static_cast<uint64_t>(n);
    HOLO_RETURN_IF_ERROR(parser_.Feed(buf, static_cast<size_t>(n)));
  }
}

void MessageLink::Close() {
  if (!closed_.exchange(true)) ::shutdown(fd_, SHUT_RDWR);
}

}  // namespace holo::offload
