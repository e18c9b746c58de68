// Quality layers on the live path (net/layer_control.h, SitePublisher's
// reduced layer): a viewer that cannot keep up is moved to the reduced layer
// and back when it can, while a fast viewer stays on the full one; each frame
// is encoded once per layer whatever the audience, and the reduced layer only
// while someone receives it; a viewer capping its quality gets the reduced
// layer; with V1 colour a viewer changes layer only at a key frame, so every
// picture it gets decodes.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <memory>
#include <thread>
#include <vector>

#include "client/net/raw_peer.h"
#include "common/image.h"
#include "net/net_fixtures.h"
#include "net/site_client.h"
#include "protocol/messages.h"
#include "protocol/test_meshes.h"
#include "server/net/site_publisher.h"

namespace holo {
namespace {

net::ServerConfig LayerConfig() {
  net::ServerConfig c = test::LoopbackConfig();
  c.socket_send_buffer = 64 << 10;  // a small kernel buffer: the queue shows a slow viewer soon
  c.layers.up_hold_s = 0.5;
  c.layers.max_up_hold_s = 2;
  return c;
}

net::SessionStats StatsOf(net::Server* server, const std::string& name) {
  for (const auto& s : server->Sessions())
    if (s.client_name == name) return s;
  return {};
}

// Publishes synthetic frames at 30 fps: layer 0 of `full_bytes`, and layer 1
// of `reduced_bytes` on every other frame (the server does not parse them).
class Publisher {
 public:
  Publisher(net::Server* server, size_t full_bytes, size_t reduced_bytes) {
    thread_ = std::thread([=, this] {
      std::vector<uint8_t> full(full_bytes, 0x11), reduced(reduced_bytes, 0x22);
      for (int64_t i = 0; !stop_; ++i) {
        const auto t0 = std::chrono::steady_clock::now();
        server->PublishVideo(net::MakeVideoFrame(i, net::WallUs(), protocol::GeometryCodec::kG1, full, nullptr,
                                                 server->config().fragment_bytes, net::kSiteStreamId, 0, true));
        if (i % 2 == 0)
          server->PublishVideo(net::MakeVideoFrame(i, net::WallUs(), protocol::GeometryCodec::kG1, reduced, nullptr,
                                                   server->config().fragment_bytes, net::kSiteStreamId, 1, true));
        std::this_thread::sleep_until(t0 + std::chrono::milliseconds(33));
      }
    });
  }
  ~Publisher() {
    stop_ = true;
    thread_.join();
  }

 private:
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

std::unique_ptr<net::RawViewer> StartViewer(net::Server* server, const std::string& name, size_t bytes_per_10ms) {
  net::RawViewerOptions o;
  o.port = server->port();
  o.token = "view-secret";
  o.name = name;
  o.subscribe = 3;
  o.receive_buffer = 32 << 10;
  o.bytes_per_10ms = bytes_per_10ms;
  auto v = net::RawViewer::Start(o);
  HOLO_CHECK(v.ok());
  return std::move(*v);
}

// The longest time between two whole frames the viewer read after `from_us`, ms.
double LongestGapMs(const net::RawViewer& v, int64_t from_us) {
  const std::vector<int64_t> t = v.mesh_times_us();
  double gap = 0;
  for (size_t i = 1; i < t.size(); ++i)
    if (t[i - 1] >= from_us) gap = std::max(gap, (t[i] - t[i - 1]) * 1e-3);
  return gap;
}

// "v<i>" (appended: GCC 12 warns falsely on "v" + std::to_string(i)).
std::string ViewerName(size_t i) {
  std::string name = "v";
  name += std::to_string(i);
  return name;
}

int64_t SteadyNowUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

TEST(FanoutLayersTest, ASlowViewerMovesDownAndBackUpWhileAFastOneStaysOnTheFullLayer) {
  auto server = test::StartServerRetrying(LayerConfig());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  net::Server* srv = server->get();
  srv->SetLayers(2);
  // Layer 0: 40 kB × 30 fps = 1.2 MB/s; layer 1: 8 kB × 15 fps = 0.12 MB/s.
  auto fast = StartViewer(srv, "fast", 1 << 20);
  auto slow = StartViewer(srv, "slow", 4000);  // 0.4 MB/s: between the two layers
  ASSERT_TRUE(test::Eventually([&] { return srv->num_subscribed(3) == 2; }));
  Publisher pub(srv, 40000, 8000);

  ASSERT_TRUE(test::Eventually([&] { return StatsOf(srv, "slow").layer == 1; }, 10))
      << "the slow viewer was not moved to the reduced layer";
  EXPECT_TRUE(test::Eventually([&] { return slow->layer() == 1; }, 5)) << "no Stats told the viewer its layer";
  const net::SessionStats down = StatsOf(srv, "slow");
  EXPECT_GE(down.layer_switches_down, 1u);
  EXPECT_FALSE(down.layer_reason.empty());
  EXPECT_GT(srv->ViewersOnLayer(1), 0u);
  // On the reduced layer the slow viewer keeps getting frames, about 15 a second.
  int64_t since = SteadyNowUs();
  const int64_t before = slow->meshes();
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  if (StatsOf(srv, "slow").layer == 1) {  // (it may probe up meanwhile; then this window says nothing)
    EXPECT_GE(slow->meshes() - before, 12) << "the reduced layer does not reach the slow viewer";
    EXPECT_LT(LongestGapMs(*slow, since), 400.0);
  }

  // The viewer's link gets fast: it probes up after the hold and stays up.
  slow->SetRate(1 << 20);
  ASSERT_TRUE(test::Eventually([&] { return StatsOf(srv, "slow").layer == 0; }, 10))
      << "the viewer did not return to the full layer";
  since = SteadyNowUs();
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  EXPECT_EQ(StatsOf(srv, "slow").layer, 0) << StatsOf(srv, "slow").layer_reason;
  EXPECT_EQ(slow->layer(), 0);
  EXPECT_LT(LongestGapMs(*slow, since), 500.0) << "frames stall on the full layer";

  const net::SessionStats f = StatsOf(srv, "fast");
  EXPECT_EQ(f.layer, 0);
  EXPECT_EQ(f.layer_switches, 0u) << "the fast viewer was moved: " << f.layer_reason;
  EXPECT_GE(srv->counters().layer_switches, 2u);
  EXPECT_NEAR(srv->LayerMbps(0), 9.6, 4.0);
  EXPECT_NEAR(srv->LayerMbps(1), 0.96, 0.4);
}

// Viewers move only by their quality cap: a decoding client slowed down by
// the sanitizers or a loaded machine must not be moved by its queue here.
net::ServerConfig FixedLayerConfig() {
  net::ServerConfig c = test::LoopbackConfig();
  c.layers.adaptive = false;
  return c;
}

net::SitePublisherOptions Options(protocol::ColorCodec codec) {
  net::SitePublisherOptions o;
  o.color_options.codec = codec;
  o.reduced.frame_divisor = 2;
  return o;
}

std::unique_ptr<net::SiteClient> Connect(net::Server* server, const std::string& name) {
  net::ClientOptions o;
  o.port = server->port();
  o.token = "view-secret";
  o.name = name;
  o.color_wait_s = 1.0;
  o.max_pending_frames = 64;
  auto c = net::SiteClient::Start(o);
  HOLO_CHECK(c.ok());
  return std::move(*c);
}

// Two pods with pictures that change every frame.
struct Pods {
  ImageRgb8 image[2];
  ImageGray8 mask[2];
  void Frame(int64_t i) {
    for (int p = 0; p < 2; ++p) {
      test::MaskedImage(160, 120, &image[p], &mask[p], static_cast<uint32_t>(p + 1 + i % 7));
    }
  }
  std::vector<net::PodColor> List() { return {{0, &image[0], &mask[0]}, {1, &image[1], &mask[1]}}; }
};

TEST(FanoutLayersTest, EachFrameIsEncodedOncePerLayerAndTheReducedOnlyWhenSomeoneWatchesIt) {
  auto server = test::StartServerRetrying(FixedLayerConfig());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  net::Server* srv = server->get();
  net::SitePublisher pub(srv, Options(protocol::ColorCodec::kC1));
  EXPECT_EQ(srv->num_layers(), 2);
  const Mesh mesh = test::NoisySphere(20, 30);
  Pods pods;
  std::vector<std::unique_ptr<net::SiteClient>> viewers;
  for (int i = 0; i < 12; ++i) viewers.push_back(Connect(srv, ViewerName(static_cast<size_t>(i))));
  for (auto& v : viewers) ASSERT_TRUE(v->WaitConnected(10));
  ASSERT_TRUE(test::Eventually([&] { return srv->num_subscribed(3) == viewers.size(); }));

  int64_t index = 0;
  auto publish = [&](int n) {
    for (int k = 0; k < n; ++k, ++index) {
      pods.Frame(index);
      net::PublishTimings t;
      ASSERT_TRUE(pub.Publish(index, net::WallUs(), mesh, pods.List(), &t).ok());
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  };
  publish(10);
  EXPECT_EQ(pub.frames_encoded(0), 10);
  EXPECT_EQ(pub.frames_encoded(1), 0) << "nobody watches the reduced layer: it must cost nothing";

  // One viewer caps its quality: it is moved to the reduced layer.
  viewers[0]->SetQuality(2);
  ASSERT_TRUE(test::Eventually([&] { return srv->ViewersOnLayer(1) == 1; }));
  publish(20);
  EXPECT_EQ(pub.frames_encoded(0), 30) << "once per frame, whatever the audience";
  EXPECT_EQ(pub.frames_encoded(1), 10) << "every other frame, once";
  ASSERT_TRUE(test::Eventually([&] { return viewers[0]->stats().layer == 1; }));
  EXPECT_EQ(viewers[0]->stats().num_layers, 2);
  EXPECT_EQ(viewers[0]->stats().layer_step, 2) << "the reduced layer carries every other frame";
  EXPECT_EQ(viewers[1]->stats().layer_step, 1);
  EXPECT_EQ(StatsOf(srv, "v0").layer, 1);
  for (size_t i = 1; i < viewers.size(); ++i) EXPECT_EQ(StatsOf(srv, ViewerName(i)).layer, 0);
  // The capped viewer decodes its frames (coarser, but whole) and the others keep the full rate.
  net::ReceivedFrame f;
  int capped = 0, full = 0;
  // (Frames may still be on their way: poll until they are in or 5 s pass.)
  test::Eventually([&] {
    while (viewers[0]->PollFrame(&f)) {
      EXPECT_TRUE(f.has_mesh && f.has_color);
      EXPECT_EQ(f.images.size(), 2u);
      ++capped;
    }
    while (viewers[1]->PollFrame(&f)) ++full;
    return capped >= 10 && full >= 30;
  });
  EXPECT_GE(capped, 8);
  EXPECT_EQ(viewers[0]->stats().decode_errors, 0u);
  EXPECT_EQ(full, 30);
}

TEST(FanoutLayersTest, WithVideoColourAViewerChangesLayerOnlyAtAKeyFrame) {
  auto server = test::StartServerRetrying(FixedLayerConfig());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  net::Server* srv = server->get();
  net::SitePublisher pub(srv, Options(protocol::ColorCodec::kV1));
  const Mesh mesh = test::NoisySphere(20, 30);
  Pods pods;
  auto viewer = Connect(srv, "v");
  ASSERT_TRUE(viewer->WaitConnected(10));
  ASSERT_TRUE(test::Eventually([&] { return srv->num_subscribed(3) == 1; }));
  int64_t index = 0;
  int frames = 0;
  auto publish = [&](int n) {
    for (int k = 0; k < n; ++k, ++index) {
      pods.Frame(index);
      net::PublishTimings t;
      ASSERT_TRUE(pub.Publish(index, net::WallUs(), mesh, pods.List(), &t).ok());
      std::this_thread::sleep_for(std::chrono::milliseconds(30));
      net::ReceivedFrame f;
      while (viewer->PollFrame(&f)) {
        ++frames;
        EXPECT_TRUE(f.has_color) << "frame " << f.frame_index;
        EXPECT_EQ(f.images.size(), 2u) << "frame " << f.frame_index << ": a picture did not decode";
      }
    }
  };
  publish(20);
  viewer->SetQuality(0);  // down: the reduced layer starts with key frames
  ASSERT_TRUE(test::Eventually([&] { return srv->ViewersOnLayer(1) == 1; }));
  publish(30);
  EXPECT_EQ(StatsOf(srv, "v").layer, 1);
  viewer->SetQuality(10);  // up: waits for the full layer's key frame (requested by the move)
  publish(40);
  EXPECT_EQ(StatsOf(srv, "v").layer, 0);
  EXPECT_EQ(StatsOf(srv, "v").layer_switches, 2u);
  EXPECT_TRUE(test::Eventually([&] { return viewer->stats().layer == 0 && viewer->stats().layer_changes == 2; }));
  EXPECT_EQ(viewer->stats().color_images_waiting, 0u) << "a delta frame of the other layer reached the decoder";
  EXPECT_EQ(viewer->stats().decode_errors, 0u);
  // 20 + 40 full frames and 15 reduced ones, less the few around each move.
  EXPECT_GE(frames, 55);
}

}  // namespace
}  // namespace holo
