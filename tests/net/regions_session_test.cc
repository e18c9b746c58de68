// Regions over a session (PROTOCOL.md §4 Regions): the site announces them,
// a new viewer subscribes and receives them; an old viewer (subscribe 0 or
// 1|2|4) never sees message type 15; a new viewer never sends bit 8 to a
// site that did not announce; recordings keep Regions.
#include <gtest/gtest.h>

#include "client/net/raw_peer.h"
#include "net/net_fixtures.h"
#include "net/site_client.h"
#include "net/wire_message.h"
#include "protocol/sample_messages.h"
#include "server/record/recording_reader.h"
#include "server/record/recording_sink.h"
#include "server/record/recording_writer.h"
#include "test_util.h"

namespace holo::net {
namespace {

using protocol::MessageType;

struct Site {
  std::unique_ptr<Server> server;
  explicit Site(bool announce) {
    auto s = test::StartServerRetrying(test::LoopbackConfig());
    HOLO_CHECK(s.ok());
    server = std::move(*s);
    server->SetRig(test::SampleRig());
    if (announce) server->AnnounceRegions(2);
  }
  void PublishRegions(int64_t frame) {
    protocol::Regions r = test::SampleRegions();
    r.frame_index = frame;
    protocol::Header h;
    h.stream_id = kSiteStreamId;
    h.sequence = static_cast<uint32_t>(frame);
    h.capture_time_us = 1000 + frame;
    server->PublishPriority(MakeWireMessage(h, r, server->config().fragment_bytes));
  }
  uint32_t Subscription() const {
    const auto s = server->Sessions();
    return s.empty() ? 0 : s[0].subscription;
  }
};

ClientOptions Options(const Server& server) {
  ClientOptions o;
  o.port = server.port();
  o.token = "view-secret";
  o.decode = false;
  return o;
}

TEST(RegionsSession, AnnouncedRegionsReachANewViewer) {
  Site site(/*announce=*/true);
  std::atomic<int> callbacks{0};
  ClientCallbacks cb;
  cb.on_regions = [&](const ReceivedRegions&) { ++callbacks; };
  auto c = SiteClient::Start(Options(*site.server), cb);
  ASSERT_TRUE(c.ok());
  ASSERT_TRUE((*c)->WaitConnected(5));
  ASSERT_TRUE(test::Eventually([&] { return (site.Subscription() & kContentRegions) != 0; }));
  EXPECT_EQ(site.Subscription(), kContentAll | kContentRegions);
  int64_t frame = 0;
  ASSERT_TRUE(test::Eventually([&] {
    site.PublishRegions(frame++);
    return (*c)->stats().regions_received >= 3;
  }));
  ReceivedRegions r;
  ASSERT_TRUE((*c)->LatestRegions(&r));
  protocol::Regions want = test::SampleRegions();
  want.frame_index = r.regions.frame_index;
  EXPECT_EQ(r.regions, want);
  EXPECT_EQ(r.capture_time_us, 1000 + r.regions.frame_index);
  EXPECT_GE(callbacks.load(), 3);
  EXPECT_EQ((*c)->stats().decode_errors, 0u);
}

// An old viewer subscribes with 0 ("everything" to it) or 1|2|4 and does not
// know type 15: it must never receive one, and the announcement it gets is
// an ordinary Stats message.
TEST(RegionsSession, OldViewersNeverReceiveType15) {
  for (int64_t value : {0, 7}) {
    Site site(/*announce=*/true);  // one viewer per site: Subscription() is that viewer's
    auto p = RawPeer::Connect("127.0.0.1", site.server->port());
    ASSERT_TRUE(p.ok());
    ASSERT_TRUE((*p)->SendHello(protocol::Role::kViewer, "view-secret", "old-viewer").ok());
    protocol::Control sub;
    sub.value = value;
    ASSERT_TRUE((*p)->SendMessage(sub).ok());
    ASSERT_TRUE(test::Eventually([&] { return site.Subscription() == kContentAll; }));
    for (int f = 0; f < 10; ++f) site.PublishRegions(f);
    site.server->PublishPriority(MakeWireMessage({}, protocol::Ping{1, 2}, 1 << 16));
    bool saw_announce = false, saw_ping = false;
    while (!saw_ping) {
      auto m = (*p)->ReadMessage(5.0);
      ASSERT_TRUE(m.ok()) << m.status().message();
      EXPECT_NE(m->header.type, MessageType::kRegions) << "subscribe value " << value;
      if (m->header.type == MessageType::kStats)
        saw_announce |= std::get<protocol::Stats>(m->payload).values.at(0).first == protocol::kRegionsAnnounceKey;
      saw_ping |= m->header.type == MessageType::kPing && std::get<protocol::Ping>(m->payload).nonce == 1;
    }
    EXPECT_TRUE(saw_announce);
  }
}

// Without an announcement (a site that publishes no Regions, or one built
// before them) a new viewer never sends content bit 8; a viewer that does not
// want Regions never asks for them; bits above 15 are a violation.
TEST(RegionsSession, NoBit8WithoutAnnouncementOrWish) {
  {
    Site site(/*announce=*/false);
    auto c = SiteClient::Start(Options(*site.server));
    ASSERT_TRUE(c.ok());
    ASSERT_TRUE((*c)->WaitConnected(5));
    ASSERT_TRUE(test::Eventually([&] { return site.Subscription() == kContentAll; }));
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    EXPECT_EQ(site.Subscription(), kContentAll);
  }
  {
    Site site(/*announce=*/true);
    ClientOptions o = Options(*site.server);
    o.subscribe = kSubscribeAll;
    auto c = SiteClient::Start(o);
    ASSERT_TRUE(c.ok());
    ASSERT_TRUE((*c)->WaitConnected(5));
    ASSERT_TRUE(test::Eventually([&] { return site.Subscription() == kContentAll; }));
    for (int f = 0; f < 5; ++f) site.PublishRegions(f);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    EXPECT_EQ(site.Subscription(), kContentAll);
    EXPECT_EQ((*c)->stats().regions_received, 0u);
  }
  {
    Site site(/*announce=*/true);
    auto p = RawPeer::Connect("127.0.0.1", site.server->port());
    ASSERT_TRUE(p.ok());
    ASSERT_TRUE((*p)->SendHello(protocol::Role::kViewer, "view-secret", "bad").ok());
    protocol::Control sub;
    sub.value = 16;
    ASSERT_TRUE((*p)->SendMessage(sub).ok());
    EXPECT_TRUE((*p)->WaitClosed(5.0));
    EXPECT_EQ(site.server->counters().violations, 1u);
  }
}

// A recorder keeps Regions byte for byte.
TEST(RegionsSession, RecordingsKeepRegions) {
  const std::string dir = test::MakeTempDir("regions_record");
  protocol::Header h;
  std::vector<std::vector<uint8_t>> wire = {protocol::EncodeMessage(h, protocol::RigMessage{test::SampleRig()})};
  h.stream_id = kSiteStreamId;
  for (int f = 0; f < 3; ++f) {
    protocol::Regions r = test::SampleRegions();
    r.frame_index = f;
    h.sequence = static_cast<uint32_t>(f);
    wire.push_back(protocol::EncodeMessage(h, r));
  }
  {
    auto w = record::RecordingWriter::Create(dir + "/r.hrec", record::RecordingWriterOptions{});
    ASSERT_TRUE(w.ok());
    record::RecordingSink sink(w->get());
    int64_t now = 1000000;
    for (const auto& bytes : wire) {
      protocol::FrameParser parser;
      ASSERT_TRUE(parser.Feed(bytes.data(), bytes.size()).ok());
      protocol::Frame f;
      ASSERT_TRUE(parser.Next(&f));
      ASSERT_TRUE(sink.AddFrame(f, now += 33000).ok());
    }
    EXPECT_EQ(sink.stats().recorded, 4u);
    ASSERT_TRUE((*w)->Close().ok());
  }
  auto r = record::RecordingReader::Open(dir + "/r.hrec");
  ASSERT_TRUE(r.ok()) << r.status().message();
  uint64_t at = (*r)->summary().data_begin;
  std::vector<std::vector<uint8_t>> read;
  while (at < (*r)->summary().data_end) {
    auto m = (*r)->ReadAt(at);
    ASSERT_TRUE(m.ok()) << m.status().message();
    read.push_back(*m->bytes);
    at = m->next_offset;
  }
  EXPECT_EQ(read, wire);
}

}  // namespace
}  // namespace holo::net
