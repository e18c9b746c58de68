// Serving a recording as a live site (docs/recording.md §4): recorded
// protocol messages go through the session server's fan-out unchanged, and
// viewers' Control messages (pause, resume, seek, speed, key frame) drive the
// replay engine.
//
//  * RecordedPublisher — one recorded message (header + payload, whole) →
//    the fan-out: the Rig becomes the server's rig (sent first to every
//    viewer, also to viewers joining later), MeshFrame (+ its ColorFrame) a
//    video frame, AudioPose and Stats priority messages. The bytes a viewer
//    reassembles are exactly the recorded bytes (messages larger than the
//    server's fragment size are fragmented again on the way).
//  * ReplayServer — a session server + one ReplaySource (one shared
//    timeline: any viewer's control moves it for all viewers) + a pump
//    thread that emits every message when it is due.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "common/clock.h"
#include "common/log.h"
#include "common/status.h"
#include "net/server_config.h"
#include "net/session_server.h"
#include "server/record/recording_reader.h"
#include "server/record/replay.h"

namespace holo::record {

struct RecordedPublisherStats {
  uint64_t rigs = 0;
  uint64_t video_frames = 0;  // VideoFrames published (a MeshFrame with its ColorFrame is one)
  uint64_t meshes = 0;
  uint64_t colors = 0;
  uint64_t priority = 0;      // AudioPose + Stats
  uint64_t ignored = 0;       // session messages (never in a valid recording)
};

class RecordedPublisher {
 public:
  explicit RecordedPublisher(net::Server* server) : server_(server) {}
  // `bytes`: one whole protocol frame (header + payload) as recorded;
  // `header`: its decoded header. A MeshFrame is held until the next call (or
  // Flush) so that a ColorFrame of the same stream and sequence joins it in
  // one video frame (queues drop frames whole).
  Status Publish(const std::vector<uint8_t>& bytes, const protocol::Header& header);
  // Publishes a held MeshFrame.
  void Flush();
  const RecordedPublisherStats& stats() const { return stats_; }

 private:
  net::WireMessagePtr ToWire(const std::vector<uint8_t>& bytes, const protocol::Header& header) const;
  net::Server* server_;
  std::shared_ptr<net::VideoFrame> held_;
  protocol::Header held_header_;
  RecordedPublisherStats stats_;
  bool regions_announced_ = false;  // AnnounceRegions called (on the first Regions message)
};

struct ReplayServerOptions {
  ReplayOptions replay;
  net::ServerConfig net;
  // Log lines of the session server (refusals, …) and of rejected controls.
  std::function<void(const std::string&)> log;
  // Called on the pump thread for every message emitted: its header, the
  // clock time it was due and the clock time it went to the fan-out.
  std::function<void(const protocol::Header&, int64_t due_us, int64_t emitted_us)> on_emit;
};

struct ReplayServerStats {
  uint64_t emitted = 0;
  uint64_t controls_applied = 0;
  uint64_t controls_rejected = 0;  // not replay commands, speed outside 0.25..4, seek outside the recording
  uint64_t join_key_frames = 0;    // key frames re-sent because a viewer joined a paused replay
};

class ReplayServer final : public net::StreamControlSink {
 public:
  // Opens the session server (config `options.net`), announces the
  // recording's geometry codec, sets the recorded Rig and starts the pump
  // thread on `clock` (must outlive the server).
  static StatusOr<std::unique_ptr<ReplayServer>> Start(std::shared_ptr<const RecordingReader> reader, Clock* clock,
                                                      ReplayServerOptions options);
  ~ReplayServer() override;  // Stop()
  void Stop();

  uint16_t port() const { return server_->port(); }
  net::Server& server() { return *server_; }
  ReplaySource& source() { return *source_; }
  ReplayServerStats stats() const;
  // The first error of the replay (a damaged message: DataLoss), else OK.
  Status status() const;

  // StreamControlSink: a viewer's control → ReplaySource::ApplyControl.
  void OnControl(const net::ControlEvent& event) override;

 private:
  ReplayServer() = default;
  void PumpLoop();
  // Through options_.log when set, else the log at `level`.
  void Log(const std::string& line, spdlog::level::level_enum level = spdlog::level::info) const;

  std::shared_ptr<const RecordingReader> reader_;
  Clock* clock_ = nullptr;
  ReplayServerOptions options_;
  std::unique_ptr<ReplaySource> source_;
  std::unique_ptr<net::Server> server_;  // after source_: destroyed first (controls use source_)
  std::unique_ptr<RecordedPublisher> publisher_;
  std::thread pump_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mu_;
  ReplayServerStats stats_;
  Status error_;
};

}  // namespace holo::record
