#include "server/record/replay_net.h"

#include <algorithm>
#include <cstdio>
#include <span>
#include <utility>

#include "common/log.h"
#include "net/wire_message.h"

namespace holo::record {

using protocol::MessageType;

net::WireMessagePtr RecordedPublisher::ToWire(const std::vector<uint8_t>& bytes, const protocol::Header& h) const {
  const std::span<const uint8_t> payload = std::span<const uint8_t>(bytes).subspan(protocol::kHeaderSize);
  const size_t fragment = server_->config().fragment_bytes;
  if (payload.size() > fragment) return net::MakeWireMessageFromBytes(h, payload, fragment);
  // One frame: the recorded bytes as they are.
  auto m = std::make_shared<net::WireMessage>();
  m->type = h.type;
  m->stream_id = h.stream_id;
  m->capture_time_us = h.capture_time_us;
  m->bytes = bytes;
  m->frame_ends = {static_cast<uint32_t>(bytes.size())};
  m->payload_bytes = payload.size();
  return m;
}

void RecordedPublisher::Flush() {
  if (!held_) return;
  server_->PublishVideo(std::move(held_));
  held_.reset();
  stats_.video_frames += 1;
}

Status RecordedPublisher::Publish(const std::vector<uint8_t>& bytes, const protocol::Header& h) {
  if (bytes.size() < protocol::kHeaderSize || bytes.size() - protocol::kHeaderSize != h.payload_length ||
      (h.flags & protocol::kFlagMoreFragments) != 0)
    return InvalidArgument("recorded message of " + std::to_string(bytes.size()) +
                           " bytes does not match its header (payload length " + std::to_string(h.payload_length) +
                           ")");
  switch (h.type) {
    case MessageType::kRig:
      Flush();
      server_->SetRigMessage(ToWire(bytes, h));
      stats_.rigs += 1;
      return OkStatus();
    case MessageType::kMeshFrame: {
      Flush();
      auto f = std::make_shared<net::VideoFrame>();
      f->frame_index = h.sequence;
      f->capture_time_us = h.capture_time_us;
      f->parts.push_back(ToWire(bytes, h));
      held_ = std::move(f);
      held_header_ = h;
      stats_.meshes += 1;
      return OkStatus();
    }
    case MessageType::kColorFrame: {
      stats_.colors += 1;
      if (held_ && held_header_.stream_id == h.stream_id && held_header_.sequence == h.sequence) {
        held_->parts.push_back(ToWire(bytes, h));
        Flush();
        return OkStatus();
      }
      Flush();
      auto f = std::make_shared<net::VideoFrame>();
      f->frame_index = h.sequence;
      f->capture_time_us = h.capture_time_us;
      f->parts.push_back(ToWire(bytes, h));
      server_->PublishVideo(std::move(f));
      stats_.video_frames += 1;
      return OkStatus();
    }
    case MessageType::kRegions:
      // The recording carries active regions: announce them (as the live site
      // did) so that viewers subscribe, now and at every later Welcome.
      if (!regions_announced_) {
        const size_t count = bytes.size() > protocol::kHeaderSize + 8 ? bytes[protocol::kHeaderSize + 8] : 0;
        server_->AnnounceRegions(count);
        regions_announced_ = true;
      }
      server_->PublishPriority(ToWire(bytes, h));
      stats_.priority += 1;
      return OkStatus();
    case MessageType::kAudioPose:
    case MessageType::kStats:
      server_->PublishPriority(ToWire(bytes, h));
      stats_.priority += 1;
      return OkStatus();
    default:
      stats_.ignored += 1;
      return OkStatus();
  }
}

StatusOr<std::unique_ptr<ReplayServer>> ReplayServer::Start(std::shared_ptr<const RecordingReader> reader,
                                                            Clock* clock, ReplayServerOptions options) {
  if (reader == nullptr || clock == nullptr) return InvalidArgument("replay server: no recording or clock");
  std::unique_ptr<ReplayServer> rs(new ReplayServer());
  rs->reader_ = reader;
  rs->clock_ = clock;
  rs->options_ = std::move(options);
  auto source = ReplaySource::Create(reader, clock, rs->options_.replay);
  if (!source.ok()) return source.status();
  rs->source_ = std::move(*source);
  net::ServerHooks hooks;
  hooks.log = rs->options_.log;
  hooks.control = rs.get();
  auto server = net::Server::Start(rs->options_.net, hooks);
  if (!server.ok()) return server.status().WithContext("replay server");
  rs->server_ = std::move(*server);
  // Announce the recording's geometry codec (from its first key frame).
  const RecordingSummary& sum = reader->summary();
  if (!sum.index.empty()) {
    auto m = reader->ReadAt(sum.index.front().offset);
    if (!m.ok()) return m.status();
    auto p = protocol::DecodePayload(m->header,
                                     std::span<const uint8_t>(*m->bytes).subspan(protocol::kHeaderSize));
    if (p.ok() && std::holds_alternative<protocol::MeshFrame>(*p))
      rs->server_->SetPublishedCodecs(std::get<protocol::MeshFrame>(*p).codec, protocol::ColorCodec::kC1);
  }
  // The Rig first: viewers that connect before the first Pump get it at Welcome.
  auto rig = reader->ReadAt(sum.data_begin);
  if (!rig.ok()) return rig.status();
  rs->publisher_ = std::make_unique<RecordedPublisher>(rs->server_.get());
  Status s = rs->publisher_->Publish(*rig->bytes, rig->header);
  if (!s.ok()) return s;
  rs->pump_ = std::thread([p = rs.get()] { p->PumpLoop(); });
  return rs;
}

ReplayServer::~ReplayServer() { Stop(); }

void ReplayServer::Stop() {
  stop_ = true;
  if (pump_.joinable()) pump_.join();
  if (server_) server_->Stop();
}

ReplayServerStats ReplayServer::stats() const {
  std::lock_guard<std::mutex> l(mu_);
  return stats_;
}

Status ReplayServer::status() const {
  std::lock_guard<std::mutex> l(mu_);
  return error_;
}

void ReplayServer::Log(const std::string& line, spdlog::level::level_enum level) const {
  if (options_.log) {
    options_.log(line);
  } else {
    spdlog::log(level, "{}", line);
  }
}

void ReplayServer::OnControl(const net::ControlEvent& ev) {
  using protocol::ControlCommand;
  if (ev.control.command == ControlCommand::kSetQuality) return;  // one recorded quality
  Status s = source_->ApplyControl(ev.control);
  std::lock_guard<std::mutex> l(mu_);
  if (s.ok()) {
    stats_.controls_applied += 1;
  } else {
    stats_.controls_rejected += 1;
    Log("replay: control from session " + std::to_string(ev.session_id) + " ('" + ev.client_name +
        "') rejected: " + s.message());
  }
}

void ReplayServer::PumpLoop() {
  size_t viewers_seen = 0;
  int64_t due = 0;
  auto sink = [&](std::shared_ptr<const std::vector<uint8_t>> bytes, protocol::Header h) {
    Status s = publisher_->Publish(*bytes, h);
    if (!s.ok()) Log("replay: " + s.message(), spdlog::level::warn);
    if (options_.on_emit) options_.on_emit(h, due, clock_->NowUs());
  };
  while (!stop_) {
    // A viewer that joins (subscribes to video in) a paused replay would see
    // nothing until resume: re-emit the Rig and the key frame at the current
    // position (to every viewer: the others get that frame once more).
    const size_t viewers = server_->num_subscribed(net::kContentGeometry | net::kContentColor);
    if (viewers > viewers_seen) {
      const ReplayState st = source_->state();
      if (st.paused && !st.ended && st.emitted > 0) {
        protocol::Control c;
        c.command = protocol::ControlCommand::kRequestKeyFrame;
        if (source_->ApplyControl(c).ok()) {
          std::lock_guard<std::mutex> l(mu_);
          stats_.join_key_frames += 1;
        }
      }
    }
    viewers_seen = viewers;
    const int64_t now = clock_->NowUs();
    due = source_->NextDueUs();
    if (due > now) {
      publisher_->Flush();
      clock_->SleepUntilUs(std::min(due, now + 20000));
      continue;
    }
    auto n = source_->Pump(sink, 1);
    if (!n.ok()) {
      publisher_->Flush();
      Log("replay stopped: " + n.status().message(), spdlog::level::warn);
      {
        std::lock_guard<std::mutex> l(mu_);
        if (error_.ok()) error_ = n.status();
      }
      clock_->SleepUntilUs(clock_->NowUs() + 20000);  // the replay has ended; a Seek may resume it
      continue;
    }
    std::lock_guard<std::mutex> l(mu_);
    stats_.emitted += *n;
  }
  publisher_->Flush();
}

}  // namespace holo::record
