// Native broadcast playback (client/net/broadcast_player.h, docs/broadcast.md
// §4): the URL, HTTP head and manifest parsers on untrusted input, the
// follower's choices (join at the live edge, parts in order, skip on 404,
// catch up), and a player against a live packager behind a small HTTP server
// that loses a part, stalls and sees the site restart.
#include <algorithm>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <fstream>
#include <functional>
#include <mutex>
#include <set>
#include <thread>

#include <gtest/gtest.h>

#include "client/net/broadcast_player.h"
#include "common/file_util.h"
#include "net/site_client.h"
#include "record/record_test_util.h"
#include "server/record/live_packager.h"
#include "test_util.h"

namespace holo::net {
namespace {

int64_t WallUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

TEST(BroadcastUrl, AcceptsEdgeUrlsAndRefusesOthers) {
  auto u = ParseBroadcastUrl("http://127.0.0.1:8081/show/live.json?md5=abc_-&expires=17");
  ASSERT_TRUE(u.ok()) << u.status().ToString();
  EXPECT_EQ(u->host, "127.0.0.1");
  EXPECT_EQ(u->port, 8081);
  EXPECT_EQ(u->dir, "/show/");
  EXPECT_EQ(u->query, "?md5=abc_-&expires=17");
  u = ParseBroadcastUrl("http://edge.example/live/show/");
  ASSERT_TRUE(u.ok());
  EXPECT_EQ(u->port, 80);
  EXPECT_EQ(u->dir, "/live/show/");
  for (const char* bad : {"https://e/show/", "ftp://e/show/", "http://e", "http://e/", "http://e:0/s/", "http://e:99999/s/",
                          "http://e:8a/s/", "http://e/s/../x/", "http://e/s p/", "http://e\r\n/s/", "http://:80/s/"})
    EXPECT_FALSE(ParseBroadcastUrl(bad).ok()) << bad;
}

std::span<const uint8_t> Bytes(const std::string& s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

TEST(HttpHead, ParsesEveryPrefixAndRefusesWhatAnEdgeNeverSends) {
  const std::string ok =
      "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: 27\r\nConnection: keep-alive\r\n\r\n";
  bool complete = false;
  auto h = ParseHttpResponseHead(Bytes(ok + "{...}"), &complete);
  ASSERT_TRUE(h.ok() && complete);
  EXPECT_EQ(h->status, 200);
  EXPECT_EQ(h->content_length, 27u);
  EXPECT_EQ(h->head_bytes, ok.size());
  EXPECT_TRUE(h->keep_alive);
  for (size_t n = 0; n < ok.size(); ++n) {
    const std::string prefix = ok.substr(0, n);
    std::vector<uint8_t> fresh(prefix.begin(), prefix.end());  // its own buffer: ASan sees overreads
    auto r = ParseHttpResponseHead(fresh, &complete);
    ASSERT_TRUE(r.ok()) << n;
    ASSERT_FALSE(complete) << n;
  }
  auto refuse = [&](const std::string& head) {
    bool c = false;
    auto r = ParseHttpResponseHead(Bytes(head), &c);
    return !r.ok() && r.status().code() == StatusCode::kDataLoss;
  };
  EXPECT_TRUE(refuse("HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n"));
  EXPECT_TRUE(refuse("HTTP/1.1 200 OK\r\n\r\n"));  // no length
  EXPECT_TRUE(refuse("HTTP/1.1 200 OK\r\nContent-Length: -1\r\n\r\n"));
  EXPECT_TRUE(refuse("HTTP/1.1 200 OK\r\nContent-Length: 1\r\nContent-Length: 2\r\n\r\n"));
  EXPECT_TRUE(refuse("HTTP/1.1 200 OK\r\nContent-Length: 99999999999999999\r\n\r\n"));
  EXPECT_TRUE(refuse("HTTP/2 200 OK\r\nContent-Length: 1\r\n\r\n"));
  EXPECT_TRUE(refuse("HTTP/1.1 2x0 OK\r\nContent-Length: 1\r\n\r\n"));
  EXPECT_TRUE(refuse("HTTP/1.1 200 OK\r\nno colon\r\n\r\n"));
  EXPECT_TRUE(refuse("HTTP/1.1 200 OK\r\nX: " + std::string(17000, 'a')));
  bool c = false;
  auto nb = ParseHttpResponseHead(Bytes("HTTP/1.1 204 No Content\r\nConnection: close\r\n\r\n"), &c);
  ASSERT_TRUE(nb.ok() && c);
  EXPECT_FALSE(nb->keep_alive);
}

// A manifest written by the real packager.
std::string PackagedManifest(const std::string& dir, int frames) {
  record::LivePackagerOptions o;
  o.dir = dir;
  o.segment_us = 500000;
  o.part_us = 100000;
  auto p = record::LivePackager::Open(o, 1700000000000000);
  HOLO_CHECK(p.ok());
  for (const auto& m : test::MakeTestStream(frames, 30, 2))
    HOLO_CHECK((*p)->AddMessage(m.frame, 1700000000000000 + m.time_us).ok());
  return *ReadFileToString(dir + "/live.json");
}

TEST(LiveManifest, ParsesThePackagersManifestAndRefusesDamage) {
  const std::string text = PackagedManifest(test::MakeTempDir("bp_manifest"), 40);
  auto m = ParseLiveManifest(text);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  ASSERT_EQ(m->segments.size(), 3u);  // 0, 0.5 s, 1.0 s (open)
  EXPECT_TRUE(m->segments[0].complete);
  EXPECT_FALSE(m->segments[2].complete);
  EXPECT_EQ(m->segments[1].parts[0].name, "seg_00001.p0");
  EXPECT_EQ(m->update_interval_ms, 100);
  EXPECT_EQ(m->cache_bucket_ms, 100);  // the packager's default
  for (size_t n = 0; n < text.size(); n += 3) {
    auto r = ParseLiveManifest(text.substr(0, n));
    if (r.ok()) ADD_FAILURE() << "prefix " << n << " parsed";
  }
  auto damaged = [&](const std::string& from, const std::string& to) {
    std::string t = text;
    const size_t at = t.find(from);
    HOLO_CHECK(at != std::string::npos);
    t.replace(at, from.size(), to);
    auto r = ParseLiveManifest(t);
    return !r.ok() && r.status().code() == StatusCode::kDataLoss;
  };
  EXPECT_TRUE(damaged("\"holoport-live\"", "\"other\""));
  EXPECT_TRUE(damaged("\"version\": 1", "\"version\": 2"));
  EXPECT_TRUE(damaged("seg_00001.p0", "seg_00001.p1"));
  EXPECT_TRUE(damaged("seg_00001.p0", "../../etc/passwd"));
  EXPECT_TRUE(damaged("\"number\": 1", "\"number\": 0"));  // not increasing
  EXPECT_TRUE(damaged("\"update_interval_ms\": 100", "\"update_interval_ms\": \"100\""));
  EXPECT_TRUE(damaged("\"ended\": false", "\"ended\": 0"));
  EXPECT_TRUE(damaged("\"cache_bucket_ms\": 100", "\"cache_bucket_ms\": -1"));
  EXPECT_TRUE(damaged("\"cache_bucket_ms\": 100", "\"cache_bucket_ms\": 60001"));
  EXPECT_TRUE(damaged("\"cache_bucket_ms\": 100", "\"cache_bucket_ms\": 0.5"));
  // Absent (an older packager): no bucket.
  std::string older = text;
  const size_t at = older.find("\"cache_bucket_ms\": 100,");
  ASSERT_NE(at, std::string::npos);
  older.erase(at, std::string("\"cache_bucket_ms\": 100,").size());
  auto o = ParseLiveManifest(older);
  ASSERT_TRUE(o.ok()) << o.status().ToString();
  EXPECT_EQ(o->cache_bucket_ms, 0);
}

TEST(LiveManifest, PollsCarryTheCacheBucketAndKeepTheSignature) {
  auto u = ParseBroadcastUrl("http://edge:8080/show/live.json?md5=abc_-&expires=17");
  ASSERT_TRUE(u.ok());
  EXPECT_EQ(ManifestTarget(*u, 0, 1700000000123), "/show/live.json?md5=abc_-&expires=17");
  EXPECT_EQ(ManifestTarget(*u, 100, 1700000000123), "/show/live.json?md5=abc_-&expires=17&b=17000000001");
  EXPECT_EQ(ManifestTarget(*u, 100, 1700000000199), ManifestTarget(*u, 100, 1700000000100));  // one bucket
  EXPECT_NE(ManifestTarget(*u, 100, 1700000000200), ManifestTarget(*u, 100, 1700000000199));  // the next
  auto plain = ParseBroadcastUrl("http://edge/show/");
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ(ManifestTarget(*plain, 250, 1000), "/show/live.json?b=4");
}

LiveManifest MakeManifest(std::vector<std::pair<uint64_t, int>> segs, bool last_open, int64_t published) {
  LiveManifest m;
  m.availability_start_unix_us = 1;
  m.published_unix_us = published;
  m.target_part_us = 100000;
  m.update_interval_ms = 100;
  for (size_t i = 0; i < segs.size(); ++i) {
    LiveSegmentRef s;
    s.number = segs[i].first;
    s.complete = !(last_open && i + 1 == segs.size());
    for (int k = 0; k < segs[i].second; ++k)
      s.parts.push_back({s.number, static_cast<uint64_t>(k), record::LivePartName(s.number, k), 0});
    m.segments.push_back(s);
  }
  return m;
}

TEST(LiveFollower, JoinsAtTheNewestSegmentFollowsPartsSkipsAndCatchesUp) {
  LiveFollower f;
  EXPECT_FALSE(f.Next());  // no manifest yet
  f.OnManifest(MakeManifest({{3, 5}, {4, 5}, {5, 2}}, true, 10));
  auto p = f.Next();
  ASSERT_TRUE(p);
  EXPECT_EQ(p->name, "seg_00005.p0");  // the live edge, at a join point
  f.Done(*p);
  p = f.Next();
  ASSERT_TRUE(p);
  EXPECT_EQ(p->name, "seg_00005.p1");
  f.Done(*p);
  EXPECT_FALSE(f.Next());  // wait for p2
  // An older manifest (another edge's cached copy) changes nothing.
  f.OnManifest(MakeManifest({{3, 5}}, false, 5));
  EXPECT_FALSE(f.Next());
  f.OnManifest(MakeManifest({{4, 5}, {5, 3}, {6, 1}}, true, 20));
  p = f.Next();
  ASSERT_TRUE(p);
  EXPECT_EQ(p->name, "seg_00005.p2");
  f.Done(*p);
  p = f.Next();  // segment 5 complete with 3 parts: on to 6
  ASSERT_TRUE(p);
  EXPECT_EQ(p->name, "seg_00006.p0");
  f.Done(*p);
  // A 404 on a part: continue at the next segment's part 0.
  f.OnManifest(MakeManifest({{6, 4}, {7, 2}}, true, 30));
  p = f.Next();
  ASSERT_TRUE(p);
  EXPECT_EQ(p->name, "seg_00006.p1");
  f.Skip(*p);
  p = f.Next();
  ASSERT_TRUE(p);
  EXPECT_EQ(p->name, "seg_00007.p0");
  EXPECT_EQ(f.stats().skips, 1u);
  // Far behind (a stall): jump to the newest segment.
  f.OnManifest(MakeManifest({{7, 5}, {8, 5}, {9, 5}, {10, 1}}, true, 40));
  p = f.Next();
  ASSERT_TRUE(p);
  EXPECT_EQ(p->name, "seg_00010.p0");
  EXPECT_EQ(f.stats().catch_ups, 1u);
}

// A tiny HTTP/1.1 file server (keep-alive) over `dir`, with a hook that may
// answer 404 or delay an object.
class TestEdge {
 public:
  struct Rule {
    int status = 0;      // 0: serve the file
    int delay_ms = 0;
  };
  TestEdge(std::string dir, std::function<Rule(const std::string&)> rule) : dir_(std::move(dir)), rule_(rule) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    HOLO_CHECK(::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0);
    HOLO_CHECK(::listen(fd_, 16) == 0);
    socklen_t len = sizeof(a);
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] { Accept(); });
  }
  ~TestEdge() {
    stop_ = true;
    ::shutdown(fd_, SHUT_RDWR);
    ::close(fd_);
    thread_.join();
    for (auto& t : conns_) t.join();
  }
  int port() const { return port_; }
  std::vector<std::string> log() {
    std::lock_guard<std::mutex> l(mu_);
    return log_;
  }

 private:
  void Accept() {
    while (!stop_) {
      const int c = ::accept(fd_, nullptr, nullptr);
      if (c < 0) return;
      timeval tv{0, 200000};
      ::setsockopt(c, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
      conns_.emplace_back([this, c] { Serve(c); });
    }
  }
  void Serve(int c) {
    std::string buf;
    char tmp[4096];
    while (!stop_) {
      const size_t end = buf.find("\r\n\r\n");
      if (end == std::string::npos) {
        const ssize_t n = ::recv(c, tmp, sizeof(tmp), 0);
        if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK)) break;
        if (n > 0) buf.append(tmp, static_cast<size_t>(n));
        continue;
      }
      const std::string line = buf.substr(0, buf.find("\r\n"));
      buf.erase(0, end + 4);
      std::string path = line.substr(4, line.find(' ', 4) - 4);
      path = path.substr(0, path.find('?'));
      const std::string name = path.substr(path.rfind('/') + 1);
      {
        std::lock_guard<std::mutex> l(mu_);
        log_.push_back(name);
      }
      const Rule r = rule_(name);
      if (r.delay_ms) std::this_thread::sleep_for(std::chrono::milliseconds(r.delay_ms));
      auto body = ReadFileToString(dir_ + "/" + name);
      const int status = r.status ? r.status : (body.ok() ? 200 : 404);
      const std::string content = status == 200 ? *body : std::string("not found");
      const std::string resp = "HTTP/1.1 " + std::to_string(status) + " X\r\nContent-Length: " +
                               std::to_string(content.size()) + "\r\n\r\n" + content;
      if (::send(c, resp.data(), resp.size(), MSG_NOSIGNAL) < 0) break;
    }
    ::close(c);
  }
  std::string dir_;
  std::function<Rule(const std::string&)> rule_;
  int fd_ = -1;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  std::vector<std::thread> conns_;
  std::mutex mu_;
  std::vector<std::string> log_;
};

// holoport-client --http feeds the broadcast's messages into a SiteClient in
// fed mode: the same decode and delivery path as a site connection.
TEST(FedSiteClient, DecodesFedMessagesLikeASiteConnection) {
  ClientOptions co;
  co.fed = true;
  co.subscribe = kSubscribeGeometry | kSubscribeAudio;
  auto client = SiteClient::Start(co);
  ASSERT_TRUE(client.ok()) << client.status().ToString();
  ASSERT_TRUE((*client)->WaitConnected(2.0));
  const auto stream = test::MakeTestStream(3, 30, 4);
  auto feed = [&](const std::vector<uint8_t>& frame) {
    auto h = protocol::DecodeHeader(frame.data(), frame.size());
    HOLO_CHECK(h.ok());
    RawMessage m;
    m.header = *h;
    m.payload.assign(frame.begin() + protocol::kHeaderSize, frame.end());
    m.received_us = WallUs();
    (*client)->Feed(std::move(m));
  };
  std::vector<uint8_t> bad_mesh;
  for (const auto& m : stream) {
    if (m.type == protocol::MessageType::kMeshFrame && bad_mesh.empty()) {
      bad_mesh = m.frame;
      bad_mesh[protocol::kHeaderSize + 8] = 99;  // the geometry codec: unknown
    }
    feed(m.frame);
  }
  ReceivedFrame f;
  ASSERT_TRUE((*client)->WaitFrame(&f, 2.0));
  EXPECT_TRUE(f.has_mesh);
  EXPECT_GT(f.mesh.num_vertices(), 0u);
  EXPECT_TRUE((*client)->rig().has_value());
  feed(bad_mesh);
  for (int i = 0; i < 100 && (*client)->stats().decode_errors == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ((*client)->stats().decode_errors, 1u);
  (*client)->Stop();
}

// A broadcast of the synthetic studio carries the stream's own time as its
// capture time (from 0): no latency is made up from it. Capture times on the
// wall clock give the latency.
TEST(FedSiteClient, LatencyOnlyFromCaptureTimesOnTheWallClock) {
  const auto stream = test::MakeTestStream(3, 30, 4);
  for (const bool wall : {false, true}) {
    ClientOptions co;
    co.fed = true;
    co.subscribe = kSubscribeGeometry;
    auto client = SiteClient::Start(co);
    ASSERT_TRUE(client.ok()) << client.status().ToString();
    ASSERT_TRUE((*client)->WaitConnected(2.0));
    const int64_t base = wall ? WallUs() - 40000 : 0;  // captured 40 ms before the first message arrives
    for (const auto& msg : stream) {
      auto h = protocol::DecodeHeader(msg.frame.data(), msg.frame.size());
      HOLO_CHECK(h.ok());
      RawMessage m;
      m.header = *h;
      m.header.capture_time_us += base;
      m.payload.assign(msg.frame.begin() + protocol::kHeaderSize, msg.frame.end());
      m.received_us = WallUs();
      (*client)->Feed(std::move(m));
    }
    ReceivedFrame f;
    ASSERT_TRUE((*client)->WaitFrame(&f, 2.0));
    EXPECT_EQ(f.latency_known, wall);
    if (wall) {
      EXPECT_GE(f.latency_ms, 40.0);
      EXPECT_LT(f.latency_ms, 5000.0);
    } else {
      EXPECT_EQ(f.latency_ms, 0.0);
    }
    (*client)->Stop();
  }
}

TEST(BroadcastPlayer, SurvivesA404AStalledEdgeAndASiteRestart) {
  const std::string dir = test::MakeTempDir("bp_live");
  record::LivePackagerOptions o;
  o.dir = dir;
  o.segment_us = 400000;
  o.part_us = 100000;
  auto packager = record::LivePackager::Open(o, WallUs());
  ASSERT_TRUE(packager.ok());
  // Faults: part 1 of segment 3 is missing at the edge; segment 5's part 0
  // takes 700 ms (a slow edge).
  TestEdge edge(dir, [](const std::string& name) {
    TestEdge::Rule r;
    if (name == "seg_00003.p1") r.status = 404;
    if (name == "seg_00005.p0") r.delay_ms = 700;
    return r;
  });
  std::mutex mu;
  std::vector<protocol::MessageType> got;
  int rigs = 0;
  BroadcastPlayerOptions po;
  po.url = "http://127.0.0.1:" + std::to_string(edge.port()) + "/show/live.json";
  po.retry_s = 0.05;
  auto player = BroadcastPlayer::Start(po, [&](const protocol::Header& h, std::span<const uint8_t>, int64_t) {
    std::lock_guard<std::mutex> l(mu);
    got.push_back(h.type);
    if (h.type == protocol::MessageType::kRig) ++rigs;
  });
  ASSERT_TRUE(player.ok()) << player.status().ToString();
  // The site: 1.5 s of stream, a restart (0.3 s off the air), 1.5 s more.
  const auto stream = test::MakeTestStream(45, 30, 2);
  auto play = [&](int64_t start) {
    int64_t tick = start;
    for (const auto& m : stream) {
      while (WallUs() < start + m.time_us) {
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
        if (WallUs() - tick > 10000) {
          tick = WallUs();
          ASSERT_TRUE((*packager)->Tick(tick).ok());
        }
      }
      ASSERT_TRUE((*packager)->AddMessage(m.frame, WallUs()).ok());
    }
  };
  play(WallUs());
  ASSERT_TRUE((*packager)->Discontinuity(WallUs()).ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  play(WallUs());
  ASSERT_TRUE((*packager)->Finish(WallUs()).ok());
  // Let the player drain.
  for (int i = 0; i < 100 && !(*player)->ended(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  (*player)->Stop();
  const BroadcastPlayerStats s = (*player)->stats();
  EXPECT_TRUE((*player)->ended());
  EXPECT_EQ(s.not_found, 1u) << s.last_error;
  EXPECT_EQ(s.follower.skips, 1u);
  EXPECT_GE(s.follower.discontinuities, 1u);
  EXPECT_EQ(s.damaged_parts, 0u);
  // It played on after each fault: segments after 3 and after the slow 5, and
  // the restarted stream's new Rig.
  const auto log = edge.log();
  const std::set<std::string> fetched(log.begin(), log.end());
  EXPECT_TRUE(fetched.count("seg_00004.p0"));
  // After the slow part it went on: the next part of segment 5, or (on a
  // loaded machine, behind the live edge after the 700 ms wait) a later
  // segment.
  const auto slow = std::find(log.begin(), log.end(), "seg_00005.p0");
  ASSERT_NE(slow, log.end());
  EXPECT_TRUE(std::any_of(slow + 1, log.end(), [](const std::string& n) {
    return n.rfind("seg_", 0) == 0 && n > "seg_00005.p0" && n.find(".p") != std::string::npos;
  })) << "stopped at the slow part";
  const uint64_t last = (*packager)->next_segment() - 1;
  EXPECT_TRUE(fetched.count(record::LivePartName(last, 0))) << "never reached the last segment " << last;
  EXPECT_FALSE(fetched.count("seg_00003.p2")) << "kept playing a segment after its lost part";
  std::lock_guard<std::mutex> l(mu);
  ASSERT_FALSE(got.empty());
  EXPECT_EQ(got.front(), protocol::MessageType::kRig);
  EXPECT_GE(rigs, 3);
  EXPECT_GT(s.parts, 15u);
  EXPECT_FALSE(s.latency_ms.empty());
}

}  // namespace
}  // namespace holo::net
