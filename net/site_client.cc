#include "net/site_client.h"

#include <pthread.h>
#include <time.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <thread>

#include <asio.hpp>
#include <asio/ssl.hpp>

#include "net/wire_message.h"
#include "protocol/color_codec.h"
#include "protocol/geometry_codec.h"
#include "protocol/video_codec.h"

namespace holo::net {

using asio::ip::tcp;
using protocol::Header;
using protocol::MessageType;

namespace {

std::chrono::microseconds Timeout(double s) { return std::chrono::microseconds(static_cast<int64_t>(s * 1e6)); }

const char* ReasonName(protocol::RefuseReason r) {
  switch (r) {
    case protocol::RefuseReason::kUnsupportedVersion: return "UNSUPPORTED_VERSION";
    case protocol::RefuseReason::kBadToken: return "BAD_TOKEN";
    case protocol::RefuseReason::kRoleNotAllowed: return "ROLE_NOT_ALLOWED";
    case protocol::RefuseReason::kMalformed: return "MALFORMED";
    case protocol::RefuseReason::kOverloaded: return "OVERLOADED";
    case protocol::RefuseReason::kNoCommonCodec: return "NO_COMMON_CODEC";
    case protocol::RefuseReason::kBadCalibration: return "BAD_CALIBRATION";
  }
  return "UNKNOWN";
}

std::vector<uint8_t> Encode(Header h, const protocol::Payload& p) { return protocol::EncodeMessage(h, p); }

// Reassembles fragments into whole messages, keeping the payload bytes
// (recorders store them as received). Same rules as MessageAssembler.
class RawAssembler {
 public:
  explicit RawAssembler(uint32_t max_message_bytes) : max_(max_message_bytes) {}
  void Reset() { partial_.clear(); }
  // Returns OK; `*complete` when `out` holds a whole message.
  Status Add(protocol::Frame&& f, bool* complete, RawMessage* out) {
    *complete = false;
    const auto key = std::make_pair(f.header.stream_id, static_cast<uint16_t>(f.header.type));
    const bool more = f.header.flags & protocol::kFlagMoreFragments;
    auto it = partial_.find(key);
    if (it == partial_.end() && !more) {
      out->header = f.header;
      out->payload = std::move(f.payload);
      *complete = true;
      return OkStatus();
    }
    if (it == partial_.end()) {
      if (partial_.size() >= 16) return DataLoss("fragments: more than 16 messages in progress");
      it = partial_.emplace(key, RawMessage{f.header, {}, 0}).first;
    } else if (it->second.header.sequence != f.header.sequence ||
               it->second.header.capture_time_us != f.header.capture_time_us) {
      return DataLoss("fragments: a fragment of another message interrupts stream " +
                      std::to_string(f.header.stream_id));
    }
    RawMessage& p = it->second;
    if (f.payload.size() > max_ - p.payload.size())
      return DataLoss("fragments: reassembled message exceeds " + std::to_string(max_) + " bytes");
    p.payload.insert(p.payload.end(), f.payload.begin(), f.payload.end());
    if (more) return OkStatus();
    *out = std::move(p);
    out->header.flags = static_cast<uint16_t>(out->header.flags & ~protocol::kFlagMoreFragments);
    out->header.payload_length = static_cast<uint32_t>(out->payload.size());
    partial_.erase(it);
    *complete = true;
    return OkStatus();
  }

 private:
  uint32_t max_;
  std::map<std::pair<uint32_t, uint16_t>, RawMessage> partial_;
};

}  // namespace

const char* ClientStateName(ClientState s) {
  switch (s) {
    case ClientState::kConnecting: return "connecting";
    case ClientState::kConnected: return "connected";
    case ClientState::kBackoff: return "backoff";
    case ClientState::kRefused: return "refused";
    case ClientState::kStopped: return "stopped";
  }
  return "?";
}

Status ClientOptions::Check() const {
  if (!fed && host.empty()) return InvalidArgument("client: host must be set");
  if (!fed && port == 0) return InvalidArgument("client: port must be set (1..65535)");
  if (token.size() > 256) return InvalidArgument("client: token over 256 bytes");
  if (name.size() > 1024) return InvalidArgument("client: name over 1024 bytes");
  if (subscribe > (kSubscribeAll | kSubscribeRegions)) return InvalidArgument("client: subscribe bits must be 0..15");
  if (!(backoff_initial_s > 0 && backoff_initial_s <= backoff_max_s && backoff_max_s <= 3600))
    return InvalidArgument("client: need 0 < backoff_initial_s <= backoff_max_s <= 3600");
  if (!(connect_timeout_s > 0 && connect_timeout_s <= 3600)) return InvalidArgument("client: connect_timeout_s 0..3600");
  if (!(ping_interval_s >= 0 && ping_interval_s <= 3600)) return InvalidArgument("client: ping_interval_s 0..3600");
  if (!(color_wait_s >= 0 && color_wait_s <= 10)) return InvalidArgument("client: color_wait_s 0..10");
  if (quality < 0 || quality > 10) return InvalidArgument("client: quality must be 0..10, got " + std::to_string(quality));
  if (max_pending_frames < 1 || max_pending_audio < 1 || max_send_queue < 1)
    return InvalidArgument("client: queue sizes must be >= 1");
  if (max_message_bytes < 1024 || max_message_bytes > (64u << 20))
    return InvalidArgument("client: max_message_bytes 1024..64 MiB");
  if (role == protocol::Role::kThinClient) return InvalidArgument("client: thin clients talk to a render host");
  return OkStatus();
}

// ------------------------------------------------------------------ NetContext

struct NetContext::Impl {
  void Shutdown() {
    work.reset();
    {
      std::lock_guard<std::mutex> l(cpu_mu);
      clocks.clear();
    }
    for (auto& t : threads)
      if (t.joinable()) t.join();
    threads.clear();
  }
  asio::io_context io;
  std::optional<asio::executor_work_guard<asio::io_context::executor_type>> work;
  std::vector<std::thread> threads;
  std::mutex cpu_mu;
  std::vector<clockid_t> clocks;
};

NetContext::NetContext(int threads) : impl_(std::make_unique<Impl>()) {
  impl_->work.emplace(impl_->io.get_executor());
  Impl* raw = impl_.get();
  for (int i = 0; i < std::max(1, threads); ++i) {
    impl_->threads.emplace_back([raw] {
      clockid_t cid;
      if (pthread_getcpuclockid(pthread_self(), &cid) == 0) {
        std::lock_guard<std::mutex> l(raw->cpu_mu);
        raw->clocks.push_back(cid);
      }
      raw->io.run();
    });
  }
}

NetContext::~NetContext() { impl_->Shutdown(); }

double NetContext::CpuMs() const {
  std::lock_guard<std::mutex> l(impl_->cpu_mu);
  double ms = 0;
  for (clockid_t c : impl_->clocks) {
    timespec ts{};
    if (clock_gettime(c, &ts) == 0) ms += ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
  }
  return ms;
}

// ------------------------------------------------------------------ SiteClient::Impl

struct SiteClient::Impl : std::enable_shared_from_this<SiteClient::Impl> {
  Impl(ClientOptions o, ClientCallbacks c, NetContext* ctx)
      : opt(std::move(o)),
        cb(std::move(c)),
        own_ctx(ctx ? nullptr : std::make_unique<NetContext>(1)),
        io(ctx ? ctx->impl()->io : own_ctx->impl()->io),
        strand(asio::make_strand(io)),
        resolver(io),
        timer(io),
        ping_timer(io),
        color_timer(io),
        assembler(o.max_message_bytes) {
    limits.max_message_bytes = opt.max_message_bytes;
    limits.max_frame_payload = std::min<uint32_t>(limits.max_frame_payload, opt.max_message_bytes);
    if (opt.tls.enabled) {
      ssl = std::make_unique<asio::ssl::context>(asio::ssl::context::tls_client);
      ssl->set_options(asio::ssl::context::default_workarounds | asio::ssl::context::no_sslv2 |
                       asio::ssl::context::no_sslv3 | asio::ssl::context::no_tlsv1 |
                       asio::ssl::context::no_tlsv1_1);
    }
  }

  // ---- lifecycle (strand)
  void Connect() {
    if (stopped) return;
    SetState(ClientState::kConnecting, OkStatus());
    ++attempt_id;
    const uint64_t my = attempt_id;
    parser = std::make_unique<protocol::FrameParser>(limits);
    assembler.Reset();
    welcomed = false;
    tls.reset();  // the previous connection's handlers have all run (backoff ≥ its timer)
    sock.reset();
    auto self = shared_from_this();
    timer.expires_after(Timeout(opt.connect_timeout_s));
    timer.async_wait(asio::bind_executor(strand, [this, self, my](std::error_code ec) {
      if (ec || my != attempt_id || welcomed || stopped) return;
      Lost(Unavailable("no Welcome from " + opt.host + ":" + std::to_string(opt.port) + " within " +
                       std::to_string(opt.connect_timeout_s) + " s"));
    }));
    resolver.async_resolve(
        opt.host, std::to_string(opt.port),
        asio::bind_executor(strand, [this, self, my](std::error_code ec, tcp::resolver::results_type results) {
          if (my != attempt_id || stopped) return;
          if (ec) {
            Lost(Unavailable("resolve " + opt.host + ": " + ec.message()));
            return;
          }
          sock = std::make_unique<tcp::socket>(io);
          asio::async_connect(*sock, results,
                              asio::bind_executor(strand, [this, self, my](std::error_code ec2, const tcp::endpoint&) {
                                if (my != attempt_id || stopped) return;
                                if (ec2) {
                                  Lost(Unavailable("connect to " + opt.host + ":" + std::to_string(opt.port) + ": " +
                                                   ec2.message()));
                                  return;
                                }
                                std::error_code ignore;
                                sock->set_option(tcp::no_delay(true), ignore);
                                if (ssl) {
                                  StartTls(my);
                                } else {
                                  SendHello();
                                  DoRead(my);
                                }
                              }));
        }));
  }

  // Once, at start: the CA file and the verification mode.
  Status SetUpTls() {
    if (!ssl) return OkStatus();
    std::error_code ec;
    if (opt.tls.verify) {
      ssl->set_verify_mode(asio::ssl::verify_peer, ec);
      if (!ec && !opt.tls.ca_file.empty()) ssl->load_verify_file(opt.tls.ca_file, ec);
      if (!ec && opt.tls.ca_file.empty()) ssl->set_default_verify_paths(ec);
      if (ec) return InvalidArgument("tls: cannot load CA file '" + opt.tls.ca_file + "': " + ec.message());
      ssl->set_verify_callback(asio::ssl::host_name_verification(opt.host), ec);
    } else {
      ssl->set_verify_mode(asio::ssl::verify_none, ec);
    }
    if (ec) return Internal("tls: " + ec.message());
    return OkStatus();
  }

  void StartTls(uint64_t my) {
    tls = std::make_unique<asio::ssl::stream<tcp::socket>>(std::move(*sock), *ssl);
    sock.reset();
    SSL_set_tlsext_host_name(tls->native_handle(), opt.host.c_str());
    auto self = shared_from_this();
    tls->async_handshake(asio::ssl::stream_base::client, asio::bind_executor(strand, [this, self, my](std::error_code ec) {
                           if (my != attempt_id || stopped) return;
                           if (ec) {
                             Lost(Unavailable("TLS handshake with " + opt.host + ": " + ec.message()));
                             return;
                           }
                           SendHello();
                           DoRead(my);
                         }));
  }

  tcp::socket* Lowest() { return tls ? &tls->next_layer() : sock.get(); }

  void CloseSocket() {
    std::error_code ignore;
    if (tcp::socket* s = Lowest()) {
      s->shutdown(tcp::socket::shutdown_both, ignore);
      s->close(ignore);
    }
    writing = false;
    out.clear();
  }

  // The connection ended: back off and retry (or stop).
  void Lost(const Status& why) {
    ++attempt_id;  // invalidates handlers of this connection
    CloseSocket();
    timer.cancel();
    ping_timer.cancel();
    FlushPending();
    if (!welcomed) CountFailure();
    welcomed = false;
    if (stopped) return;
    if (!opt.reconnect) {
      SetState(ClientState::kStopped, why);
      return;
    }
    const double delay = std::min(opt.backoff_max_s, opt.backoff_initial_s * std::pow(2.0, std::min(backoff_step, 30)));
    ++backoff_step;
    SetState(ClientState::kBackoff, why);
    auto self = shared_from_this();
    const uint64_t my = attempt_id;
    timer.expires_after(Timeout(delay));
    timer.async_wait(asio::bind_executor(strand, [this, self, my](std::error_code ec) {
      if (ec || my != attempt_id || stopped) return;
      Connect();
    }));
  }

  void CountFailure() {
    std::lock_guard<std::mutex> l(mu);
    ++stats.connect_failures;
  }

  void SetState(ClientState s, const Status& why) {
    {
      std::lock_guard<std::mutex> l(mu);
      state = s;
      last_status = why;
    }
    cv.notify_all();
    if (cb.on_state) cb.on_state(s, why);
  }

  // ---- reading (strand)
  void DoRead(uint64_t my) {
    auto self = shared_from_this();
    auto h = asio::bind_executor(strand, [this, self, my](std::error_code ec, size_t n) {
      if (my != attempt_id || stopped) return;
      if (ec) {
        Lost(Unavailable(ec == asio::error::eof ? "site closed the connection" : "read: " + ec.message()));
        return;
      }
      {
        std::lock_guard<std::mutex> l(mu);
        stats.bytes_received += n;
      }
      const Status fed = parser->Feed(rbuf.data(), n);
      protocol::Frame f;
      while (my == attempt_id && parser->Next(&f)) OnFrame(std::move(f));
      if (my != attempt_id || stopped) return;
      if (!fed.ok()) {
        Lost(DataLoss("site sent a bad frame: " + fed.message()));
        return;
      }
      DoRead(my);
    });
    if (tls)
      tls->async_read_some(asio::buffer(rbuf), std::move(h));
    else
      sock->async_read_some(asio::buffer(rbuf), std::move(h));
  }

  void OnFrame(protocol::Frame&& f) {
    bool complete = false;
    RawMessage raw;
    Status s = assembler.Add(std::move(f), &complete, &raw);
    if (!s.ok()) {
      Lost(DataLoss("site sent bad fragments: " + s.message()));
      return;
    }
    if (!complete) return;
    raw.received_us = WallUs();
    {
      std::lock_guard<std::mutex> l(mu);
      ++stats.messages_received;
    }
    const MessageType t = raw.header.type;
    if (!welcomed) {
      if (t == MessageType::kRefuse) {
        auto p = protocol::DecodePayload(t, raw.payload, limits);
        if (!p.ok()) {
          Lost(DataLoss("malformed Refuse: " + p.status().message()));
          return;
        }
        const auto& r = std::get<protocol::Refuse>(*p);
        {
          std::lock_guard<std::mutex> l(mu);
          refusal = r;
        }
        const Status why = Unavailable(std::string("refused: ") + ReasonName(r.reason) + ": " + r.message);
        if (r.reason == protocol::RefuseReason::kOverloaded && opt.reconnect) {
          Lost(why);  // the site is full now; try again later
        } else {
          ++attempt_id;
          CloseSocket();
          timer.cancel();
          CountFailure();
          SetState(ClientState::kRefused, why);
        }
        return;
      }
      if (t != MessageType::kWelcome) {
        Lost(DataLoss(std::string("expected Welcome, got ") + protocol::MessageTypeName(t)));
        return;
      }
      auto p = protocol::DecodePayload(t, raw.payload, limits);
      if (!p.ok()) {
        Lost(DataLoss("malformed Welcome: " + p.status().message()));
        return;
      }
      welcomed = true;
      backoff_step = 0;
      video_decoders.clear();  // a new connection starts each stream afresh
      timer.cancel();
      {
        std::lock_guard<std::mutex> l(mu);
        welcome = std::get<protocol::Welcome>(*p);
        refusal.reset();
        ++stats.connects;
      }
      if (opt.role != protocol::Role::kPublisher) {
        protocol::Control c;
        c.command = protocol::ControlCommand::kSubscribe;
        // Regions only after the site announces them (Deliver, kStats).
        c.value = subscription.load() & kSubscribeAll;
        if (c.value != 0) Queue(Encode(Header{}, c), false);
        regions_subscribed = false;
        // The viewer's quality cap, again on every connection (the site keeps it per session).
        const int q = quality.load();
        if (q < 10) {
          protocol::Control qc;
          qc.command = protocol::ControlCommand::kSetQuality;
          qc.value = q;
          Queue(Encode(Header{}, qc), false);
        }
      }
      SetState(ClientState::kConnected, OkStatus());
      ArmPing();
      return;
    }
    Deliver(raw);
  }

  // A whole content message after Welcome (from the socket, or Feed()).
  void Deliver(const RawMessage& raw) {
    const MessageType t = raw.header.type;
    if (cb.on_raw) cb.on_raw(raw);
    switch (t) {
      case MessageType::kMeshFrame: OnMesh(raw); return;
      case MessageType::kColorFrame: OnColor(raw); return;
      case MessageType::kAudioPose: {
        // A lean frame's sequence and capture time are the header's.
        auto p = protocol::DecodePayload(raw.header, raw.payload, limits);
        if (!p.ok()) return BadPayload(t, p.status());
        const auto& a = std::get<protocol::AudioPose>(*p);
        {
          std::lock_guard<std::mutex> l(mu);
          ++stats.audio_received;
          audio_q.emplace_back(a, raw.header.stream_id);
          while (audio_q.size() > opt.max_pending_audio) audio_q.pop_front();
        }
        if (cb.on_audio) cb.on_audio(a, raw.header.stream_id);
        return;
      }
      case MessageType::kRig: {
        auto p = protocol::DecodePayload(t, raw.payload, limits);
        if (!p.ok()) return BadPayload(t, p.status());
        const Rig& r = std::get<protocol::RigMessage>(*p).rig;
        {
          std::lock_guard<std::mutex> l(mu);
          rig = r;
        }
        if (cb.on_rig) cb.on_rig(r);
        return;
      }
      case MessageType::kPing: {
        auto p = protocol::DecodePayload(t, raw.payload, limits);
        if (!p.ok()) return BadPayload(t, p.status());
        const auto& ping = std::get<protocol::Ping>(*p);
        const int64_t now = WallUs();
        Queue(Encode(Header{}, protocol::Pong{ping.nonce, ping.send_time_us, now, now}), false);
        return;
      }
      case MessageType::kPong: {
        auto p = protocol::DecodePayload(t, raw.payload, limits);
        if (!p.ok()) return BadPayload(t, p.status());
        const auto& pong = std::get<protocol::Pong>(*p);
        const int64_t t3 = WallUs();
        const int64_t rtt = (t3 - pong.ping_send_time_us) - (pong.send_time_us - pong.receive_time_us);
        if (rtt < 0 || rtt > 3600LL * 1000000) return;
        const int64_t offset = ((pong.receive_time_us - pong.ping_send_time_us) + (pong.send_time_us - t3)) / 2;
        std::lock_guard<std::mutex> l(mu);
        stats.rtt_ms = rtt * 1e-3;
        if (stats.rtt_min_ms < 0 || rtt * 1e-3 <= stats.rtt_min_ms) {
          stats.rtt_min_ms = rtt * 1e-3;
          stats.clock_offset_us = offset;
        }
        return;
      }
      case MessageType::kStats: {
        auto p = protocol::DecodePayload(t, raw.payload, limits);
        if (!p.ok()) return BadPayload(t, p.status());
        for (const auto& [key, value] : std::get<protocol::Stats>(*p).values) {
          if (key == protocol::kLayerKey || key == protocol::kLayersKey || key == protocol::kLayerStepKey) {
            // Informational (a site's stats are not trusted for anything else): clamped.
            const int v = std::isfinite(value) ? static_cast<int>(std::clamp(value, 0.0, 16.0)) : 0;
            std::lock_guard<std::mutex> l(mu);
            if (key == protocol::kLayersKey) {
              stats.num_layers = std::max(v, 1);
            } else if (key == protocol::kLayerStepKey) {
              stats.layer_step = std::max(v, 1);
            } else if (v != stats.layer) {
              stats.layer = v;
              ++stats.layer_changes;
            }
            continue;
          }
          if (key != protocol::kRegionsAnnounceKey) continue;
          // The site publishes Regions: ask for them (once per connection).
          if ((subscription.load() & kSubscribeRegions) && !regions_subscribed && !opt.fed &&
              opt.role != protocol::Role::kPublisher) {
            protocol::Control c;
            c.command = protocol::ControlCommand::kSubscribe;
            c.value = kSubscribeRegions;
            Queue(Encode(Header{}, c), false);
            regions_subscribed = true;
          }
        }
        return;
      }
      case MessageType::kRegions: {
        auto p = protocol::DecodePayload(t, raw.payload, limits);
        if (!p.ok()) return BadPayload(t, p.status());
        ReceivedRegions r;
        r.regions = std::move(std::get<protocol::Regions>(*p));
        r.capture_time_us = raw.header.capture_time_us;
        r.received_us = raw.received_us;
        {
          std::lock_guard<std::mutex> l(mu);
          ++stats.regions_received;
          latest_regions = r;
        }
        if (cb.on_regions) cb.on_regions(r);
        return;
      }
      case MessageType::kWelcome:
      case MessageType::kRefuse:
      case MessageType::kHello:
        Lost(DataLoss(std::string("unexpected ") + protocol::MessageTypeName(t) + " after Welcome"));
        return;
      default:
        return;  // Control, ClientPose, RenderedFrame: not for this client
    }
  }

  // Asks the site for a colour keyframe (V1), at most once per 250 ms: the
  // site's answer takes a frame or two to arrive, and every pod stream that
  // waits would ask again.
  void RequestKeyframe() {
    const auto now = std::chrono::steady_clock::now();
    if (now - last_keyframe_request < std::chrono::milliseconds(250)) return;
    last_keyframe_request = now;
    protocol::Control c;
    c.command = protocol::ControlCommand::kRequestKeyFrame;
    Queue(Encode(Header{}, c), false);
    std::lock_guard<std::mutex> l(mu);
    ++stats.keyframe_requests;
  }

  void BadPayload(MessageType t, const Status& s) {
    std::lock_guard<std::mutex> l(mu);
    ++stats.decode_errors;
    last_decode_error = Status(s.code(), std::string(protocol::MessageTypeName(t)) + ": " + s.message());
  }

  static bool PeekFrameIndex(const std::vector<uint8_t>& p, int64_t* fi) {
    if (p.size() < 8) return false;
    uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v |= static_cast<uint64_t>(p[i]) << (8 * i);
    *fi = static_cast<int64_t>(v);
    return true;
  }

  void OnMesh(const RawMessage& raw) {
    ReceivedFrame f;
    f.capture_time_us = raw.header.capture_time_us;
    f.received_us = raw.received_us;
    f.wire_bytes = raw.payload.size();
    f.has_mesh = true;
    if (opt.decode) {
      auto p = protocol::DecodePayload(MessageType::kMeshFrame, raw.payload, limits);
      if (!p.ok()) return BadPayload(MessageType::kMeshFrame, p.status());
      const auto& m = std::get<protocol::MeshFrame>(*p);
      f.frame_index = m.frame_index;
      const auto t0 = std::chrono::steady_clock::now();
      const Status s = protocol::DecodeGeometry(m.data, &f.mesh, limits);
      if (!s.ok()) return BadPayload(MessageType::kMeshFrame, s);
      std::lock_guard<std::mutex> l(mu);
      stats.mesh_decode_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    } else if (!PeekFrameIndex(raw.payload, &f.frame_index)) {
      return BadPayload(MessageType::kMeshFrame, DataLoss("mesh_frame: truncated"));
    }
    FlushPending();  // an older frame whose colour never came
    pending = std::move(f);
    if (!(subscription & kSubscribeColor)) {
      FlushPending();
      return;
    }
    auto self = shared_from_this();
    const uint64_t my = attempt_id;
    color_timer.expires_after(Timeout(opt.color_wait_s));
    color_timer.async_wait(asio::bind_executor(strand, [this, self, my](std::error_code ec) {
      if (ec || my != attempt_id) return;
      FlushPending();
    }));
  }

  void OnColor(const RawMessage& raw) {
    int64_t fi = -1;
    std::vector<DecodedImage> images;
    if (opt.decode) {
      auto p = protocol::DecodePayload(MessageType::kColorFrame, raw.payload, limits);
      if (!p.ok()) return BadPayload(MessageType::kColorFrame, p.status());
      const auto& c = std::get<protocol::ColorFrame>(*p);
      fi = c.frame_index;
      const auto t0 = std::chrono::steady_clock::now();
      uint64_t waiting = 0;
      for (const auto& img : c.images) {
        DecodedImage d;
        d.pod_id = img.pod_id;
        if (c.codec == protocol::ColorCodec::kV1) {
          // V1: one decoder per pod stream; a delta frame without its
          // predecessor (joined mid-stream, a frame dropped on the way) waits
          // for a keyframe, which this client asks the site for.
          auto& dec = video_decoders[img.pod_id];
          if (dec == nullptr) dec = std::make_unique<protocol::VideoDecoder>();
          const Status s = dec->Decode(img.data, limits);
          if (s.code() == StatusCode::kUnavailable) {
            ++waiting;
            continue;
          }
          if (!s.ok()) {
            BadPayload(MessageType::kColorFrame, s);
            ++waiting;  // the decoder now waits for a keyframe too
            continue;
          }
          d.image = dec->image();
          d.mask = dec->mask();
        } else {
          const Status s = protocol::DecodeColor(img.data, &d.image, &d.mask, limits);
          if (!s.ok()) return BadPayload(MessageType::kColorFrame, s);
        }
        images.push_back(std::move(d));
      }
      if (waiting > 0) RequestKeyframe();
      std::lock_guard<std::mutex> l(mu);
      stats.color_images_waiting += waiting;
      stats.color_decode_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    } else if (!PeekFrameIndex(raw.payload, &fi)) {
      return BadPayload(MessageType::kColorFrame, DataLoss("color_frame: truncated"));
    }
    if (pending && pending->frame_index == fi) {
      pending->images = std::move(images);
      pending->has_color = true;
      pending->wire_bytes += raw.payload.size();
      FlushPending();
      return;
    }
    FlushPending();
    ReceivedFrame f;  // colour without (subscribed) geometry
    f.frame_index = fi;
    f.capture_time_us = raw.header.capture_time_us;
    f.received_us = raw.received_us;
    f.wire_bytes = raw.payload.size();
    f.has_color = true;
    f.images = std::move(images);
    pending = std::move(f);
    FlushPending();
  }

  void FlushPending() {
    if (!pending) return;
    color_timer.cancel();
    ReceivedFrame f = std::move(*pending);
    pending.reset();
    {
      std::lock_guard<std::mutex> l(mu);
      const int64_t latency_us = f.received_us + stats.clock_offset_us - f.capture_time_us;
      constexpr int64_t kDayUs = int64_t{86400} * 1000000;
      f.latency_known = f.capture_time_us > 0 && latency_us > -kDayUs && latency_us < kDayUs;
      f.latency_ms = f.latency_known ? static_cast<double>(latency_us) * 1e-3 : 0.0;
      ++stats.frames_received;
      stats.last_frame_index = f.frame_index;
      // Without a callback the queue holds the only copy (a frame is a
      // mesh and eight images: copying it cost the live viewers ~2 % of
      // the machine).
      if (cb.on_frame == nullptr) {
        frames.push_back(std::move(f));
      } else if (keep_frames) {
        frames.push_back(f);
      }
      while (frames.size() > opt.max_pending_frames) {
        frames.pop_front();
        ++stats.frames_dropped_local;
      }
    }
    cv.notify_all();
    if (cb.on_frame) cb.on_frame(f);
  }

  // ---- writing (strand)
  void SendHello() {
    protocol::Hello h;
    h.role = opt.role;
    h.capabilities = opt.capabilities;
    h.access_token = opt.token;
    h.client_name = opt.name;
    Queue(Encode(Header{}, h), true);
  }

  // `force`: also before Welcome (the Hello).
  void Queue(std::vector<uint8_t> bytes, bool force) {
    if (!force && !welcomed) {
      std::lock_guard<std::mutex> l(mu);
      ++stats.sends_dropped;
      return;
    }
    if (out.size() >= opt.max_send_queue) {
      std::lock_guard<std::mutex> l(mu);
      ++stats.sends_dropped;
      return;
    }
    out.push_back(std::move(bytes));
    DoWrite();
  }

  void DoWrite() {
    if (writing || out.empty() || !Lowest()) return;
    writing = true;
    auto self = shared_from_this();
    const uint64_t my = attempt_id;
    auto h = asio::bind_executor(strand, [this, self, my](std::error_code ec, size_t) {
      if (my != attempt_id || stopped) return;
      writing = false;
      if (ec) {
        Lost(Unavailable("write: " + ec.message()));
        return;
      }
      out.pop_front();
      DoWrite();
    });
    if (tls)
      asio::async_write(*tls, asio::buffer(out.front()), std::move(h));
    else
      asio::async_write(*sock, asio::buffer(out.front()), std::move(h));
  }

  void ArmPing() {
    if (opt.ping_interval_s <= 0) return;
    auto self = shared_from_this();
    const uint64_t my = attempt_id;
    // First ping at once (RTT and clock offset early), then every interval.
    ping_timer.expires_after(ping_count == 0 ? std::chrono::microseconds(0) : Timeout(opt.ping_interval_s));
    ping_timer.async_wait(asio::bind_executor(strand, [this, self, my](std::error_code ec) {
      if (ec || my != attempt_id || stopped) return;
      ++ping_count;
      Queue(Encode(Header{}, protocol::Ping{ping_count, WallUs()}), false);
      ArmPing();
    }));
  }

  // Posts a send from any thread.
  void Post(std::vector<uint8_t> bytes) {
    auto self = shared_from_this();
    asio::post(strand, [this, self, b = std::move(bytes)]() mutable {
      if (stopped) return;
      Queue(std::move(b), false);
    });
  }

  ClientOptions opt;
  ClientCallbacks cb;
  std::unique_ptr<NetContext> own_ctx;
  asio::io_context& io;
  asio::strand<asio::io_context::executor_type> strand;
  tcp::resolver resolver;
  asio::steady_timer timer;       // connect timeout, backoff
  asio::steady_timer ping_timer;
  asio::steady_timer color_timer;
  std::unique_ptr<asio::ssl::context> ssl;
  std::unique_ptr<tcp::socket> sock;
  std::unique_ptr<asio::ssl::stream<tcp::socket>> tls;
  protocol::Limits limits;
  std::unique_ptr<protocol::FrameParser> parser;
  RawAssembler assembler;
  std::array<uint8_t, 65536> rbuf{};
  std::deque<std::vector<uint8_t>> out;
  bool writing = false;
  bool welcomed = false;
  bool keep_frames = false;  // on_frame set and the pull API used too
  uint64_t attempt_id = 0;
  int backoff_step = 0;
  uint64_t ping_count = 0;
  std::atomic<uint32_t> subscription{0};
  std::atomic<int> quality{10};  // Control set quality, resent after every Welcome when < 10
  bool regions_subscribed = false;  // Subscribe(regions) sent on this connection (strand)
  std::optional<ReceivedFrame> pending;
  std::map<uint16_t, std::unique_ptr<protocol::VideoDecoder>> video_decoders;  // V1, per pod (strand)
  std::chrono::steady_clock::time_point last_keyframe_request{};
  std::atomic<bool> stopped{false};

  mutable std::mutex mu;
  std::condition_variable cv;
  ClientState state = ClientState::kConnecting;
  Status last_status;
  Status last_decode_error;
  std::optional<protocol::Refuse> refusal;
  std::optional<protocol::Welcome> welcome;
  protocol::HeadPose last_sent_pose;  // SendAudioPose: for a classic frame made from a lean one without pose
  std::optional<Rig> rig;
  std::optional<ReceivedRegions> latest_regions;
  std::deque<ReceivedFrame> frames;
  std::deque<std::pair<protocol::AudioPose, uint32_t>> audio_q;
  ClientStats stats;
};

// ------------------------------------------------------------------ SiteClient

SiteClient::SiteClient(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}
SiteClient::~SiteClient() { Stop(); }

StatusOr<std::unique_ptr<SiteClient>> SiteClient::Start(ClientOptions options, ClientCallbacks callbacks,
                                                        NetContext* context) {
  HOLO_RETURN_IF_ERROR(options.Check());
  auto impl = std::make_shared<Impl>(std::move(options), std::move(callbacks), context);
  HOLO_RETURN_IF_ERROR(impl->SetUpTls());
  impl->subscription = impl->opt.subscribe;
  impl->quality = impl->opt.quality;
  Impl* raw = impl.get();
  if (raw->opt.fed) {
    asio::post(impl->strand, [raw, keep = impl] {
      raw->welcomed = true;
      raw->SetState(ClientState::kConnected, OkStatus());
    });
  } else {
    asio::post(impl->strand, [raw, keep = impl] { raw->Connect(); });
  }
  return std::unique_ptr<SiteClient>(new SiteClient(std::move(impl)));
}

void SiteClient::Feed(RawMessage message) {
  if (!impl_ || !impl_->opt.fed || impl_->stopped) return;
  auto impl = impl_;
  asio::post(impl->strand, [impl, m = std::move(message)]() mutable {
    if (impl->stopped) return;
    {
      std::lock_guard<std::mutex> l(impl->mu);
      ++impl->stats.messages_received;
      impl->stats.bytes_received += m.payload.size() + protocol::kHeaderSize;
    }
    impl->Deliver(m);
  });
}

void SiteClient::Stop() {
  if (!impl_ || impl_->stopped.exchange(true)) return;
  std::mutex done_mu;
  std::condition_variable done_cv;
  bool done = false;
  auto impl = impl_;
  asio::post(impl->strand, [&, impl] {
    ++impl->attempt_id;
    impl->resolver.cancel();
    impl->CloseSocket();
    impl->timer.cancel();
    impl->ping_timer.cancel();
    impl->color_timer.cancel();
    {
      std::lock_guard<std::mutex> l(impl->mu);
      impl->state = ClientState::kStopped;
    }
    impl->cv.notify_all();
    std::lock_guard<std::mutex> l(done_mu);
    done = true;
    done_cv.notify_all();
  });
  std::unique_lock<std::mutex> l(done_mu);
  done_cv.wait(l, [&] { return done; });
  l.unlock();
  // Own io thread: let the cancelled handlers finish, then join it (the
  // io_context itself lives as long as the Impl).
  if (impl->own_ctx) impl->own_ctx->impl()->Shutdown();
}

ClientState SiteClient::state() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->state;
}

Status SiteClient::status() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->last_status;
}

std::optional<protocol::Refuse> SiteClient::refusal() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->refusal;
}

std::optional<protocol::Welcome> SiteClient::welcome() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->welcome;
}

std::optional<Rig> SiteClient::rig() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->rig;
}

bool SiteClient::WaitConnected(double timeout_s) {
  std::unique_lock<std::mutex> l(impl_->mu);
  impl_->cv.wait_for(l, Timeout(timeout_s), [&] {
    return impl_->state == ClientState::kConnected || impl_->state == ClientState::kRefused ||
           impl_->state == ClientState::kStopped;
  });
  return impl_->state == ClientState::kConnected;
}

bool SiteClient::PollFrame(ReceivedFrame* out) {
  std::lock_guard<std::mutex> l(impl_->mu);
  impl_->keep_frames = true;
  if (impl_->frames.empty()) return false;
  *out = std::move(impl_->frames.front());
  impl_->frames.pop_front();
  return true;
}

bool SiteClient::LatestFrame(ReceivedFrame* out) {
  std::lock_guard<std::mutex> l(impl_->mu);
  impl_->keep_frames = true;
  if (impl_->frames.empty()) return false;
  *out = std::move(impl_->frames.back());
  impl_->stats.frames_dropped_local += impl_->frames.size() - 1;
  impl_->frames.clear();
  return true;
}

bool SiteClient::WaitFrame(ReceivedFrame* out, double timeout_s) {
  std::unique_lock<std::mutex> l(impl_->mu);
  impl_->keep_frames = true;
  impl_->cv.wait_for(l, Timeout(timeout_s), [&] { return !impl_->frames.empty(); });
  if (impl_->frames.empty()) return false;
  *out = std::move(impl_->frames.front());
  impl_->frames.pop_front();
  return true;
}

bool SiteClient::PollAudio(protocol::AudioPose* out, uint32_t* stream_id) {
  std::lock_guard<std::mutex> l(impl_->mu);
  if (impl_->audio_q.empty()) return false;
  *out = std::move(impl_->audio_q.front().first);
  if (stream_id) *stream_id = impl_->audio_q.front().second;
  impl_->audio_q.pop_front();
  return true;
}

void SiteClient::SendAudioPose(const protocol::AudioPose& audio) {
  Header h;
  h.stream_id = 0;
  h.sequence = audio.sequence;
  h.capture_time_us = audio.capture_time_us;
  protocol::AudioCodec negotiated = protocol::AudioCodec::kOpus;
  protocol::HeadPose last_pose;
  {
    std::lock_guard<std::mutex> l(impl_->mu);
    if (impl_->welcome) negotiated = impl_->welcome->audio_codec;
    if (audio.has_pose) impl_->last_sent_pose = audio.pose;
    last_pose = impl_->last_sent_pose;
  }
  if (audio.codec == protocol::AudioCodec::kOpus && negotiated == protocol::AudioCodec::kOpusLean) {
    impl_->Post(Encode(h, protocol::ToLeanAudioPose(audio)));
  } else if (audio.codec == protocol::AudioCodec::kOpusLean && negotiated != protocol::AudioCodec::kOpusLean) {
    impl_->Post(Encode(h, protocol::ToClassicAudioPose(audio, last_pose)));
  } else {
    impl_->Post(Encode(h, audio));
  }
}

void SiteClient::SendClientPose(const protocol::ClientPose& pose) {
  Header h;
  h.capture_time_us = pose.time_us;
  impl_->Post(Encode(h, pose));
}

void SiteClient::SendControl(const protocol::Control& control) {
  if (control.command == protocol::ControlCommand::kSubscribe && control.value >= 0 && control.value <= 15)
    impl_->subscription |= control.value == 0 ? kSubscribeAll : static_cast<uint32_t>(control.value);
  if (control.command == protocol::ControlCommand::kUnsubscribe && control.value >= 0 && control.value <= 15)
    impl_->subscription &= ~(control.value == 0 ? kSubscribeAll : static_cast<uint32_t>(control.value));
  impl_->Post(Encode(Header{}, control));
}

namespace {
protocol::Control MakeControl(protocol::ControlCommand c, int64_t value = 0, float speed = 1.0f) {
  protocol::Control out;
  out.command = c;
  out.stream_id = 0;
  out.value = value;
  out.speed = speed;
  return out;
}
}  // namespace

void SiteClient::Subscribe(uint32_t bits) { SendControl(MakeControl(protocol::ControlCommand::kSubscribe, bits)); }
void SiteClient::Unsubscribe(uint32_t bits) { SendControl(MakeControl(protocol::ControlCommand::kUnsubscribe, bits)); }
void SiteClient::SetQuality(int level) {
  impl_->quality = std::clamp(level, 0, 10);
  SendControl(MakeControl(protocol::ControlCommand::kSetQuality, impl_->quality.load()));
}
void SiteClient::Pause() { SendControl(MakeControl(protocol::ControlCommand::kPause)); }
void SiteClient::Resume() { SendControl(MakeControl(protocol::ControlCommand::kResume)); }
void SiteClient::SetLoop(bool loop) { SendControl(MakeControl(protocol::ControlCommand::kSetLoop, loop ? 1 : 0)); }
void SiteClient::Seek(int64_t t) { SendControl(MakeControl(protocol::ControlCommand::kSeek, t)); }
void SiteClient::SetSpeed(float s) { SendControl(MakeControl(protocol::ControlCommand::kSetSpeed, 0, s)); }

bool SiteClient::LatestRegions(ReceivedRegions* out) const {
  std::lock_guard<std::mutex> l(impl_->mu);
  if (!impl_->latest_regions) return false;
  *out = *impl_->latest_regions;
  return true;
}

ClientStats SiteClient::stats() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  ClientStats s = impl_->stats;
  return s;
}

}  // namespace holo::net
