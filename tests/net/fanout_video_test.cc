// The live path with V1 colour (per-pod inter-frame video): a site that
// publishes V1 reaches its viewers with every pod's picture, a viewer that
// joins mid-stream gets a key frame on the next frame instead of waiting for
// the periodic one, a viewer's key-frame request reaches the publisher, and a
// client that lacks the frame a delta depends on shows no stale picture and
// asks for a key frame.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

#include "common/image.h"
#include "net/net_fixtures.h"
#include "net/site_client.h"
#include "protocol/messages.h"
#include "protocol/test_meshes.h"
#include "protocol/video_codec.h"
#include "server/net/site_publisher.h"

namespace holo {
namespace {

// Two pods whose pictures move a little every frame (a delta frame then
// carries real motion, not a copy).
struct MovingPods {
  ImageRgb8 image[2];
  ImageGray8 mask[2];
  void Frame(int64_t index) {
    for (int p = 0; p < 2; ++p) {
      test::MaskedImage(160, 120, &image[p], &mask[p], static_cast<uint32_t>(p + 1));
      // Shift the content by `index` pixels (wrapping) so consecutive frames differ.
      ImageRgb8 shifted = image[p];
      const int dx = static_cast<int>(index % 16);
      for (int y = 0; y < image[p].height(); ++y)
        for (int x = 0; x < image[p].width(); ++x) {
          const int sx = (x + dx) % image[p].width();
          for (int c = 0; c < 3; ++c) shifted.at(x, y, c) = image[p].at(sx, y, c);
        }
      image[p] = shifted;
    }
  }
  std::vector<net::PodColor> Pods() { return {{0, &image[0], &mask[0]}, {1, &image[1], &mask[1]}}; }
};

// PSNR over the mask's foreground of a decoded picture against its source.
double ForegroundPsnr(const ImageRgb8& a, const ImageRgb8& b, const ImageGray8& mask) {
  double se = 0;
  size_t n = 0;
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x) {
      if (mask.at(x, y) == 0) continue;
      for (int c = 0; c < 3; ++c) {
        const double d = static_cast<double>(a.at(x, y, c)) - b.at(x, y, c);
        se += d * d;
      }
      n += 3;
    }
  if (n == 0) return 0;
  const double mse = se / static_cast<double>(n);
  return mse <= 0 ? 99.0 : 10.0 * std::log10(255.0 * 255.0 / mse);
}

net::SitePublisherOptions VideoOptions() {
  net::SitePublisherOptions o;
  o.color_options.codec = protocol::ColorCodec::kV1;
  o.reduced.enabled = false;  // the full layer's key frames (layers: fanout_layers_test)
  return o;
}

std::unique_ptr<net::SiteClient> Connect(net::Server* server) {
  net::ClientOptions o;
  o.port = server->port();
  o.token = "view-secret";
  o.color_wait_s = 1.0;
  auto c = net::SiteClient::Start(o);
  HOLO_CHECK(c.ok());
  return std::move(*c);
}

TEST(FanoutVideoTest, ViewersDecodeEveryPodAndALateViewerGetsAKeyFrameAtOnce) {
  auto server = test::StartServerRetrying(test::LoopbackConfig());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  net::SitePublisher pub(server->get(), VideoOptions());
  const Mesh mesh = test::NoisySphere(20, 30);
  MovingPods pods;

  auto first = Connect(server->get());
  ASSERT_TRUE(first->WaitConnected(10));
  ASSERT_TRUE(test::Eventually([&] { return (*server)->num_subscribed(3) == 1; }));
  int64_t index = 0;
  // 70 frames: past the periodic key frame at 60, so the stream is in the
  // middle of a group of pictures when the second viewer joins.
  int decoded = 0;
  for (; index < 70; ++index) {
    pods.Frame(index);
    net::PublishTimings t;
    ASSERT_TRUE(pub.Publish(index, net::WallUs(), mesh, pods.Pods(), &t).ok());
    net::ReceivedFrame f;
    ASSERT_TRUE(first->WaitFrame(&f, 5.0)) << "frame " << index;
    ASSERT_TRUE(f.has_color) << "frame " << index;
    ASSERT_EQ(f.images.size(), 2u) << "frame " << index << ": a pod's picture is missing";
    for (const auto& im : f.images) {
      ASSERT_LT(im.pod_id, 2);
      EXPECT_GT(ForegroundPsnr(im.image, pods.image[im.pod_id], pods.mask[im.pod_id]), 30.0)
          << "frame " << index << " pod " << im.pod_id;
    }
    ++decoded;
  }
  EXPECT_EQ(decoded, 70);
  EXPECT_EQ(first->stats().color_images_waiting, 0u);

  // A second viewer joins mid-stream: the very next frame is a key frame on
  // every pod, and it decodes both pictures from it.
  auto late = Connect(server->get());
  ASSERT_TRUE(late->WaitConnected(10));
  ASSERT_TRUE(test::Eventually([&] { return (*server)->num_subscribed(3) == 2; }));
  // Let the 250 ms limit between forced key frames pass (the first viewer's
  // join forced one at frame 0, 70 frames ago; publishing took < 250 ms on a
  // fast machine).
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  pods.Frame(index);
  net::PublishTimings t;
  ASSERT_TRUE(pub.Publish(index, net::WallUs(), mesh, pods.Pods(), &t).ok());
  EXPECT_TRUE(t.color_keyframe) << "no key frame for the viewer that joined";
  net::ReceivedFrame f;
  ASSERT_TRUE(late->WaitFrame(&f, 5.0));
  ASSERT_TRUE(f.has_color);
  EXPECT_EQ(f.images.size(), 2u);
  ++index;

  // The next frame is a delta frame again (no key frame without a reason).
  pods.Frame(index);
  ASSERT_TRUE(pub.Publish(index, net::WallUs(), mesh, pods.Pods(), &t).ok());
  EXPECT_FALSE(t.color_keyframe);
  ASSERT_TRUE(late->WaitFrame(&f, 5.0));
  EXPECT_EQ(f.images.size(), 2u);
}

TEST(FanoutVideoTest, AKeyFrameRequestReachesThePublisher) {
  auto server = test::StartServerRetrying(test::LoopbackConfig());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  net::SitePublisher pub(server->get(), VideoOptions());
  const Mesh mesh = test::NoisySphere(20, 30);
  MovingPods pods;
  auto viewer = Connect(server->get());
  ASSERT_TRUE(viewer->WaitConnected(10));
  const uint64_t before = (*server)->counters().keyframe_requests;
  protocol::Control c;
  c.command = protocol::ControlCommand::kRequestKeyFrame;
  viewer->SendControl(c);
  ASSERT_TRUE(test::Eventually([&] { return (*server)->counters().keyframe_requests > before; }));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  // Frame 0 is a key frame anyway (a new stream); frame 1 is one only because
  // of the request, frame 2 is not.
  pods.Frame(0);
  net::PublishTimings t;
  ASSERT_TRUE(pub.Publish(0, net::WallUs(), mesh, pods.Pods(), &t).ok());
  EXPECT_TRUE(t.color_keyframe);
  viewer->SendControl(c);
  ASSERT_TRUE(test::Eventually([&] { return (*server)->counters().keyframe_requests > before + 1; }));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  pods.Frame(1);
  ASSERT_TRUE(pub.Publish(1, net::WallUs(), mesh, pods.Pods(), &t).ok());
  EXPECT_TRUE(t.color_keyframe) << "the request did not force a key frame";
  pods.Frame(2);
  ASSERT_TRUE(pub.Publish(2, net::WallUs(), mesh, pods.Pods(), &t).ok());
  EXPECT_FALSE(t.color_keyframe);
}

// A viewer that receives a delta frame without its predecessor (here: the
// publisher's stream started before the viewer's decoder saw a key frame,
// forced by encoding directly) shows no picture for that pod and asks the
// site for a key frame.
TEST(FanoutVideoTest, AViewerMissingAFrameAsksForAKeyFrame) {
  auto server = test::StartServerRetrying(test::LoopbackConfig());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  // Encode two frames of one pod; send only the second (a delta) in a
  // ColorFrame, as if the first had been lost.
  auto enc = protocol::VideoEncoder::Create({});
  ASSERT_TRUE(enc.ok());
  MovingPods pods;
  std::vector<uint8_t> key, delta;
  pods.Frame(0);
  ASSERT_TRUE((*enc)->Encode(pods.image[0], pods.mask[0], &key).ok());
  pods.Frame(1);
  ASSERT_TRUE((*enc)->Encode(pods.image[0], pods.mask[0], &delta).ok());
  (*server)->SetPublishedCodecs(protocol::GeometryCodec::kG1, protocol::ColorCodec::kV1);

  auto viewer = Connect(server->get());
  ASSERT_TRUE(viewer->WaitConnected(10));
  // Frames go to subscribed viewers only; the subscription follows Welcome.
  ASSERT_TRUE(test::Eventually([&] { return (*server)->num_subscribed(3) == 1; }));
  const uint64_t before = (*server)->counters().keyframe_requests;
  protocol::ColorFrame cf;
  cf.frame_index = 1;
  cf.codec = protocol::ColorCodec::kV1;
  cf.images.push_back({0, delta});
  std::vector<uint8_t> geometry;
  ASSERT_TRUE(protocol::EncodeGeometry(test::NoisySphere(20, 30), {}, &geometry).ok());
  (*server)->PublishVideo(net::MakeVideoFrame(1, net::WallUs(), protocol::GeometryCodec::kG1, geometry, &cf,
                                              (*server)->config().fragment_bytes));
  net::ReceivedFrame f;
  ASSERT_TRUE(viewer->WaitFrame(&f, 5.0));
  EXPECT_TRUE(f.has_mesh);
  EXPECT_TRUE(f.images.empty()) << "a delta frame without its key frame was shown";
  EXPECT_EQ(viewer->stats().color_images_waiting, 1u);
  EXPECT_EQ(viewer->stats().decode_errors, 0u) << "waiting for a key frame is not an error";
  ASSERT_TRUE(test::Eventually([&] { return (*server)->counters().keyframe_requests > before; }))
      << "the viewer did not ask for a key frame";

  // The key frame arrives: the pod's picture is shown again.
  cf.frame_index = 2;
  cf.images[0].data = key;
  (*server)->PublishVideo(net::MakeVideoFrame(2, net::WallUs(), protocol::GeometryCodec::kG1, geometry, &cf,
                                              (*server)->config().fragment_bytes));
  ASSERT_TRUE(viewer->WaitFrame(&f, 5.0));
  ASSERT_EQ(f.images.size(), 1u);
  EXPECT_GT(ForegroundPsnr(f.images[0].image, [&] {
              MovingPods p;
              p.Frame(0);
              return p.image[0];
            }(), pods.mask[0]),
            30.0);
}

}  // namespace
}  // namespace holo
