// Handshake and robustness of the session server over loopback: tokens,
// versions, roles, limits; malformed input, giant lengths, half-sent
// headers and slowloris handshakes close only the offending connection.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "client/net/raw_peer.h"
#include "net/net_fixtures.h"
#include "net/site_client.h"

namespace holo::net {
namespace {

using protocol::MessageType;
using protocol::RefuseReason;
using test::Eventually;
using test::LoopbackConfig;

struct Site {
  test::LogCapture log;
  std::unique_ptr<Server> server;
  explicit Site(ServerConfig cfg = LoopbackConfig(), StreamControlSink* sink = nullptr) {
    ServerHooks h;
    h.log = log.Hook();
    h.control = sink;
    auto s = Server::Start(cfg, h);
    HOLO_CHECK_MSG(s.ok(), s.status().ToString());
    server = std::move(*s);
  }
  uint16_t port() const { return server->port(); }
};

std::unique_ptr<RawPeer> Connect(uint16_t port) {
  auto p = RawPeer::Connect("127.0.0.1", port);
  HOLO_CHECK(p.ok());
  return std::move(*p);
}

// Sends a Hello and returns the Refuse the server answered with.
protocol::Refuse ExpectRefused(uint16_t port, protocol::Role role, const std::string& token) {
  auto p = Connect(port);
  EXPECT_TRUE(p->SendHello(role, token, "tester").ok());
  auto m = p->ReadMessage(5.0);
  EXPECT_TRUE(m.ok()) << m.status().ToString();
  if (!m.ok() || m->header.type != MessageType::kRefuse) {
    ADD_FAILURE() << "expected Refuse";
    return {};
  }
  EXPECT_TRUE(p->WaitClosed(5.0)) << "server kept the refused connection open";
  return std::get<protocol::Refuse>(m->payload);
}

ClientOptions Viewer(uint16_t port, const std::string& token = "view-secret") {
  ClientOptions o;
  o.port = port;
  o.token = token;
  o.name = "normal";
  o.reconnect = false;
  o.max_pending_frames = 1000;
  return o;
}

TEST(NetSession, WrongOrMissingTokenIsRefusedWithReason) {
  Site site;
  EXPECT_EQ(ExpectRefused(site.port(), protocol::Role::kViewer, "wrong").reason, RefuseReason::kBadToken);
  EXPECT_EQ(ExpectRefused(site.port(), protocol::Role::kViewer, "").reason, RefuseReason::kBadToken);
  // The publisher token does not let a viewer in, nor the viewer token a publisher.
  EXPECT_EQ(ExpectRefused(site.port(), protocol::Role::kViewer, "pub-secret").reason, RefuseReason::kBadToken);
  EXPECT_EQ(ExpectRefused(site.port(), protocol::Role::kPublisher, "view-secret").reason, RefuseReason::kBadToken);
  EXPECT_EQ(ExpectRefused(site.port(), protocol::Role::kThinClient, "view-secret").reason,
            RefuseReason::kRoleNotAllowed);
  EXPECT_TRUE(site.log.Contains("BAD_TOKEN"));
  EXPECT_TRUE(site.log.Contains("ROLE_NOT_ALLOWED"));
  EXPECT_EQ(site.server->counters().refused, 5u);

  // The client library reports the refusal as a clear status and does not retry.
  ClientOptions o = Viewer(site.port(), "nope");
  o.reconnect = true;
  auto c = SiteClient::Start(o);
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE((*c)->WaitConnected(5.0));
  EXPECT_EQ((*c)->state(), ClientState::kRefused);
  EXPECT_NE((*c)->status().message().find("BAD_TOKEN"), std::string::npos) << (*c)->status().ToString();
  ASSERT_TRUE((*c)->refusal().has_value());
  EXPECT_EQ((*c)->refusal()->reason, RefuseReason::kBadToken);
}

TEST(NetSession, TokensCompareByValue) {
  EXPECT_TRUE(TokensEqual("abc", "abc"));
  EXPECT_FALSE(TokensEqual("abc", "abd"));
  EXPECT_FALSE(TokensEqual("abc", "abcd"));
  EXPECT_FALSE(TokensEqual("", "a"));
}

TEST(NetSession, VersionMismatchIsRefusedClearly) {
  Site site;
  {  // A header of protocol version 2.
    auto p = Connect(site.port());
    std::vector<uint8_t> bytes = protocol::EncodeMessage({}, protocol::Ping{1, 2});
    bytes[4] = 2;
    ASSERT_TRUE(p->Send(bytes).ok());
    auto m = p->ReadMessage(5.0);
    ASSERT_TRUE(m.ok()) << m.status().ToString();
    ASSERT_EQ(m->header.type, MessageType::kRefuse);
    const auto& r = std::get<protocol::Refuse>(m->payload);
    EXPECT_EQ(r.reason, RefuseReason::kUnsupportedVersion);
    EXPECT_NE(r.message.find("peer speaks protocol version 2, this build speaks 1"), std::string::npos) << r.message;
    EXPECT_EQ(r.server_max_version, protocol::kProtocolVersion);
  }
  {  // A Hello asking for versions 2..3.
    auto p = Connect(site.port());
    protocol::Hello h;
    h.min_version = 2;
    h.max_version = 3;
    h.access_token = "view-secret";
    h.capabilities.audio = {protocol::AudioCodec::kOpus};
    ASSERT_TRUE(p->SendMessage(h).ok());
    auto m = p->ReadMessage(5.0);
    ASSERT_TRUE(m.ok());
    ASSERT_EQ(m->header.type, MessageType::kRefuse);
    EXPECT_EQ(std::get<protocol::Refuse>(m->payload).reason, RefuseReason::kUnsupportedVersion);
  }
  EXPECT_TRUE(site.log.Contains("UNSUPPORTED_VERSION"));
}

TEST(NetSession, NoCommonCodecAndFullSiteAreRefused) {
  ServerConfig cfg = LoopbackConfig();
  cfg.max_viewers = 2;
  Site site(cfg);
  {
    auto p = Connect(site.port());
    protocol::Hello h;
    h.access_token = "view-secret";
    h.capabilities.geometry = {protocol::GeometryCodec::kG0};
    h.capabilities.color = {protocol::ColorCodec::kC1};
    h.capabilities.audio = {protocol::AudioCodec::kOpus};
    ASSERT_TRUE(p->SendMessage(h).ok());
    auto m = p->ReadMessage(5.0);
    ASSERT_TRUE(m.ok());
    ASSERT_EQ(m->header.type, MessageType::kRefuse);
    EXPECT_EQ(std::get<protocol::Refuse>(m->payload).reason, RefuseReason::kNoCommonCodec);
  }
  auto a = SiteClient::Start(Viewer(site.port()));
  auto b = SiteClient::Start(Viewer(site.port()));
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_TRUE((*a)->WaitConnected(5) && (*b)->WaitConnected(5));
  EXPECT_EQ(ExpectRefused(site.port(), protocol::Role::kViewer, "view-secret").reason, RefuseReason::kOverloaded);
  EXPECT_TRUE(site.log.Contains("max_viewers"));
}

// A normal viewer that must keep receiving while others misbehave.
class Watcher {
 public:
  explicit Watcher(Server* s) : server_(s) {
    auto c = SiteClient::Start(Viewer(s->port()));
    HOLO_CHECK(c.ok());
    client_ = std::move(*c);
    HOLO_CHECK(client_->WaitConnected(5.0));
    HOLO_CHECK(Eventually([&] { return s->num_subscribed(kContentGeometry) >= 1; }));
    content_ = test::MakeContent(10, 10);
  }
  // Publishes one frame and checks that it arrives.
  void PublishAndExpect() {
    server_->PublishVideo(
        MakeVideoFrame(next_, WallUs(), protocol::GeometryCodec::kG1, content_.geometry, nullptr, 65536));
    ReceivedFrame f;
    ASSERT_TRUE(client_->WaitFrame(&f, 5.0)) << "normal viewer lost frame " << next_;
    EXPECT_EQ(f.frame_index, next_);
    ++next_;
  }
  SiteClient* client() { return client_.get(); }

 private:
  Server* server_;
  std::unique_ptr<SiteClient> client_;
  test::EncodedContent content_;
  int64_t next_ = 0;
};

std::unique_ptr<RawPeer> Welcomed(uint16_t port) {
  auto p = Connect(port);
  HOLO_CHECK(p->SendHello(protocol::Role::kViewer, "view-secret", "attacker").ok());
  auto m = p->ReadMessage(5.0);
  HOLO_CHECK(m.ok() && m->header.type == MessageType::kWelcome);
  return p;
}

TEST(NetSession, MalformedMessageClosesOnlyThatClient) {
  Site site;
  Watcher w(site.server.get());
  w.PublishAndExpect();
  {  // bad magic after Welcome
    auto p = Welcomed(site.port());
    const std::vector<uint8_t> junk(64, 0xAB);
    ASSERT_TRUE(p->Send(junk).ok());
    EXPECT_TRUE(p->WaitClosed(5.0));
    w.PublishAndExpect();
  }
  {  // a well-framed Control whose payload has trailing bytes
    auto p = Welcomed(site.port());
    std::vector<uint8_t> bytes = protocol::EncodeMessage({}, protocol::Control{});
    bytes.push_back(0);
    bytes[28] += 1;  // payload_length covers the extra byte
    ASSERT_TRUE(p->Send(bytes).ok());
    EXPECT_TRUE(p->WaitClosed(5.0));
    w.PublishAndExpect();
  }
  {  // a subscribe with unknown content bits
    auto p = Welcomed(site.port());
    protocol::Control c;
    c.value = 99;
    ASSERT_TRUE(p->SendMessage(c).ok());
    EXPECT_TRUE(p->WaitClosed(5.0));
  }
  {  // a MeshFrame from a viewer
    auto p = Welcomed(site.port());
    ASSERT_TRUE(p->SendMessage(protocol::MeshFrame{}).ok());
    EXPECT_TRUE(p->WaitClosed(5.0));
  }
  w.PublishAndExpect();
  EXPECT_EQ(site.server->counters().violations, 4u);
  EXPECT_TRUE(site.log.Contains("protocol violation"));
  EXPECT_EQ(site.server->num_viewers(), 1u);
  EXPECT_EQ(w.client()->state(), ClientState::kConnected);
}

TEST(NetSession, GiantLengthFieldClosesOnlyThatClient) {
  Site site;
  Watcher w(site.server.get());
  auto p = Welcomed(site.port());
  protocol::Header h;
  h.type = MessageType::kControl;
  h.payload_length = 0xFFFFFFF0u;
  uint8_t bytes[protocol::kHeaderSize];
  protocol::EncodeHeader(h, bytes);
  ASSERT_TRUE(p->Send(bytes).ok());
  EXPECT_TRUE(p->WaitClosed(5.0));
  EXPECT_TRUE(site.log.Contains("payload_length"));
  // Before the handshake too.
  auto q = Connect(site.port());
  ASSERT_TRUE(q->Send(bytes).ok());
  EXPECT_TRUE(q->WaitClosed(5.0));
  w.PublishAndExpect();
  // A fragmented message growing past max_message_bytes.
  auto r = Welcomed(site.port());
  std::vector<uint8_t> frag(600 * 1024, 0);
  for (int i = 0; i < 3; ++i) {
    protocol::Header fh;
    fh.type = MessageType::kStats;
    fh.flags = protocol::kFlagMoreFragments;
    fh.payload_length = static_cast<uint32_t>(frag.size());
    uint8_t hb[protocol::kHeaderSize];
    protocol::EncodeHeader(fh, hb);
    if (!r->Send(hb).ok() || !r->Send(frag).ok()) break;
  }
  EXPECT_TRUE(r->WaitClosed(5.0));
  w.PublishAndExpect();
}

TEST(NetSession, HalfSentHeaderAndSlowlorisHandshakesTimeOut) {
  ServerConfig cfg = LoopbackConfig();
  cfg.handshake_timeout_s = 0.3;
  cfg.idle_timeout_s = 0.5;
  Site site(cfg);
  Watcher w(site.server.get());
  // Half a header before the handshake.
  auto half = Connect(site.port());
  const std::vector<uint8_t> hello = protocol::EncodeMessage({}, protocol::Hello{});
  ASSERT_TRUE(half->Send(std::span<const uint8_t>(hello.data(), 10)).ok());
  // Slowloris: a Hello dribbled one byte every 50 ms (would take seconds).
  std::atomic<bool> closed{false};
  std::thread loris([&] {
    auto p = Connect(site.port());
    for (size_t i = 0; i < hello.size(); ++i) {
      if (!p->Send(std::span<const uint8_t>(hello.data() + i, 1)).ok()) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      uint8_t b;
      if (!p->Read(&b, 1, 0.0).ok()) break;  // closed by the server
    }
    closed = p->WaitClosed(2.0);
  });
  EXPECT_TRUE(half->WaitClosed(3.0));
  loris.join();
  EXPECT_TRUE(closed.load());
  // Half a header after the handshake: the idle timeout ends it.
  auto idle = Welcomed(site.port());
  ASSERT_TRUE(idle->Send(std::span<const uint8_t>(hello.data(), 10)).ok());
  EXPECT_TRUE(idle->WaitClosed(3.0));
  const ServerCounters c = site.server->counters();
  EXPECT_GE(c.handshake_timeouts, 2u);
  EXPECT_GE(c.idle_timeouts, 1u);
  EXPECT_TRUE(site.log.Contains("handshake timeout"));
  // The normal viewer pings and so stays; it still receives.
  w.PublishAndExpect();
}

class RecordingSink : public StreamControlSink {
 public:
  void OnControl(const ControlEvent& e) override {
    std::lock_guard<std::mutex> l(mu);
    events.push_back(e);
  }
  std::vector<ControlEvent> Events() {
    std::lock_guard<std::mutex> l(mu);
    return events;
  }
  std::mutex mu;
  std::vector<ControlEvent> events;
};

TEST(NetSession, PlaybackControlsReachTheSinkAndQualityIsKept) {
  RecordingSink sink;
  Site site(LoopbackConfig(), &sink);
  auto c = SiteClient::Start(Viewer(site.port()));
  ASSERT_TRUE(c.ok());
  ASSERT_TRUE((*c)->WaitConnected(5));
  (*c)->Pause();
  (*c)->Seek(2500000);
  (*c)->SetSpeed(0.25f);
  (*c)->Resume();
  (*c)->SetQuality(3);
  ASSERT_TRUE(Eventually([&] { return sink.Events().size() == 5; }));
  const auto ev = sink.Events();
  EXPECT_EQ(ev[0].control.command, protocol::ControlCommand::kPause);
  EXPECT_EQ(ev[1].control.command, protocol::ControlCommand::kSeek);
  EXPECT_EQ(ev[1].control.value, 2500000);
  EXPECT_EQ(ev[2].control.command, protocol::ControlCommand::kSetSpeed);
  EXPECT_FLOAT_EQ(ev[2].control.speed, 0.25f);
  EXPECT_EQ(ev[3].control.command, protocol::ControlCommand::kResume);
  EXPECT_EQ(ev[0].client_name, "normal");
  EXPECT_TRUE(Eventually([&] { return site.server->Sessions()[0].quality == 3; }));
  // A speed outside 0.1..8 is a violation.
  auto p = Welcomed(site.port());
  protocol::Control bad;
  bad.command = protocol::ControlCommand::kSetSpeed;
  bad.speed = 100.0f;
  ASSERT_TRUE(p->SendMessage(bad).ok());
  EXPECT_TRUE(p->WaitClosed(5));
  EXPECT_EQ(sink.Events().size(), 5u);
}

TEST(NetSession, UnsubscribedContentIsNotSent) {
  Site site;
  ClientOptions o = Viewer(site.port());
  o.subscribe = kSubscribeColor;
  auto c = SiteClient::Start(o);
  ASSERT_TRUE(c.ok());
  ASSERT_TRUE((*c)->WaitConnected(5));
  ASSERT_TRUE(Eventually([&] { return site.server->num_subscribed(kContentColor) == 1; }));
  const test::EncodedContent content = test::MakeContent(10, 10);
  site.server->PublishVideo(MakeVideoFrame(3, WallUs(), protocol::GeometryCodec::kG1, content.geometry,
                                           &content.color, 65536));
  ReceivedFrame f;
  ASSERT_TRUE((*c)->WaitFrame(&f, 5));
  EXPECT_EQ(f.frame_index, 3);
  EXPECT_FALSE(f.has_mesh);
  EXPECT_TRUE(f.has_color);
  EXPECT_EQ(f.images.size(), 2u);
}

}  // namespace
}  // namespace holo::net
