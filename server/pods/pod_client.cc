#include "server/pods/pod_client.h"

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "common/log.h"
#include "net/wire_message.h"
#include "server/pods/socket_io.h"

namespace holo::pods {

using protocol::Message;
using protocol::MessageType;

Status PodClientOptions::Check() const {
  if (port == 0) return InvalidArgument("the site's pod port must be set (1..65535)");
  if (token.empty()) return InvalidArgument("a pod token is required");
  if (queue_frames < 1) return InvalidArgument("queue_frames must be >= 1");
  if (backoff_initial_ms < 1 || backoff_max_ms < backoff_initial_ms)
    return InvalidArgument("backoff must satisfy 1 <= initial <= max");
  if (!clock) return InvalidArgument("a pod clock is required");
  return OkStatus();
}

PodClient::PodClient(PodClientOptions options) : options_(std::move(options)) {}

PodClient::~PodClient() { Stop(); }

void PodClient::Log(const std::string& s, spdlog::level::level_enum level) {
  if (options_.log) {
    options_.log(s);
  } else {
    spdlog::log(level, "{}: {}", options_.name, s);
  }
}

Status PodClient::Start() {
  HOLO_RETURN_IF_ERROR(options_.Check());
  thread_ = std::thread([this] { Run(); });
  return OkStatus();
}

void PodClient::Stop() {
  stop_ = true;
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

bool PodClient::Offer(protocol::PodFrame frame) {
  protocol::Header h;
  h.stream_id = 1;
  h.sequence = static_cast<uint32_t>(frame.frame_number);
  h.capture_time_us = frame.capture_time_us;
  h.flags = protocol::kFlagKeyFrame;
  // Fragments of 256 KB: a VGA pod frame is one or two.
  std::vector<std::vector<uint8_t>> frags = protocol::EncodeFragmented(h, frame, 256 * 1024);
  std::vector<uint8_t> bytes;
  for (auto& f : frags) bytes.insert(bytes.end(), f.begin(), f.end());
  std::lock_guard<std::mutex> l(mu_);
  c_.offered++;
  if (!connected_) {
    c_.dropped_disconnected++;
    return false;
  }
  bool dropped = false;
  if (queue_.size() >= options_.queue_frames) {
    queue_.pop_front();
    c_.dropped_queue_full++;
    dropped = true;
  }
  queue_.push_back(std::move(bytes));
  cv_.notify_one();
  return !dropped;
}

PodClientCounters PodClient::counters() const {
  std::lock_guard<std::mutex> l(mu_);
  PodClientCounters c = c_;
  c.connected = connected_;
  return c;
}

Status PodClient::status() const {
  std::lock_guard<std::mutex> l(mu_);
  return status_;
}

void PodClient::Run() {
  int backoff = options_.backoff_initial_ms;
  while (!stop_) {
    bool welcomed = false;
    const Status s = Session(&welcomed);
    connected_ = false;
    {
      std::lock_guard<std::mutex> l(mu_);
      c_.dropped_disconnected += queue_.size();
      queue_.clear();
      if (!s.ok()) c_.last_error = s.message();
      if (!welcomed) c_.connect_failures++;
    }
    if (stop_) break;
    if (s.code() == StatusCode::kInvalidArgument) {  // refused: retrying cannot help
      std::lock_guard<std::mutex> l(mu_);
      status_ = s;
      Log("giving up: " + s.message(), spdlog::level::err);
      return;
    }
    if (welcomed) backoff = options_.backoff_initial_ms;  // a working link: start over
    Log(s.message() + "; reconnecting in " + std::to_string(backoff) + " ms", spdlog::level::warn);
    std::unique_lock<std::mutex> l(mu_);
    cv_.wait_for(l, std::chrono::milliseconds(backoff), [&] { return stop_.load(); });
    backoff = std::min(backoff * 2, options_.backoff_max_ms);
  }
}

Status PodClient::Session(bool* welcomed) {
  HOLO_ASSIGN_OR_RETURN(Socket sock, Connect(options_.host, options_.port, options_.connect_timeout_ms));
  const std::string site = options_.host + ":" + std::to_string(options_.port);
  // About two frames in flight in the kernel: beyond that, frames wait (and
  // are dropped, oldest first) in this client's queue instead of piling up
  // latency in socket buffers.
  SetBufferSizes(sock, 256 * 1024, 0);
  {
    protocol::Hello hello;
    hello.role = protocol::Role::kPod;
    hello.access_token = options_.token;
    hello.client_name = options_.name;
    protocol::RigMessage cal;
    cal.rig.name = options_.name;
    cal.rig.pods.push_back(options_.calibration);
    protocol::Header h;
    std::vector<uint8_t> bytes = protocol::EncodeMessage(h, hello);
    const std::vector<uint8_t> rig_bytes = protocol::EncodeMessage(h, cal);
    bytes.insert(bytes.end(), rig_bytes.begin(), rig_bytes.end());
    HOLO_RETURN_IF_ERROR(SendAll(sock, bytes.data(), bytes.size(), options_.send_timeout_ms));
  }
  MessageReader reader;
  Message m;
  Status s = reader.Read(sock, options_.handshake_timeout_ms, &m);
  if (s.code() == StatusCode::kOutOfRange) return Unavailable("site " + site + " did not answer the handshake");
  if (!s.ok()) return s.WithContext("handshake with " + site);
  if (m.header.type == MessageType::kRefuse) {
    const auto& r = std::get<protocol::Refuse>(m.payload);
    return InvalidArgument("site " + site + " refused this pod: " + r.message);
  }
  if (m.header.type != MessageType::kWelcome)
    return DataLoss(std::string("site sent ") + protocol::MessageTypeName(m.header.type) + " instead of welcome");
  *welcomed = true;
  {
    std::lock_guard<std::mutex> l(mu_);
    c_.connects++;
    queue_.clear();
  }
  connected_ = true;
  Log("connected to " + site);
  while (!stop_) {
    std::vector<uint8_t> item;
    {
      std::unique_lock<std::mutex> l(mu_);
      cv_.wait_for(l, std::chrono::milliseconds(1), [&] { return stop_ || !queue_.empty(); });
      if (!queue_.empty()) {
        item = std::move(queue_.front());
        queue_.pop_front();
      }
    }
    if (!item.empty()) {
      HOLO_RETURN_IF_ERROR(SendAll(sock, item.data(), item.size(), options_.send_timeout_ms).WithContext("link to " + site));
      std::lock_guard<std::mutex> l(mu_);
      c_.sent++;
      c_.bytes_sent += item.size();
    }
    // Pings (and anything else) from the site, without waiting.
    for (;;) {
      s = reader.Read(sock, 0, &m);
      if (s.code() == StatusCode::kOutOfRange) break;
      if (!s.ok()) return s.WithContext("link to " + site);
      // t1 when the Ping's bytes arrived (mapped onto the pod's clock).
      const int64_t t1 = options_.clock() - (net::WallUs() - reader.arrival_us());
      if (m.header.type == MessageType::kPing) {
        const auto& p = std::get<protocol::Ping>(m.payload);
        protocol::Pong pong{p.nonce, p.send_time_us, t1, options_.clock()};
        protocol::Header h;
        const std::vector<uint8_t> bytes = protocol::EncodeMessage(h, pong);
        HOLO_RETURN_IF_ERROR(SendAll(sock, bytes.data(), bytes.size(), options_.send_timeout_ms));
        std::lock_guard<std::mutex> l(mu_);
        c_.pings_answered++;
      } else if (m.header.type == MessageType::kRefuse) {
        return InvalidArgument("site " + site + " closed the link: " + std::get<protocol::Refuse>(m.payload).message);
      }
    }
  }
  return OkStatus();
}

}  // namespace holo::pods
