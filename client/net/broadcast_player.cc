#include "client/net/broadcast_player.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>

#include <nlohmann/json.hpp>

#include "net/wire_message.h"
#include "protocol/live_format.h"

namespace holo::net {
namespace {

int64_t SteadyMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

bool UrlChar(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) || std::strchr("-._~/?&=%+", c) != nullptr;
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

}  // namespace

// ---------------------------------------------------------------- parsing

StatusOr<BroadcastUrl> ParseBroadcastUrl(const std::string& url) {
  const std::string scheme = "http://";
  if (url.rfind("https://", 0) == 0) return InvalidArgument("broadcast URL: https is not supported, use http://");
  if (url.rfind(scheme, 0) != 0) return InvalidArgument("broadcast URL must start with http://, got '" + url + "'");
  if (url.size() > 4096) return InvalidArgument("broadcast URL over 4096 characters");
  const size_t slash = url.find('/', scheme.size());
  if (slash == std::string::npos) return InvalidArgument("broadcast URL has no path (http://EDGE/NAME/live.json)");
  BroadcastUrl out;
  std::string hostport = url.substr(scheme.size(), slash - scheme.size());
  const size_t colon = hostport.rfind(':');
  if (colon != std::string::npos) {
    const std::string p = hostport.substr(colon + 1);
    if (p.empty() || p.size() > 5 || !std::all_of(p.begin(), p.end(), ::isdigit))
      return InvalidArgument("broadcast URL: bad port '" + p + "'");
    const int port = std::stoi(p);
    if (port < 1 || port > 65535) return InvalidArgument("broadcast URL: port out of range: " + p);
    out.port = static_cast<uint16_t>(port);
    hostport = hostport.substr(0, colon);
  }
  if (hostport.empty()) return InvalidArgument("broadcast URL: empty host");
  for (char c : hostport)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-')
      return InvalidArgument("broadcast URL: bad character in host '" + hostport + "'");
  out.host = hostport;
  std::string rest = url.substr(slash);
  for (char c : rest)
    if (!UrlChar(c)) return InvalidArgument(std::string("broadcast URL: character '") + c + "' not allowed");
  const size_t q = rest.find('?');
  if (q != std::string::npos) {
    out.query = rest.substr(q);
    rest = rest.substr(0, q);
  }
  if (rest.size() >= 9 && rest.compare(rest.size() - 9, 9, "live.json") == 0) rest.resize(rest.size() - 9);
  if (rest.empty() || rest.back() != '/') rest += '/';
  if (rest.size() < 3) return InvalidArgument("broadcast URL: the path names no broadcast (http://EDGE/NAME/)");
  if (rest.find("..") != std::string::npos) return InvalidArgument("broadcast URL: '..' in the path");
  out.dir = rest;
  return out;
}

StatusOr<HttpResponseHead> ParseHttpResponseHead(std::span<const uint8_t> bytes, bool* complete) {
  *complete = false;
  constexpr size_t kMaxHead = 16384;
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), std::min(bytes.size(), kMaxHead + 4));
  const size_t end = text.find("\r\n\r\n");
  if (end == std::string_view::npos) {
    if (bytes.size() > kMaxHead) return DataLoss("http: response head over 16 KiB");
    return HttpResponseHead{};
  }
  if (end + 4 > kMaxHead) return DataLoss("http: response head over 16 KiB");
  HttpResponseHead h;
  h.head_bytes = end + 4;
  const std::string_view head = text.substr(0, end);
  size_t line_end = head.find("\r\n");
  const std::string_view status = head.substr(0, line_end);
  if (status.size() < 12 || (status.substr(0, 9) != "HTTP/1.1 " && status.substr(0, 9) != "HTTP/1.0 ") ||
      !std::isdigit(static_cast<unsigned char>(status[9])) || !std::isdigit(static_cast<unsigned char>(status[10])) ||
      !std::isdigit(static_cast<unsigned char>(status[11])) || (status.size() > 12 && status[12] != ' '))
    return DataLoss("http: bad status line '" + std::string(status.substr(0, 64)) + "'");
  h.status = (status[9] - '0') * 100 + (status[10] - '0') * 10 + (status[11] - '0');
  if (h.status < 100) return DataLoss("http: bad status " + std::to_string(h.status));
  h.keep_alive = status.substr(0, 9) == "HTTP/1.1 ";
  bool have_length = false;
  while (line_end != std::string_view::npos) {
    const size_t start = line_end + 2;
    line_end = head.find("\r\n", start);
    const std::string_view line = head.substr(start, line_end == std::string_view::npos ? line_end : line_end - start);
    const size_t colon = line.find(':');
    if (colon == std::string_view::npos || colon == 0) return DataLoss("http: malformed header line");
    const std::string name = Lower(std::string(line.substr(0, colon)));
    std::string_view value = line.substr(colon + 1);
    while (!value.empty() && (value.front() == ' ' || value.front() == '\t')) value.remove_prefix(1);
    while (!value.empty() && (value.back() == ' ' || value.back() == '\t')) value.remove_suffix(1);
    if (name == "content-length") {
      if (have_length) return DataLoss("http: two Content-Length headers");
      if (value.empty() || value.size() > 15 || !std::all_of(value.begin(), value.end(), ::isdigit))
        return DataLoss("http: bad Content-Length '" + std::string(value.substr(0, 32)) + "'");
      h.content_length = std::stoull(std::string(value));
      have_length = true;
    } else if (name == "transfer-encoding") {
      return DataLoss("http: Transfer-Encoding is not supported (an edge sends Content-Length)");
    } else if (name == "connection") {
      const std::string v = Lower(std::string(value));
      if (v == "close") h.keep_alive = false;
      if (v == "keep-alive") h.keep_alive = true;
    }
  }
  const bool no_body = h.status == 204 || h.status == 304 || h.status < 200;
  if (!have_length && !no_body) return DataLoss("http: response without Content-Length");
  *complete = true;
  return h;
}

StatusOr<LiveManifest> ParseLiveManifest(std::string_view text) {
  if (text.size() > (16u << 20)) return DataLoss("live.json: over 16 MiB");
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) return DataLoss("live.json: not a JSON object");
  auto bad = [](const std::string& what) { return DataLoss("live.json: " + what); };
  auto get_int = [&](const nlohmann::json& o, const char* key, int64_t lo, int64_t hi, int64_t* out) -> Status {
    if (!o.contains(key) || !o[key].is_number_integer()) return bad(std::string(key) + " missing or not an integer");
    const int64_t v = o[key].get<int64_t>();
    if (v < lo || v > hi) return bad(std::string(key) + " = " + std::to_string(v) + " out of range");
    *out = v;
    return OkStatus();
  };
  if (!j.contains("format") || j["format"] != "holoport-live") return bad("format is not \"holoport-live\"");
  int64_t version = 0;
  HOLO_RETURN_IF_ERROR(get_int(j, "version", 0, INT64_MAX, &version));
  if (version != 1) return bad("version " + std::to_string(version) + " (this player reads 1)");
  constexpr int64_t kMaxTime = int64_t{1} << 60;
  LiveManifest m;
  HOLO_RETURN_IF_ERROR(get_int(j, "availability_start_unix_us", 1, kMaxTime, &m.availability_start_unix_us));
  HOLO_RETURN_IF_ERROR(get_int(j, "published_unix_us", 1, kMaxTime, &m.published_unix_us));
  HOLO_RETURN_IF_ERROR(get_int(j, "target_part_us", 1000, 60000000, &m.target_part_us));
  int64_t interval = 0;
  HOLO_RETURN_IF_ERROR(get_int(j, "update_interval_ms", 1, 60000, &interval));
  m.update_interval_ms = static_cast<int>(interval);
  if (j.contains("cache_bucket_ms")) {
    int64_t bucket = 0;
    HOLO_RETURN_IF_ERROR(get_int(j, "cache_bucket_ms", 0, 60000, &bucket));
    m.cache_bucket_ms = static_cast<int>(bucket);
  }
  if (!j.contains("ended") || !j["ended"].is_boolean()) return bad("ended missing or not a boolean");
  m.ended = j["ended"].get<bool>();
  if (!j.contains("segments") || !j["segments"].is_array()) return bad("segments missing or not an array");
  if (j["segments"].size() > 10000) return bad("over 10,000 segments");
  size_t total_parts = 0;
  for (const auto& s : j["segments"]) {
    if (!s.is_object()) return bad("a segment is not an object");
    LiveSegmentRef seg;
    int64_t number = 0;
    HOLO_RETURN_IF_ERROR(get_int(s, "number", 0, int64_t{1} << 40, &number));
    seg.number = static_cast<uint64_t>(number);
    if (!m.segments.empty() && seg.number <= m.segments.back().number)
      return bad("segment numbers do not increase at " + std::to_string(seg.number));
    if (!s.contains("complete") || !s["complete"].is_boolean()) return bad("segment complete missing");
    if (!s.contains("discontinuity") || !s["discontinuity"].is_boolean()) return bad("segment discontinuity missing");
    seg.complete = s["complete"].get<bool>();
    seg.discontinuity = s["discontinuity"].get<bool>();
    if (!s.contains("parts") || !s["parts"].is_array()) return bad("segment parts missing");
    total_parts += s["parts"].size();
    if (total_parts > 100000) return bad("over 100,000 parts");
    char expect[48];
    for (const auto& p : s["parts"]) {
      if (!p.is_object() || !p.contains("name") || !p["name"].is_string()) return bad("a part without a name");
      std::snprintf(expect, sizeof(expect), "seg_%05llu.p%zu", static_cast<unsigned long long>(seg.number),
                    seg.parts.size());
      if (p["name"].get<std::string>() != expect)
        return bad("part name '" + p["name"].get<std::string>().substr(0, 64) + "', expected " + expect);
      LivePartRef ref;
      ref.segment = seg.number;
      ref.part = seg.parts.size();
      ref.name = expect;
      HOLO_RETURN_IF_ERROR(get_int(p, "available_unix_us", 0, kMaxTime, &ref.available_unix_us));
      seg.parts.push_back(std::move(ref));
    }
    m.segments.push_back(std::move(seg));
  }
  return m;
}

std::string ManifestTarget(const BroadcastUrl& url, int cache_bucket_ms, int64_t unix_ms) {
  std::string target = url.dir + "live.json" + url.query;
  if (cache_bucket_ms <= 0 || unix_ms < 0) return target;
  target += url.query.empty() ? '?' : '&';
  target += "b=" + std::to_string(unix_ms / cache_bucket_ms);
  return target;
}

// ---------------------------------------------------------------- follower

const LiveSegmentRef* LiveFollower::Find(uint64_t number) const {
  for (const auto& s : manifest_.segments)
    if (s.number == number) return &s;
  return nullptr;
}

void LiveFollower::JoinAt(const LiveSegmentRef& s) {
  segment_ = s.number;
  part_ = 0;
  joined_ = true;
  stats_.joins += 1;
}

void LiveFollower::OnManifest(const LiveManifest& manifest) {
  if (have_ && manifest.published_unix_us < manifest_.published_unix_us) return;  // an older copy (another edge)
  manifest_ = manifest;
  have_ = true;
}

std::optional<LivePartRef> LiveFollower::Next() {
  if (!have_) return std::nullopt;
  const auto& segs = manifest_.segments;
  // The newest segment that can be joined (its part 0 exists).
  const LiveSegmentRef* newest = nullptr;
  for (auto it = segs.rbegin(); it != segs.rend(); ++it)
    if (!it->parts.empty()) {
      newest = &*it;
      break;
    }
  if (!newest) return std::nullopt;
  if (!joined_) JoinAt(*newest);
  // Too far behind (or our segment left the window): catch up.
  int listed_after = 0;
  for (const auto& s : segs)
    if (s.number > segment_ && !s.parts.empty()) ++listed_after;
  if (listed_after >= options_.catch_up_segments || (segment_ < segs.front().number)) {
    stats_.catch_ups += 1;
    JoinAt(*newest);
  }
  for (int guard = 0; guard < 3; ++guard) {
    const LiveSegmentRef* s = Find(segment_);
    if (s && part_ < s->parts.size()) {
      return s->parts[part_];
    }
    if (s && !s->complete) return std::nullopt;  // wait for its next part
    // Segment finished (or missing): the next listed segment, from part 0.
    const LiveSegmentRef* next = nullptr;
    for (const auto& c : segs)
      if (c.number > segment_ && !c.parts.empty()) {
        next = &c;
        break;
      }
    if (!next) return std::nullopt;
    segment_ = next->number;
    part_ = 0;
  }
  return std::nullopt;
}

void LiveFollower::Done(const LivePartRef& part) {
  if (part.segment != segment_ || part.part != part_) return;
  if (part.part == 0) {
    const LiveSegmentRef* s = Find(part.segment);
    if (s && s->discontinuity) stats_.discontinuities += 1;
  }
  part_ += 1;
}

void LiveFollower::Skip(const LivePartRef& part) {
  if (part.segment != segment_ || part.part != part_) return;
  stats_.skips += 1;
  // A segment's later parts need its earlier ones only for continuity, but
  // the next join point is the next segment's part 0.
  segment_ += 1;
  part_ = 0;
}

// ---------------------------------------------------------------- HTTP

HttpGetter::HttpGetter(std::string host, uint16_t port, double timeout_s)
    : host_(std::move(host)), port_(port), timeout_s_(timeout_s) {}

HttpGetter::~HttpGetter() { Close(); }

void HttpGetter::Close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

Status HttpGetter::Connect() {
  Close();
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  const int rc = ::getaddrinfo(host_.c_str(), std::to_string(port_).c_str(), &hints, &res);
  if (rc != 0) return Unavailable("http: resolve " + host_ + ": " + gai_strerror(rc));
  Status last = Unavailable("http: no address for " + host_);
  for (addrinfo* a = res; a; a = a->ai_next) {
    const int fd = ::socket(a->ai_family, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (fd < 0) continue;
    int r = ::connect(fd, a->ai_addr, a->ai_addrlen);
    if (r != 0 && errno == EINPROGRESS) {
      pollfd p{fd, POLLOUT, 0};
      r = ::poll(&p, 1, static_cast<int>(timeout_s_ * 1000)) == 1 ? 0 : -1;
      int err = 0;
      socklen_t len = sizeof(err);
      if (r == 0 && (::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len) != 0 || err != 0)) {
        errno = err;
        r = -1;
      } else if (r != 0) {
        errno = ETIMEDOUT;
      }
    }
    if (r == 0) {
      const int one = 1;
      ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
      fd_ = fd;
      ::freeaddrinfo(res);
      return OkStatus();
    }
    last = Unavailable("http: connect to " + host_ + ":" + std::to_string(port_) + ": " + std::strerror(errno));
    ::close(fd);
  }
  ::freeaddrinfo(res);
  return last;
}

StatusOr<HttpGetter::Response> HttpGetter::Get(const std::string& target, uint64_t max_body) {
  const int64_t deadline = SteadyMs() + static_cast<int64_t>(timeout_s_ * 1000);
  auto wait = [&](short events) -> Status {
    const int64_t left = deadline - SteadyMs();
    if (left <= 0) return Unavailable("http: GET " + target + " timed out");
    pollfd p{fd_, events, 0};
    const int r = ::poll(&p, 1, static_cast<int>(left));
    if (r == 0) return Unavailable("http: GET " + target + " timed out");
    if (r < 0 && errno != EINTR) return Unavailable(std::string("http: poll: ") + std::strerror(errno));
    return OkStatus();
  };
  // One retry on a fresh connection: a kept-alive connection may have been
  // closed by the server in between.
  for (int attempt = 0; attempt < 2; ++attempt) {
    const bool reused = fd_ >= 0;
    if (!reused) HOLO_RETURN_IF_ERROR(Connect());
    const std::string req = "GET " + target + " HTTP/1.1\r\nHost: " + host_ + "\r\nUser-Agent: holoport-client\r\n\r\n";
    size_t sent = 0;
    Status err;
    while (sent < req.size() && err.ok()) {
      const ssize_t n = ::send(fd_, req.data() + sent, req.size() - sent, MSG_NOSIGNAL);
      if (n > 0) {
        sent += static_cast<size_t>(n);
      } else if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
        err = wait(POLLOUT);
      } else {
        err = Unavailable(std::string("http: send: ") + std::strerror(errno));
      }
    }
    std::vector<uint8_t> buf;
    HttpResponseHead head;
    bool complete = false;
    uint8_t chunk[65536];
    while (err.ok()) {
      const ssize_t n = ::recv(fd_, chunk, sizeof(chunk), 0);
      if (n > 0) {
        buf.insert(buf.end(), chunk, chunk + n);
        if (!complete) {
          auto h = ParseHttpResponseHead(buf, &complete);
          if (!h.ok()) {
            Close();
            return h.status();
          }
          if (complete) {
            head = *h;
            if (head.content_length > max_body) {
              Close();
              return DataLoss("http: " + target + " is " + std::to_string(head.content_length) +
                              " bytes, over the limit of " + std::to_string(max_body));
            }
          }
        }
        if (complete && buf.size() >= head.head_bytes + head.content_length) break;
      } else if (n == 0) {
        err = Unavailable("http: the server closed the connection");
      } else if (errno == EAGAIN || errno == EINTR) {
        err = wait(POLLIN);
      } else {
        err = Unavailable(std::string("http: recv: ") + std::strerror(errno));
      }
    }
    if (!err.ok()) {
      Close();
      // A reused connection that died before any byte: try once on a new one.
      if (reused && buf.empty() && attempt == 0 && err.message().find("timed out") == std::string::npos) continue;
      return err;
    }
    if (buf.size() != head.head_bytes + head.content_length) {
      Close();
      return DataLoss("http: more bytes than Content-Length");
    }
    Response r;
    r.status = head.status;
    r.body.assign(buf.begin() + static_cast<std::ptrdiff_t>(head.head_bytes), buf.end());
    if (!head.keep_alive) Close();
    return r;
  }
  return Unavailable("http: GET " + target + " failed");
}

// ---------------------------------------------------------------- player

Status BroadcastPlayerOptions::Check() const {
  HOLO_RETURN_IF_ERROR(ParseBroadcastUrl(url).status());
  if (!(http_timeout_s > 0 && http_timeout_s <= 600)) return InvalidArgument("player: http_timeout_s 0..600");
  if (!(retry_s > 0 && retry_s <= 60)) return InvalidArgument("player: retry_s 0..60");
  if (follower.catch_up_segments < 1) return InvalidArgument("player: catch_up_segments must be ≥ 1");
  return OkStatus();
}

BroadcastPlayer::BroadcastPlayer(BroadcastPlayerOptions options, BroadcastUrl url, Sink sink)
    : options_(std::move(options)), url_(std::move(url)), sink_(std::move(sink)) {}

StatusOr<std::unique_ptr<BroadcastPlayer>> BroadcastPlayer::Start(BroadcastPlayerOptions options, Sink sink) {
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_ASSIGN_OR_RETURN(BroadcastUrl url, ParseBroadcastUrl(options.url));
  std::unique_ptr<BroadcastPlayer> p(new BroadcastPlayer(std::move(options), std::move(url), std::move(sink)));
  p->thread_ = std::thread([raw = p.get()] { raw->Run(); });
  return p;
}

BroadcastPlayer::~BroadcastPlayer() { Stop(); }

void BroadcastPlayer::Stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

BroadcastPlayerStats BroadcastPlayer::stats() const {
  std::lock_guard<std::mutex> l(mu_);
  return stats_;
}

void BroadcastPlayer::Run() {
  HttpGetter http(url_.host, url_.port, options_.http_timeout_s);
  LiveFollower follower(options_.follower);
  int64_t next_manifest_ms = 0;
  int64_t interval_ms = 250;
  int bucket_ms = 0;  // the first poll carries no bucket: the manifest names it
  auto sleep_ms = [&](int64_t ms) {
    const int64_t until = SteadyMs() + ms;
    while (!stop_ && SteadyMs() < until) std::this_thread::sleep_for(std::chrono::milliseconds(std::min<int64_t>(10, ms)));
  };
  auto error = [&](const std::string& why, uint64_t BroadcastPlayerStats::*counter) {
    std::lock_guard<std::mutex> l(mu_);
    stats_.*counter += 1;
    stats_.last_error = why;
  };
  while (!stop_) {
    if (SteadyMs() >= next_manifest_ms) {
      auto r = http.Get(ManifestTarget(url_, bucket_ms, WallUs() / 1000), 16u << 20);
      next_manifest_ms = SteadyMs() + interval_ms;
      if (!r.ok()) {
        error(r.status().message(), &BroadcastPlayerStats::http_errors);
        sleep_ms(static_cast<int64_t>(options_.retry_s * 1000));
        continue;
      }
      if (r->status == 403) {
        error("live.json: 403 (signature missing, wrong or expired)", &BroadcastPlayerStats::refused);
        sleep_ms(1000);
        continue;
      }
      if (r->status != 200) {
        error("live.json: HTTP " + std::to_string(r->status), &BroadcastPlayerStats::http_errors);
        sleep_ms(static_cast<int64_t>(options_.retry_s * 1000));
        continue;
      }
      auto m = ParseLiveManifest(
          std::string_view(reinterpret_cast<const char*>(r->body.data()), r->body.size()));
      if (!m.ok()) {
        error(m.status().message(), &BroadcastPlayerStats::http_errors);
        continue;
      }
      interval_ms = std::clamp<int64_t>(m->update_interval_ms, 50, 2000);
      bucket_ms = m->cache_bucket_ms;
      follower.OnManifest(*m);
      std::lock_guard<std::mutex> l(mu_);
      stats_.manifests += 1;
      availability_start_ = m->availability_start_unix_us;
    }
    auto next = follower.Next();
    {
      std::lock_guard<std::mutex> l(mu_);
      stats_.follower = follower.stats();
    }
    if (!next) {
      if (follower.ended()) ended_ = true;
      sleep_ms(std::max<int64_t>(0, std::min<int64_t>(20, next_manifest_ms - SteadyMs())));
      continue;
    }
    auto r = http.Get(url_.dir + next->name + url_.query);
    if (!r.ok()) {
      error(next->name + ": " + r.status().message(), &BroadcastPlayerStats::http_errors);
      sleep_ms(static_cast<int64_t>(options_.retry_s * 1000));
      continue;  // the same part again (a slow or restarting edge); catch-up handles long stalls
    }
    if (r->status == 404 || r->status == 410) {
      error(next->name + ": HTTP " + std::to_string(r->status), &BroadcastPlayerStats::not_found);
      follower.Skip(*next);
      continue;
    }
    if (r->status == 403) {
      error(next->name + ": 403 (signature missing, wrong or expired)", &BroadcastPlayerStats::refused);
      sleep_ms(1000);
      continue;
    }
    if (r->status != 200) {
      error(next->name + ": HTTP " + std::to_string(r->status), &BroadcastPlayerStats::http_errors);
      sleep_ms(static_cast<int64_t>(options_.retry_s * 1000));
      continue;
    }
    auto records = record::ParseLiveRecords(r->body);
    if (!records.ok() || records->empty() ||
        (next->part == 0 && records->front().header.type != protocol::MessageType::kRig)) {
      error(next->name + ": " + (records.ok() ? std::string("part 0 does not start with the Rig")
                                              : records.status().message()),
            &BroadcastPlayerStats::damaged_parts);
      follower.Skip(*next);
      continue;
    }
    const int64_t now = WallUs();
    for (const auto& rec : *records)
      sink_(rec.header, rec.frame.subspan(protocol::kHeaderSize), now);
    follower.Done(*next);
    std::lock_guard<std::mutex> l(mu_);
    stats_.parts += 1;
    stats_.messages += records->size();
    stats_.bytes += r->body.size();
    stats_.follower = follower.stats();
    if (availability_start_ > 0)
      stats_.latency_ms.push_back(static_cast<double>(now - (availability_start_ + records->back().time_us)) * 1e-3);
  }
}

}  // namespace holo::net
