// Fan-out over loopback: every frame in order to every viewer, slow and
// stalled viewers do not disturb normal ones (counts, not timings), audio
// relay, reconnect after a server restart.
#include <gtest/gtest.h>

#include <atomic>
#include <mutex>
#include <thread>

#include "client/net/raw_peer.h"
#include "net/net_fixtures.h"
#include "net/site_client.h"

namespace holo::net {
namespace {

using test::Eventually;
using test::LoopbackConfig;

ClientOptions ViewerOptions(uint16_t port, const std::string& name) {
  ClientOptions o;
  o.port = port;
  o.token = "view-secret";
  o.name = name;
  o.ping_interval_s = 0.05;
  o.max_pending_frames = 1000;
  return o;
}

TEST(NetFanout, TwoViewersReceiveEveryFrameInOrderWithRigAndDecodedContent) {
  ServerConfig cfg = LoopbackConfig();
  cfg.queue_video_frames = 64;  // nominal load: no frame may be lost
  auto server = Server::Start(cfg);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  Rig rig;
  rig.name = "test-rig";
  rig.pods.resize(2);
  for (int i = 0; i < 2; ++i) {
    rig.pods[i].id = i;
    rig.pods[i].name = "pod" + std::to_string(i);
    rig.pods[i].depth = rig.pods[i].color = Intrinsics::FromFov(160, 120, 60.0);
  }
  (*server)->SetRig(rig);
  const test::EncodedContent content = test::MakeContent();

  std::vector<std::unique_ptr<SiteClient>> viewers;
  for (int i = 0; i < 2; ++i) {
    auto c = SiteClient::Start(ViewerOptions((*server)->port(), "viewer" + std::to_string(i)));
    ASSERT_TRUE(c.ok()) << c.status().ToString();
    ASSERT_TRUE((*c)->WaitConnected(5.0)) << (*c)->status().ToString();
    viewers.push_back(std::move(*c));
  }
  ASSERT_TRUE(Eventually([&] { return (*server)->num_subscribed(kContentGeometry) == 2; }));

  const int kFrames = 60;
  for (int i = 0; i < kFrames; ++i) {
    (*server)->PublishVideo(MakeVideoFrame(i, WallUs(), protocol::GeometryCodec::kG1, content.geometry, &content.color,
                                           cfg.fragment_bytes));
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  for (auto& v : viewers) {
    for (int i = 0; i < kFrames; ++i) {
      ReceivedFrame f;
      ASSERT_TRUE(v->WaitFrame(&f, 5.0)) << "frame " << i;
      EXPECT_EQ(f.frame_index, i);
      ASSERT_TRUE(f.has_mesh);
      ASSERT_TRUE(f.has_color);
      EXPECT_EQ(f.mesh.num_vertices(), content.vertices);
      ASSERT_EQ(f.images.size(), 2u);
      EXPECT_EQ(f.images[1].pod_id, 1);
      EXPECT_EQ(f.images[0].image.width(), 160);
      EXPECT_GE(f.latency_ms, -50.0);
    }
    ASSERT_TRUE(v->rig().has_value());
    EXPECT_EQ(v->rig()->name, "test-rig");
    EXPECT_EQ(v->rig()->pods.size(), 2u);
    EXPECT_EQ(v->stats().decode_errors, 0u);
  }
  for (const auto& s : (*server)->Sessions()) {
    EXPECT_EQ(s.video_frames_sent, static_cast<uint64_t>(kFrames)) << s.client_name;
    EXPECT_EQ(s.video_frames_dropped, 0u);
  }
  // RTT measured both ways.
  EXPECT_TRUE(Eventually([&] {
    for (const auto& s : (*server)->Sessions())
      if (s.rtt_ms < 0) return false;
    return viewers[0]->stats().rtt_ms >= 0;
  }));
}

// A raw-socket viewer of the geometry reading `bytes_per_10ms` every 10 ms
// (0: never reads).
std::unique_ptr<RawViewer> StartRawViewer(uint16_t port, size_t bytes_per_10ms, const std::string& name) {
  RawViewerOptions o;
  o.port = port;
  o.token = "view-secret";
  o.name = name;
  o.subscribe = kSubscribeGeometry;
  o.bytes_per_10ms = bytes_per_10ms;
  auto v = RawViewer::Start(o);
  HOLO_CHECK_MSG(v.ok(), v.status().ToString());
  return std::move(*v);
}

TEST(NetFanout, RecorderGetsRawMessagesByteIdentical) {
  ServerConfig cfg = LoopbackConfig();
  cfg.queue_video_frames = 64;
  cfg.fragment_bytes = 8192;  // several fragments per message: reassembly is exercised
  auto server = Server::Start(cfg);
  ASSERT_TRUE(server.ok());
  const test::EncodedContent content = test::MakeContent(60, 80);
  std::mutex mu;
  std::vector<RawMessage> raws;
  ClientOptions o = ViewerOptions((*server)->port(), "recorder");
  o.role = protocol::Role::kRecorder;
  o.decode = false;
  ClientCallbacks cb;
  cb.on_raw = [&](const RawMessage& m) {
    if (m.header.type != protocol::MessageType::kMeshFrame && m.header.type != protocol::MessageType::kColorFrame)
      return;
    std::lock_guard<std::mutex> l(mu);
    raws.push_back(m);
  };
  auto rec = SiteClient::Start(o, cb);
  ASSERT_TRUE(rec.ok());
  ASSERT_TRUE((*rec)->WaitConnected(5.0));
  ASSERT_TRUE(Eventually([&] { return (*server)->num_subscribed(kContentGeometry) == 1; }));
  for (int i = 0; i < 5; ++i)
    (*server)->PublishVideo(MakeVideoFrame(i, 1000 + i, protocol::GeometryCodec::kG1, content.geometry,
                                           &content.color, cfg.fragment_bytes));
  ASSERT_TRUE(Eventually([&] {
    std::lock_guard<std::mutex> l(mu);
    return raws.size() == 10;
  }));
  for (int i = 0; i < 5; ++i) {
    const RawMessage& mesh = raws[2 * i];
    const RawMessage& color = raws[2 * i + 1];
    ASSERT_EQ(mesh.header.type, protocol::MessageType::kMeshFrame);
    EXPECT_EQ(mesh.header.capture_time_us, 1000 + i);
    EXPECT_EQ(mesh.header.flags & protocol::kFlagMoreFragments, 0);
    EXPECT_EQ(mesh.header.payload_length, mesh.payload.size());
    EXPECT_EQ(mesh.payload, protocol::EncodePayload(protocol::MeshFrame{i, protocol::GeometryCodec::kG1,
                                                                        content.geometry}));
    protocol::ColorFrame c = content.color;
    c.frame_index = i;
    EXPECT_EQ(color.payload, protocol::EncodePayload(c));
  }
}

TEST(NetFanout, SlowAndStalledViewersDoNotAffectNormalViewers) {
  ServerConfig cfg = LoopbackConfig();
  // 24 frames (0.8 s) of slack: normal viewers survive scheduling hiccups
  // of a loaded machine; the stalled one still loses most of 90 frames.
  cfg.queue_video_frames = 24;
  cfg.socket_send_buffer = 64 << 10;
  auto server = Server::Start(cfg);
  ASSERT_TRUE(server.ok());
  const test::EncodedContent content = test::MakeContent(120, 160);  // ~50 KB per frame
  const size_t frame_bytes = content.geometry.size();
  std::vector<std::unique_ptr<SiteClient>> normal;
  for (int i = 0; i < 4; ++i) {
    ClientOptions o = ViewerOptions((*server)->port(), "normal" + std::to_string(i));
    o.decode = false;
    o.subscribe = kSubscribeGeometry;
    auto c = SiteClient::Start(o);
    ASSERT_TRUE(c.ok());
    ASSERT_TRUE((*c)->WaitConnected(5.0));
    normal.push_back(std::move(*c));
  }
  // 30 fps × frame_bytes per second; 1/10 of that per second = frame_bytes·3/100 per 10 ms.
  const auto slow = StartRawViewer((*server)->port(), std::max<size_t>(256, frame_bytes * 3 / 100), "slow");
  const auto stalled = StartRawViewer((*server)->port(), 0, "stalled");
  ASSERT_TRUE(Eventually([&] { return (*server)->num_subscribed(kContentGeometry) == 6; }));

  const int kFrames = 90;
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < kFrames; ++i) {
    (*server)->PublishVideo(
        MakeVideoFrame(i, WallUs(), protocol::GeometryCodec::kG1, content.geometry, nullptr, cfg.fragment_bytes));
    std::this_thread::sleep_until(start + std::chrono::microseconds(33333 * (i + 1)));
  }
  ASSERT_TRUE(Eventually([&] {
    for (auto& c : normal)
      if (c->stats().last_frame_index != kFrames - 1) return false;
    return true;
  }, 5.0));
  for (auto& c : normal) {
    const ClientStats s = c->stats();
    EXPECT_GE(s.frames_received, static_cast<uint64_t>(kFrames * 95 / 100)) << "normal viewer lost frames";
  }
  uint64_t stalled_dropped = 0, slow_dropped = 0;
  for (const auto& s : (*server)->Sessions()) {
    if (s.client_name == "stalled") stalled_dropped = s.video_frames_dropped;
    if (s.client_name == "slow") slow_dropped = s.video_frames_dropped;
    if (s.client_name.rfind("normal", 0) == 0) {
      EXPECT_GE(s.video_frames_sent, static_cast<uint64_t>(kFrames * 95 / 100));
    }
    EXPECT_LE(s.queue_video, static_cast<size_t>(cfg.queue_video_frames));
  }
  EXPECT_GT(stalled_dropped, static_cast<uint64_t>(kFrames / 2)) << "the stalled viewer should lose most frames";
  EXPECT_GT(slow_dropped, 0u) << "the slow viewer should lose frames";
  EXPECT_LT(slow->meshes(), kFrames);
}

TEST(NetFanout, AudioPoseFromPublisherReachesEveryAudioSubscriber) {
  ServerConfig cfg = LoopbackConfig();
  std::atomic<int> hooked{0};
  ServerHooks hooks;
  hooks.on_audio = [&](uint64_t, const protocol::AudioPose&) { ++hooked; };
  auto server = Server::Start(cfg, hooks);
  ASSERT_TRUE(server.ok());
  std::vector<std::unique_ptr<SiteClient>> viewers;
  for (int i = 0; i < 3; ++i) {
    ClientOptions o = ViewerOptions((*server)->port(), "v" + std::to_string(i));
    if (i == 2) o.subscribe = kSubscribeGeometry;  // no audio
    auto c = SiteClient::Start(o);
    ASSERT_TRUE(c.ok());
    ASSERT_TRUE((*c)->WaitConnected(5.0));
    viewers.push_back(std::move(*c));
  }
  ClientOptions po = ViewerOptions((*server)->port(), "participant");
  po.role = protocol::Role::kPublisher;
  po.token = "pub-secret";
  auto publisher = SiteClient::Start(po);
  ASSERT_TRUE(publisher.ok());
  ASSERT_TRUE((*publisher)->WaitConnected(5.0)) << (*publisher)->status().ToString();
  ASSERT_TRUE(Eventually([&] { return (*server)->num_subscribed(kContentAudio) == 2; }));

  const int kFrames = 50;
  for (int i = 0; i < kFrames; ++i) {
    protocol::AudioPose a;
    a.codec = protocol::AudioCodec::kPcm16;
    a.sample_rate = 8000;
    a.sequence = static_cast<uint32_t>(i);
    a.capture_time_us = 1000 + 20000 * i;
    a.pose.x = 0.01f * i;
    a.pose.yaw = 0.5f;
    a.audio.assign(320, static_cast<uint8_t>(i));  // 20 ms of 8 kHz s16 mono
    (*publisher)->SendAudioPose(a);
  }
  for (int v = 0; v < 2; ++v) {
    for (int i = 0; i < kFrames; ++i) {
      protocol::AudioPose a;
      uint32_t stream = 0;
      ASSERT_TRUE(Eventually([&] { return viewers[v]->PollAudio(&a, &stream); })) << "viewer " << v << " audio " << i;
      EXPECT_EQ(a.sequence, static_cast<uint32_t>(i));
      EXPECT_FLOAT_EQ(a.pose.x, 0.01f * i);
      EXPECT_EQ(a.audio.size(), 320u);
      EXPECT_EQ(a.audio[0], static_cast<uint8_t>(i));
      EXPECT_GE(stream, kFirstParticipantStreamId);
    }
  }
  protocol::AudioPose a;
  EXPECT_FALSE(viewers[2]->PollAudio(&a));
  EXPECT_EQ(viewers[2]->stats().audio_received, 0u);
  EXPECT_EQ(hooked.load(), kFrames);
  EXPECT_EQ((*server)->counters().audio_relayed, static_cast<uint64_t>(kFrames));
}

TEST(NetFanout, AudioJumpsAheadOfQueuedVideo) {
  ServerConfig cfg = LoopbackConfig();
  cfg.queue_video_frames = 16;
  cfg.socket_send_buffer = 4096;
  auto server = Server::Start(cfg);
  ASSERT_TRUE(server.ok());
  // A raw viewer that does not read yet: video piles up in its queue.
  auto p = RawPeer::Connect("127.0.0.1", (*server)->port());
  ASSERT_TRUE(p.ok());
  (*p)->SetReceiveBuffer(8 << 10);
  ASSERT_TRUE((*p)->SendHello(protocol::Role::kViewer, "view-secret", "reader").ok());
  ASSERT_TRUE((*p)->ReadMessage(5).ok());
  protocol::Control c;
  c.command = protocol::ControlCommand::kSubscribe;
  c.value = kContentAll;
  ASSERT_TRUE((*p)->SendMessage(c).ok());
  ASSERT_TRUE(Eventually([&] { return (*server)->num_subscribed(kContentAll) == 1; }));
  const test::EncodedContent content = test::MakeContent(120, 160);
  for (int i = 0; i < 10; ++i)
    (*server)->PublishVideo(
        MakeVideoFrame(i, WallUs(), protocol::GeometryCodec::kG1, content.geometry, nullptr, 4096));
  ASSERT_TRUE(Eventually([&] { return (*server)->Sessions()[0].queue_video >= 5; }));
  // Frames already written to the kernel cannot be overtaken; the ones still
  // in the server's queue must be.
  const SessionStats before = (*server)->Sessions()[0];
  protocol::AudioPose a;
  a.codec = protocol::AudioCodec::kOpus;
  a.audio = {1, 2, 3};
  (*server)->PublishAudio(a, kFirstParticipantStreamId);
  int meshes_before_audio = 0, meshes_after_audio = 0;
  bool audio_seen = false;
  while (meshes_before_audio + meshes_after_audio < 10) {
    auto m = (*p)->ReadMessage(5);
    ASSERT_TRUE(m.ok()) << m.status().ToString();
    if (m->header.type == protocol::MessageType::kAudioPose) audio_seen = true;
    if (m->header.type == protocol::MessageType::kMeshFrame) ++(audio_seen ? meshes_after_audio : meshes_before_audio);
  }
  ASSERT_TRUE(audio_seen);
  // At most the frames already written plus the one in flight came first.
  EXPECT_LE(meshes_before_audio, static_cast<int>(before.video_frames_sent) + 1)
      << "audio waited behind queued video frames";
  EXPECT_GE(meshes_after_audio, static_cast<int>(before.queue_video) - 1);
}

TEST(NetFanout, ClientReconnectsAfterServerRestart) {
  ServerConfig cfg = LoopbackConfig();
  auto server = Server::Start(cfg);
  ASSERT_TRUE(server.ok());
  const uint16_t port = (*server)->port();
  ClientOptions o = ViewerOptions(port, "reconnecting");
  o.backoff_initial_s = 0.02;
  o.backoff_max_s = 0.2;
  std::atomic<int> backoffs{0};
  ClientCallbacks cb;
  cb.on_state = [&](ClientState s, const Status&) {
    if (s == ClientState::kBackoff) ++backoffs;
  };
  auto client = SiteClient::Start(o, cb);
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->WaitConnected(5.0));
  (*server)->Stop();
  server->reset();
  ASSERT_TRUE(Eventually([&] { return backoffs.load() >= 2; }, 5.0)) << "client did not back off and retry";
  cfg.port = port;
  auto again = Server::Start(cfg);
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  ASSERT_TRUE(Eventually([&] { return (*client)->stats().connects == 2; }, 5.0)) << (*client)->status().ToString();
  ASSERT_TRUE(Eventually([&] { return (*again)->num_subscribed(kContentGeometry) == 1; }));
  const test::EncodedContent content = test::MakeContent(10, 10);
  (*again)->PublishVideo(MakeVideoFrame(7, WallUs(), protocol::GeometryCodec::kG1, content.geometry, nullptr, 65536));
  ReceivedFrame f;
  ASSERT_TRUE((*client)->WaitFrame(&f, 5.0));
  EXPECT_EQ(f.frame_index, 7);
  EXPECT_GE((*client)->stats().connect_failures, 1u);
}

}  // namespace
}  // namespace holo::net
