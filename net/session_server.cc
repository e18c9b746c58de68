#include "net/session_server.h"

#include <fcntl.h>
#include <linux/sockios.h>
#include <pthread.h>
#include <sys/ioctl.h>
#include <time.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <mutex>
#include <optional>
#include <span>
#include <thread>

#include <asio.hpp>
#include <asio/ssl.hpp>
#include <openssl/crypto.h>
#include <openssl/evp.h>

#include "common/log.h"
#include "net/layer_control.h"

namespace holo::net {

using asio::ip::tcp;
using protocol::Control;
using protocol::ControlCommand;
using protocol::Header;
using protocol::Message;
using protocol::MessageType;
using protocol::RefuseReason;
using protocol::Role;

namespace {

using Sha = std::array<unsigned char, 32>;

Sha HashToken(const std::string& s) {
  Sha out{};
  unsigned int len = 0;
  EVP_Digest(s.data(), s.size(), out.data(), &len, EVP_sha256(), nullptr);
  return out;
}

int64_t SteadyUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

const char* RefuseReasonName(RefuseReason r) {
  switch (r) {
    case RefuseReason::kUnsupportedVersion: return "UNSUPPORTED_VERSION";
    case RefuseReason::kBadToken: return "BAD_TOKEN";
    case RefuseReason::kRoleNotAllowed: return "ROLE_NOT_ALLOWED";
    case RefuseReason::kMalformed: return "MALFORMED";
    case RefuseReason::kOverloaded: return "OVERLOADED";
    case RefuseReason::kNoCommonCodec: return "NO_COMMON_CODEC";
    case RefuseReason::kBadCalibration: return "BAD_CALIBRATION";
  }
  return "UNKNOWN";
}

std::chrono::microseconds Seconds(double s) { return std::chrono::microseconds(static_cast<int64_t>(s * 1e6)); }

bool IsViewerRole(Role r) { return r == Role::kViewer || r == Role::kRenderHost || r == Role::kRecorder; }

}  // namespace

bool TokensEqual(const std::string& a, const std::string& b) {
  const Sha ha = HashToken(a), hb = HashToken(b);
  return CRYPTO_memcmp(ha.data(), hb.data(), ha.size()) == 0;
}

class Session;

class Server::Impl {
 public:
  Impl(ServerConfig c, ServerHooks h) : cfg(std::move(c)), hooks(std::move(h)), acceptor(io) {
    publisher_hash = HashToken(cfg.publisher_token);
    viewer_hash = HashToken(cfg.viewer_token);
  }

  // Through the hook when one is set, else the log at `level` (refusals and
  // failures are warnings, arrivals and departures info).
  void Log(const std::string& s, spdlog::level::level_enum level = spdlog::level::info) {
    if (hooks.log) {
      hooks.log(s);
    } else {
      spdlog::log(level, "[net] {}", s);
    }
  }
  void Accept();
  // Registers a session after a successful Hello; false when the site is full.
  bool Register(const std::shared_ptr<Session>& s, Role role, std::string* why);
  void Remove(uint64_t id, bool was_pending);
  std::vector<std::shared_ptr<Session>> Viewers() const {
    std::lock_guard<std::mutex> l(mu);
    return viewers_list;
  }
  void RebuildViewersLocked();

  ServerConfig cfg;
  ServerHooks hooks;
  Sha publisher_hash{}, viewer_hash{};
  // io first: destroyed last.
  asio::io_context io;
  std::optional<asio::executor_work_guard<asio::io_context::executor_type>> work;
  tcp::acceptor acceptor;
  std::unique_ptr<asio::ssl::context> ssl;
  std::vector<std::thread> threads;
  std::mutex cpu_mu;
  std::vector<clockid_t> cpu_clocks;
  std::atomic<bool> stopped{false};

  mutable std::mutex mu;
  std::map<uint64_t, std::shared_ptr<Session>> sessions;  // every open connection
  std::map<uint64_t, std::shared_ptr<Session>> viewers;   // welcomed viewers/render hosts/recorders
  std::vector<std::shared_ptr<Session>> viewers_list;     // snapshot of `viewers` for publishing
  size_t publishers = 0;
  uint32_t next_publisher_slot = 0;
  size_t pending = 0;
  WireMessagePtr rig_msg;
  WireMessagePtr regions_announce;  // Stats "site.regions" (null: this site publishes no Regions)
  // Each layer's codecs (SetPublishedCodecs, SetLayerCodecs); layer 0's
  // are the ones Welcome names.
  struct LayerCodecs {
    protocol::GeometryCodec geometry = protocol::GeometryCodec::kG1;
    protocol::ColorCodec color = protocol::ColorCodec::kC1;
  };
  std::array<LayerCodecs, kMaxLayers> layer_codecs{};
  uint64_t next_id = 1;
  uint32_t rig_sequence = 0;
  std::atomic<uint32_t> audio_sequence{0};

  // An AudioPose for viewers. A lean frame (codec 3) gets its classic twin
  // (codec 2) for viewers that negotiated the classic layout; a lean frame
  // sent without a pose gets the stream's last pose there.
  WireMessagePtr AudioMessage(Header h, const protocol::AudioPose& a) {
    WireMessagePtr m = MakeWireMessage(h, a, cfg.fragment_bytes);
    if (a.codec != protocol::AudioCodec::kOpusLean) return m;
    protocol::HeadPose fallback;
    {
      std::lock_guard<std::mutex> l(pose_mu);
      if (last_pose.size() > 4096 && last_pose.count(h.stream_id) == 0) last_pose.clear();  // bounded
      protocol::HeadPose& p = last_pose[h.stream_id];
      if (a.has_pose) p = a.pose;
      fallback = p;
    }
    return WithClassicAudio(m, MakeWireMessage(h, protocol::ToClassicAudioPose(a, fallback), cfg.fragment_bytes));
  }
  // The same for an AudioPose already encoded (a replayed recording): the
  // message as it is when it is not a whole lean frame that decodes.
  WireMessagePtr AudioMessage(const WireMessagePtr& m) {
    if (m->type != MessageType::kAudioPose || m->classic_audio || m->frame_ends.size() != 1 ||
        m->bytes.size() <= protocol::kHeaderSize ||
        m->bytes[protocol::kHeaderSize] != static_cast<uint8_t>(protocol::AudioCodec::kOpusLean)) {
      return m;
    }
    auto h = protocol::DecodeHeader(m->bytes.data(), m->bytes.size());
    if (!h.ok()) return m;
    auto p = protocol::DecodePayload(*h, std::span<const uint8_t>(m->bytes).subspan(protocol::kHeaderSize));
    if (!p.ok()) return m;
    return AudioMessage(*h, std::get<protocol::AudioPose>(*p));
  }
  std::mutex pose_mu;
  std::map<uint32_t, protocol::HeadPose> last_pose;  // by stream id, lean frames' last pose

  struct Atomics {
    std::atomic<uint64_t> accepted{0}, welcomed{0}, refused{0}, rejected_pending{0}, violations{0},
        handshake_timeouts{0}, idle_timeouts{0}, priority_overflows{0}, video_frames_published{0},
        audio_published{0}, audio_relayed{0}, controls_forwarded{0}, keyframe_requests{0}, layer_switches{0};
    std::array<std::atomic<uint64_t>, kMaxLayers> layer_keyframe_requests{};
  } n;

  // Quality layers: how many the site publishes, and each one's recent
  // bitrate (decaying sums of bytes and of time between its frames).
  std::atomic<int> num_layers{1};
  std::array<std::atomic<int>, kMaxLayers> layer_step{1, 1, 1, 1};
  std::mutex layer_mu;
  struct LayerRate {
    double bytes = 0, seconds = 0;
    int64_t last_us = -1;
  };
  std::array<LayerRate, kMaxLayers> layer_rate;
  // Notes a published frame of `layer`; returns every layer's bytes/s.
  std::array<double, kMaxLayers> NoteLayerFrame(int layer, size_t bytes, int64_t now_us) {
    std::lock_guard<std::mutex> l(layer_mu);
    LayerRate& r = layer_rate[static_cast<size_t>(layer)];
    if (r.last_us >= 0 && now_us > r.last_us) {
      const double dt = static_cast<double>(now_us - r.last_us) * 1e-6;
      const double f = std::exp(-dt / 2.0);  // 2 s memory
      r.bytes = r.bytes * f + static_cast<double>(bytes);
      r.seconds = r.seconds * f + dt;
    }
    r.last_us = now_us;
    return LayerRatesLocked();
  }
  std::array<double, kMaxLayers> LayerRatesLocked() const {
    std::array<double, kMaxLayers> out{};
    for (size_t i = 0; i < out.size(); ++i)
      out[i] = layer_rate[i].seconds > 0 ? layer_rate[i].bytes / layer_rate[i].seconds : 0.0;
    return out;
  }
};

class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(Server::Impl* srv, tcp::socket sock, uint64_t id)
      : srv_(srv),
        strand_(asio::make_strand(srv->io)),
        sock_(std::move(sock)),
        deadline_(srv->io),
        ping_timer_(srv->io),
        id_(id),
        parser_(MakeLimits(srv->cfg)),
        assembler_(MakeLimits(srv->cfg)),
        layers_(srv->cfg.layers) {
    std::error_code ec;
    const auto ep = sock_.remote_endpoint(ec);
    peer_ = ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
    sock_.set_option(tcp::no_delay(true), ec);
    if (srv->cfg.socket_send_buffer > 0)
      sock_.set_option(asio::socket_base::send_buffer_size(srv->cfg.socket_send_buffer), ec);
    if (srv->ssl) tls_ = std::make_unique<asio::ssl::stream<tcp::socket>>(std::move(sock_), *srv->ssl);
  }

  static protocol::Limits MakeLimits(const ServerConfig& c) {
    protocol::Limits l;
    l.max_message_bytes = c.max_message_bytes;
    l.max_frame_payload = std::min<uint32_t>(l.max_frame_payload, c.max_message_bytes);
    return l;
  }

  uint64_t id() const { return id_; }
  uint32_t subscription() const { return subscription_.load(std::memory_order_relaxed); }

  void Start() {
    auto self = shared_from_this();
    asio::dispatch(strand_, [this, self] {
      deadline_.expires_after(Seconds(srv_->cfg.handshake_timeout_s));
      deadline_.async_wait(asio::bind_executor(strand_, [this, self](std::error_code ec) {
        if (ec || closed_ || state_ != State::kHandshake) return;
        srv_->n.handshake_timeouts++;
        CloseNow("handshake timeout (" + std::to_string(srv_->cfg.handshake_timeout_s) + " s without a Hello)");
      }));
      if (tls_) {
        tls_->async_handshake(asio::ssl::stream_base::server,
                              asio::bind_executor(strand_, [this, self](std::error_code ec) {
                                if (closed_) return;
                                if (ec) {
                                  CloseNow("TLS handshake failed: " + ec.message());
                                  return;
                                }
                                DoRead();
                              }));
      } else {
        DoRead();
      }
    });
  }

  // Fan-out entry points (any thread). `rates`: each layer's bytes/s.
  void EnqueueVideo(const VideoFramePtr& f, std::span<const double> rates) {
    if (!(subscription() & (kContentGeometry | kContentColor))) return;
    bool switched = false;
    int old_target = 0, new_target = 0, now_layer = 0, num_layers = 1;
    std::string reason, name;
    {
      std::lock_guard<std::mutex> l(mu_);
      name = client_name_;
      num_layers = layers_.num_layers();
      if (closing_) return;  // (state_ is the strand's: a frame queued before Active waits for it in StartWrite)
      const int64_t now = SteadyUs();
      old_target = layers_.target();
      if (f->layer == layers_.layer()) layers_.Update(now, rates);
      new_target = layers_.target();
      const int old_layer = layers_.layer();
      if (!layers_.Take(f->layer, f->independent, &switched)) {
        if (new_target != old_target) reason = layers_.reason();
      } else {
        now_layer = layers_.layer();
        if (switched && now_layer > old_layer) {
          // Down because the viewer fell behind: what waits of the old layer
          // is the backlog; the new layer's independent frame replaces it.
          video_dropped_ += video_.size();
          video_.clear();
        }
        ++video_queued_;
        bool dropped = false;
        if (video_.size() >= static_cast<size_t>(srv_->cfg.queue_video_frames)) {
          video_.pop_front();  // never the frame in flight: whole frames only
          ++video_dropped_;
          dropped = true;
        }
        video_.push_back(f);
        layers_.OnEnqueue(now, video_.size(), dropped);
        KickLocked();
        if (new_target != old_target) reason = layers_.reason();
      }
    }
    if (new_target != old_target) {
      // The target layer must send an independent frame soon (V1: a key frame).
      srv_->n.layer_keyframe_requests[static_cast<size_t>(new_target)]++;
      LogLayerMove(name, old_target, new_target, reason);
    }
    if (switched) {
      srv_->n.layer_switches++;
      EnqueuePriorityAlways(LayerStats(now_layer, num_layers));
    }
  }

  // Stats telling the viewer its layer (PROTOCOL.md §4 Stats).
  WireMessagePtr LayerStats(int layer, int num_layers) const {
    protocol::Stats st;
    st.values = {{std::string(protocol::kLayerKey), static_cast<double>(layer)},
                 {std::string(protocol::kLayersKey), static_cast<double>(num_layers)},
                 {std::string(protocol::kLayerStepKey),
                  static_cast<double>(srv_->layer_step[static_cast<size_t>(layer)].load())}};
    return MakeWireMessage(Header{}, st, srv_->cfg.fragment_bytes);
  }
  void LogLayerMove(const std::string& name, int from, int to, const std::string& why) {
    srv_->Log("session " + std::to_string(id_) + " '" + name + "': layer " + std::to_string(from) + " -> " +
              std::to_string(to) + " (" + why + ")");
  }

  // The layer this viewer receives or is about to (the publisher encodes a
  // layer only while someone is on it).
  bool OnLayer(int layer) const {
    std::lock_guard<std::mutex> l(mu_);
    return layers_.layer() == layer || layers_.target() == layer;
  }

  void EnqueuePriority(const WireMessagePtr& lean_or_other) {
    // A viewer that did not negotiate lean frames gets their classic twin.
    const WireMessagePtr& m = lean_or_other->classic_audio && !lean_audio_.load(std::memory_order_relaxed)
                                  ? lean_or_other->classic_audio
                                  : lean_or_other;
    const uint32_t bit = ContentBitOf(m->type);
    if (bit != 0 && !(subscription() & bit)) return;
    bool overflow = false;
    {
      std::lock_guard<std::mutex> l(mu_);
      if (closing_) return;
      if (prio_.size() >= static_cast<size_t>(srv_->cfg.queue_priority_messages)) {
        overflow = true;
        closing_ = true;
      } else {
        prio_.push_back(m);
        KickLocked();
      }
    }
    if (overflow) {
      srv_->n.priority_overflows++;
      auto self = shared_from_this();
      asio::post(strand_, [this, self] { CloseNow("priority queue full (audio/control not read): closed"); });
    }
  }

  void Close(const std::string& why) {
    auto self = shared_from_this();
    asio::post(strand_, [this, self, why] { CloseNow(why); });
  }

  SessionStats Stats() const {
    SessionStats s;
    s.session_id = id_;
    s.peer = peer_;
    s.subscription = subscription();
    s.quality = quality_.load();
    std::lock_guard<std::mutex> l(mu_);
    s.role = role_;
    s.client_name = client_name_;
    s.video_frames_queued = video_queued_;
    s.video_frames_sent = video_sent_;
    s.video_frames_dropped = video_dropped_;
    s.audio_sent = audio_sent_;
    s.messages_received = messages_received_;
    s.bytes_sent = bytes_sent_;
    s.bytes_received = bytes_received_;
    s.queue_video = video_.size();
    s.queue_priority = prio_.size();
    s.rtt_ms = rtt_ms_;
    s.rtt_min_ms = rtt_min_ms_;
    s.layer = layers_.layer();
    s.target_layer = layers_.target();
    s.layer_switches = layers_.switches();
    s.layer_switches_down = layers_.switches_down();
    s.layer_reason = layers_.reason();
    s.throughput_mbps = layers_.throughput_bytes_per_s() < 0 ? -1 : layers_.throughput_bytes_per_s() * 8e-6;
    return s;
  }

 private:
  enum class State { kHandshake, kActive, kRefusing, kClosed };

  tcp::socket& Lowest() { return tls_ ? tls_->next_layer() : sock_; }

  void KickLocked() {
    if (writing_ || kick_posted_) return;
    kick_posted_ = true;
    auto self = shared_from_this();
    asio::post(strand_, [this, self] { StartWrite(); });
  }

  void DoRead() {
    auto self = shared_from_this();
    auto h = asio::bind_executor(strand_, [this, self](std::error_code ec, size_t n) { OnRead(ec, n); });
    if (tls_)
      tls_->async_read_some(asio::buffer(rbuf_), std::move(h));
    else
      sock_.async_read_some(asio::buffer(rbuf_), std::move(h));
  }

  void OnRead(std::error_code ec, size_t n) {
    if (closed_) return;
    if (ec) {
      if (state_ == State::kRefusing) {
        CloseNow("");
      } else {
        CloseNow(ec == asio::error::eof ? "peer closed the connection" : "read failed: " + ec.message());
      }
      return;
    }
    last_rx_us_ = SteadyUs();
    {
      std::lock_guard<std::mutex> l(mu_);
      bytes_received_ += n;
    }
    if (state_ == State::kRefusing) {  // draining until the peer closes
      DoRead();
      return;
    }
    const Status fed = parser_.Feed(rbuf_.data(), n);
    protocol::Frame f;
    while (!closed_ && state_ != State::kRefusing && parser_.Next(&f)) OnFrame(std::move(f));
    if (closed_ || state_ == State::kRefusing) {
      if (!closed_) DoRead();
      return;
    }
    if (!fed.ok()) {
      if (state_ == State::kHandshake && fed.code() == StatusCode::kUnsupportedVersion) {
        Refuse(RefuseReason::kUnsupportedVersion, fed.message());
        DoRead();
        return;
      }
      Violation("bad frame: " + fed.ToString());
      return;
    }
    DoRead();
  }

  void OnFrame(protocol::Frame&& f) {
    {
      std::lock_guard<std::mutex> l(mu_);
      ++messages_received_;
    }
    if (state_ == State::kHandshake && f.header.type != MessageType::kHello) {
      Refuse(RefuseReason::kMalformed, std::string("expected Hello first, got ") +
                                           protocol::MessageTypeName(f.header.type));
      return;
    }
    bool complete = false;
    Message m;
    const Status s = assembler_.Add(std::move(f), &complete, &m);
    if (!s.ok()) {
      if (state_ == State::kHandshake) {
        Refuse(RefuseReason::kMalformed, "malformed Hello: " + s.message());
      } else {
        Violation(s.ToString());
      }
      return;
    }
    if (complete) OnMessage(m);
  }

  void OnMessage(const Message& m) {
    const MessageType t = m.header.type;
    if (state_ == State::kHandshake) {
      OnHello(std::get<protocol::Hello>(m.payload));
      return;
    }
    switch (t) {
      case MessageType::kControl: OnControl(std::get<Control>(m.payload)); return;
      case MessageType::kPing: {
        const auto& p = std::get<protocol::Ping>(m.payload);
        protocol::Pong pong{p.nonce, p.send_time_us, WallUs(), WallUs()};
        Header h;
        EnqueuePriority(MakeWireMessage(h, pong, srv_->cfg.fragment_bytes));
        return;
      }
      case MessageType::kPong: {
        const auto& p = std::get<protocol::Pong>(m.payload);
        if (p.nonce != ping_nonce_) return;  // not ours (or stale): ignore
        const double rtt = static_cast<double>(SteadyUs() - p.ping_send_time_us) * 1e-3;
        if (rtt < 0 || rtt > 3.6e6) return;
        std::lock_guard<std::mutex> l(mu_);
        rtt_ms_ = rtt;
        rtt_min_ms_ = rtt_min_ms_ < 0 ? rtt : std::min(rtt_min_ms_, rtt);
        return;
      }
      case MessageType::kAudioPose: {
        if (role_ != Role::kPublisher) return;  // viewers' audio goes to their own site (docs/sessions.md)
        const auto& a = std::get<protocol::AudioPose>(m.payload);
        srv_->n.audio_relayed++;
        if (srv_->hooks.on_audio) srv_->hooks.on_audio(id_, a);
        Header h = m.header;
        h.stream_id = kFirstParticipantStreamId + publisher_slot_;
        h.flags = 0;
        auto msg = srv_->AudioMessage(h, a);
        srv_->n.audio_published++;
        for (const auto& v : srv_->Viewers())
          if (v.get() != this) v->EnqueuePriority(msg);
        return;
      }
      case MessageType::kClientPose:
      case MessageType::kStats:
        return;  // accepted, not used by a site server
      default:
        Violation(std::string("unexpected ") + protocol::MessageTypeName(t) + " from a " + protocol::RoleName(role_));
        return;
    }
  }

  void OnControl(const Control& c) {
    ControlEvent ev{id_, client_name_, role_, c};
    switch (c.command) {
      case ControlCommand::kSubscribe:
      case ControlCommand::kUnsubscribe: {
        if (c.stream_id != 0 && c.stream_id != kSiteStreamId) {
          Violation("control: subscribe to unknown stream " + std::to_string(c.stream_id));
          return;
        }
        if (c.value < 0 || c.value > kContentKnown) {
          Violation("control.value: content bits must be 0..15, got " + std::to_string(c.value));
          return;
        }
        const uint32_t bits = c.value == 0 ? kContentAll : static_cast<uint32_t>(c.value);
        if (c.command == ControlCommand::kSubscribe)
          subscription_.fetch_or(bits);
        else
          subscription_.fetch_and(~bits);
        return;
      }
      case ControlCommand::kSetQuality:
        if (c.value < 0 || c.value > 10) {
          Violation("control.value: quality must be 0..10, got " + std::to_string(c.value));
          return;
        }
        quality_ = static_cast<int>(c.value);
        {
          int before = 0, after = 0;
          {
            std::lock_guard<std::mutex> l(mu_);
            before = layers_.target();
            layers_.SetMinLayer(LayerController::MinLayerForQuality(quality_, layers_.num_layers()), SteadyUs());
            after = layers_.target();
          }
          if (after != before) {  // the viewer's own cap moves it: the new layer's next frame must decode alone
            srv_->n.layer_keyframe_requests[static_cast<size_t>(after)]++;
            LogLayerMove(client_name_, before, after, "quality " + std::to_string(c.value));
          }
        }
        break;
      case ControlCommand::kSetSpeed:
        if (!(c.speed >= 0.1f && c.speed <= 8.0f)) {
          Violation("control.speed: must be 0.1..8");
          return;
        }
        break;
      case ControlCommand::kRequestKeyFrame: {
        srv_->n.keyframe_requests++;
        int layer = 0, target = 0;
        {
          std::lock_guard<std::mutex> l(mu_);
          layer = layers_.layer();
          target = layers_.target();
        }
        srv_->n.layer_keyframe_requests[static_cast<size_t>(layer)]++;
        if (target != layer) srv_->n.layer_keyframe_requests[static_cast<size_t>(target)]++;
        break;
      }
      case ControlCommand::kSeek:
        if (c.value < 0) {
          Violation("control.value: seek time must be >= 0");
          return;
        }
        break;
      default:
        break;
    }
    if (srv_->hooks.control) {
      srv_->n.controls_forwarded++;
      srv_->hooks.control->OnControl(ev);
    }
  }

  void OnHello(const protocol::Hello& h) {
    {
      std::lock_guard<std::mutex> l(mu_);
      role_ = h.role;
      client_name_ = h.client_name;
    }
    if (h.min_version > protocol::kProtocolVersion || h.max_version < protocol::kProtocolVersion) {
      Refuse(RefuseReason::kUnsupportedVersion, "client speaks protocol versions " + std::to_string(h.min_version) +
                                                    ".." + std::to_string(h.max_version) + ", this server speaks " +
                                                    std::to_string(protocol::kProtocolVersion));
      return;
    }
    const Sha got = HashToken(h.access_token);
    const Sha* want = nullptr;
    if (h.role == Role::kPublisher) want = &srv_->publisher_hash;
    if (IsViewerRole(h.role)) want = &srv_->viewer_hash;
    if (want == nullptr) {
      Refuse(RefuseReason::kRoleNotAllowed,
             std::string("role ") + protocol::RoleName(h.role) + " is not served by a site server");
      return;
    }
    if (CRYPTO_memcmp(got.data(), want->data(), got.size()) != 0) {
      Refuse(RefuseReason::kBadToken, std::string("access token not accepted for role ") + protocol::RoleName(h.role));
      return;
    }
    auto has = [](const auto& list, auto v) { return std::find(list.begin(), list.end(), v) != list.end(); };
    protocol::Welcome w;
    w.session_id = id_;
    w.max_message_bytes = srv_->cfg.max_message_bytes;
    w.server_name = srv_->cfg.name;
    std::array<Server::Impl::LayerCodecs, kMaxLayers> layer_codecs;
    {
      std::lock_guard<std::mutex> l(srv_->mu);
      layer_codecs = srv_->layer_codecs;
    }
    w.geometry_codec = layer_codecs[0].geometry;
    w.color_codec = layer_codecs[0].color;
    // Lean frames (PROTOCOL.md §9.1) when the peer has them: 31 instead of 55 kbit/s a voice.
    if (has(h.capabilities.audio, protocol::AudioCodec::kOpusLean)) {
      w.audio_codec = protocol::AudioCodec::kOpusLean;
    } else if (has(h.capabilities.audio, protocol::AudioCodec::kOpus)) {
      w.audio_codec = protocol::AudioCodec::kOpus;
    } else if (has(h.capabilities.audio, protocol::AudioCodec::kPcm16)) {
      w.audio_codec = protocol::AudioCodec::kPcm16;
    } else {
      Refuse(RefuseReason::kNoCommonCodec, "no common audio codec (this site speaks Opus and PCM)");
      return;
    }
    if (IsViewerRole(h.role)) {
      if (!has(h.capabilities.geometry, w.geometry_codec)) {
        Refuse(RefuseReason::kNoCommonCodec, "this site publishes geometry codec G" +
                                                 std::to_string(static_cast<int>(w.geometry_codec) - 1) +
                                                 ", which the client does not list");
        return;
      }
      if (!has(h.capabilities.color, w.color_codec)) {
        Refuse(RefuseReason::kNoCommonCodec,
               std::string("this site publishes colour codec ") +
                   (w.color_codec == protocol::ColorCodec::kV1
                        ? std::string("V1")
                        : "C" + std::to_string(static_cast<int>(w.color_codec) - 1)) +
                   ", which the client does not list");
        return;
      }
      // The layers this viewer can be moved to: those down to the first
      // whose codecs its Hello does not list.
      int decodable = 1;
      while (decodable < kMaxLayers &&
             has(h.capabilities.geometry, layer_codecs[static_cast<size_t>(decodable)].geometry) &&
             has(h.capabilities.color, layer_codecs[static_cast<size_t>(decodable)].color))
        ++decodable;
      decodable_layers_ = decodable;
    }
    std::string why;
    if (!srv_->Register(shared_from_this(), h.role, &why)) {
      Refuse(RefuseReason::kOverloaded, why);
      return;
    }
    registered_ = true;
    lean_audio_ = w.audio_codec == protocol::AudioCodec::kOpusLean;
    srv_->n.welcomed++;
    if (IsViewerRole(h.role)) {  // a new viewer starts at a key frame of the full layer
      srv_->n.keyframe_requests++;
      srv_->n.layer_keyframe_requests[0]++;
    }
    Header hdr;
    EnqueuePriority(MakeWireMessage(hdr, w, srv_->cfg.fragment_bytes));
    if (IsViewerRole(h.role)) {
      WireMessagePtr rig, announce;
      {
        std::lock_guard<std::mutex> l(srv_->mu);
        rig = srv_->rig_msg;
        announce = srv_->regions_announce;
      }
      if (rig) EnqueuePriorityAlways(rig);
      if (announce) EnqueuePriorityAlways(announce);
      const int layers = std::min(srv_->num_layers.load(), decodable_layers_.load());
      if (layers > 1) {
        EnqueuePriorityAlways(LayerStats(0, layers));  // the site has layers: the viewer starts on the full one
      }
    }
    state_ = State::kActive;
    srv_->Log("welcome " + peer_ + " '" + h.client_name + "' as " + protocol::RoleName(h.role) + " (session " +
              std::to_string(id_) + ")");
    ArmIdle();
    ArmPing();
  }

  // Rig: not tied to a content bit, not subject to the subscription.
  void EnqueuePriorityAlways(const WireMessagePtr& m) {
    std::lock_guard<std::mutex> l(mu_);
    if (closing_) return;
    prio_.push_back(m);
    KickLocked();
  }

 public:
  void SendRig(const WireMessagePtr& m) { EnqueuePriorityAlways(m); }

  void SetPublisherSlot(uint32_t slot) { publisher_slot_ = slot; }

 private:
  void Refuse(RefuseReason reason, const std::string& message) {
    srv_->n.refused++;
    std::string name;
    {
      std::lock_guard<std::mutex> l(mu_);
      name = client_name_;
    }
    srv_->Log(
        "refused " + peer_ + (name.empty() ? "" : " '" + name + "'") + ": " + RefuseReasonName(reason) + ": " + message,
        spdlog::level::warn);
    protocol::Refuse r{reason, protocol::kProtocolVersion, protocol::kProtocolVersion, message};
    Header h;
    EnqueuePriorityAlways(MakeWireMessage(h, r, srv_->cfg.fragment_bytes));
    state_ = State::kRefusing;
    {
      std::lock_guard<std::mutex> l(mu_);
      closing_ = true;  // nothing else is queued
    }
    // Linger at most a second for the peer to read the Refuse and close.
    auto self = shared_from_this();
    deadline_.expires_after(std::chrono::seconds(1));
    deadline_.async_wait(asio::bind_executor(strand_, [this, self](std::error_code ec) {
      if (!ec) CloseNow("");
    }));
  }

  void Violation(const std::string& what) {
    srv_->n.violations++;
    CloseNow("protocol violation: " + what);
  }

  void ArmIdle() {
    auto self = shared_from_this();
    const int64_t idle_us = static_cast<int64_t>(srv_->cfg.idle_timeout_s * 1e6);
    const int64_t wait = std::max<int64_t>(1000, last_rx_us_ + idle_us - SteadyUs());
    deadline_.expires_after(std::chrono::microseconds(wait));
    deadline_.async_wait(asio::bind_executor(strand_, [this, self, idle_us](std::error_code ec) {
      if (ec || closed_ || state_ != State::kActive) return;
      if (SteadyUs() - last_rx_us_ >= idle_us) {
        srv_->n.idle_timeouts++;
        CloseNow("idle timeout (" + std::to_string(srv_->cfg.idle_timeout_s) + " s without a byte)");
        return;
      }
      ArmIdle();
    }));
  }

  void ArmPing() {
    if (srv_->cfg.ping_interval_s <= 0) return;
    auto self = shared_from_this();
    ping_timer_.expires_after(Seconds(srv_->cfg.ping_interval_s));
    ping_timer_.async_wait(asio::bind_executor(strand_, [this, self](std::error_code ec) {
      if (ec || closed_ || state_ != State::kActive) return;
      ping_nonce_ = (id_ << 32) ^ ++ping_count_;
      protocol::Ping p{ping_nonce_, SteadyUs()};
      Header h;
      EnqueuePriorityAlways(MakeWireMessage(h, p, srv_->cfg.fragment_bytes));
      ArmPing();
    }));
  }

  void StartWrite() {
    std::unique_lock<std::mutex> l(mu_);
    kick_posted_ = false;
    if (writing_ || closed_) return;
    bufs_.clear();
    holding_.clear();
    audio_in_write_ = 0;
    frame_done_in_write_ = false;
    size_t video_bytes_in_write = 0;
    for (int i = 0; i < 64 && !prio_.empty(); ++i) {
      const WireMessagePtr& m = prio_.front();
      bufs_.push_back(asio::buffer(m->bytes));
      if (m->type == MessageType::kAudioPose) ++audio_in_write_;
      holding_.push_back(m);
      prio_.pop_front();
    }
    if (state_ == State::kActive) {
      const uint32_t sub = subscription();
      if (!inflight_ && !video_.empty()) {
        inflight_ = std::move(video_.front());
        video_.pop_front();
        part_ = 0;
        frag_ = 0;
      }
      size_t video_bytes = 0;
      const auto count_video = [&] { video_bytes_in_write = video_bytes; };
      if (inflight_) writing_frame_ = inflight_;  // keeps the bytes alive during the write
      while (inflight_ && video_bytes < srv_->cfg.fragment_bytes) {
        if (part_ < inflight_->parts.size()) {
          const WireMessage& part = *inflight_->parts[part_];
          if (!(sub & ContentBitOf(part.type))) {
            ++part_;
            frag_ = 0;
          } else {
            const size_t begin = frag_ == 0 ? 0 : part.frame_ends[frag_ - 1];
            const size_t end = part.frame_ends[frag_];
            bufs_.push_back(asio::buffer(part.bytes.data() + begin, end - begin));
            video_bytes += end - begin;
            if (++frag_ == part.frame_ends.size()) {
              ++part_;
              frag_ = 0;
            }
          }
        }
        if (part_ >= inflight_->parts.size()) {
          inflight_.reset();
          frame_done_in_write_ = true;
        }
      }
      count_video();
    }
    if (bufs_.empty()) return;
    writing_ = true;
    write_start_us_ = SteadyUs();
    write_video_bytes_ = video_bytes_in_write;
    l.unlock();
    auto self = shared_from_this();
    auto h = asio::bind_executor(strand_, [this, self](std::error_code ec, size_t n) { OnWrite(ec, n); });
    if (tls_)
      asio::async_write(*tls_, bufs_, std::move(h));
    else
      asio::async_write(sock_, bufs_, std::move(h));
  }

  void OnWrite(std::error_code ec, size_t n) {
    bool refusing_done = false;
    // What the kernel still holds for this viewer (a slow link fills the send buffer first).
    int unsent_i = 0;
    const size_t unsent =
        !ec && ::ioctl(Lowest().native_handle(), SIOCOUTQ, &unsent_i) == 0 && unsent_i > 0 ? static_cast<size_t>(unsent_i) : 0;
    {
      std::lock_guard<std::mutex> l(mu_);
      writing_ = false;
      bytes_sent_ += n;
      if (!ec) {
        audio_sent_ += audio_in_write_;
        if (frame_done_in_write_) ++video_sent_;
        if (write_video_bytes_ > 0) {
          const int64_t now = SteadyUs();
          layers_.OnWrite(now, n, now - write_start_us_, unsent);
        }
      }
      holding_.clear();
      writing_frame_.reset();
      refusing_done = state_ == State::kRefusing && prio_.empty();
    }
    if (closed_) return;
    if (ec) {
      CloseNow("write failed: " + ec.message());
      return;
    }
    if (refusing_done) {
      std::error_code ignore;
      Lowest().shutdown(tcp::socket::shutdown_send, ignore);
      return;
    }
    StartWrite();
  }

 public:
  void CloseNow(const std::string& why) {
    if (closed_) return;
    closed_ = true;
    const bool was_pending = state_ == State::kHandshake || (state_ == State::kRefusing && !registered_);
    state_ = State::kClosed;
    {
      std::lock_guard<std::mutex> l(mu_);
      closing_ = true;
      prio_.clear();
      video_.clear();
    }
    if (!why.empty()) srv_->Log("closed " + peer_ + " (session " + std::to_string(id_) + "): " + why);
    std::error_code ignore;
    deadline_.cancel();
    ping_timer_.cancel();
    Lowest().shutdown(tcp::socket::shutdown_both, ignore);
    Lowest().close(ignore);
    srv_->Remove(id_, was_pending);
  }

 private:
  Server::Impl* srv_;
  asio::strand<asio::io_context::executor_type> strand_;
  tcp::socket sock_;
  std::unique_ptr<asio::ssl::stream<tcp::socket>> tls_;
  asio::steady_timer deadline_;
  asio::steady_timer ping_timer_;
  const uint64_t id_;
  std::string peer_;
  // Strand-only state.
  State state_ = State::kHandshake;
  bool closed_ = false;
  bool registered_ = false;
  int64_t last_rx_us_ = SteadyUs();
  uint64_t ping_nonce_ = 0, ping_count_ = 0;
  uint32_t publisher_slot_ = 0;
  protocol::FrameParser parser_;
  protocol::MessageAssembler assembler_;
  std::array<uint8_t, 16384> rbuf_{};
  std::vector<asio::const_buffer> bufs_;
  std::vector<WireMessagePtr> holding_;
  VideoFramePtr inflight_, writing_frame_;
  size_t part_ = 0, frag_ = 0;
  uint64_t audio_in_write_ = 0;
  bool frame_done_in_write_ = false;
  // Shared state (mu_).
  mutable std::mutex mu_;
  Role role_ = Role::kViewer;
  std::string client_name_;
  std::deque<WireMessagePtr> prio_;
  std::deque<VideoFramePtr> video_;
  bool writing_ = false, kick_posted_ = false, closing_ = false;
  uint64_t video_queued_ = 0, video_sent_ = 0, video_dropped_ = 0, audio_sent_ = 0, messages_received_ = 0;
  uint64_t bytes_sent_ = 0, bytes_received_ = 0;
  double rtt_ms_ = -1, rtt_min_ms_ = -1;
  std::atomic<uint32_t> subscription_{0};
  std::atomic<bool> lean_audio_{false};  // negotiated audio codec 3 (lean AudioPose frames)
  std::atomic<int> quality_{10};
  // Layers 0..n-1 have codecs this viewer listed in its Hello (set before
  // Register; SetNumLayers never gives it more).
  std::atomic<int> decodable_layers_{kMaxLayers};
  // Quality layer policy (mu_); recorders always take the full layer.
  LayerController layers_;
  int64_t write_start_us_ = 0;
  size_t write_video_bytes_ = 0;

 public:
  void SetNumLayers(int n) {
    std::lock_guard<std::mutex> l(mu_);
    layers_.SetNumLayers(role_ == Role::kRecorder ? 1 : std::min(n, decodable_layers_.load()));
    layers_.SetMinLayer(LayerController::MinLayerForQuality(quality_, layers_.num_layers()), SteadyUs());
  }
};

void Server::Impl::Accept() {
  acceptor.async_accept(asio::make_strand(io), [this](std::error_code ec, tcp::socket sock) {
    if (stopped) return;
    if (ec) {
      if (ec == asio::error::operation_aborted) return;
      Log("accept failed: " + ec.message(), spdlog::level::warn);
      Accept();
      return;
    }
    // Programs started by the site (popen, fork+exec) must not inherit viewer connections.
    ::fcntl(sock.native_handle(), F_SETFD, FD_CLOEXEC);
    n.accepted++;
    std::shared_ptr<Session> s;
    {
      std::lock_guard<std::mutex> l(mu);
      if (stopped) return;  // Stop() set it under `mu`: no session is added after its snapshot
      if (pending >= static_cast<size_t>(cfg.max_pending)) {
        n.rejected_pending++;
      } else {
        ++pending;
        s = std::make_shared<Session>(this, std::move(sock), next_id++);
        sessions[s->id()] = s;
      }
    }
    if (s) {
      s->Start();
    } else {
      std::error_code ignore;
      Log("closed a new connection at once: " + std::to_string(cfg.max_pending) + " handshakes already in progress",
          spdlog::level::warn);
      sock.close(ignore);
    }
    Accept();
  });
}

bool Server::Impl::Register(const std::shared_ptr<Session>& s, Role role, std::string* why) {
  std::lock_guard<std::mutex> l(mu);
  if (role == Role::kPublisher) {
    if (publishers >= static_cast<size_t>(cfg.max_publishers)) {
      *why = "site full: " + std::to_string(publishers) + " publishers (max_publishers)";
      return false;
    }
    ++publishers;
    s->SetPublisherSlot(next_publisher_slot++);
  } else {
    if (viewers.size() >= static_cast<size_t>(cfg.max_viewers)) {
      *why = "site full: " + std::to_string(viewers.size()) + " viewers (max_viewers)";
      return false;
    }
    viewers[s->id()] = s;
    s->SetNumLayers(num_layers.load());
    RebuildViewersLocked();
  }
  --pending;
  return true;
}

void Server::Impl::RebuildViewersLocked() {
  viewers_list.clear();
  viewers_list.reserve(viewers.size());
  for (const auto& [id, v] : viewers) viewers_list.push_back(v);
}

void Server::Impl::Remove(uint64_t id, bool was_pending) {
  std::lock_guard<std::mutex> l(mu);
  auto it = sessions.find(id);
  if (it == sessions.end()) return;
  if (viewers.erase(id)) {
    RebuildViewersLocked();
  } else if (was_pending) {
    --pending;
  } else {
    --publishers;
  }
  sessions.erase(it);
}

// ------------------------------------------------------------------ Server

Server::Server(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Server::~Server() { Stop(); }

StatusOr<std::unique_ptr<Server>> Server::Start(const ServerConfig& config, ServerHooks hooks) {
  HOLO_RETURN_IF_ERROR(config.Check().WithContext("server config"));
  auto impl = std::make_unique<Impl>(config, std::move(hooks));
  if (config.tls.enabled) {
    try {
      auto ctx = std::make_unique<asio::ssl::context>(asio::ssl::context::tls_server);
      ctx->set_options(asio::ssl::context::default_workarounds | asio::ssl::context::no_sslv2 |
                       asio::ssl::context::no_sslv3 | asio::ssl::context::no_tlsv1 |
                       asio::ssl::context::no_tlsv1_1);
      ctx->use_certificate_chain_file(config.tls.cert_file);
      ctx->use_private_key_file(config.tls.key_file, asio::ssl::context::pem);
      impl->ssl = std::move(ctx);
    } catch (const std::system_error& e) {
      return InvalidArgument("tls: cannot load certificate '" + config.tls.cert_file + "' / key '" +
                             config.tls.key_file + "': " + e.what());
    }
  }
  std::error_code ec;
  const asio::ip::address addr = asio::ip::make_address(config.host, ec);
  if (ec) return InvalidArgument("listen: '" + config.host + "' is not an IP address: " + ec.message());
  const tcp::endpoint ep(addr, config.port);
  impl->acceptor.open(ep.protocol(), ec);
  // Nor the listening socket: a child would keep the port after the site stops.
  if (!ec) ::fcntl(impl->acceptor.native_handle(), F_SETFD, FD_CLOEXEC);
  if (!ec) impl->acceptor.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) impl->acceptor.bind(ep, ec);
  if (!ec) impl->acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec)
    return Unavailable("listen on " + config.host + ":" + std::to_string(config.port) + ": " + ec.message());
  impl->work.emplace(impl->io.get_executor());
  impl->Accept();
  Impl* raw = impl.get();
  for (int i = 0; i < config.threads; ++i) {
    impl->threads.emplace_back([raw] {
      clockid_t cid;
      if (pthread_getcpuclockid(pthread_self(), &cid) == 0) {
        std::lock_guard<std::mutex> l(raw->cpu_mu);
        raw->cpu_clocks.push_back(cid);
      }
      raw->io.run();
    });
  }
  return std::unique_ptr<Server>(new Server(std::move(impl)));
}

uint16_t Server::port() const {
  std::error_code ec;
  const auto ep = impl_->acceptor.local_endpoint(ec);
  return ec ? 0 : ep.port();
}

const ServerConfig& Server::config() const { return impl_->cfg; }

void Server::SetPublishedCodecs(protocol::GeometryCodec geometry, protocol::ColorCodec color) {
  std::lock_guard<std::mutex> l(impl_->mu);
  impl_->layer_codecs.fill({geometry, color});
}

void Server::SetLayerCodecs(int layer, protocol::GeometryCodec geometry, protocol::ColorCodec color) {
  HOLO_CHECK(layer >= 1 && layer < kMaxLayers);
  std::lock_guard<std::mutex> l(impl_->mu);
  impl_->layer_codecs[static_cast<size_t>(layer)] = {geometry, color};
}

void Server::SetRig(const Rig& rig) {
  Header h;
  std::vector<std::shared_ptr<Session>> viewers;
  WireMessagePtr msg;
  {
    std::lock_guard<std::mutex> l(impl_->mu);
    h.sequence = impl_->rig_sequence++;
    msg = MakeWireMessage(h, protocol::RigMessage{rig}, impl_->cfg.fragment_bytes);
    impl_->rig_msg = msg;
    viewers = impl_->viewers_list;
  }
  for (const auto& v : viewers) v->SendRig(msg);
}

void Server::AnnounceRegions(size_t num_regions) {
  std::vector<std::shared_ptr<Session>> viewers;
  WireMessagePtr msg;
  {
    std::lock_guard<std::mutex> l(impl_->mu);
    protocol::Stats s;
    s.values = {{protocol::kRegionsAnnounceKey, static_cast<double>(num_regions)}};
    msg = MakeWireMessage(Header{}, s, impl_->cfg.fragment_bytes);
    impl_->regions_announce = msg;
    viewers = impl_->viewers_list;
  }
  for (const auto& v : viewers) v->SendRig(msg);
}

void Server::SetRigMessage(WireMessagePtr message) {
  HOLO_CHECK(message != nullptr && message->type == MessageType::kRig);
  std::vector<std::shared_ptr<Session>> viewers;
  {
    std::lock_guard<std::mutex> l(impl_->mu);
    impl_->rig_msg = message;
    viewers = impl_->viewers_list;
  }
  for (const auto& v : viewers) v->SendRig(message);
}

void Server::PublishVideo(VideoFramePtr frame) {
  HOLO_CHECK(frame->layer >= 0 && frame->layer < kMaxLayers);
  impl_->n.video_frames_published++;
  const auto rates = impl_->NoteLayerFrame(frame->layer, frame->bytes(), SteadyUs());
  for (const auto& v : impl_->Viewers()) v->EnqueueVideo(frame, rates);
}

void Server::SetLayers(int n) {
  HOLO_CHECK(n >= 1 && n <= kMaxLayers);
  impl_->num_layers = n;
  for (const auto& v : impl_->Viewers()) v->SetNumLayers(n);
}

int Server::num_layers() const { return impl_->num_layers.load(); }

void Server::SetLayerFrameStep(int layer, int step) {
  HOLO_CHECK(layer >= 0 && layer < kMaxLayers && step >= 1);
  impl_->layer_step[static_cast<size_t>(layer)] = step;
}

size_t Server::ViewersOnLayer(int layer) const {
  size_t n = 0;
  for (const auto& v : impl_->Viewers())
    if (v->OnLayer(layer)) ++n;
  return n;
}

double Server::LayerMbps(int layer) const {
  if (layer < 0 || layer >= kMaxLayers) return 0;
  std::lock_guard<std::mutex> l(impl_->layer_mu);
  return impl_->LayerRatesLocked()[static_cast<size_t>(layer)] * 8e-6;
}

void Server::PublishAudio(const protocol::AudioPose& audio, uint32_t stream_id) {
  Header h;
  h.stream_id = stream_id;
  h.sequence = audio.sequence;
  h.capture_time_us = audio.capture_time_us;
  PublishPriority(impl_->AudioMessage(h, audio));
}

void Server::PublishPriority(WireMessagePtr message) {
  if (message->type == MessageType::kAudioPose) {
    impl_->n.audio_published++;
    message = impl_->AudioMessage(message);
  }
  for (const auto& v : impl_->Viewers()) v->EnqueuePriority(message);
}

size_t Server::num_viewers() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->viewers.size();
}

size_t Server::num_publishers() const {
  std::lock_guard<std::mutex> l(impl_->mu);
  return impl_->publishers;
}

size_t Server::num_subscribed(uint32_t bits) const {
  size_t n = 0;
  for (const auto& v : impl_->Viewers())
    if (v->subscription() & bits) ++n;
  return n;
}

std::vector<SessionStats> Server::Sessions() const {
  std::vector<std::shared_ptr<Session>> all;
  {
    std::lock_guard<std::mutex> l(impl_->mu);
    for (const auto& [id, s] : impl_->sessions) all.push_back(s);
  }
  std::vector<SessionStats> out;
  out.reserve(all.size());
  for (const auto& s : all) out.push_back(s->Stats());
  return out;
}

ServerCounters Server::counters() const {
  const auto& a = impl_->n;
  ServerCounters c;
  c.accepted = a.accepted;
  c.welcomed = a.welcomed;
  c.refused = a.refused;
  c.rejected_pending = a.rejected_pending;
  c.violations = a.violations;
  c.handshake_timeouts = a.handshake_timeouts;
  c.idle_timeouts = a.idle_timeouts;
  c.priority_overflows = a.priority_overflows;
  c.video_frames_published = a.video_frames_published;
  c.audio_published = a.audio_published;
  c.audio_relayed = a.audio_relayed;
  c.controls_forwarded = a.controls_forwarded;
  c.keyframe_requests = a.keyframe_requests;
  c.layer_switches = a.layer_switches;
  for (size_t i = 0; i < c.layer_keyframe_requests.size(); ++i) c.layer_keyframe_requests[i] = a.layer_keyframe_requests[i];
  return c;
}

double Server::IoCpuMs() const {
  std::lock_guard<std::mutex> l(impl_->cpu_mu);
  double ms = 0;
  for (clockid_t c : impl_->cpu_clocks) {
    timespec ts{};
    if (clock_gettime(c, &ts) == 0) ms += ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
  }
  return ms;
}

void Server::Stop() {
  {
    std::lock_guard<std::mutex> l(impl_->mu);
    if (impl_->stopped.exchange(true)) return;
  }
  asio::post(impl_->io, [this] {
    std::error_code ignore;
    impl_->acceptor.close(ignore);
  });
  std::vector<std::shared_ptr<Session>> all;
  {
    std::lock_guard<std::mutex> l(impl_->mu);
    for (const auto& [id, s] : impl_->sessions) all.push_back(s);
  }
  for (const auto& s : all) s->Close("server stopping");
  impl_->work.reset();
  {
    std::lock_guard<std::mutex> l(impl_->cpu_mu);
    impl_->cpu_clocks.clear();  // invalid once the threads end
  }
  for (auto& t : impl_->threads) t.join();
  impl_->threads.clear();
  std::lock_guard<std::mutex> l(impl_->mu);
  impl_->sessions.clear();
  impl_->viewers.clear();
  impl_->viewers_list.clear();
}

}  // namespace holo::net
