// Playing a live broadcast from an HTTP edge (docs/broadcast.md §4):
// `holoport-client --http http://EDGE/NAME/live.json[?md5=…&expires=…]`.
//
// * ParseBroadcastUrl / ParseHttpResponseHead / ParseLiveManifest: parsers of
//   untrusted input (a URL from the user, an HTTP response head and a JSON
//   manifest from the network): every field checked, errors name it.
// * LiveFollower: which part to fetch next — joins at the newest segment's
//   part 0 (the Rig + a key frame), follows parts in order, skips to the next
//   segment on a 404 or a damaged part, jumps to the newest segment when it
//   falls `catch_up_segments` behind. Pure logic: tests drive it directly.
// * HttpGetter: one keep-alive HTTP/1.1 connection with timeouts (plain
//   sockets; http:// only). Our own rather than libcurl: GET with keep-alive
//   to our edges is all it needs, and its response-head parser is checked
//   and fuzzed like our other parsers of network bytes.
// * BroadcastPlayer: a thread that polls the manifest, fetches parts through
//   an HttpGetter, parses them (protocol/live_format.h) and hands every
//   message to a sink (SiteClient::Feed: the same decode and display path as
//   a site connection); it reports latency (now − packager receive time of the
//   newest message).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "common/status.h"
#include "protocol/messages.h"

namespace holo::net {

struct BroadcastUrl {
  std::string host;
  uint16_t port = 80;
  std::string dir;    // path of the broadcast, with both slashes ("/show/")
  std::string query;  // "?md5=…&expires=…" or empty: appended to every object
};
// Accepts http://HOST[:PORT]/PATH/ or http://HOST[:PORT]/PATH/live.json, with
// an optional query. InvalidArgument naming what is wrong (https, no path,
// bad port, characters outside the URL set).
StatusOr<BroadcastUrl> ParseBroadcastUrl(const std::string& url);

struct HttpResponseHead {
  int status = 0;
  uint64_t content_length = 0;
  size_t head_bytes = 0;  // bytes up to and including the blank line
  bool keep_alive = true;
};
// Parses an HTTP/1.x response head from `bytes`. `*complete` false (and OK)
// while the blank line has not arrived yet. DataLoss for a malformed status
// line or header, a head over 16 KiB, a missing or bad Content-Length, or
// chunked transfer coding (edges send lengths). Safe on untrusted input.
StatusOr<HttpResponseHead> ParseHttpResponseHead(std::span<const uint8_t> bytes, bool* complete);

struct LivePartRef {
  uint64_t segment = 0;
  uint64_t part = 0;
  std::string name;
  int64_t available_unix_us = 0;
};
struct LiveSegmentRef {
  uint64_t number = 0;
  bool complete = false;
  bool discontinuity = false;
  std::vector<LivePartRef> parts;
};
struct LiveManifest {
  int64_t availability_start_unix_us = 0;
  int64_t published_unix_us = 0;
  int64_t target_part_us = 0;
  int update_interval_ms = 0;
  int cache_bucket_ms = 0;  // 0 (or absent): no bucket in manifest requests
  bool ended = false;
  std::vector<LiveSegmentRef> segments;  // numbers strictly increasing
};
// Validates docs/broadcast.md §3 (format, version, types, ranges, part names
// seg_NNNNN.pK consecutive from 0, segment numbers increasing, ≤ 10,000
// segments and ≤ 100,000 parts). DataLoss naming the field. Safe on untrusted
// input.
StatusOr<LiveManifest> ParseLiveManifest(std::string_view text);

// The request target of a manifest poll: the broadcast's live.json with the
// URL's query (a signature), plus `b=floor(unix_ms / cache_bucket_ms)` when
// the manifest names a bucket length (docs/broadcast.md §4): an edge keeps
// one copy per bucket, so viewers polling in the same bucket share it.
std::string ManifestTarget(const BroadcastUrl& url, int cache_bucket_ms, int64_t unix_ms);

struct LiveFollowerOptions {
  // Jump to the newest segment when this many segments (or more) are listed
  // after the one being played: the player is too far behind (a slow edge, a
  // stall) and catches up instead of playing old content.
  int catch_up_segments = 2;
};

struct LiveFollowerStats {
  uint64_t joins = 0;       // (re)starts at a segment's part 0
  uint64_t catch_ups = 0;   // jumps forward because of lag
  uint64_t skips = 0;       // parts given up (404, damaged)
  uint64_t discontinuities = 0;
};

class LiveFollower {
 public:
  explicit LiveFollower(LiveFollowerOptions options = {}) : options_(options) {}
  // The newest manifest (older ones are ignored: `published_unix_us` must not go back).
  void OnManifest(const LiveManifest& manifest);
  // The part to fetch next, or nothing until a newer manifest lists it.
  std::optional<LivePartRef> Next();
  // The part from Next() arrived and was played.
  void Done(const LivePartRef& part);
  // The part from Next() is missing or damaged: continue at the next segment's part 0.
  void Skip(const LivePartRef& part);
  const LiveFollowerStats& stats() const { return stats_; }
  bool ended() const { return have_ && manifest_.ended; }

 private:
  const LiveSegmentRef* Find(uint64_t number) const;
  void JoinAt(const LiveSegmentRef& s);
  LiveFollowerOptions options_;
  LiveManifest manifest_;
  bool have_ = false;
  bool joined_ = false;
  uint64_t segment_ = 0, part_ = 0;  // the position: next part to play
  LiveFollowerStats stats_;
};

// One keep-alive HTTP/1.1 connection (reconnects when the server closed it).
class HttpGetter {
 public:
  HttpGetter(std::string host, uint16_t port, double timeout_s = 5.0);
  ~HttpGetter();
  HttpGetter(const HttpGetter&) = delete;
  HttpGetter& operator=(const HttpGetter&) = delete;
  struct Response {
    int status = 0;
    std::vector<uint8_t> body;
  };
  // GET `target`; Unavailable on connect/IO errors or timeout, DataLoss on a
  // malformed response; a body over `max_body` bytes is refused (DataLoss).
  StatusOr<Response> Get(const std::string& target, uint64_t max_body = 80u << 20);

 private:
  Status Connect();
  void Close();
  std::string host_;
  uint16_t port_;
  double timeout_s_;
  int fd_ = -1;
};

struct BroadcastPlayerOptions {
  std::string url;  // ParseBroadcastUrl
  double http_timeout_s = 5.0;
  LiveFollowerOptions follower;
  // Wait between attempts after a network error, s.
  double retry_s = 0.2;
  Status Check() const;
};

struct BroadcastPlayerStats {
  uint64_t manifests = 0;
  uint64_t parts = 0;
  uint64_t messages = 0;
  uint64_t bytes = 0;
  uint64_t http_errors = 0;     // network errors and 5xx
  uint64_t not_found = 0;       // 404 for a listed part
  uint64_t damaged_parts = 0;
  uint64_t refused = 0;         // 403 (bad or expired signature)
  LiveFollowerStats follower;
  std::vector<double> latency_ms;  // per part: arrival − packager receive time of its last message
  std::string last_error;
};

class BroadcastPlayer {
 public:
  // Every message of every part goes to `sink` (on the player's thread), with
  // `received_us` = the Unix time the part arrived.
  using Sink = std::function<void(const protocol::Header& header, std::span<const uint8_t> payload,
                                  int64_t received_us)>;
  static StatusOr<std::unique_ptr<BroadcastPlayer>> Start(BroadcastPlayerOptions options, Sink sink);
  ~BroadcastPlayer();  // Stop()
  void Stop();
  BroadcastPlayerStats stats() const;
  bool ended() const { return ended_; }

 private:
  BroadcastPlayer(BroadcastPlayerOptions options, BroadcastUrl url, Sink sink);
  void Run();
  BroadcastPlayerOptions options_;
  BroadcastUrl url_;
  Sink sink_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> ended_{false};
  mutable std::mutex mu_;
  BroadcastPlayerStats stats_;
  int64_t availability_start_ = 0;  // under mu_
  std::thread thread_;
};

}  // namespace holo::net
