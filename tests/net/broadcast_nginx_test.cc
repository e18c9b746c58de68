// The shipped nginx origin + edge configuration (config/nginx/, started by
// scripts/broadcast.sh; docs/broadcast.md §5–6) on free loopback ports:
// concurrent misses make one origin request, content types, cache headers
// and CORS for browsers, the manifest is never served older than a player's
// cache bucket (one origin request per bucket, not per poll), and a private
// broadcast answers 403 to a missing, wrong or expired signature without
// asking the origin.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "common/file_util.h"
#include "test_util.h"

namespace holo {
namespace {

std::string ScriptPath() { return std::string(HOLO_TEST_DATA_DIR) + "/../../scripts/broadcast.sh"; }

bool HaveNginx() { return std::system("command -v nginx > /dev/null 2>&1") == 0; }

int FreePort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  HOLO_CHECK(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0);
  socklen_t len = sizeof(a);
  HOLO_CHECK(::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0);
  ::close(fd);
  return ntohs(a.sin_port);
}

struct Response {
  int status = 0;
  std::multimap<std::string, std::string> headers;  // lower-case names
  std::string body;
  std::string Header(const std::string& name) const {
    auto it = headers.find(name);
    return it == headers.end() ? std::string() : it->second;
  }
};

// One request on a fresh connection (Connection: close), read to the end.
Response Request(int port, const std::string& target, const std::string& method = "GET") {
  Response r;
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<uint16_t>(port));
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0) {
    ::close(fd);
    return r;
  }
  const std::string req = method + " " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\nOrigin: http://viewer.example\r\n" +
                          "Connection: close\r\n\r\n";
  HOLO_CHECK(::send(fd, req.data(), req.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(req.size()));
  std::string all;
  char buf[65536];
  while (true) {
    const ssize_t n = ::recv(fd, buf, sizeof(buf), 0);
    if (n <= 0) break;
    all.append(buf, static_cast<size_t>(n));
  }
  ::close(fd);
  const size_t end = all.find("\r\n\r\n");
  if (end == std::string::npos) return r;
  std::istringstream head(all.substr(0, end));
  std::string line;
  std::getline(head, line);
  if (line.size() >= 12) r.status = std::atoi(line.c_str() + 9);
  while (std::getline(head, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const size_t colon = line.find(':');
    if (colon == std::string::npos) continue;
    std::string name = line.substr(0, colon);
    for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    size_t v = colon + 1;
    while (v < line.size() && line[v] == ' ') ++v;
    r.headers.emplace(name, line.substr(v));
  }
  r.body = all.substr(end + 4);
  return r;
}

std::string Shell(const std::string& cmd) {
  std::string out;
  FILE* p = ::popen(cmd.c_str(), "r");
  HOLO_CHECK(p != nullptr);
  char buf[512];
  while (std::fgets(buf, sizeof(buf), p)) out += buf;
  ::pclose(p);
  while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
  return out;
}

// Lines of `log` whose request is `GET path` (the origin's access log).
int OriginRequests(const std::string& log, const std::string& path) {
  std::ifstream f(log);
  std::string line;
  int n = 0;
  while (std::getline(f, line))
    if (line.find("\"GET " + path + " ") != std::string::npos) ++n;
  return n;
}

class Broadcast : public ::testing::Test {
 protected:
  void Start(const std::string& secret) {
    if (!HaveNginx()) GTEST_SKIP() << "nginx is not installed (scripts/setup.sh installs nginx-light)";
    dir_ = test::MakeTempDir("bcast_nginx");
    HOLO_CHECK(MakeDirs(dir_ + "/root/show").ok());
    std::mt19937 rng(7);
    part_.resize(300000);
    for (char& c : part_) c = static_cast<char>(rng());
    HOLO_CHECK(WriteStringToFile(dir_ + "/root/show/seg_00000.p0", part_).ok());
    HOLO_CHECK(WriteStringToFile(dir_ + "/root/show/live.json", "{\"n\": 1}\n").ok());
    HOLO_CHECK(WriteStringToFile(dir_ + "/root/show/.seg_00000.p1.tmp", "partial").ok());
    origin_ = FreePort();
    edge_ = FreePort();
    secret_ = secret;
    const std::string cmd = ScriptPath() + " start --run " + dir_ + "/run --root " + dir_ + "/root --origin-port " +
                            std::to_string(origin_) + " --edges 1 --edge-port " + std::to_string(edge_) +
                            (secret.empty() ? "" : " --secret " + secret) + " > " + dir_ + "/start.log 2>&1";
    started_ = std::system(cmd.c_str()) == 0;
    ASSERT_TRUE(started_) << Shell("cat " + dir_ + "/start.log");
  }
  void TearDown() override {
    if (started_) (void)std::system((ScriptPath() + " stop --run " + dir_ + "/run").c_str());
  }
  std::string OriginLog() const { return dir_ + "/run/origin/access.log"; }
  std::string Sign(const std::string& name, const std::string& extra = "") const {
    const std::string url = Shell(ScriptPath() + " sign --name " + name + " --secret " + secret_ + " " + extra);
    return url.substr(url.find('?'));
  }

  std::string dir_, part_, secret_;
  int origin_ = 0, edge_ = 0;
  bool started_ = false;
};

TEST_F(Broadcast, ConcurrentMissesMakeOneOriginRequestAndBrowsersGetCorsAndTypes) {
  Start("");
  if (IsSkipped()) return;
  constexpr int kViewers = 40;
  std::vector<Response> got(kViewers);
  std::vector<std::thread> threads;
  for (int i = 0; i < kViewers; ++i)
    threads.emplace_back([&, i] { got[i] = Request(edge_, "/show/seg_00000.p0"); });
  for (auto& t : threads) t.join();
  for (const Response& r : got) {
    ASSERT_EQ(r.status, 200);
    ASSERT_TRUE(r.body == part_);
  }
  EXPECT_EQ(OriginRequests(OriginLog(), "/show/seg_00000.p0"), 1);
  const Response part = Request(edge_, "/show/seg_00000.p0");
  EXPECT_EQ(part.Header("x-cache-status"), "HIT");
  EXPECT_EQ(part.Header("content-type"), "application/octet-stream");
  EXPECT_EQ(part.Header("cache-control"), "public, max-age=31536000, immutable");
  EXPECT_EQ(part.headers.count("access-control-allow-origin"), 1u);  // once: a browser refuses two
  EXPECT_EQ(part.Header("access-control-allow-origin"), "*");

  const Response manifest = Request(edge_, "/show/live.json");
  ASSERT_EQ(manifest.status, 200);
  EXPECT_EQ(manifest.Header("content-type"), "application/json");
  EXPECT_EQ(manifest.Header("cache-control"), "no-cache");
  EXPECT_EQ(manifest.Header("access-control-allow-origin"), "*");
  const Response preflight = Request(edge_, "/show/live.json", "OPTIONS");
  EXPECT_EQ(preflight.status, 204);
  EXPECT_EQ(preflight.Header("access-control-allow-origin"), "*");
  EXPECT_NE(preflight.Header("access-control-allow-methods").find("GET"), std::string::npos);

  // Unknown objects and the packager's temporary files are 404, with CORS.
  const Response missing = Request(edge_, "/show/seg_00099.p0");
  EXPECT_EQ(missing.status, 404);
  EXPECT_EQ(missing.Header("access-control-allow-origin"), "*");
  EXPECT_EQ(Request(edge_, "/show/.seg_00000.p1.tmp").status, 404);
  EXPECT_EQ(Request(origin_, "/show/.seg_00000.p1.tmp").status, 404);
}

TEST_F(Broadcast, TheManifestIsNeverServedStale) {
  Start("");
  if (IsSkipped()) return;
  const Response first = Request(edge_, "/show/live.json");
  ASSERT_EQ(first.body, "{\"n\": 1}\n");
  EXPECT_EQ(first.Header("cache-control"), "no-cache");
  // It changes every part (250 ms); nginx caches in whole seconds, so the
  // edge passes every poll through: the next request sees the new one.
  ASSERT_TRUE(WriteStringToFile(dir_ + "/root/show/live.json", "{\"n\": 2}\n").ok());
  EXPECT_EQ(Request(edge_, "/show/live.json").body, "{\"n\": 2}\n");
  ASSERT_TRUE(WriteStringToFile(dir_ + "/root/show/live.json", "{\"n\": 3}\n").ok());
  EXPECT_EQ(Request(edge_, "/show/live.json").body, "{\"n\": 3}\n");
}

TEST_F(Broadcast, TheManifestIsCachedOncePerBucketAndNoLonger) {
  Start("");
  if (IsSkipped()) return;
  // Players in one bucket share one origin request.
  const Response a = Request(edge_, "/show/live.json?b=100");
  ASSERT_EQ(a.status, 200);
  EXPECT_EQ(a.body, "{\"n\": 1}\n");
  EXPECT_EQ(a.Header("cache-control"), "no-cache");  // browsers still never keep it
  EXPECT_EQ(a.Header("content-type"), "application/json");
  EXPECT_EQ(a.Header("access-control-allow-origin"), "*");
  ASSERT_TRUE(WriteStringToFile(dir_ + "/root/show/live.json", "{\"n\": 2}\n").ok());
  for (int i = 0; i < 5; ++i) {
    const Response again = Request(edge_, "/show/live.json?b=100");
    EXPECT_EQ(again.body, "{\"n\": 1}\n");
    EXPECT_EQ(again.Header("x-cache-status"), "HIT");
  }
  EXPECT_EQ(OriginRequests(OriginLog(), "/show/live.json"), 1);
  // The next bucket asks the origin again and sees the new manifest.
  EXPECT_EQ(Request(edge_, "/show/live.json?b=101").body, "{\"n\": 2}\n");
  EXPECT_EQ(OriginRequests(OriginLog(), "/show/live.json"), 2);
  // A poll without a bucket, or with anything but digits, passes through
  // and is not cached for later bucket-less polls.
  ASSERT_TRUE(WriteStringToFile(dir_ + "/root/show/live.json", "{\"n\": 3}\n").ok());
  EXPECT_EQ(Request(edge_, "/show/live.json").body, "{\"n\": 3}\n");
  EXPECT_EQ(Request(edge_, "/show/live.json?b=x1").body, "{\"n\": 3}\n");
  EXPECT_EQ(Request(edge_, "/show/live.json?b=" + std::string(17, '9')).body, "{\"n\": 3}\n");
  ASSERT_TRUE(WriteStringToFile(dir_ + "/root/show/live.json", "{\"n\": 4}\n").ok());
  EXPECT_EQ(Request(edge_, "/show/live.json").body, "{\"n\": 4}\n");
  EXPECT_EQ(Request(edge_, "/show/live.json?b=x1").body, "{\"n\": 4}\n");
  EXPECT_EQ(OriginRequests(OriginLog(), "/show/live.json"), 7);
  // The bucket's copy stays as it was (the key is the bucket, not the poll).
  EXPECT_EQ(Request(edge_, "/show/live.json?b=101").body, "{\"n\": 2}\n");
}

TEST_F(Broadcast, PrivateBroadcastServesOnlySignedUnexpiredUrls) {
  Start("s3cret-viewer-token");
  if (IsSkipped()) return;
  const std::string good = Sign("show", "--ttl 600");
  EXPECT_EQ(Request(edge_, "/show/live.json").status, 403);  // unsigned
  EXPECT_EQ(Request(edge_, "/show/seg_00000.p0").status, 403);
  std::string wrong = good;
  wrong[6] = wrong[6] == 'A' ? 'B' : 'A';  // inside the md5 value
  EXPECT_EQ(Request(edge_, "/show/seg_00000.p0" + wrong).status, 403);
  const std::string expired = Sign("show", "--expires " + std::to_string(std::time(nullptr) - 10));
  EXPECT_EQ(Request(edge_, "/show/seg_00000.p0" + expired).status, 403);
  const std::string other = Sign("other", "--ttl 600");  // signed for another broadcast
  EXPECT_EQ(Request(edge_, "/show/seg_00000.p0" + other).status, 403);
  const Response bad = Request(edge_, "/show/live.json" + wrong);
  EXPECT_EQ(bad.status, 403);
  EXPECT_EQ(bad.Header("access-control-allow-origin"), "*");  // a browser can read the refusal
  // None of those reached the origin.
  EXPECT_EQ(OriginRequests(OriginLog(), "/show/seg_00000.p0"), 0);
  EXPECT_EQ(OriginRequests(OriginLog(), "/show/live.json"), 0);

  const Response ok = Request(edge_, "/show/seg_00000.p0" + good);
  ASSERT_EQ(ok.status, 200);
  EXPECT_TRUE(ok.body == part_);
  EXPECT_EQ(Request(edge_, "/show/live.json" + good).status, 200);
  // A bucketed poll is checked the same way: no signature, no copy.
  EXPECT_EQ(Request(edge_, "/show/live.json?b=5").status, 403);
  EXPECT_EQ(Request(edge_, "/show/live.json" + wrong + "&b=5").status, 403);
  EXPECT_EQ(Request(edge_, "/show/live.json" + good + "&b=5").status, 200);
  EXPECT_EQ(Request(edge_, "/show/live.json" + good + "&b=5").Header("x-cache-status"), "HIT");
  // Another viewer's signature shares the cached copy.
  const Response again = Request(edge_, "/show/seg_00000.p0" + Sign("show", "--ttl 900"));
  EXPECT_EQ(again.status, 200);
  EXPECT_EQ(again.Header("x-cache-status"), "HIT");
  EXPECT_EQ(OriginRequests(OriginLog(), "/show/seg_00000.p0"), 1);
}

}  // namespace
}  // namespace holo
