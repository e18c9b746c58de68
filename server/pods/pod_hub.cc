#include "server/pods/pod_hub.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include <nlohmann/json.hpp>

#include "common/clock.h"
#include "net/session_server.h"
#include "net/wire_message.h"
#include "common/log.h"
#include "protocol/color_codec.h"
#include "protocol/depth_codec.h"

namespace holo::pods {

using protocol::Message;
using protocol::MessageType;
using protocol::RefuseReason;

struct PodHub::PodState {
  PodCounters c;
  // 64 pings = 6.4 s: enough exchanges for one that no queue delayed, while
  // a 100 ppm drift moves the offset only 0.6 ms in that time.
  ClockOffsetEstimator clock{64};
  uint64_t conn_id = 0;  // the connection that owns this pod (0: none)
  bool have_transit = false;
  int64_t last_transit_us = 0;
};

struct PodHub::Conn {
  uint64_t id = 0;
  Socket socket;
  std::string peer;
  std::atomic<bool> closing{false};
};

namespace {

std::string Fmt(double v) {
  char b[32];
  std::snprintf(b, sizeof(b), "%.4g", v);
  return b;
}

Status CompareIntrinsics(const std::string& what, const Intrinsics& got, const Intrinsics& want,
                         const PodHubOptions& o) {
  if (got.width != want.width || got.height != want.height)
    return InvalidArgument(what + " size " + std::to_string(got.width) + "x" + std::to_string(got.height) +
                           " differs from the rig's " + std::to_string(want.width) + "x" + std::to_string(want.height));
  const std::pair<const char*, std::pair<double, double>> fields[] = {
      {"fx", {got.fx, want.fx}}, {"fy", {got.fy, want.fy}}, {"cx", {got.cx, want.cx}}, {"cy", {got.cy, want.cy}}};
  for (const auto& [name, v] : fields)
    if (!(std::abs(v.first - v.second) <= o.max_intrinsics_px))
      return InvalidArgument(what + "." + name + " " + Fmt(v.first) + " differs from the rig's " + Fmt(v.second) +
                             " by more than " + Fmt(o.max_intrinsics_px) + " px");
  for (size_t i = 0; i < got.distortion.size(); ++i)
    if (!(std::abs(got.distortion[i] - want.distortion[i]) <= o.max_distortion))
      return InvalidArgument(what + ".distortion[" + std::to_string(i) + "] " + Fmt(got.distortion[i]) +
                             " differs from the rig's " + Fmt(want.distortion[i]));
  return OkStatus();
}

Status ComparePose(const std::string& what, const Pose& got, const Pose& want, const PodHubOptions& o) {
  const double dt_mm = (got.translation() - want.translation()).norm() * 1e3;
  if (!(dt_mm <= o.max_translation_mm))
    return InvalidArgument(what + " translation differs from the rig's by " + Fmt(dt_mm) + " mm (at most " +
                           Fmt(o.max_translation_mm) + ")");
  const Eigen::Matrix3f r = got.linear().transpose() * want.linear();
  const double c = std::clamp((static_cast<double>(r.trace()) - 1.0) / 2.0, -1.0, 1.0);
  const double deg = std::acos(c) * 180.0 / M_PI;
  if (!(deg <= o.max_rotation_deg))
    return InvalidArgument(what + " rotation differs from the rig's by " + Fmt(deg) + " degrees (at most " +
                           Fmt(o.max_rotation_deg) + ")");
  return OkStatus();
}

}  // namespace

Status PodHubOptions::Check() const {
  if (pod_token.empty()) return InvalidArgument("pod_token must not be empty (pods authenticate with it)");
  HOLO_RETURN_IF_ERROR(grouping.Check());
  if (ping_interval_ms < 1) return InvalidArgument("ping_interval_ms must be >= 1");
  if (handshake_timeout_ms < 1 || idle_timeout_ms < 1) return InvalidArgument("timeouts must be >= 1 ms");
  if (output_sets < 1) return InvalidArgument("output_sets must be >= 1");
  return limits.Check();
}

Status CheckPodCalibration(const Rig& rig, const PodCalibration& pod, const PodHubOptions& options, int* index) {
  for (size_t i = 0; i < rig.pods.size(); ++i) {
    const PodCalibration& r = rig.pods[i];
    if (r.id != pod.id) continue;
    const std::string who = "pod " + std::to_string(pod.id) + (r.name.empty() ? "" : " (" + r.name + ")") + ": ";
    HOLO_RETURN_IF_ERROR(CompareIntrinsics(who + "depth", pod.depth, r.depth, options));
    HOLO_RETURN_IF_ERROR(CompareIntrinsics(who + "color", pod.color, r.color, options));
    HOLO_RETURN_IF_ERROR(ComparePose(who + "world_from_depth", pod.world_from_depth, r.world_from_depth, options));
    HOLO_RETURN_IF_ERROR(ComparePose(who + "color_from_depth", pod.color_from_depth, r.color_from_depth, options));
    *index = static_cast<int>(i);
    return OkStatus();
  }
  std::string ids;
  for (const PodCalibration& r : rig.pods) ids += (ids.empty() ? "" : ", ") + std::to_string(r.id);
  return InvalidArgument("pod " + std::to_string(pod.id) + " is not in rig '" + rig.name + "' (pod ids " + ids + ")");
}

PodHub::PodHub(const Rig& rig, PodHubOptions options, std::function<void(const std::string&)> log)
    : rig_(rig), options_(std::move(options)), log_(std::move(log)),
      grouper_(static_cast<int>(rig.pods.size()), options_.grouping) {
  for (size_t i = 0; i < rig.pods.size(); ++i) {
    auto p = std::make_unique<PodState>();
    p->c.pod_id = rig.pods[i].id;
    p->c.name = rig.pods[i].name;
    pods_.push_back(std::move(p));
    grouper_.SetExpected(static_cast<int>(i), false);  // expected once connected
  }
}

StatusOr<std::unique_ptr<PodHub>> PodHub::Start(const Rig& rig, PodHubOptions options,
                                                std::function<void(const std::string&)> log) {
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_RETURN_IF_ERROR(rig.Check());
  if (rig.pods.size() > 64) return InvalidArgument("a pod hub serves at most 64 pods");
  std::unique_ptr<PodHub> hub(new PodHub(rig, std::move(options), std::move(log)));
  HOLO_ASSIGN_OR_RETURN(hub->listener_, Listen(hub->options_.host, hub->options_.port));
  hub->port_ = LocalPort(hub->listener_);
  hub->accept_thread_ = std::thread([h = hub.get()] { h->AcceptLoop(); });
  return hub;
}

PodHub::~PodHub() { Stop(); }

void PodHub::Log(const std::string& line, spdlog::level::level_enum level) {
  if (log_) {
    log_(line);
  } else {
    spdlog::log(level, "pod hub: {}", line);
  }
}

void PodHub::SetOnSet(std::function<void(const SetInfo&)> fn) {
  std::lock_guard<std::mutex> l(mu_);
  on_set_ = std::move(fn);
}

void PodHub::Stop() {
  if (stop_.exchange(true)) return;
  listener_.Shutdown();
  if (accept_thread_.joinable()) accept_thread_.join();
  std::vector<std::pair<uint64_t, std::thread>> threads;
  {
    std::lock_guard<std::mutex> l(mu_);
    for (auto& c : conns_) {
      c->closing = true;
      c->socket.Shutdown();
    }
    threads = std::move(threads_);
  }
  for (auto& [id, t] : threads)
    if (t.joinable()) t.join();
  listener_.Close();
  cv_.notify_all();
}

void PodHub::AcceptLoop() {
  const size_t max_conns = options_.max_connections > 0 ? options_.max_connections : 2 * rig_.pods.size() + 8;
  while (!stop_) {
    {
      // Join the threads of closed connections (reconnecting pods must not pile them up).
      std::vector<std::thread> done;
      {
        std::lock_guard<std::mutex> l(mu_);
        for (uint64_t id : finished_)
          for (auto it = threads_.begin(); it != threads_.end(); ++it)
            if (it->first == id) {
              done.push_back(std::move(it->second));
              threads_.erase(it);
              break;
            }
        finished_.clear();
      }
      for (auto& t : done)
        if (t.joinable()) t.join();
    }
    std::string peer;
    auto s = Accept(listener_, 200, &peer);
    if (!s.ok()) {
      if (s.status().code() == StatusCode::kOutOfRange) continue;
      if (!stop_) Log("accept failed: " + s.status().message(), spdlog::level::warn);
      if (stop_) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      continue;
    }
    auto conn = std::make_shared<Conn>();
    conn->socket = std::move(*s);
    conn->peer = peer;
    SetBufferSizes(conn->socket, 0, 256 * 1024);  // latency stays in the pod's queue, not in the kernel
    std::lock_guard<std::mutex> l(mu_);
    if (stop_) return;
    counters_.accepted++;
    if (conns_.size() >= max_conns) {
      counters_.refused++;
      Log("closed " + peer + " at accept: " + std::to_string(conns_.size()) + " connections already (at most " +
              std::to_string(max_conns) + ")",
          spdlog::level::warn);
      continue;  // `conn` closes its socket
    }
    conn->id = next_conn_id_++;
    conns_.push_back(conn);
    threads_.emplace_back(conn->id, std::thread([this, conn] { Serve(conn); }));
  }
}

Status PodHub::Handshake(Conn& conn, int* pod_index) {
  MessageReader reader(options_.limits);
  auto refuse = [&](RefuseReason reason, const std::string& why) {
    protocol::Refuse r;
    r.reason = reason;
    r.message = why;
    protocol::Header h;
    const auto bytes = protocol::EncodeMessage(h, r);
    (void)SendAll(conn.socket, bytes.data(), bytes.size(), 1000);
    std::lock_guard<std::mutex> l(mu_);
    counters_.refused++;
    return Unavailable("refused " + conn.peer + ": " + why);
  };
  Message m;
  Status s = reader.Read(conn.socket, options_.handshake_timeout_ms, &m);
  if (s.code() == StatusCode::kUnsupportedVersion) return refuse(RefuseReason::kUnsupportedVersion, s.message());
  if (!s.ok()) return s.WithContext("handshake from " + conn.peer);
  if (m.header.type != MessageType::kHello)
    return refuse(RefuseReason::kMalformed, std::string("expected hello, got ") + protocol::MessageTypeName(m.header.type));
  const auto& hello = std::get<protocol::Hello>(m.payload);
  if (hello.role != protocol::Role::kPod)
    return refuse(RefuseReason::kRoleNotAllowed,
                  std::string("this is a pod port: role ") + protocol::RoleName(hello.role) + " is not served here");
  if (hello.min_version > protocol::kProtocolVersion || hello.max_version < protocol::kProtocolVersion)
    return refuse(RefuseReason::kUnsupportedVersion, "this hub speaks protocol version 1");
  if (!net::TokensEqual(hello.access_token, options_.pod_token))
    return refuse(RefuseReason::kBadToken, "access token not accepted for role pod");
  s = reader.Read(conn.socket, options_.handshake_timeout_ms, &m);
  if (!s.ok()) return s.WithContext("handshake from " + conn.peer + " (calibration)");
  if (m.header.type != MessageType::kRig)
    return refuse(RefuseReason::kMalformed,
                  std::string("expected the pod's calibration (rig), got ") + protocol::MessageTypeName(m.header.type));
  const Rig& cal = std::get<protocol::RigMessage>(m.payload).rig;
  if (cal.pods.size() != 1)
    return refuse(RefuseReason::kMalformed,
                  "a pod sends exactly its own calibration (1 pod), got " + std::to_string(cal.pods.size()));
  int index = -1;
  s = CheckPodCalibration(rig_, cal.pods[0], options_, &index);
  if (!s.ok()) return refuse(RefuseReason::kBadCalibration, s.message());
  protocol::Welcome w;
  w.session_id = conn.id;
  w.server_name = "pod hub (" + rig_.name + ")";
  protocol::Header h;
  const auto bytes = protocol::EncodeMessage(h, w);
  HOLO_RETURN_IF_ERROR(SendAll(conn.socket, bytes.data(), bytes.size(), 1000));
  *pod_index = index;
  return OkStatus();
}

void PodHub::Serve(std::shared_ptr<Conn> conn) {
  int pod = -1;
  Status s = Handshake(*conn, &pod);
  if (!s.ok()) {
    Log(s.message(), spdlog::level::warn);
    conn->socket.Shutdown();
    std::lock_guard<std::mutex> l(mu_);
    conns_.erase(std::remove_if(conns_.begin(), conns_.end(), [&](const auto& c) { return c->id == conn->id; }),
                 conns_.end());
    finished_.push_back(conn->id);
    return;
  }
  std::shared_ptr<Conn> replaced;
  {
    std::lock_guard<std::mutex> l(mu_);
    PodState& ps = *pods_[static_cast<size_t>(pod)];
    if (ps.conn_id != 0) {
      for (auto& c : conns_)
        if (c->id == ps.conn_id) replaced = c;
    }
    ps.conn_id = conn->id;
    ps.c.connected = true;
    ps.c.peer = conn->peer;
    ps.c.connections++;
    ps.clock.Reset();
    ps.have_transit = false;
    grouper_.SetExpected(pod, true);
  }
  if (replaced) {
    replaced->closing = true;
    replaced->socket.Shutdown();
    Log("pod " + std::to_string(rig_.pods[static_cast<size_t>(pod)].id) + ": new connection from " + conn->peer +
        " replaces the one from " + replaced->peer);
  }
  Log("pod " + std::to_string(rig_.pods[static_cast<size_t>(pod)].id) + " connected from " + conn->peer);

  MessageReader reader(options_.limits);
  std::mt19937_64 rng(conn->id * 7919 + 17);
  uint64_t nonce = 0;
  int64_t next_ping = 0;  // steady ms
  int64_t last_heard = RealClock::Instance().NowUs() / 1000;
  std::string why;
  while (!stop_ && !conn->closing) {
    const int64_t now_ms = RealClock::Instance().NowUs() / 1000;
    if (now_ms >= next_ping) {
      nonce = rng();
      protocol::Ping p{nonce, net::WallUs()};
      protocol::Header h;
      const auto bytes = protocol::EncodeMessage(h, p);
      s = SendAll(conn->socket, bytes.data(), bytes.size(), 1000);
      if (!s.ok()) {
        why = s.message();
        break;
      }
      next_ping = now_ms + options_.ping_interval_ms;
    }
    if (now_ms - last_heard > options_.idle_timeout_ms) {
      why = "silent for " + std::to_string(options_.idle_timeout_ms) + " ms";
      break;
    }
    Message m;
    s = reader.Read(conn->socket, static_cast<int>(std::max<int64_t>(1, next_ping - now_ms)), &m);
    if (s.code() == StatusCode::kOutOfRange) continue;
    if (!s.ok()) {
      why = s.message();
      if (s.code() == StatusCode::kDataLoss || s.code() == StatusCode::kUnsupportedVersion) {
        std::lock_guard<std::mutex> l(mu_);
        counters_.violations++;
        why = "malformed message: " + why;
      }
      break;
    }
    // When its bytes arrived, not when this thread got to them (it may have
    // been decoding): the Pong's t3 and the frame's arrival.
    const int64_t arrival = reader.arrival_us() > 0 ? reader.arrival_us() : net::WallUs();
    last_heard = RealClock::Instance().NowUs() / 1000;
    if (m.header.type == MessageType::kPodFrame) {
      s = HandleFrame(pod, std::get<protocol::PodFrame>(m.payload), arrival);
      if (!s.ok()) {
        std::lock_guard<std::mutex> l(mu_);
        counters_.violations++;
        why = "malformed frame: " + s.message();
        break;
      }
    } else if (m.header.type == MessageType::kPong) {
      const auto& p = std::get<protocol::Pong>(m.payload);
      if (p.nonce != nonce) continue;  // stale
      std::lock_guard<std::mutex> l(mu_);
      PodState& ps = *pods_[static_cast<size_t>(pod)];
      if (ps.conn_id == conn->id) {
        ps.clock.Add(p.ping_send_time_us, p.receive_time_us, p.send_time_us, arrival);
        ps.c.offset_ms = static_cast<double>(ps.clock.offset_us()) * 1e-3;
        ps.c.rtt_ms = static_cast<double>(ps.clock.rtt_us()) * 1e-3;
      }
    } else if (m.header.type == MessageType::kPing) {
      const auto& p = std::get<protocol::Ping>(m.payload);
      protocol::Pong pong{p.nonce, p.send_time_us, arrival, net::WallUs()};
      protocol::Header h;
      const auto bytes = protocol::EncodeMessage(h, pong);
      s = SendAll(conn->socket, bytes.data(), bytes.size(), 1000);
      if (!s.ok()) {
        why = s.message();
        break;
      }
    } else if (m.header.type == MessageType::kStats) {
      // Pods may report their own counters; not used yet.
    } else {
      std::lock_guard<std::mutex> l(mu_);
      counters_.violations++;
      why = std::string("unexpected ") + protocol::MessageTypeName(m.header.type) + " from a pod";
      break;
    }
  }
  conn->socket.Shutdown();
  {
    std::lock_guard<std::mutex> l(mu_);
    PodState& ps = *pods_[static_cast<size_t>(pod)];
    if (ps.conn_id == conn->id) {
      ps.conn_id = 0;
      ps.c.connected = false;
      ps.c.last_error = stop_ ? "hub stopped" : why;
      grouper_.SetExpected(pod, false);
      // Sets that waited only for this pod may leave now.
      ReleaseReady(net::WallUs());
    }
    conns_.erase(std::remove_if(conns_.begin(), conns_.end(), [&](const auto& c) { return c->id == conn->id; }),
                 conns_.end());
    finished_.push_back(conn->id);
  }
  cv_.notify_all();
  if (!stop_) Log("pod " + std::to_string(rig_.pods[static_cast<size_t>(pod)].id) + " (" + conn->peer + ") closed: " + why);
}

Status PodHub::HandleFrame(int pod, const protocol::PodFrame& f, int64_t arrival_us) {
  const PodCalibration& cal = rig_.pods[static_cast<size_t>(pod)];
  const double cpu0 = ThreadCpuTimeMs();
  if (f.pod_id != cal.id)
    return DataLoss("frame of pod " + std::to_string(f.pod_id) + " on the connection of pod " + std::to_string(cal.id));
  {
    // A frame whose set has already left is not worth decoding (a pod or
    // link that fell behind catches up faster). Its blobs are still checked
    // for their sizes below when it is decoded; a late one is counted only.
    std::lock_guard<std::mutex> l(mu_);
    PodState& ps = *pods_[static_cast<size_t>(pod)];
    if (ps.clock.has_estimate() && grouper_.IsLate(ps.clock.ToSite(f.capture_time_us))) {
      ps.c.received++;
      ps.c.bytes += f.depth.size() + f.color.size() + 32;
      ps.c.late++;
      ps.c.dropped++;
      return OkStatus();
    }
  }
  auto frame = std::make_shared<RgbdFrame>();
  // D1 or D2 (the blob names its codec; it must agree with the frame's).
  HOLO_ASSIGN_OR_RETURN(protocol::DepthCodec blob_codec, protocol::PeekDepthCodec(f.depth));
  if (blob_codec != f.depth_codec)
    return DataLoss("depth blob is codec D" + std::to_string(static_cast<int>(blob_codec)) + ", the frame says D" +
                    std::to_string(static_cast<int>(f.depth_codec)));
  HOLO_RETURN_IF_ERROR(protocol::DecodeDepth(f.depth, &frame->depth, options_.limits));
  if (frame->depth.width() != cal.depth.width || frame->depth.height() != cal.depth.height)
    return DataLoss("depth image is " + std::to_string(frame->depth.width()) + "x" +
                    std::to_string(frame->depth.height()) + ", the calibration says " + std::to_string(cal.depth.width) +
                    "x" + std::to_string(cal.depth.height));
  ImageGray8 mask;
  HOLO_RETURN_IF_ERROR(protocol::DecodeColor(f.color, &frame->color, &mask, options_.limits));
  if (frame->color.width() != cal.color.width || frame->color.height() != cal.color.height)
    return DataLoss("colour image is " + std::to_string(frame->color.width()) + "x" +
                    std::to_string(frame->color.height()) + ", the calibration says " + std::to_string(cal.color.width) +
                    "x" + std::to_string(cal.color.height));
  frame->pod_id = cal.id;
  std::vector<SetInfo> infos;
  std::function<void(const SetInfo&)> on_set;
  {
    std::lock_guard<std::mutex> l(mu_);
    PodState& ps = *pods_[static_cast<size_t>(pod)];
    ps.c.decode_cpu_ms += ThreadCpuTimeMs() - cpu0;
    ps.c.received++;
    ps.c.bytes += f.depth.size() + f.color.size() + 32;
    if (!ps.clock.has_estimate()) {
      ps.c.dropped++;  // no clock offset yet: its time on the site clock is unknown
      return OkStatus();
    }
    const int64_t site_time = ps.clock.ToSite(f.capture_time_us);
    const int64_t transit = arrival_us - site_time;
    if (ps.have_transit) {
      const double d = std::abs(static_cast<double>(transit - ps.last_transit_us)) * 1e-3;
      ps.c.jitter_ms += (d - ps.c.jitter_ms) / 16.0;
    }
    ps.have_transit = true;
    ps.last_transit_us = transit;
    frame->timestamp_us = site_time;
    const AddResult r = grouper_.Add(PodSample{pod, site_time, f.frame_number, std::move(frame)}, arrival_us);
    if (r == AddResult::kLate) {
      ps.c.late++;
      ps.c.dropped++;
    } else if (r == AddResult::kDuplicate) {
      ps.c.duplicates++;
      ps.c.dropped++;
    }
    ReleaseReady(arrival_us);
    infos.swap(released_info_);
    on_set = on_set_;
  }
  cv_.notify_all();
  if (on_set)
    for (const SetInfo& i : infos) on_set(i);
  return OkStatus();
}

void PodHub::ReleaseReady(int64_t now_us) {
  std::vector<GroupedSet> sets;
  grouper_.Poll(now_us, &sets);
  for (GroupedSet& g : sets) {
    SetInfo info;
    info.index = static_cast<int64_t>(counters_.sets_released);
    info.time_us = g.time_us;
    info.released_us = now_us;
    info.present = g.present;
    info.complete = g.complete;
    info.spread_us = g.spread_us;
    for (size_t p = 0; p < g.pods.size(); ++p)
      if (g.pods[p].frame) info.pods_mask |= uint64_t{1} << p;
    counters_.sets_released++;
    if (g.complete) counters_.sets_complete++;
    if (on_set_) released_info_.push_back(info);
    ready_.emplace_back(info, std::move(g));
    while (ready_.size() > options_.output_sets) {
      for (const PodSample& s : ready_.front().second.pods)
        if (s.frame) pods_[static_cast<size_t>(s.pod)]->c.dropped++;
      ready_.pop_front();
      counters_.sets_dropped++;
    }
  }
}

Status PodHub::Next(RgbdFrameSet* out) {
  std::pair<SetInfo, GroupedSet> item;
  std::vector<SetInfo> infos;
  std::function<void(const SetInfo&)> on_set;
  {
    std::unique_lock<std::mutex> l(mu_);
    for (;;) {
      if (stop_) return OutOfRange("pod hub stopped");
      ReleaseReady(net::WallUs());
      if (!ready_.empty()) break;
      // Wake for the next timeout release, a new frame, or Stop.
      const int64_t deadline = grouper_.NextDeadlineUs();
      const int64_t wait_us =
          deadline == INT64_MAX ? 20000 : std::clamp<int64_t>(deadline - net::WallUs(), 200, 20000);
      cv_.wait_for(l, std::chrono::microseconds(wait_us));
    }
    item = std::move(ready_.front());
    ready_.pop_front();
    counters_.sets_taken++;
    last_set_ = item.first;
    infos.swap(released_info_);
    on_set = on_set_;
  }
  if (on_set)
    for (const SetInfo& i : infos) on_set(i);
  const GroupedSet& g = item.second;
  out->frame_index = item.first.index;
  out->frames.resize(rig_.pods.size());
  for (size_t p = 0; p < rig_.pods.size(); ++p) {
    RgbdFrame& f = out->frames[p];
    const PodCalibration& cal = rig_.pods[p];
    f.pod_id = cal.id;
    f.mask = ImageGray8();
    if (g.pods[p].frame) {
      f.timestamp_us = g.pods[p].frame->timestamp_us;
      f.color = std::move(g.pods[p].frame->color);
      f.depth = std::move(g.pods[p].frame->depth);
    } else {
      // A missing pod: no valid depth, so fusion and texturing take nothing from it.
      f.timestamp_us = 0;
      f.depth.Resize(cal.depth.width, cal.depth.height, 0);
      f.color.Resize(cal.color.width, cal.color.height, 0);
    }
  }
  return OkStatus();
}

Status PodHub::Seek(int64_t) { return Unavailable("a pod hub is live: it cannot seek"); }

Status PodHub::Skip(int64_t n) {
  std::lock_guard<std::mutex> l(mu_);
  for (int64_t i = 0; i < n && !ready_.empty(); ++i) {
    ready_.pop_front();
    counters_.sets_dropped++;
  }
  return OkStatus();
}

std::vector<PodCounters> PodHub::Pods() const {
  std::lock_guard<std::mutex> l(mu_);
  std::vector<PodCounters> v;
  for (const auto& p : pods_) v.push_back(p->c);
  return v;
}

HubCounters PodHub::counters() const {
  std::lock_guard<std::mutex> l(mu_);
  return counters_;
}

SetInfo PodHub::last_set() const {
  std::lock_guard<std::mutex> l(mu_);
  return last_set_;
}

std::string PodCountersJson(const PodCounters& c) {
  nlohmann::json j;
  j["pod"] = c.pod_id;
  j["name"] = c.name;
  j["connected"] = c.connected;
  j["peer"] = c.peer;
  j["connections"] = c.connections;
  j["received"] = c.received;
  j["late"] = c.late;
  j["duplicates"] = c.duplicates;
  j["dropped"] = c.dropped;
  j["bytes"] = c.bytes;
  j["offset_ms"] = std::round(c.offset_ms * 1000) / 1000;
  j["rtt_ms"] = std::round(c.rtt_ms * 1000) / 1000;
  j["jitter_ms"] = std::round(c.jitter_ms * 1000) / 1000;
  j["decode_cpu_ms"] = std::round(c.decode_cpu_ms * 10) / 10;
  if (!c.last_error.empty()) j["last_error"] = c.last_error;
  return j.dump();
}

std::string HubCountersJson(const HubCounters& c) {
  nlohmann::json j;
  j["pod_hub"] = true;
  j["accepted"] = c.accepted;
  j["refused"] = c.refused;
  j["violations"] = c.violations;
  j["sets_released"] = c.sets_released;
  j["sets_complete"] = c.sets_complete;
  j["sets_taken"] = c.sets_taken;
  j["sets_dropped"] = c.sets_dropped;
  return j.dump();
}

std::string SetInfoJson(const SetInfo& s) {
  nlohmann::json j;
  j["pod_set"] = s.index;
  j["time_us"] = s.time_us;
  j["released_us"] = s.released_us;
  j["present"] = s.present;
  j["complete"] = s.complete;
  j["spread_us"] = s.spread_us;
  j["pods_mask"] = s.pods_mask;
  return j.dump();
}

}  // namespace holo::pods
