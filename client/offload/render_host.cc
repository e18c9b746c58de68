#include "client/offload/render_host.h"

#include <sys/socket.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <variant>

#include <asio.hpp>

#include "client/offload/gl_scene.h"
#include "client/offload/message_link.h"
#include "client/reproject/fov.h"
#include "common/log.h"
#include "net/session_server.h"
#include "net/wire_message.h"

namespace holo::offload {
namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

double Ewma(double old, double x) { return old <= 0 ? x : 0.8 * old + 0.2 * x; }

}  // namespace

StatusOr<HostRenderer> ParseHostRenderer(const std::string& name) {
  if (name == "cpu") return HostRenderer::kCpu;
  if (name == "gl") return HostRenderer::kGl;
  if (name == "auto") return HostRenderer::kAuto;
  return InvalidArgument("renderer must be cpu, gl or auto, got '" + name + "'");
}

Status RenderHostOptions::Check() const {
  if (!(margin >= 0 && margin <= 2)) return InvalidArgument("render host: --margin must be in [0, 2]");
  if (width < 16 || width > 4096) return InvalidArgument("render host: --width must be 16..4096");
  if (max_thin_clients < 1) return InvalidArgument("render host: max_thin_clients must be >= 1");
  if (!(handshake_timeout_s > 0) || !(idle_timeout_s > 0)) return InvalidArgument("render host: timeouts must be > 0");
  if (!(ping_interval_s > 0)) return InvalidArgument("render host: ping_interval_s must be > 0");
  if (!(extra_horizon_ms >= 0 && extra_horizon_ms < 1000)) return InvalidArgument("render host: extra horizon must be in [0, 1000) ms");
  if (!(ipd_m >= 0 && ipd_m <= 0.2)) return InvalidArgument("render host: --ipd must be in [0, 0.2] m");
  if (token.empty() && site.token.empty()) return InvalidArgument("render host: no token for thin clients");
  return OkStatus();
}

// One thin client: a reader thread (handshake, poses, pings) and a render
// thread (predict, render, encode, send).
struct Session {
  uint64_t id = 0;
  std::unique_ptr<MessageLink> link;
  std::thread reader;
  std::atomic<bool> done{false};

  std::mutex mu;
  std::condition_variable cv;
  std::unique_ptr<pose::PosePredictor> predictor;
  pose::PoseSample newest;
  reproject::FieldOfView fov;
  uint64_t pose_seq = 0;
  int64_t ping_sent_us = 0;
  ThinClientStats stats;
};

struct RenderHost::Impl {
  RenderHostOptions o;
  std::atomic<bool> stopping{false};

  mutable std::mutex mesh_mu;
  std::map<int64_t, std::shared_ptr<const Mesh>> meshes;  // newest 16
  std::condition_variable mesh_cv;

  asio::io_context io;
  std::unique_ptr<asio::ip::tcp::acceptor> acceptor;
  std::thread accept_thread;

  mutable std::mutex sessions_mu;
  std::vector<std::shared_ptr<Session>> sessions;
  uint64_t next_id = 1;
  std::atomic<uint64_t> accepted{0}, refused{0}, closed_on_error{0}, site_frames{0};
  std::atomic<int64_t> last_site_frame{-1};
  std::atomic<bool> site_connected{false};

  // Through o.log when set, else the log at `level`.
  void Log(const std::string& s, spdlog::level::level_enum level = spdlog::level::info) {
    if (o.log) {
      o.log(s);
    } else {
      spdlog::log(level, "render-host: {}", s);
    }
  }

  void OnSiteFrame(const net::ReceivedFrame& f) {
    if (!f.has_mesh || f.mesh.num_vertices() == 0) return;
    auto mesh = std::make_shared<const Mesh>(f.mesh);
    {
      std::lock_guard<std::mutex> lock(mesh_mu);
      meshes[f.frame_index] = std::move(mesh);
      while (meshes.size() > 16) meshes.erase(meshes.begin());
    }
    site_frames++;
    last_site_frame = f.frame_index;
    mesh_cv.notify_all();
  }

  std::pair<int64_t, std::shared_ptr<const Mesh>> NewestMesh() const {
    std::lock_guard<std::mutex> lock(mesh_mu);
    if (meshes.empty()) return {-1, nullptr};
    return *meshes.rbegin();
  }

  void AcceptLoop() {
    while (!stopping) {
      asio::ip::tcp::socket socket(io);
      asio::error_code ec;
      acceptor->accept(socket, ec);
      if (stopping) break;
      if (ec) {
        Log("accept: " + ec.message(), spdlog::level::warn);
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        continue;
      }
      size_t live = 0;
      {
        std::lock_guard<std::mutex> lock(sessions_mu);
        for (const auto& s : sessions) live += s->done ? 0 : 1;
      }
      if (live >= static_cast<size_t>(o.max_thin_clients) + 16) {  // a flood of connections: no thread each
        Log("too many connections; closing one at accept", spdlog::level::warn);
        continue;  // the socket closes here
      }
      const int fd = socket.release(ec);
      if (ec) continue;
      auto session = std::make_shared<Session>();
      // A thin client sends only small messages (Hello, ClientPose, Ping/Pong, Stats, Control).
      protocol::Limits limits;
      limits.max_frame_payload = 64 * 1024;
      limits.max_message_bytes = 64 * 1024;
      session->link = std::make_unique<MessageLink>(fd, limits);
      std::lock_guard<std::mutex> lock(sessions_mu);
      // Reap finished sessions (their threads have returned), keep the last 32 for stats.
      for (auto it = sessions.begin(); it != sessions.end() && sessions.size() > 32;) {
        if ((*it)->done) {
          if ((*it)->reader.joinable()) (*it)->reader.join();
          it = sessions.erase(it);
        } else {
          ++it;
        }
      }
      session->id = next_id++;
      session->stats.id = session->id;
      session->stats.peer = session->link->peer();
      sessions.push_back(session);
      session->reader = std::thread([this, session] { RunSession(session); session->done = true; });
    }
  }

  size_t OpenSessions() {
    std::lock_guard<std::mutex> lock(sessions_mu);
    size_t n = 0;
    for (const auto& s : sessions) {
      std::lock_guard<std::mutex> l(s->mu);  // order: sessions_mu, then a session's mu (as in stats())
      n += s->stats.open && !s->done ? 1 : 0;
    }
    return n;
  }

  void Refuse(Session& s, protocol::RefuseReason reason, const std::string& message) {
    protocol::Refuse r;
    r.reason = reason;
    r.message = message;
    (void)s.link->Send(r);
    Log("refused thin client " + s.link->peer() + ": " + message, spdlog::level::warn);
    refused++;
    std::lock_guard<std::mutex> lock(s.mu);
    s.stats.open = false;
    s.stats.close_reason = "refused: " + message;
  }

  void CloseSession(Session& s, const std::string& reason, bool error) {
    {
      std::lock_guard<std::mutex> lock(s.mu);
      if (!s.stats.open) return;
      s.stats.open = false;
      s.stats.close_reason = reason;
    }
    if (error) closed_on_error++;
    Log("thin client " + std::to_string(s.id) + " (" + s.stats.name + ", " + s.link->peer() + ") closed: " + reason);
    s.link->Close();
    s.cv.notify_all();
  }

  // Handshake (PROTOCOL.md §3, as a site does it): Hello with role thin
  // client, a version range containing 1, the token, C1 among the colour codecs.
  bool Handshake(Session& s) {
    auto first = s.link->Read(o.handshake_timeout_s);
    if (!first.ok()) {
      Refuse(s, protocol::RefuseReason::kMalformed, "handshake: " + first.status().ToString());
      return false;
    }
    const auto* hello = std::get_if<protocol::Hello>(&first->payload);
    if (!hello) {
      Refuse(s, protocol::RefuseReason::kMalformed,
             std::string("first message must be Hello, got ") + protocol::MessageTypeName(first->header.type));
      return false;
    }
    if (hello->min_version > protocol::kProtocolVersion || hello->max_version < protocol::kProtocolVersion) {
      Refuse(s, protocol::RefuseReason::kUnsupportedVersion, "this render host speaks protocol version 1");
      return false;
    }
    if (hello->role != protocol::Role::kThinClient) {
      Refuse(s, protocol::RefuseReason::kRoleNotAllowed,
             std::string("a render host serves thin clients, not ") + protocol::RoleName(hello->role));
      return false;
    }
    const std::string& token = o.token.empty() ? o.site.token : o.token;
    if (!net::TokensEqual(hello->access_token, token)) {
      Refuse(s, protocol::RefuseReason::kBadToken, "access token not accepted for role thin client");
      return false;
    }
    const auto& colors = hello->capabilities.color;
    if (!colors.empty() && std::find(colors.begin(), colors.end(), protocol::ColorCodec::kC1) == colors.end()) {
      Refuse(s, protocol::RefuseReason::kNoCommonCodec, "the render host sends C1 (JPEG) images");
      return false;
    }
    if (OpenSessions() > static_cast<size_t>(o.max_thin_clients)) {
      Refuse(s, protocol::RefuseReason::kOverloaded, "too many thin clients");
      return false;
    }
    protocol::Welcome w;
    w.session_id = s.id;
    w.color_codec = protocol::ColorCodec::kC1;
    w.server_name = "render-host";
    if (auto st = s.link->Send(w); !st.ok()) {
      Log("thin client " + s.link->peer() + ": " + st.ToString(), spdlog::level::warn);
      return false;
    }
    {
      std::lock_guard<std::mutex> lock(s.mu);
      s.stats.name = hello->client_name;
    }
    accepted++;
    Log("thin client " + std::to_string(s.id) + " '" + hello->client_name + "' from " + s.link->peer() + " welcomed");
    return true;
  }

  void RunSession(std::shared_ptr<Session> sp) {
    Session& s = *sp;
    if (!Handshake(s)) {
      s.link->Close();
      return;
    }
    auto predictor = pose::MakePredictor(o.predictor);
    if (!predictor.ok()) {
      CloseSession(s, predictor.status().ToString(), true);
      return;
    }
    s.predictor = std::move(*predictor);
    std::thread renderer([this, sp] { RenderLoop(*sp); });
    while (!stopping) {
      auto msg = s.link->Read(o.idle_timeout_s);
      if (!msg.ok()) {
        const bool error = msg.status().code() != StatusCode::kUnavailable;
        CloseSession(s, error ? "malformed message: " + msg.status().ToString() : msg.status().message(), error);
        break;
      }
      if (auto* cp = std::get_if<protocol::ClientPose>(&msg->payload)) {
        reproject::FieldOfView fov;
        auto sample = reproject::FromClientPose(*cp, &fov);
        if (!sample.ok()) {
          CloseSession(s, "malformed ClientPose: " + sample.status().ToString(), true);
          break;
        }
        std::lock_guard<std::mutex> lock(s.mu);
        if (s.pose_seq > 0 && sample->time_us <= s.newest.time_us) {
          continue;  // out of order or repeated: keep the newer one
        }
        s.predictor->Observe(*sample);
        s.newest = *sample;
        s.fov = fov;
        s.pose_seq++;
        s.stats.poses++;
        s.cv.notify_all();
      } else if (auto* ping = std::get_if<protocol::Ping>(&msg->payload)) {
        const int64_t now = net::WallUs();
        (void)s.link->Send(protocol::Pong{ping->nonce, ping->send_time_us, now, now});
      } else if (auto* pong = std::get_if<protocol::Pong>(&msg->payload)) {
        const int64_t now = net::WallUs();
        std::lock_guard<std::mutex> lock(s.mu);
        if (pong->ping_send_time_us == s.ping_sent_us && now >= pong->ping_send_time_us) {
          s.stats.rtt_ms = (now - pong->ping_send_time_us) * 1e-3;
        }
      } else if (auto* st = std::get_if<protocol::Stats>(&msg->payload)) {
        for (const auto& [key, value] : st->values) {
          if (key == "pose_to_photon_ms" && std::isfinite(value) && value >= 0 && value < 2000) {
            std::lock_guard<std::mutex> lock(s.mu);
            s.stats.reported_latency_ms = value;
          }
        }
      } else if (std::holds_alternative<protocol::Control>(msg->payload)) {
        // Subscriptions and quality are not used by the render host.
      } else {
        CloseSession(s, std::string("unexpected message from a thin client: ") +
                            protocol::MessageTypeName(msg->header.type), true);
        break;
      }
    }
    CloseSession(s, "render host stopping", false);
    renderer.join();
  }

  void RenderLoop(Session& s) {
    uint64_t rendered_seq = 0;
    auto last_ping = Clock::now() - std::chrono::seconds(10);
    reproject::RenderedView view;
    std::unique_ptr<GlMeshRenderer> gl;
    if (o.renderer != HostRenderer::kCpu) {
      auto r = GlMeshRenderer::Create();
      if (r.ok()) {
        gl = std::move(*r);
      } else if (o.renderer == HostRenderer::kGl) {
        CloseSession(s, r.status().ToString(), true);
        return;
      } else {
        Log("thin client " + std::to_string(s.id) + ": " + r.status().ToString() + "; using the CPU renderer",
            spdlog::level::warn);
      }
    }
    {
      std::lock_guard<std::mutex> lock(s.mu);
      s.stats.renderer = gl ? "gl (" + gl->Describe() + ")" : "cpu";
    }
    while (!stopping && !s.link->closed()) {
      if (MsSince(last_ping) >= o.ping_interval_s * 1e3) {
        last_ping = Clock::now();
        const int64_t now = net::WallUs();
        {
          std::lock_guard<std::mutex> lock(s.mu);
          s.ping_sent_us = now;
        }
        (void)s.link->Send(protocol::Ping{s.id, now});
      }
      pose::PoseSample sample, predicted;
      reproject::FieldOfView fov;
      double horizon_ms = 0;
      {
        std::unique_lock<std::mutex> lock(s.mu);
        s.cv.wait_for(lock, std::chrono::milliseconds(50),
                      [&] { return s.pose_seq != rendered_seq || !s.stats.open || stopping; });
        if (s.pose_seq == rendered_seq || !s.stats.open) continue;
        rendered_seq = s.pose_seq;
        sample = s.newest;
        fov = s.fov;
        // Pose sample → display: what the client reports (pose→photon), else
        // the round trip + this host's render and encode time.
        if (s.stats.reported_latency_ms > 0) {
          horizon_ms = s.stats.reported_latency_ms;
        } else {
          horizon_ms = std::max(0.0, s.stats.rtt_ms) + s.stats.render_ms + s.stats.encode_ms;
        }
        horizon_ms += o.extra_horizon_ms;
        predicted = s.predictor->Predict(sample.time_us + static_cast<int64_t>(std::llround(horizon_ms * 1e3)));
        s.stats.horizon_ms = horizon_ms;
      }
      auto [frame_index, mesh] = NewestMesh();
      if (!mesh) continue;
      const reproject::FieldOfView big = fov.Enlarged(o.margin);
      const int w = o.width;
      const int h = std::clamp(static_cast<int>(std::lround(w * (fov.up + fov.down) / (fov.left + fov.right))), 16, 4096);
      std::array<int, 2> size = reproject::ResolutionForFov(fov, w, h, big);
      size[0] = std::clamp(size[0], 16, 4096);
      size[1] = std::clamp(size[1], 16, 4096);
      double render_ms = 0, encode_ms = 0;
      bool failed = false;
      const int eyes = o.stereo ? 2 : 1;
      for (int eye = 0; eye < eyes && !failed; ++eye) {
        Pose at = predicted.ToPose();
        if (o.stereo) {
          const float dx = static_cast<float>((eye == 0 ? -0.5 : 0.5) * o.ipd_m);
          at.translation() += at.linear() * Eigen::Vector3f(dx, 0, 0);
        }
        const auto t0 = Clock::now();
        reproject::SceneRenderFn scene = reproject::MeshSceneRenderer(*mesh);
        if (gl) {
          scene = [&gl, mesh = mesh, frame_index = frame_index](const CameraModel& cam, ImageRgb8* c, ImageDepth16* d, ImageGray8* m) {
            return gl->Render(*mesh, frame_index, cam, c, d, m);
          };
        }
        Status st = reproject::RenderAtPose(scene, at, big, size[0], size[1], &view);
        render_ms += MsSince(t0);
        if (!st.ok()) {
          CloseSession(s, "render: " + st.ToString(), true);
          failed = true;
          break;
        }
        view.frame_index = frame_index;
        view.pose_time_us = sample.time_us;
        const auto t1 = Clock::now();
        auto wire = reproject::EncodeRenderedView(view, o.encode);
        encode_ms += MsSince(t1);
        if (!wire.ok()) {
          CloseSession(s, "encode: " + wire.status().ToString(), true);
          failed = true;
          break;
        }
        if (eye == eyes - 1) {
          // Counted before the last eye goes out, so that a client that has
          // the frame never sees a count without it.
          std::lock_guard<std::mutex> lock(s.mu);
          s.stats.frames_sent++;
        }
        st = s.link->Send(*wire, o.stereo ? static_cast<uint32_t>(eye + 1) : 0u, net::WallUs());
        if (!st.ok()) {
          CloseSession(s, st.message(), false);
          failed = true;
        }
      }
      if (failed) break;
      std::lock_guard<std::mutex> lock(s.mu);
      s.stats.render_ms = Ewma(s.stats.render_ms, render_ms);
      s.stats.encode_ms = Ewma(s.stats.encode_ms, encode_ms);
      s.stats.bytes_sent = s.link->bytes_sent();
    }
  }
};

StatusOr<std::unique_ptr<RenderHost>> RenderHost::Start(RenderHostOptions options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  options.site.role = protocol::Role::kRenderHost;
  options.site.decode = true;
  options.site.subscribe = net::kSubscribeGeometry;  // the G1 mesh carries vertex colours
  HOLO_RETURN_IF_ERROR(options.site.Check());
  std::unique_ptr<RenderHost> host(new RenderHost());
  host->impl_ = std::make_unique<Impl>();
  Impl* impl = host->impl_.get();
  impl->o = options;

  asio::error_code ec;
  const asio::ip::address address = asio::ip::make_address(options.listen_host, ec);
  if (ec) return InvalidArgument("render host: --listen: '" + options.listen_host + "' is not an IP address");
  impl->acceptor = std::make_unique<asio::ip::tcp::acceptor>(impl->io);
  const asio::ip::tcp::endpoint ep(address, options.listen_port);
  impl->acceptor->open(ep.protocol(), ec);
  if (!ec) impl->acceptor->set_option(asio::socket_base::reuse_address(true), ec);
  if (!ec) impl->acceptor->bind(ep, ec);
  if (!ec) impl->acceptor->listen(16, ec);
  if (ec) {
    return Unavailable("render host: listen on " + options.listen_host + ":" + std::to_string(options.listen_port) +
                       ": " + ec.message());
  }
  host->port_ = impl->acceptor->local_endpoint().port();

  net::ClientCallbacks cb;
  cb.on_frame = [impl](const net::ReceivedFrame& f) { impl->OnSiteFrame(f); };
  cb.on_state = [impl](net::ClientState state, const Status& status) {
    if (state == net::ClientState::kConnected) {
      impl->site_connected = true;
      impl->Log("site: connected");
    } else if (state == net::ClientState::kBackoff) {
      if (impl->site_connected.exchange(false)) {
        impl->Log("site: connection lost (" + status.ToString() + "); reconnecting", spdlog::level::warn);
      } else {
        impl->Log("site: unreachable (" + status.ToString() + "); retrying", spdlog::level::warn);
      }
    } else if (state == net::ClientState::kRefused) {
      impl->Log("site: refused: " + status.ToString(), spdlog::level::err);
    }
  };
  auto site = net::SiteClient::Start(options.site, cb);
  if (!site.ok()) return site.status();
  host->site_ = std::move(*site);
  impl->accept_thread = std::thread([impl] { impl->AcceptLoop(); });
  impl->Log("listening for thin clients on " + options.listen_host + ":" + std::to_string(host->port_) +
            "; site " + options.site.host + ":" + std::to_string(options.site.port));
  return host;
}

RenderHost::~RenderHost() { Stop(); }

void RenderHost::Stop() {
  if (!impl_ || impl_->stopping.exchange(true)) return;
  ::shutdown(impl_->acceptor->native_handle(), SHUT_RDWR);
  if (impl_->accept_thread.joinable()) impl_->accept_thread.join();
  asio::error_code ec;
  impl_->acceptor->close(ec);
  std::vector<std::shared_ptr<Session>> sessions;
  {
    std::lock_guard<std::mutex> lock(impl_->sessions_mu);
    sessions = impl_->sessions;
  }
  for (auto& s : sessions) {
    s->link->Close();
    s->cv.notify_all();
  }
  for (auto& s : sessions) {
    if (s->reader.joinable()) s->reader.join();
  }
  if (site_) site_->Stop();
}

RenderHostStats RenderHost::stats() const {
  RenderHostStats r;
  r.thin_accepted = impl_->accepted;
  r.thin_refused = impl_->refused;
  r.thin_closed_on_error = impl_->closed_on_error;
  r.site_frames = impl_->site_frames;
  r.last_site_frame = impl_->last_site_frame;
  std::lock_guard<std::mutex> lock(impl_->sessions_mu);
  for (const auto& s : impl_->sessions) {
    std::lock_guard<std::mutex> l(s->mu);
    r.clients.push_back(s->stats);
  }
  return r;
}

std::shared_ptr<const Mesh> RenderHost::MeshForFrame(int64_t frame_index) const {
  std::lock_guard<std::mutex> lock(impl_->mesh_mu);
  auto it = impl_->meshes.find(frame_index);
  return it == impl_->meshes.end() ? nullptr : it->second;
}

}  // namespace holo::offload
