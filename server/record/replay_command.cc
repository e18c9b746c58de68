#include "server/record/replay_command.h"

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <csignal>
#include <cstdio>
#include <memory>
#include <mutex>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/clock.h"
#include "common/file_util.h"
#include "common/log.h"
#include "common/mesh.h"
#include "common/quantile.h"
#include "net/server_config.h"
#include "protocol/geometry_codec.h"
#include "server/record/recording_reader.h"
#include "server/record/replay.h"
#include "server/record/replay_net.h"

namespace holo::record {
namespace {

volatile std::sig_atomic_t g_replay_stop = 0;
void OnReplaySignal(int) { g_replay_stop = 1; }

int Fail(const Status& s) {
  spdlog::error("holoport-server: replay: {}", s.message());
  return 1;
}

std::string RandomToken() {
  std::ifstream f("/dev/urandom", std::ios::binary);
  unsigned char b[24] = {};
  f.read(reinterpret_cast<char*>(b), sizeof(b));
  static const char* hex = "0123456789abcdef";
  std::string t;
  for (unsigned char c : b) {
    t.push_back(hex[c >> 4]);
    t.push_back(hex[c & 15]);
  }
  return t;
}

// The --stats output: "-" stdout, "" none (nullptr), else the file.
StatusOr<FILE*> OpenStats(const std::string& path) {
  if (path == "-") return stdout;
  if (path.empty()) return static_cast<FILE*>(nullptr);
  FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) return Unavailable(path + ": cannot open for writing");
  return f;
}

void CloseStats(FILE* stats) {
  if (stats != nullptr && stats != stdout) std::fclose(stats);
}

int RunNetworkReplay(const ReplayCommandOptions& o, std::shared_ptr<const RecordingReader> reader) {
  if (!o.export_dir.empty())
    return Fail(InvalidArgument("--export is not available with --listen (viewers receive the meshes)"));
  ReplayServerOptions so;
  if (!o.net_config.empty()) {
    auto c = net::LoadServerConfig(o.net_config);
    if (!c.ok()) return Fail(c.status());
    so.net = *c;
  } else {
    so.net.host = "0.0.0.0";
  }
  if (!o.listen.empty()) {
    Status st = net::ParseHostPort(o.listen, &so.net.host, &so.net.port);
    if (!st.ok()) return Fail(st.WithContext("--listen"));
  }
  std::string viewer_token = o.viewer_token, publisher_token = o.publisher_token;
  if (viewer_token.empty() && std::getenv("HOLO_VIEWER_TOKEN")) viewer_token = std::getenv("HOLO_VIEWER_TOKEN");
  if (publisher_token.empty() && std::getenv("HOLO_PUBLISHER_TOKEN"))
    publisher_token = std::getenv("HOLO_PUBLISHER_TOKEN");
  if (!viewer_token.empty()) so.net.viewer_token = viewer_token;
  if (!publisher_token.empty()) so.net.publisher_token = publisher_token;
  if (so.net.viewer_token.empty())
    return Fail(InvalidArgument(
        "serving a replay needs a viewer token: --viewer-token, env HOLO_VIEWER_TOKEN or viewer_token in --net-config"));
  if (so.net.publisher_token.empty()) so.net.publisher_token = RandomToken();
  so.replay.speed = o.speed;
  so.replay.loop = o.loop;
  so.replay.start_us = static_cast<int64_t>(o.start_s * 1e6);
  if (o.quiet) so.log = [](const std::string&) {};
  auto stats_file = OpenStats(o.stats_path);
  if (!stats_file.ok()) return Fail(stats_file.status());
  FILE* const stats = *stats_file;
  RealClock& clock = RealClock::Instance();
  std::vector<double> lateness_ms;  // mesh frames: fan-out time − due time
  std::mutex late_mu;
  so.on_emit = [&](const protocol::Header& h, int64_t due, int64_t emitted) {
    const double late = static_cast<double>(emitted - due) * 1e-3;
    if (h.type == protocol::MessageType::kMeshFrame) {
      std::lock_guard<std::mutex> l(late_mu);
      if (lateness_ms.size() < (1u << 20)) lateness_ms.push_back(late);  // ≈ 9.7 h at 30 fps, 8 MB
    }
    if (stats != nullptr) {
      nlohmann::ordered_json j;
      j["type"] = protocol::MessageTypeName(h.type);
      j["stream"] = h.stream_id;
      j["sequence"] = h.sequence;
      j["capture_time_us"] = h.capture_time_us;
      j["bytes"] = h.payload_length + 32u;
      j["late_ms"] = late;
      std::fprintf(stats, "%s\n", j.dump().c_str());
    }
  };
  const RecordingSummary& sum = reader->summary();
  auto rs = ReplayServer::Start(reader, &clock, so);
  if (!rs.ok()) {
    CloseStats(stats);
    return Fail(rs.status());
  }
  if (!o.quiet)
    spdlog::info(
        "holoport-server: serving {} ({}, {} messages, {} key frames{}) at {:.2f}x{} on {}:{}; viewers "
        "control it (pause, resume, seek, speed 0.25..4; one shared timeline). Ctrl-C stops.",
        o.path, FormatSeconds(sum.duration_us), sum.num_messages, sum.index.size(),
        sum.clean ? "" : "; not closed cleanly, index rebuilt", o.speed, o.loop ? ", looping" : "", so.net.host,
        (*rs)->port());
  std::signal(SIGINT, OnReplaySignal);
  std::signal(SIGTERM, OnReplaySignal);
  const int64_t start = clock.NowUs();
  int64_t next_progress = start + 5000000;
  bool said_end = false;
  while (!g_replay_stop) {
    const int64_t now = clock.NowUs();
    if (o.max_wall_s > 0 && now - start >= static_cast<int64_t>(o.max_wall_s * 1e6)) break;
    clock.SleepUntilUs(now + 50000);
    const ReplayState st = (*rs)->source().state();
    if (st.ended && !said_end && !o.quiet) {
      spdlog::info(
          "holoport-server: replay reached the end ({}); still serving: viewers can seek back. "
          "Ctrl-C stops.",
          FormatSeconds(st.duration_us));
    }
    said_end = st.ended;
    if (!o.quiet && clock.NowUs() >= next_progress) {
      uint64_t sent = 0, dropped = 0;
      size_t viewers = 0;
      for (const auto& s : (*rs)->server().Sessions()) {
        if (s.role == protocol::Role::kPublisher) continue;
        ++viewers;
        sent += s.video_frames_sent;
        dropped += s.video_frames_dropped;
      }
      spdlog::info("  at {} of {}{}, {:.2f}x: {} viewers, {} frames sent, {} dropped", FormatSeconds(st.position_us),
                   FormatSeconds(st.duration_us), st.paused ? " (paused)" : "", st.speed, viewers, sent, dropped);
      next_progress = clock.NowUs() + 5000000;
    }
  }
  const ReplayServerStats rst = (*rs)->stats();
  const Status err = (*rs)->status();
  (*rs)->Stop();
  CloseStats(stats);
  if (!o.quiet) {
    std::lock_guard<std::mutex> l(late_mu);
    spdlog::info(
        "holoport-server: replay served {} messages; controls applied {}, rejected {}; mesh frame "
        "fan-out vs schedule p50 {:.2f} ms, p99 {:.2f} ms",
        rst.emitted, rst.controls_applied, rst.controls_rejected, Quantile(lateness_ms, 0.5),
        Quantile(lateness_ms, 0.99));
  }
  if (!err.ok()) return Fail(err);
  return 0;
}

}  // namespace

int RunReplayCommand(const ReplayCommandOptions& o) {
  auto reader = RecordingReader::Open(o.path);
  if (!reader.ok()) return Fail(reader.status());
  std::shared_ptr<const RecordingReader> shared(std::move(*reader));
  if (o.network()) return RunNetworkReplay(o, shared);
  const RecordingSummary& sum = shared->summary();
  RealClock& clock = RealClock::Instance();
  ReplayOptions ro;
  ro.speed = o.speed;
  ro.loop = o.loop;
  ro.start_us = static_cast<int64_t>(o.start_s * 1e6);
  auto source = ReplaySource::Create(shared, &clock, ro);
  if (!source.ok()) return Fail(source.status());
  if (!o.export_dir.empty()) {
    Status s = MakeDirs(o.export_dir);
    if (!s.ok()) return Fail(s);
  }
  auto stats_file = OpenStats(o.stats_path);
  if (!stats_file.ok()) return Fail(stats_file.status());
  FILE* const stats = *stats_file;
  if (!o.quiet)
    spdlog::info("holoport-server: replaying {} ({}, {} messages, {} key frames{}) at {:.2f}x{}", o.path,
                 FormatSeconds(sum.duration_us), sum.num_messages, sum.index.size(),
                 sum.clean ? "" : "; not closed cleanly, index rebuilt", o.speed, o.loop ? ", looping" : "");
  std::signal(SIGINT, OnReplaySignal);
  std::signal(SIGTERM, OnReplaySignal);

  const int64_t start = clock.NowUs();
  uint64_t messages = 0, meshes = 0, bytes = 0;
  std::vector<double> lateness_ms;
  int64_t due = 0;
  Status sink_error;
  Mesh mesh;
  auto sink = [&](std::shared_ptr<const std::vector<uint8_t>> frame, protocol::Header h) {
    const int64_t now = clock.NowUs();
    const double late = static_cast<double>(now - due) * 1e-3;
    ++messages;
    bytes += frame->size();
    if (h.type == protocol::MessageType::kMeshFrame) {
      ++meshes;
      lateness_ms.push_back(late);
    }
    int64_t frame_index = -1;
    if (h.type == protocol::MessageType::kMeshFrame && (!o.export_dir.empty() || stats != nullptr)) {
      auto payload = protocol::DecodePayload(h, std::span<const uint8_t>(*frame).subspan(protocol::kHeaderSize));
      if (!payload.ok()) {
        if (sink_error.ok()) sink_error = payload.status();
        return;
      }
      const auto& mf = std::get<protocol::MeshFrame>(*payload);
      frame_index = mf.frame_index;
      if (!o.export_dir.empty()) {
        Status s = protocol::DecodeGeometry(mf.data, &mesh);
        if (s.ok()) {
          char path[4096];
          std::snprintf(path, sizeof(path), "%s/mesh_%06lld.ply", o.export_dir.c_str(),
                        static_cast<long long>(mf.frame_index));
          s = WritePly(path, mesh);
        }
        if (!s.ok() && sink_error.ok()) sink_error = s;
      }
    }
    if (stats != nullptr) {
      nlohmann::ordered_json j;
      j["wall_ms"] = static_cast<double>(now - start) * 1e-3;
      j["type"] = protocol::MessageTypeName(h.type);
      j["stream"] = h.stream_id;
      j["sequence"] = h.sequence;
      j["capture_time_us"] = h.capture_time_us;
      j["bytes"] = frame->size();
      j["frame"] = frame_index;
      j["late_ms"] = late;
      std::fprintf(stats, "%s\n", j.dump().c_str());
    }
  };

  int64_t next_progress = start + 2000000;
  int code = 0;
  while (!g_replay_stop && sink_error.ok()) {
    due = (*source)->NextDueUs();
    if (due == INT64_MAX && (*source)->state().ended) break;
    const int64_t now = clock.NowUs();
    if (o.max_wall_s > 0 && now - start >= static_cast<int64_t>(o.max_wall_s * 1e6)) break;
    if (due > now) {
      clock.SleepUntilUs(std::min(due, now + 20000));
      continue;
    }
    auto n = (*source)->Pump(sink);
    if (!n.ok()) {
      spdlog::error("holoport-server: replay stopped: {}", n.status().message());
      code = 1;
      break;
    }
    if (!o.quiet && clock.NowUs() >= next_progress) {
      const ReplayState st = (*source)->state();
      spdlog::info("  at {} of {}: {} messages, {} mesh frames", FormatSeconds(st.position_us),
                   FormatSeconds(st.duration_us), messages, meshes);
      next_progress = clock.NowUs() + 2000000;
    }
  }
  CloseStats(stats);
  if (!sink_error.ok()) return Fail(sink_error);
  const double wall = static_cast<double>(clock.NowUs() - start) * 1e-6;
  if (!o.quiet)
    spdlog::info(
        "holoport-server: replayed {} messages ({} mesh frames, {:.2f} MB) in {:.2f} s wall; "
        "mesh frame pacing error p50 {:.2f} ms, p99 {:.2f} ms, max {:.2f} ms{}{}",
        messages, meshes, static_cast<double>(bytes) / 1e6, wall, Quantile(lateness_ms, 0.5),
        Quantile(lateness_ms, 0.99),
        lateness_ms.empty() ? 0.0 : *std::max_element(lateness_ms.begin(), lateness_ms.end()),
        o.export_dir.empty() ? "" : "; meshes in ", o.export_dir);
  return code;
}

}  // namespace holo::record
