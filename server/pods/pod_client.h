// The pod's side of the pod link: connects to a site's pod port, sends Hello
// (role pod, token) and its calibration, then streams PodFrames from a
// bounded queue and answers the site's pings with its own clock. When the
// link drops it reconnects with exponential backoff; frames offered while
// disconnected, or while the queue is full (the link is slower than the
// camera), are dropped and counted: a live pod never queues latency.
// A refusal (bad token, calibration that disagrees with the site's rig) is
// final: the client stops and status() says why.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "common/log.h"
#include "common/rig.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::pods {

struct PodClientOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 0;
  std::string token;
  std::string name;            // Hello.client_name ("pod-3")
  PodCalibration calibration;  // sent after Hello
  // Encoded frames waiting for the link (oldest dropped when full).
  size_t queue_frames = 3;
  int connect_timeout_ms = 2000;
  int handshake_timeout_ms = 3000;
  // Reconnect backoff: doubles from initial to max after each failure.
  int backoff_initial_ms = 100;
  int backoff_max_ms = 2000;
  // A send that cannot complete within this closes the link (the site stalled).
  int send_timeout_ms = 2000;
  // The pod's clock (µs), for Pong stamps; must be the clock frames are stamped with.
  std::function<int64_t()> clock;
  std::function<void(const std::string&)> log;  // null: the log (common/log.h)
  Status Check() const;
};

struct PodClientCounters {
  bool connected = false;
  uint64_t connects = 0;        // successful handshakes
  uint64_t connect_failures = 0;
  uint64_t offered = 0;
  uint64_t sent = 0;
  uint64_t dropped_queue_full = 0;
  uint64_t dropped_disconnected = 0;
  uint64_t bytes_sent = 0;
  uint64_t pings_answered = 0;
  std::string last_error;
};

class PodClient {
 public:
  explicit PodClient(PodClientOptions options);
  ~PodClient();  // Stop()
  PodClient(const PodClient&) = delete;
  PodClient& operator=(const PodClient&) = delete;

  // Starts the link thread. InvalidArgument for bad options.
  Status Start();
  // Queues one frame (never blocks). Returns false if it was dropped.
  bool Offer(protocol::PodFrame frame);
  PodClientCounters counters() const;
  // OK while running; the refusal (or a fatal error) once the client gave up.
  Status status() const;
  bool connected() const { return connected_; }
  void Stop();

 private:
  void Run();
  Status Session(bool* welcomed);
  // Through options_.log when set, else the log at `level`.
  void Log(const std::string& s, spdlog::level::level_enum level = spdlog::level::info);
  PodClientOptions options_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> connected_{false};
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::vector<uint8_t>> queue_;  // encoded messages
  PodClientCounters c_;
  Status status_;
};

}  // namespace holo::pods
