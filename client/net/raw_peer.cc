#include "client/net/raw_peer.h"

#include <cmath>

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
#include <algorithm>
#include <cstring>
#include <thread>

namespace holo::net {

namespace {
int64_t NowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}
}  // namespace

RawPeer::RawPeer(int fd) : fd_(fd) {}
RawPeer::~RawPeer() { Close(); }

void RawPeer::Close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

StatusOr<std::unique_ptr<RawPeer>> RawPeer::Connect(const std::string& host, uint16_t port, double timeout_s) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  if (getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &res) != 0 || res == nullptr)
    return Unavailable("resolve " + host + " failed");
  const int fd = ::socket(res->ai_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    freeaddrinfo(res);
    return Unavailable(std::string("socket: ") + std::strerror(errno));
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK);
  int rc = ::connect(fd, res->ai_addr, res->ai_addrlen);
  freeaddrinfo(res);
  if (rc != 0 && errno != EINPROGRESS) {
    ::close(fd);
    return Unavailable(std::string("connect: ") + std::strerror(errno));
  }
  pollfd p{fd, POLLOUT, 0};
  if (::poll(&p, 1, static_cast<int>(timeout_s * 1000)) != 1) {
    ::close(fd);
    return Unavailable("connect: timeout");
  }
  int err = 0;
  socklen_t len = sizeof(err);
  ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
  if (err != 0) {
    ::close(fd);
    return Unavailable(std::string("connect: ") + std::strerror(err));
  }
  int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
  return std::unique_ptr<RawPeer>(new RawPeer(fd));
}

void RawPeer::SetReceiveBuffer(int bytes) { ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof(bytes)); }

Status RawPeer::Send(std::span<const uint8_t> bytes) {
  size_t off = 0;
  const int64_t deadline = NowMs() + 5000;
  while (off < bytes.size()) {
    const ssize_t n = ::send(fd_, bytes.data() + off, bytes.size() - off, MSG_NOSIGNAL);
    if (n > 0) {
      off += static_cast<size_t>(n);
      continue;
    }
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
      pollfd p{fd_, POLLOUT, 0};
      if (NowMs() > deadline) return Unavailable("send: timeout");
      ::poll(&p, 1, 100);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    return Unavailable(std::string("send: ") + std::strerror(errno));
  }
  return OkStatus();
}

Status RawPeer::SendMessage(const protocol::Payload& payload, protocol::Header header) {
  return Send(protocol::EncodeMessage(header, payload));
}

Status RawPeer::SendHello(protocol::Role role, const std::string& token, const std::string& name) {
  protocol::Hello h;
  h.role = role;
  h.capabilities.geometry = {protocol::GeometryCodec::kG1, protocol::GeometryCodec::kG0};
  h.capabilities.color = {protocol::ColorCodec::kC1, protocol::ColorCodec::kC0};
  h.capabilities.audio = {protocol::AudioCodec::kOpus, protocol::AudioCodec::kPcm16};
  h.access_token = token;
  h.client_name = name;
  return SendMessage(h);
}

StatusOr<size_t> RawPeer::Read(uint8_t* out, size_t max, double timeout_s) {
  if (fd_ < 0) return Unavailable("closed");
  pollfd p{fd_, POLLIN, 0};
  const int r = ::poll(&p, 1, static_cast<int>(timeout_s * 1000));
  if (r == 0) return size_t{0};
  if (r < 0) return Unavailable(std::string("poll: ") + std::strerror(errno));
  const ssize_t n = ::recv(fd_, out, max, 0);
  if (n == 0) return Unavailable("peer closed the connection");
  if (n < 0) {
    if (errno == EAGAIN || errno == EINTR) return size_t{0};
    return Unavailable(std::string("recv: ") + std::strerror(errno));
  }
  bytes_read_ += static_cast<uint64_t>(n);
  return static_cast<size_t>(n);
}

StatusOr<protocol::Message> RawPeer::ReadMessage(double timeout_s) {
  const int64_t deadline = NowMs() + static_cast<int64_t>(timeout_s * 1000);
  uint8_t buf[65536];
  for (;;) {
    protocol::Frame f;
    while (parser_.Next(&f)) {
      bool complete = false;
      protocol::Message m;
      HOLO_RETURN_IF_ERROR(assembler_.Add(std::move(f), &complete, &m));
      if (complete) return m;
    }
    const int64_t left = deadline - NowMs();
    if (left <= 0) return Unavailable("timeout waiting for a message");
    // Read a little at a time so that bytes after this message stay in the socket.
    HOLO_ASSIGN_OR_RETURN(size_t n, Read(buf, sizeof(buf), static_cast<double>(left) * 1e-3));
    HOLO_RETURN_IF_ERROR(parser_.Feed(buf, n));
  }
}

Status RawPeer::ReadFrames(size_t max_bytes, double timeout_s, std::vector<protocol::Frame>* out) {
  std::vector<uint8_t> buf(std::max<size_t>(1, max_bytes));
  HOLO_ASSIGN_OR_RETURN(size_t n, Read(buf.data(), buf.size(), timeout_s));
  HOLO_RETURN_IF_ERROR(parser_.Feed(buf.data(), n));
  protocol::Frame f;
  while (parser_.Next(&f)) out->push_back(std::move(f));
  return OkStatus();
}

bool RawPeer::WaitClosed(double timeout_s) {
  const int64_t deadline = NowMs() + static_cast<int64_t>(timeout_s * 1000);
  uint8_t buf[65536];
  for (;;) {
    const int64_t left = deadline - NowMs();
    if (left <= 0) return false;
    auto n = Read(buf, sizeof(buf), static_cast<double>(left) * 1e-3);
    if (!n.ok()) return true;
  }
}

StatusOr<std::unique_ptr<RawViewer>> RawViewer::Start(const RawViewerOptions& options) {
  HOLO_ASSIGN_OR_RETURN(auto peer, RawPeer::Connect(options.host, options.port));
  peer->SetReceiveBuffer(options.receive_buffer);
  HOLO_RETURN_IF_ERROR(peer->SendHello(protocol::Role::kViewer, options.token, options.name));
  auto w = peer->ReadMessage(options.welcome_timeout_s);
  if (!w.ok() || w->header.type != protocol::MessageType::kWelcome)
    return Unavailable(options.name + ": no Welcome");
  protocol::Control c;
  c.command = protocol::ControlCommand::kSubscribe;
  c.value = options.subscribe;
  HOLO_RETURN_IF_ERROR(peer->SendMessage(c));
  return std::unique_ptr<RawViewer>(new RawViewer(std::move(peer), options.bytes_per_10ms));
}

RawViewer::RawViewer(std::unique_ptr<RawPeer> peer, size_t bytes_per_10ms)
    : peer_(std::move(peer)), budget_(bytes_per_10ms) {
  if (budget_ > 0) thread_ = std::thread([this] { Run(); });
}

RawViewer::~RawViewer() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

void RawViewer::Run() {
  while (!stop_) {
    std::vector<protocol::Frame> frames;
    if (!peer_->ReadFrames(budget_, 0.01, &frames).ok()) return;
    for (const auto& f : frames) {
      if (f.header.type == protocol::MessageType::kMeshFrame && !(f.header.flags & protocol::kFlagMoreFragments)) {
        ++meshes_;
        const int64_t now = std::chrono::duration_cast<std::chrono::microseconds>(
                                std::chrono::steady_clock::now().time_since_epoch())
                                .count();
        const int64_t wall = std::chrono::duration_cast<std::chrono::microseconds>(
                                 std::chrono::system_clock::now().time_since_epoch())
                                 .count();
        std::lock_guard<std::mutex> l(times_mu_);
        if (mesh_times_us_.size() < 100000) {
          mesh_times_us_.push_back(now);
          mesh_latencies_ms_.push_back(static_cast<double>(wall - f.header.capture_time_us) * 1e-3);
        }
      } else if (f.header.type == protocol::MessageType::kStats && !(f.header.flags & protocol::kFlagMoreFragments)) {
        auto p = protocol::DecodePayload(f.header, f.payload);
        if (!p.ok()) continue;
        for (const auto& [key, value] : std::get<protocol::Stats>(*p).values)
          if (key == protocol::kLayerKey && std::isfinite(value)) layer_ = static_cast<int>(value);
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

std::vector<int64_t> RawViewer::mesh_times_us() const {
  std::lock_guard<std::mutex> l(times_mu_);
  return mesh_times_us_;
}

std::vector<double> RawViewer::mesh_latencies_ms() const {
  std::lock_guard<std::mutex> l(times_mu_);
  return mesh_latencies_ms_;
}

}  // namespace holo::net
