// Lean AudioPose frames (codec 3, PROTOCOL.md §9.1) through a site: a new
// peer negotiates them, an old peer (listing codec 2 only) keeps working in
// both directions — it receives the classic layout of a lean speaker's frames
// (same Opus bytes, sequence, capture time, quantized pose), and its own
// classic frames reach new viewers.
#include <gtest/gtest.h>

#include <cmath>

#include "client/net/raw_peer.h"
#include "net/net_fixtures.h"
#include "net/site_client.h"

namespace holo::net {
namespace {

using test::Eventually;
using test::LoopbackConfig;

ClientOptions Options(uint16_t port, const std::string& name, protocol::Role role) {
  ClientOptions o;
  o.port = port;
  o.role = role;
  o.token = role == protocol::Role::kPublisher ? "pub-secret" : "view-secret";
  o.name = name;
  o.reconnect = false;
  o.ping_interval_s = 0.05;
  return o;
}

// An old peer: Hello lists Opus and PCM only (what builds before codec 3 sent).
std::unique_ptr<RawPeer> OldPeer(uint16_t port, protocol::Role role, protocol::Welcome* welcome) {
  auto p = RawPeer::Connect("127.0.0.1", port);
  HOLO_CHECK(p.ok());
  protocol::Hello h;
  h.role = role;
  h.capabilities.geometry = {protocol::GeometryCodec::kG1};
  h.capabilities.color = {protocol::ColorCodec::kC1};
  h.capabilities.audio = {protocol::AudioCodec::kOpus, protocol::AudioCodec::kPcm16};
  h.access_token = role == protocol::Role::kPublisher ? "pub-secret" : "view-secret";
  h.client_name = "old";
  HOLO_CHECK((*p)->SendMessage(h).ok());
  auto m = (*p)->ReadMessage(5.0);
  HOLO_CHECK(m.ok() && m->header.type == protocol::MessageType::kWelcome);
  *welcome = std::get<protocol::Welcome>(m->payload);
  return std::move(*p);
}

protocol::AudioPose LeanFrame(uint32_t seq) {
  protocol::AudioPose a;
  a.codec = protocol::AudioCodec::kOpusLean;
  a.sequence = seq;
  a.capture_time_us = 5000000 + 20000 * static_cast<int64_t>(seq);
  a.pose = protocol::QuantizeLeanPose({0.5f + 0.001f * static_cast<float>(seq), -1.25f, 1.6f, 0.3f, -0.05f, 0.0f});
  a.has_pose = seq % 2 == 0;  // pose every other frame
  if (!a.has_pose) a.pose = {};
  a.audio = {0xF8, 0xFF, 0xFE, static_cast<uint8_t>(seq)};
  return a;
}

// Next AudioPose an old raw viewer reads (other messages skipped).
protocol::Message NextAudio(RawPeer& p) {
  for (int i = 0; i < 100; ++i) {
    auto m = p.ReadMessage(5.0);
    HOLO_CHECK_MSG(m.ok(), m.status().ToString());
    if (m->header.type == protocol::MessageType::kAudioPose) return std::move(*m);
  }
  HOLO_CHECK_MSG(false, "no AudioPose");
  return {};
}

TEST(NetLeanAudio, NewPeersNegotiateLeanOldPeersKeepClassicBothWays) {
  auto server = Server::Start(LoopbackConfig());
  ASSERT_TRUE(server.ok());
  const uint16_t port = (*server)->port();
  auto viewer = SiteClient::Start(Options(port, "new-viewer", protocol::Role::kViewer));
  auto publisher = SiteClient::Start(Options(port, "new-speaker", protocol::Role::kPublisher));
  ASSERT_TRUE(viewer.ok() && publisher.ok());
  ASSERT_TRUE((*viewer)->WaitConnected(5.0) && (*publisher)->WaitConnected(5.0));
  EXPECT_EQ((*viewer)->welcome()->audio_codec, protocol::AudioCodec::kOpusLean);
  EXPECT_EQ((*publisher)->welcome()->audio_codec, protocol::AudioCodec::kOpusLean);
  protocol::Welcome old_welcome;
  auto old_viewer = OldPeer(port, protocol::Role::kViewer, &old_welcome);
  EXPECT_EQ(old_welcome.audio_codec, protocol::AudioCodec::kOpus);
  protocol::Control sub;
  sub.command = protocol::ControlCommand::kSubscribe;
  sub.value = kContentAudio;
  ASSERT_TRUE(old_viewer->SendMessage(sub).ok());
  ASSERT_TRUE(Eventually([&] { return (*server)->num_subscribed(kContentAudio) == 2; }));

  // New speaker → new viewer (lean) and old viewer (classic).
  const int kFrames = 6;
  for (int i = 0; i < kFrames; ++i) (*publisher)->SendAudioPose(LeanFrame(static_cast<uint32_t>(i)));
  protocol::HeadPose last_pose;
  for (int i = 0; i < kFrames; ++i) {
    const protocol::AudioPose sent = LeanFrame(static_cast<uint32_t>(i));
    protocol::AudioPose got;
    uint32_t stream = 0;
    ASSERT_TRUE(Eventually([&] { return (*viewer)->PollAudio(&got, &stream); })) << i;
    EXPECT_EQ(got, sent) << "lean frame " << i << " changed on the way";
    EXPECT_GE(stream, kFirstParticipantStreamId);

    const protocol::Message m = NextAudio(*old_viewer);
    const auto& classic = std::get<protocol::AudioPose>(m.payload);
    EXPECT_EQ(classic.codec, protocol::AudioCodec::kOpus) << i;
    EXPECT_EQ(classic.sequence, sent.sequence);
    EXPECT_EQ(classic.capture_time_us, sent.capture_time_us);
    EXPECT_EQ(m.header.sequence, sent.sequence);
    EXPECT_EQ(classic.audio, sent.audio);
    if (sent.has_pose) last_pose = sent.pose;
    EXPECT_EQ(classic.pose, last_pose) << "a frame without pose carries the last one in the classic layout";
  }

  // Old speaker (classic frames) → new viewer decodes them.
  protocol::Welcome old_pub_welcome;
  auto old_publisher = OldPeer(port, protocol::Role::kPublisher, &old_pub_welcome);
  EXPECT_EQ(old_pub_welcome.audio_codec, protocol::AudioCodec::kOpus);
  protocol::AudioPose classic;
  classic.codec = protocol::AudioCodec::kOpus;
  classic.sequence = 77;
  classic.capture_time_us = 123456789;
  classic.pose = {1.0f, 2.0f, 1.5f, 0.1f, 0.2f, 0.3f};
  classic.audio = {0xF8, 0xFF, 0xFE};
  protocol::Header h;
  h.sequence = classic.sequence;
  h.capture_time_us = classic.capture_time_us;
  ASSERT_TRUE(old_publisher->SendMessage(classic, h).ok());
  protocol::AudioPose got;
  ASSERT_TRUE(Eventually([&] { return (*viewer)->PollAudio(&got); }));
  EXPECT_EQ(got, classic);
  EXPECT_EQ(std::get<protocol::AudioPose>(NextAudio(*old_viewer).payload), classic);  // and the old viewer too

  // The site's own lean voice (PublishAudio) reaches the old viewer as classic.
  (*server)->PublishAudio(LeanFrame(100), kSiteVoiceStreamId);
  const protocol::Message m = NextAudio(*old_viewer);
  EXPECT_EQ(std::get<protocol::AudioPose>(m.payload).codec, protocol::AudioCodec::kOpus);
  EXPECT_EQ(std::get<protocol::AudioPose>(m.payload).sequence, 100u);
  ASSERT_TRUE(Eventually([&] { return (*viewer)->PollAudio(&got); }));
  EXPECT_EQ(got, LeanFrame(100));
}

// A new speaker on an old site (which answers codec 2): SendAudioPose turns
// its lean frames into classic ones, the pose of a pose-less frame being the
// last one sent.
TEST(NetLeanAudio, LeanSpeakerTalksClassicToAnOldSite) {
  auto server = Server::Start(LoopbackConfig());
  ASSERT_TRUE(server.ok());
  ClientOptions o = Options((*server)->port(), "new-speaker", protocol::Role::kPublisher);
  o.capabilities.audio = {protocol::AudioCodec::kOpus};  // what an old site would pick
  auto publisher = SiteClient::Start(o);
  ASSERT_TRUE(publisher.ok());
  ASSERT_TRUE((*publisher)->WaitConnected(5.0));
  EXPECT_EQ((*publisher)->welcome()->audio_codec, protocol::AudioCodec::kOpus);
  protocol::Welcome w;
  auto old_viewer = OldPeer((*server)->port(), protocol::Role::kViewer, &w);
  protocol::Control sub;
  sub.command = protocol::ControlCommand::kSubscribe;
  sub.value = kContentAudio;
  ASSERT_TRUE(old_viewer->SendMessage(sub).ok());
  ASSERT_TRUE(Eventually([&] { return (*server)->num_subscribed(kContentAudio) == 1; }));
  for (uint32_t i = 0; i < 2; ++i) (*publisher)->SendAudioPose(LeanFrame(i));
  for (uint32_t i = 0; i < 2; ++i) {
    const protocol::Message m = NextAudio(*old_viewer);
    const auto& a = std::get<protocol::AudioPose>(m.payload);
    EXPECT_EQ(a.codec, protocol::AudioCodec::kOpus);
    EXPECT_EQ(a.sequence, i);
    EXPECT_EQ(a.pose, LeanFrame(0).pose);
  }
}

}  // namespace
}  // namespace holo::net
