#include "server/pods/socket_io.h"

#include <arpa/inet.h>
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

namespace holo::pods {
namespace {

std::string Errno() { return std::strerror(errno); }

int64_t SteadyMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

Status Resolve(const std::string& host, uint16_t port, sockaddr_in* addr) {
  std::memset(addr, 0, sizeof(*addr));
  addr->sin_family = AF_INET;
  addr->sin_port = htons(port);
  if (host.empty() || host == "0.0.0.0") {
    addr->sin_addr.s_addr = htonl(INADDR_ANY);
    return OkStatus();
  }
  if (inet_pton(AF_INET, host.c_str(), &addr->sin_addr) == 1) return OkStatus();
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  if (getaddrinfo(host.c_str(), nullptr, &hints, &res) != 0 || res == nullptr)
    return Unavailable("cannot resolve host '" + host + "'");
  addr->sin_addr = reinterpret_cast<sockaddr_in*>(res->ai_addr)->sin_addr;
  freeaddrinfo(res);
  return OkStatus();
}

void SetNoDelay(int fd) {
  int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
}

}  // namespace

Socket& Socket::operator=(Socket&& o) noexcept {
  if (this != &o) {
    Close();
    fd_ = o.fd_;
    o.fd_ = -1;
  }
  return *this;
}

void Socket::Close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

void Socket::Shutdown() {
  if (fd_ >= 0) ::shutdown(fd_, SHUT_RDWR);
}

Status ParseHostPort(const std::string& spec, std::string* host, uint16_t* port) {
  const size_t colon = spec.rfind(':');
  const std::string port_str = colon == std::string::npos ? spec : spec.substr(colon + 1);
  *host = colon == std::string::npos ? "" : spec.substr(0, colon);
  char* end = nullptr;
  const long p = std::strtol(port_str.c_str(), &end, 10);
  if (port_str.empty() || *end != '\0' || p < 0 || p > 65535)
    return InvalidArgument("'" + spec + "' is not HOST:PORT (port 0..65535)");
  *port = static_cast<uint16_t>(p);
  return OkStatus();
}

StatusOr<Socket> Listen(const std::string& host, uint16_t port) {
  sockaddr_in addr;
  HOLO_RETURN_IF_ERROR(Resolve(host, port, &addr));
  Socket s(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0));
  if (!s.valid()) return Unavailable("socket: " + Errno());
  int one = 1;
  setsockopt(s.fd(), SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  if (::bind(s.fd(), reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0)
    return Unavailable("cannot listen on " + (host.empty() ? std::string("*") : host) + ":" + std::to_string(port) +
                       ": " + Errno());
  if (::listen(s.fd(), 64) != 0) return Unavailable("listen: " + Errno());
  return s;
}

uint16_t LocalPort(const Socket& s) {
  sockaddr_in addr{};
  socklen_t len = sizeof(addr);
  if (getsockname(s.fd(), reinterpret_cast<sockaddr*>(&addr), &len) != 0) return 0;
  return ntohs(addr.sin_port);
}

StatusOr<Socket> Accept(const Socket& listener, int timeout_ms, std::string* peer) {
  pollfd p{listener.fd(), POLLIN, 0};
  const int r = ::poll(&p, 1, timeout_ms);
  if (r == 0) return OutOfRange("accept: timeout");
  if (r < 0) return errno == EINTR ? OutOfRange("accept: interrupted") : Unavailable("poll: " + Errno());
  if (p.revents & (POLLERR | POLLNVAL | POLLHUP)) return Unavailable("listener closed");
  sockaddr_in addr{};
  socklen_t len = sizeof(addr);
  Socket s(::accept4(listener.fd(), reinterpret_cast<sockaddr*>(&addr), &len, SOCK_CLOEXEC));
  if (!s.valid()) return Unavailable("accept: " + Errno());
  SetNoDelay(s.fd());
  if (peer) {
    char buf[INET_ADDRSTRLEN] = {};
    inet_ntop(AF_INET, &addr.sin_addr, buf, sizeof(buf));
    *peer = std::string(buf) + ":" + std::to_string(ntohs(addr.sin_port));
  }
  return s;
}

StatusOr<Socket> Connect(const std::string& host, uint16_t port, int timeout_ms) {
  sockaddr_in addr;
  HOLO_RETURN_IF_ERROR(Resolve(host.empty() ? "127.0.0.1" : host, port, &addr));
  const std::string where = (host.empty() ? std::string("127.0.0.1") : host) + ":" + std::to_string(port);
  Socket s(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
  if (!s.valid()) return Unavailable("socket: " + Errno());
  if (::connect(s.fd(), reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    if (errno != EINPROGRESS) return Unavailable("cannot connect to " + where + ": " + Errno());
    pollfd p{s.fd(), POLLOUT, 0};
    const int r = ::poll(&p, 1, timeout_ms);
    if (r <= 0) return Unavailable("cannot connect to " + where + ": timeout");
    int err = 0;
    socklen_t len = sizeof(err);
    getsockopt(s.fd(), SOL_SOCKET, SO_ERROR, &err, &len);
    if (err != 0) return Unavailable("cannot connect to " + where + ": " + std::strerror(err));
  }
  const int flags = fcntl(s.fd(), F_GETFL, 0);
  fcntl(s.fd(), F_SETFL, flags & ~O_NONBLOCK);
  SetNoDelay(s.fd());
  return s;
}

void SetBufferSizes(const Socket& s, int send_bytes, int receive_bytes) {
  if (send_bytes > 0) setsockopt(s.fd(), SOL_SOCKET, SO_SNDBUF, &send_bytes, sizeof(send_bytes));
  if (receive_bytes > 0) setsockopt(s.fd(), SOL_SOCKET, SO_RCVBUF, &receive_bytes, sizeof(receive_bytes));
}

Status SendAll(const Socket& s, const uint8_t* data, size_t size, int timeout_ms) {
  const int64_t deadline = SteadyMs() + timeout_ms;
  while (size > 0) {
    const ssize_t n = ::send(s.fd(), data, size, MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n > 0) {
      data += n;
      size -= static_cast<size_t>(n);
      continue;
    }
    if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) return Unavailable("send: " + Errno());
    const int64_t left = deadline - SteadyMs();
    if (left <= 0) return Unavailable("send: timed out (peer not reading)");
    pollfd p{s.fd(), POLLOUT, 0};
    if (::poll(&p, 1, static_cast<int>(left)) < 0 && errno != EINTR) return Unavailable("poll: " + Errno());
    if (p.revents & (POLLERR | POLLHUP | POLLNVAL)) return Unavailable("send: connection closed");
  }
  return OkStatus();
}

Status MessageReader::Read(const Socket& s, int timeout_ms, protocol::Message* out) {
  const int64_t deadline = SteadyMs() + timeout_ms;
  for (;;) {
    protocol::Frame f;
    while (parser_.Next(&f)) {
      bool complete = false;
      HOLO_RETURN_IF_ERROR(assembler_.Add(std::move(f), &complete, out));
      if (complete) {
        arrival_us_ = recv_us_;
        return OkStatus();
      }
    }
    const int64_t left = deadline - SteadyMs();
    if (left < 0) return OutOfRange("read: timeout");
    pollfd p{s.fd(), POLLIN, 0};
    const int r = ::poll(&p, 1, static_cast<int>(left));
    if (r == 0) return OutOfRange("read: timeout");
    if (r < 0) {
      if (errno == EINTR) continue;
      return Unavailable("poll: " + Errno());
    }
    const ssize_t n = ::recv(s.fd(), buf_.data(), buf_.size(), 0);
    recv_us_ = std::chrono::duration_cast<std::chrono::microseconds>(
                   std::chrono::system_clock::now().time_since_epoch())
                   .count();
    if (n == 0) return Unavailable("connection closed by peer");
    if (n < 0) {
      if (errno == EINTR || errno == EAGAIN) continue;
      return Unavailable("recv: " + Errno());
    }
    HOLO_RETURN_IF_ERROR(parser_.Feed(buf_.data(), static_cast<size_t>(n)));
  }
}

}  // namespace holo::pods
