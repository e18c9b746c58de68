// holoport-bench broadcast: a live broadcast through nginx caches on this
// machine (docs/broadcast.md).
//
//   holoport-bench broadcast [--viewers N] [--edges E] [--content fused|truth] [--seconds S] [--json]
//
// A site (holoport-server, its own process: the real pipeline on pre-rendered
// pod frames at 30 fps, or the studio's meshes with --content truth), the
// packager (holoport-record --live-dir, a viewer of the site), an nginx
// origin and E nginx edges (scripts/broadcast.sh; loopback ports), and N light
// HTTP viewers in this process (Asio, many connections per thread) that do
// what a player does on time — poll live.json, join at the newest segment,
// fetch every part in order over one keep-alive connection — without
// decoding or rendering. Viewers are spread over the edges round-robin.
//
// The site codes the stream in G3 + V1 unless --codecs says otherwise (G1 +
// V1 for truth content): the figures carry a "codec" qualifier.
//
// Figures (JSON lines, "content" qualifier): viewers_held (viewers that got
// every part of the window, each within 2 s of the capture of its newest
// frame), latency_p50_ms / latency_p99_ms (capture of a part's newest frame,
// the site's wall clock, on this machine, to the part received whole at a
// viewer; also for the part's oldest frame; and latency_tier_*: from the
// packager's receipt of the part's last message, the broadcast tier alone), mbps per viewer and in total,
// origin_requests_per_object_per_edge (parts; target ≤ 1),
// origin_requests_per_segment (everything the origin served, per segment
// published), edge_hit_ratio, edge_cpu_pct per edge (CPU of its nginx
// processes over the window, % of one core), packager and site CPU, and the
// loopback ceiling the bytes are compared with.
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <netinet/in.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <span>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <asio.hpp>
#include <CLI/CLI.hpp>

#include "bench.h"
#include "bench_process.h"
#include "client/net/broadcast_player.h"
#include "common/clock.h"
#include "common/log.h"
#include "common/quantile.h"
#include "common/status.h"

namespace holo::bench {
namespace {

constexpr char kPublisherToken[] = "broadcast-bench-publisher";
constexpr char kViewerToken[] = "broadcast-bench-viewer";

struct BroadcastOptions {
  int viewers = 200;
  int edges = 2;
  std::string content = "fused";
  double seconds = 15;
  double warmup_s = 4;
  int prerender = 60;
  double segment_s = 2;
  int part_ms = 250;
  int window = 3;
  int threads = 2;
  double manifest_poll_ms = 250;  // the manifest's update_interval_ms, as a player polls
  int cache_bucket_ms = 100;      // the packager's --cache-bucket-ms (0: every poll reaches the origin)
  double in_time_ms = 2000;
  std::string keep_dir;
  // The site's codecs: "g3+v1" (fused) / "g1+v1" (truth, whose studio mesh
  // G3 cannot carry) by default, "g1+c1" (the call's default), or "site"
  // (whatever holoport-server and --site-arg choose). A broadcast multiplies
  // every byte by its audience while the site encodes once: at 1,000
  // viewers G3 + V1 (2.0–2.9 Mbit/s each) held all of them, G1 + C1 (7–9
  // Mbit/s) 0–608 (docs/broadcast.md §9).
  std::string codecs = "auto";
  std::vector<std::string> site_args;  // extra holoport-server arguments
};

// holoport-server arguments and the figure's label for a --codecs choice.
std::pair<std::vector<std::string>, std::string> SiteCodecs(const std::string& codecs, const std::string& content) {
  const std::string c = codecs != "auto" ? codecs : content == "truth" ? "g1+v1" : "g3+v1";
  if (c == "site") return {{}, "site"};
  const std::string g = c.substr(0, 2), col = c.substr(3, 2);
  std::string label = c;
  for (char& ch : label) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
  return {{"--geometry-codec", g, "--color-codec", col}, label};
}

int64_t SteadyUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}
int64_t WallUs() { return WallClock::Instance().NowUs(); }

// 0 for a process that is gone (its CPU no longer counts).
double CpuMsOf(pid_t pid) { return std::max(0.0, ProcessCpuMsOf(pid)); }

// CPU of an nginx instance: its master and the master's children (workers).
double NginxCpuMs(pid_t master) {
  double ms = CpuMsOf(master);
  std::ifstream f("/proc/" + std::to_string(master) + "/task/" + std::to_string(master) + "/children");
  pid_t child = 0;
  while (f >> child) ms += CpuMsOf(child);
  return ms;
}

uint16_t FreePort() { return FreeTcpPort(); }

pid_t Spawn(const std::vector<std::string>& argv, const std::string& log_path) { return SpawnLogged(argv, log_path); }

void StopChild(pid_t pid) { StopProcess(pid, SIGTERM, 5.0); }

// Capture times (site clock) of the first and last MeshFrame of a part, by
// walking its records (lengths only: the load generator does not CRC or
// decode). False if the part holds no MeshFrame or is malformed.
bool PartCaptureTimes(std::span<const uint8_t> b, size_t head, int64_t* first, int64_t* last,
                      int64_t* last_record_time) {
  auto u32 = [&](size_t at) {
    return static_cast<uint32_t>(b[at]) | static_cast<uint32_t>(b[at + 1]) << 8 |
           static_cast<uint32_t>(b[at + 2]) << 16 | static_cast<uint32_t>(b[at + 3]) << 24;
  };
  bool any = false;
  for (size_t at = head; at + 24 + 32 <= b.size();) {
    const uint32_t len = u32(at + 8);
    if (len < 32 || len > b.size() - at - 24) return false;
    const size_t body = at + 24;
    int64_t rt = 0;
    for (int i = 7; i >= 0; --i) rt = (rt << 8) | b[at + 16 + static_cast<size_t>(i)];
    *last_record_time = rt;
    const uint16_t type = static_cast<uint16_t>(b[body + 6] | b[body + 7] << 8);
    if (type == static_cast<uint16_t>(protocol::MessageType::kMeshFrame)) {
      int64_t t = 0;
      for (int i = 7; i >= 0; --i) t = (t << 8) | b[body + 20 + static_cast<size_t>(i)];
      if (!any) *first = t;
      *last = t;
      any = true;
    }
    at = body + len;
  }
  return any;
}

struct ViewerResult {
  std::set<std::string> got;  // names of the parts received in the window
  uint64_t parts = 0, bytes = 0, late = 0, errors = 0, skips = 0, catch_ups = 0, manifests = 0;
  std::vector<double> latency_newest_ms, latency_oldest_ms;
  std::vector<double> latency_tier_ms;  // packager receive of the part's last message → part received
};

// The manifests the viewers of one thread have parsed: each distinct live.json
// body is parsed once per thread (a real audience parses on its own machines;
// here 1,000 viewers parsing every poll took a quarter of the two cores'
// samples away from the site and nginx under test). Every viewer still
// fetches every poll. Two entries: around a rewrite, replies old and new
// interleave.
struct ManifestCache {
  struct Entry {
    std::string body;
    std::shared_ptr<const net::LiveManifest> manifest;
  };
  Entry entries[2];
  int next = 0;
  std::shared_ptr<const net::LiveManifest> Get(std::string_view body) {
    for (const Entry& e : entries)
      if (e.manifest && e.body == body) return e.manifest;
    auto m = net::ParseLiveManifest(body);
    if (!m.ok()) return nullptr;
    Entry& e = entries[next];
    next ^= 1;
    e.body = std::string(body);
    e.manifest = std::make_shared<const net::LiveManifest>(std::move(*m));
    return e.manifest;
  }
};

// One light viewer: a keep-alive connection to its edge and a LiveFollower.
class LightViewer : public std::enable_shared_from_this<LightViewer> {
 public:
  LightViewer(asio::io_context& io, asio::ip::tcp::endpoint edge, std::string dir, const BroadcastOptions& o,
              ManifestCache* manifests, std::atomic<bool>* measuring, std::atomic<bool>* stop)
      : socket_(io), timer_(io), edge_(edge), dir_(std::move(dir)), o_(o), manifests_(manifests),
        measuring_(measuring), stop_(stop) {}

  void Start() {
    auto self = shared_from_this();
    socket_.async_connect(edge_, [self](std::error_code ec) {
      if (ec) {
        self->result.errors += 1;
        self->Retry();
        return;
      }
      self->socket_.set_option(asio::ip::tcp::no_delay(true));
      self->Step();
    });
  }

  ViewerResult result;

 private:
  void Retry() {
    if (*stop_) return;
    auto self = shared_from_this();
    std::error_code ignore;
    socket_.close(ignore);
    timer_.expires_after(std::chrono::milliseconds(200));
    timer_.async_wait([self](std::error_code) { self->Start(); });
  }

  void Step() {
    if (*stop_) return;
    const int64_t now = SteadyUs();
    if (now >= next_manifest_us_) {
      // The next poll is due a poll interval after this one's reply (Body), as
      // BroadcastPlayer does: a slow reply must not leave a viewer polling
      // back to back and never fetching a part. Until then, no second poll.
      next_manifest_us_ = INT64_MAX;
      // "live.json?b=BUCKET" once a manifest has named the bucket length
      // (a BroadcastUrl without dir and query: Get() prepends dir_).
      Get(net::ManifestTarget({}, applied_ ? applied_->cache_bucket_ms : 0, WallUs() / 1000), true, {});
      return;
    }
    if (auto p = follower_.Next()) {
      Get(p->name, false, *p);
      return;
    }
    auto self = shared_from_this();
    timer_.expires_after(std::chrono::microseconds(std::max<int64_t>(1000, std::min<int64_t>(20000, next_manifest_us_ - now))));
    timer_.async_wait([self](std::error_code) { self->Step(); });
  }

  void Get(const std::string& name, bool manifest, net::LivePartRef part) {
    request_ = "GET " + dir_ + name + " HTTP/1.1\r\nHost: edge\r\n\r\n";
    auto self = shared_from_this();
    asio::async_write(socket_, asio::buffer(request_), [self, manifest, part](std::error_code ec, size_t) {
      if (ec) return self->Fail();
      self->ReadHead(manifest, part);
    });
  }

  void ReadHead(bool manifest, net::LivePartRef part) {
    auto self = shared_from_this();
    asio::async_read_until(socket_, asio::dynamic_buffer(buf_), "\r\n\r\n",
                           [self, manifest, part](std::error_code ec, size_t) {
                             if (ec) return self->Fail();
                             bool complete = false;
                             auto h = net::ParseHttpResponseHead(
                                 std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(self->buf_.data()),
                                                          self->buf_.size()),
                                 &complete);
                             if (!h.ok() || !complete) return self->Fail();
                             self->head_ = *h;
                             const size_t want = h->head_bytes + h->content_length;
                             if (self->buf_.size() >= want) return self->Body(manifest, part);
                             asio::async_read(self->socket_, asio::dynamic_buffer(self->buf_),
                                              asio::transfer_exactly(want - self->buf_.size()),
                                              [self, manifest, part](std::error_code ec2, size_t) {
                                                if (ec2) return self->Fail();
                                                self->Body(manifest, part);
                                              });
                           });
  }

  void Body(bool manifest, const net::LivePartRef& part) {
    // Capture times are the site's wall clock (Unix µs); the site runs on this machine.
    const int64_t now = WallUs();
    const size_t end = head_.head_bytes + head_.content_length;
    const bool measured = measuring_->load();
    if (manifest) {
      next_manifest_us_ = SteadyUs() + static_cast<int64_t>(o_.manifest_poll_ms * 1000);
      if (head_.status == 200) {
        const std::string_view body(buf_.data() + head_.head_bytes, head_.content_length);
        auto m = manifests_->Get(body);
        if (m && m != applied_) {
          follower_.OnManifest(*m);
          applied_ = std::move(m);
        }
        if (measured) result.manifests += 1;
      } else if (measured) {
        result.errors += 1;
      }
    } else if (head_.status == 200) {
      if (measured) {
        const std::span<const uint8_t> bytes(reinterpret_cast<const uint8_t*>(buf_.data()) + head_.head_bytes,
                                             head_.content_length);
        int64_t first = 0, last = 0, record_time = 0;
        result.parts += 1;
        result.got.insert(part.name);
        result.bytes += head_.content_length;
        const bool have = PartCaptureTimes(bytes, 0, &first, &last, &record_time);
        if (applied_ && applied_->availability_start_unix_us > 0)
          result.latency_tier_ms.push_back(
              static_cast<double>(now - applied_->availability_start_unix_us - record_time) * 1e-3);
        if (have) {
          const double newest = static_cast<double>(now - last) * 1e-3;
          result.latency_newest_ms.push_back(newest);
          result.latency_oldest_ms.push_back(static_cast<double>(now - first) * 1e-3);
          if (newest > o_.in_time_ms) result.late += 1;
        }
      }
      follower_.Done(part);
    } else {
      if (measured) result.errors += 1;
      follower_.Skip(part);
    }
    if (measured) {
      result.skips = follower_.stats().skips - skips_at_start_;
      result.catch_ups = follower_.stats().catch_ups - catch_ups_at_start_;
    } else {
      skips_at_start_ = follower_.stats().skips;
      catch_ups_at_start_ = follower_.stats().catch_ups;
    }
    buf_.erase(0, end);
    if (!head_.keep_alive) {
      std::error_code ignore;
      socket_.close(ignore);
      buf_.clear();
      return Start();
    }
    Step();
  }

  void Fail() {
    if (measuring_->load()) result.errors += 1;
    buf_.clear();
    next_manifest_us_ = 0;  // a fresh connection starts with a poll
    Retry();
  }

  asio::ip::tcp::socket socket_;
  asio::steady_timer timer_;
  asio::ip::tcp::endpoint edge_;
  std::string dir_;
  const BroadcastOptions& o_;
  ManifestCache* manifests_;
  std::shared_ptr<const net::LiveManifest> applied_;  // the last manifest given to follower_
  std::atomic<bool>* measuring_;
  std::atomic<bool>* stop_;
  net::LiveFollower follower_;
  int64_t next_manifest_us_ = 0;
  std::string request_, buf_;
  net::HttpResponseHead head_;
  uint64_t skips_at_start_ = 0, catch_ups_at_start_ = 0;
};

struct LogCounts {
  std::map<std::string, int> by_kind;  // "part", "manifest", "segment", "other"
  int hits = 0, total = 0;                  // parts
  int manifest_hits = 0, manifest_total = 0;  // live.json
};

// Lines of an access log (holo format: $msec first, "$request", …, cache
// status last on edges) with $msec in [t0, t1].
LogCounts CountLog(const std::string& path, double t0, double t1) {
  LogCounts c;
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line)) {
    const double t = std::atof(line.c_str());
    if (t < t0 || t > t1) continue;
    const size_t q = line.find('"');
    const size_t q2 = line.find('"', q + 1);
    if (q == std::string::npos || q2 == std::string::npos) continue;
    const std::string req = line.substr(q + 1, q2 - q - 1);
    std::string kind = "other";
    if (req.find("/live.json") != std::string::npos) kind = "manifest";
    else if (req.find(".hrec") != std::string::npos) kind = "segment";
    else if (req.find("/seg_") != std::string::npos) kind = "part";
    c.by_kind[kind] += 1;
    const std::string status = line.substr(line.rfind(' ') + 1);
    if (kind == "part") {
      c.total += 1;
      if (status == "HIT") c.hits += 1;
    } else if (kind == "manifest") {
      c.manifest_total += 1;
      if (status == "HIT") c.manifest_hits += 1;
    }
  }
  return c;
}

int RunBroadcast(const BenchArgs& args, const BroadcastOptions& o) {
  const auto [codec_args, codec_label] = SiteCodecs(o.codecs, o.content);
  if (o.content == "truth" && codec_label.rfind("G3", 0) == 0) {
    spdlog::error("broadcast: --codecs {} needs --content fused (G3 codes the site's fused grid; the studio's "
                  "meshes have none)", o.codecs);
    return 2;
  }
  if (std::system("command -v nginx > /dev/null 2>&1") != 0) {
    spdlog::error("broadcast: nginx is not installed (scripts/setup.sh installs nginx-light)");
    return 2;
  }
  const std::string bin = SelfDir();
  const std::string script = std::string(HOLO_SOURCE_DIR) + "/scripts/broadcast.sh";
  std::string dir = o.keep_dir;
  if (dir.empty()) {
    char tmpl[] = "/tmp/holoport-broadcast-XXXXXX";
    if (!mkdtemp(tmpl)) return 1;
    dir = tmpl;
  }
  if (std::system(("mkdir -p '" + dir + "/root'").c_str()) != 0) return 1;
  auto progress = [&](const std::string& s) {
    if (!args.json) spdlog::info("broadcast: {}", s);
  };
  const std::string content = o.content;
  auto emit = [&](const std::string& metric, double value, const std::string& unit,
                  std::map<std::string, std::string> q = {}) {
    q["content"] = content;
    q["codec"] = codec_label;
    q["viewers"] = std::to_string(o.viewers);
    q["edges"] = std::to_string(o.edges);
    EmitFigure("broadcast", args.workload, metric, value, unit, q);
  };

  // 1. The site and the packager.
  const uint16_t site_port = FreePort();
  std::vector<std::string> site = {bin + "/holoport-server", "--source", "synthetic", "--workload", args.workload,
                                   "--listen", "127.0.0.1:" + std::to_string(site_port), "--publisher-token",
                                   kPublisherToken, "--viewer-token", kViewerToken, "--pace", "30"};
  if (o.content == "truth") {
    site.insert(site.end(), {"--truth-mesh", "--truth-loop", std::to_string(o.prerender), "-n", "-1"});
  } else {
    site.insert(site.end(), {"--prerender", std::to_string(o.prerender), "-n", "-1"});
  }
  site.insert(site.end(), codec_args.begin(), codec_args.end());
  site.insert(site.end(), o.site_args.begin(), o.site_args.end());
  progress("site: " + o.content + " " + args.workload + ", " + codec_label + " (pre-rendering " +
           std::to_string(o.prerender) + " frames)");
  const pid_t site_pid = Spawn(site, dir + "/site.log");
  const pid_t packager_pid =
      Spawn({bin + "/holoport-record", "--live-dir", dir + "/root/show", "--connect",
             "127.0.0.1:" + std::to_string(site_port), "--token", kViewerToken, "--segment-seconds",
             std::to_string(o.segment_s), "--part-ms", std::to_string(o.part_ms), "--window", std::to_string(o.window),
             "--cache-bucket-ms", std::to_string(o.cache_bucket_ms),
             "--connect-timeout", "120", "-q"},
            dir + "/packager.log");
  // 2. nginx origin + edges.
  const uint16_t origin_port = FreePort();
  std::vector<uint16_t> edge_ports;
  for (int i = 0; i < o.edges; ++i) {
    uint16_t p = FreePort();
    while (std::find(edge_ports.begin(), edge_ports.end(), p) != edge_ports.end() || p == origin_port) p = FreePort();
    edge_ports.push_back(p);
  }
  // broadcast.sh numbers edges from one base port: start each edge on its own.
  std::string cmd = script + " start --run '" + dir + "/run' --root '" + dir + "/root' --origin-port " +
                    std::to_string(origin_port) + " --edges 0 > '" + dir + "/nginx.log' 2>&1";
  int rc = std::system(cmd.c_str());
  for (int i = 0; i < o.edges && rc == 0; ++i) {
    // One edge per run directory, pointing at the shared origin.
    cmd = script + " start --run '" + dir + "/run_e" + std::to_string(i) + "' --root '" + dir + "/root' --origin-port " +
          std::to_string(origin_port) + " --no-origin --edges 1 --edge-port " + std::to_string(edge_ports[i]) +
          " >> '" + dir + "/nginx.log' 2>&1";
    rc = std::system(cmd.c_str());
  }
  auto stop_all = [&] {
    std::system((script + " stop --run '" + dir + "/run' > /dev/null 2>&1").c_str());
    for (int i = 0; i < o.edges; ++i)
      std::system((script + " stop --run '" + dir + "/run_e" + std::to_string(i) + "' > /dev/null 2>&1").c_str());
    StopChild(packager_pid);
    StopChild(site_pid);
  };
  if (rc != 0) {
    spdlog::error("broadcast: nginx did not start (see {}/nginx.log)", dir);
    stop_all();
    return 1;
  }
  // 3. Wait for the broadcast at an edge (the site pre-renders first).
  {
    net::HttpGetter probe("127.0.0.1", edge_ports[0], 2.0);
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(300);
    bool live = false;
    while (!live && std::chrono::steady_clock::now() < until) {
      auto r = probe.Get("/show/live.json");
      if (r.ok() && r->status == 200) {
        auto m = net::ParseLiveManifest(std::string_view(reinterpret_cast<const char*>(r->body.data()), r->body.size()));
        live = m.ok() && m->segments.size() >= 2;
      }
      if (!live) std::this_thread::sleep_for(std::chrono::milliseconds(500));
    }
    if (!live) {
      spdlog::error("broadcast: no broadcast at the edge within 300 s (see {})", dir);
      stop_all();
      return 1;
    }
  }
  progress("live; " + std::to_string(o.viewers) + " viewers on " + std::to_string(o.edges) + " edges, " +
           std::to_string(o.threads) + " threads");
  // 4. The viewers.
  std::atomic<bool> measuring{false}, stop{false};
  std::vector<std::unique_ptr<asio::io_context>> ios;
  std::vector<std::shared_ptr<LightViewer>> viewers;
  std::vector<ManifestCache> manifest_caches(static_cast<size_t>(o.threads));  // one per thread
  for (int t = 0; t < o.threads; ++t) ios.push_back(std::make_unique<asio::io_context>());
  for (int i = 0; i < o.viewers; ++i) {
    asio::ip::tcp::endpoint ep(asio::ip::make_address("127.0.0.1"), edge_ports[static_cast<size_t>(i % o.edges)]);
    const size_t t = static_cast<size_t>(i % o.threads);
    viewers.push_back(std::make_shared<LightViewer>(*ios[t], ep, "/show/", o, &manifest_caches[t], &measuring, &stop));
  }
  for (auto& v : viewers) v->Start();
  std::vector<std::thread> threads;
  for (int t = 0; t < o.threads; ++t)
    threads.emplace_back([&, t] {
      ios[static_cast<size_t>(t)]->run();
    });
  std::this_thread::sleep_for(std::chrono::duration<double>(o.warmup_s));
  // 5. The measured window.
  std::vector<pid_t> edge_masters;
  auto read_pid = [](const std::string& path) {
    std::ifstream f(path);
    pid_t p = 0;
    f >> p;
    return p;
  };
  for (int i = 0; i < o.edges; ++i) edge_masters.push_back(read_pid(dir + "/run_e" + std::to_string(i) + "/edge0/nginx.pid"));
  const pid_t origin_master = read_pid(dir + "/run/origin/nginx.pid");
  std::vector<double> edge_cpu0;
  for (pid_t p : edge_masters) edge_cpu0.push_back(NginxCpuMs(p));
  const double origin_cpu0 = NginxCpuMs(origin_master), site_cpu0 = CpuMsOf(site_pid),
               packager_cpu0 = CpuMsOf(packager_pid), self_cpu0 = ProcessCpuMs();
  // The packager's manifest, read every 250 ms through the window: which
  // parts it published when (name → available_unix_us).
  std::map<std::string, int64_t> published;
  auto read_manifest = [&]() -> int64_t {  // records its parts in `published`; the newest segment's number
    auto text = std::ifstream(dir + "/root/show/live.json");
    std::stringstream ss;
    ss << text.rdbuf();
    auto m = net::ParseLiveManifest(ss.str());
    if (!m.ok() || m->segments.empty()) return -1;
    for (const auto& seg : m->segments)
      for (const auto& p : seg.parts) published.emplace(p.name, p.available_unix_us);
    return static_cast<int64_t>(m->segments.back().number);
  };
  const int64_t seg0 = read_manifest();
  const double t0 = WallS();
  measuring = true;
  while (WallS() < t0 + o.seconds) {
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    read_manifest();
  }
  measuring = false;
  const double t1 = WallS();
  const int64_t seg1 = read_manifest();
  std::vector<double> edge_cpu;
  for (size_t i = 0; i < edge_masters.size(); ++i) edge_cpu.push_back(NginxCpuMs(edge_masters[i]) - edge_cpu0[i]);
  const double origin_cpu = NginxCpuMs(origin_master) - origin_cpu0, site_cpu = CpuMsOf(site_pid) - site_cpu0,
               packager_cpu = CpuMsOf(packager_pid) - packager_cpu0, self_cpu = ProcessCpuMs() - self_cpu0;
  stop = true;
  for (auto& io : ios) io->stop();
  for (auto& t : threads) t.join();
  std::this_thread::sleep_for(std::chrono::milliseconds(1200));  // edges flush their buffered logs
  stop_all();

  // 6. Figures.
  const double window_s = t1 - t0;
  const double segments = static_cast<double>(std::max<int64_t>(1, seg1 - seg0));
  std::vector<double> newest, oldest, tier, mbps;
  int held = 0, complete = 0;
  uint64_t total_bytes = 0, total_parts = 0, total_errors = 0, total_late = 0, total_skips = 0, total_catch_ups = 0;
  const LogCounts origin = CountLog(dir + "/run/origin/access.log", t0, t1);
  // Parts published in the window (the packager's manifest), and those a
  // held viewer must have: published at least 1 s after the window opened
  // and 1.5 s before it closed (whatever the latency, they fall inside it).
  double parts_published = 0;
  std::vector<std::string> must_have;
  for (const auto& [name, at] : published) {
    const double at_s = static_cast<double>(at) * 1e-6;
    if (at_s >= t0 && at_s <= t1) parts_published += 1;
    if (at_s >= t0 + 1.0 && at_s <= t1 - 1.5) must_have.push_back(name);
  }
  if (must_have.empty())
    spdlog::warn("broadcast: the packager published no part in the window's interior: no viewer counts as held");
  for (auto& v : viewers) {
    const ViewerResult& r = v->result;
    newest.insert(newest.end(), r.latency_newest_ms.begin(), r.latency_newest_ms.end());
    oldest.insert(oldest.end(), r.latency_oldest_ms.begin(), r.latency_oldest_ms.end());
    tier.insert(tier.end(), r.latency_tier_ms.begin(), r.latency_tier_ms.end());
    mbps.push_back(static_cast<double>(r.bytes) * 8 / window_s / 1e6);
    total_bytes += r.bytes;
    total_parts += r.parts;
    total_errors += r.errors;
    total_late += r.late;
    total_skips += r.skips;
    total_catch_ups += r.catch_ups;
    // Every part published inside the window, none late, no error, skip or jump.
    bool all = !must_have.empty() && r.errors == 0 && r.skips == 0 && r.catch_ups == 0;
    for (size_t k = 0; all && k < must_have.size(); ++k) all = r.got.count(must_have[k]) > 0;
    if (all) ++complete;
    if (all && r.late == 0) ++held;
  }
  int edge_hits = 0, edge_total = 0, manifest_hits = 0, manifest_total = 0;
  for (int i = 0; i < o.edges; ++i) {
    const LogCounts e = CountLog(dir + "/run_e" + std::to_string(i) + "/edge0/access.log", t0, t1);
    edge_hits += e.hits;
    edge_total += e.total;
    manifest_hits += e.manifest_hits;
    manifest_total += e.manifest_total;
  }
  auto count = [&](const LogCounts& c, const std::string& k) {
    auto it = c.by_kind.find(k);
    return it == c.by_kind.end() ? 0 : it->second;
  };
  const std::string required = std::to_string(must_have.size());
  emit("viewers_held", held, "viewers",
       {{"of", std::to_string(o.viewers)}, {"in_time_ms", std::to_string(static_cast<int>(o.in_time_ms))},
        {"parts_required", required}});
  emit("viewers_complete", complete, "viewers",
       {{"of", std::to_string(o.viewers)},
        {"what", "every part published from 1 s after the window opened to 1.5 s before it closed, no skip, jump or "
                 "error, any latency"},
        {"parts_required", required}});
  emit("latency_p50_ms", Quantile(newest, 0.5), "ms", {{"from", "capture of the part's newest frame"}, {"to", "part received"}});
  emit("latency_p99_ms", Quantile(newest, 0.99), "ms", {{"from", "capture of the part's newest frame"}, {"to", "part received"}});
  emit("latency_oldest_p50_ms", Quantile(oldest, 0.5), "ms", {{"from", "capture of the part's oldest frame"}, {"to", "part received"}});
  emit("latency_oldest_p99_ms", Quantile(oldest, 0.99), "ms", {{"from", "capture of the part's oldest frame"}, {"to", "part received"}});
  emit("latency_tier_p50_ms", Quantile(tier, 0.5), "ms",
       {{"from", "packager received the part's last message"}, {"to", "part received"}});
  emit("latency_tier_p99_ms", Quantile(tier, 0.99), "ms",
       {{"from", "packager received the part's last message"}, {"to", "part received"}});
  emit("mbps", Quantile(mbps, 0.5), "Mbit/s", {{"per", "viewer (median)"}});
  emit("mbps_total", static_cast<double>(total_bytes) * 8 / window_s / 1e6, "Mbit/s",
       {{"note", "all viewers; loopback ceiling ~23,700 Mbit/s for one TCP stream"}});
  emit("parts_per_viewer_per_s", static_cast<double>(total_parts) / window_s / o.viewers, "1/s",
       {{"published", std::to_string(parts_published / window_s)}});
  emit("viewer_errors", static_cast<double>(total_errors), "count");
  emit("viewer_skips", static_cast<double>(total_skips), "count", {{"what", "parts given up (404, damaged)"}});
  emit("viewer_catch_ups", static_cast<double>(total_catch_ups), "count",
       {{"what", "jumps to the newest segment after falling 2 segments behind"}});
  emit("parts_late", static_cast<double>(total_late), "count", {{"in_time_ms", std::to_string(static_cast<int>(o.in_time_ms))}});
  emit("origin_requests_per_object_per_edge", count(origin, "part") / std::max(1.0, parts_published) / o.edges, "requests",
       {{"object", "part"}, {"target", "<= 1"}});
  // Per segment published and per edge, by kind of object: a segment's
  // parts each cross from the origin to an edge once (the target: <= 1 per
  // object), live.json about once per cache bucket per edge.
  const std::string parts_per_segment = std::to_string(static_cast<int>(o.segment_s * 1000 / o.part_ms));
  emit("origin_requests_per_segment", count(origin, "part") / segments / o.edges, "requests",
       {{"per", "edge"}, {"object", "part"}, {"parts_per_segment", parts_per_segment}, {"target", "<= 1 per part"}});
  emit("origin_requests_per_segment", count(origin, "manifest") / segments / o.edges, "requests",
       {{"per", "edge"}, {"object", "live.json"}, {"cache_bucket_ms", std::to_string(o.cache_bucket_ms)}});
  emit("origin_manifest_requests_per_s", count(origin, "manifest") / window_s, "1/s",
       {{"summed_over", "edges"}, {"viewer_polls_per_s", std::to_string(manifest_total / window_s)}});
  emit("edge_hit_ratio", edge_total ? static_cast<double>(edge_hits) / edge_total : 0.0, "ratio", {{"objects", "parts"}});
  emit("edge_hit_ratio", manifest_total ? static_cast<double>(manifest_hits) / manifest_total : 0.0, "ratio",
       {{"objects", "live.json"}, {"cache_bucket_ms", std::to_string(o.cache_bucket_ms)}});
  for (size_t i = 0; i < edge_cpu.size(); ++i)
    emit("edge_cpu_pct", edge_cpu[i] / (window_s * 10.0), "% of one core", {{"edge", std::to_string(i)}});
  emit("origin_cpu_pct", origin_cpu / (window_s * 10.0), "% of one core");
  emit("packager_cpu_pct", packager_cpu / (window_s * 10.0), "% of one core");
  emit("site_cpu_pct", site_cpu / (window_s * 10.0), "% of one core");
  emit("viewers_cpu_pct", self_cpu / (window_s * 10.0), "% of one core", {{"threads", std::to_string(o.threads)}});
  emit("segments_published", segments, "count", {{"seconds", std::to_string(window_s)}});
  // A run's directory (the broadcast's segments, nginx's cache and logs:
  // 30–70 MB) is kept only when asked for (--keep); a failed run keeps it
  // for its logs (the returns above).
  if (o.keep_dir.empty()) {
    std::error_code ignore;
    std::filesystem::remove_all(dir, ignore);
  } else if (!args.json) {
    spdlog::info("broadcast: logs in {}", dir);
  }
  return 0;
}

BenchFn Setup(CLI::App& app) {
  DropCommonOptions(app, {"--frames", "--repeats"});  // this benchmark does not read them
  auto o = std::make_shared<BroadcastOptions>();
  app.add_option("--viewers", o->viewers, "light HTTP viewers")->check(CLI::Range(1, 20000));
  app.add_option("--edges", o->edges, "nginx edge caches")->check(CLI::Range(1, 16));
  app.add_option("--content", o->content, "fused (the real pipeline on pre-rendered frames) or truth (studio meshes)")
      ->check(CLI::IsMember({"fused", "truth"}));
  app.add_option("--seconds", o->seconds, "measured window, s")->check(CLI::Range(3.0, 3600.0));
  app.add_option("--warmup", o->warmup_s, "seconds between the viewers' start and the window")->check(CLI::Range(0.0, 120.0));
  app.add_option("--prerender", o->prerender, "pod frame sets the site renders first and loops")->check(CLI::Range(2, 600));
  app.add_option("--segment-seconds", o->segment_s, "packager segment length")->check(CLI::Range(0.5, 10.0));
  app.add_option("--part-ms", o->part_ms, "packager part length")->check(CLI::Range(50, 2000));
  app.add_option("--window", o->window, "segments in live.json")->check(CLI::Range(1, 100));
  app.add_option("--threads", o->threads, "viewer threads (each an Asio loop with many connections)")
      ->check(CLI::Range(1, 64));
  app.add_option("--manifest-poll-ms", o->manifest_poll_ms, "how often a viewer polls live.json")
      ->check(CLI::Range(50.0, 5000.0));
  app.add_option("--cache-bucket-ms", o->cache_bucket_ms,
                 "the packager's live.json cache bucket (viewers key their polls by it; 0: every poll reaches the "
                 "origin)")
      ->check(CLI::Range(0, 60000));
  app.add_option("--in-time-ms", o->in_time_ms, "a part is in time within this of its newest frame's capture")
      ->check(CLI::Range(100.0, 60000.0));
  app.add_option("--keep", o->keep_dir, "keep logs, configs and the broadcast in this directory");
  app.add_option("--codecs", o->codecs,
                 "the site's geometry + colour codecs: auto (g3+v1 for fused, g1+v1 for truth), g3+v1, g1+v1, g1+c1, "
                 "or site (holoport-server's defaults and --site-arg)")
      ->check(CLI::IsMember({"auto", "g3+v1", "g1+v1", "g1+c1", "site"}));
  app.add_option("--site-arg", o->site_args,
                 "an extra holoport-server argument (repeatable; e.g. --site-arg=--geometry-codec --site-arg=g3)");
  return [o](const BenchArgs& args) { return RunBroadcast(args, *o); };
}

HOLO_REGISTER_BENCH_OPTIONS("broadcast",
                            "live broadcast through an nginx origin + edges to N light HTTP viewers (docs/broadcast.md)",
                            Setup);

}  // namespace
}  // namespace holo::bench
