// The live path with G3 geometry (protocol/surface_codec.h): a site that
// publishes the stream mesh's distance grid reaches its native viewers as a
// mesh on the surface, a frame without its grid is refused with a reason,
// and a viewer that cannot decode G3 (one that lists only G1 and G0) is
// refused with a message naming the codec. A site whose full layer is G1 +
// C1 may code its reduced layer as G3 + V1: viewers that decode those get it,
// the others stay on the full layer.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <thread>
#include <vector>

#include "common/image.h"
#include "common/sdf_grid.h"
#include "net/net_fixtures.h"
#include "net/site_client.h"
#include "protocol/messages.h"
#include "protocol/test_meshes.h"
#include "server/net/site_publisher.h"

namespace holo {
namespace {

constexpr float kRadius = 0.2f;

// A ball of radius kRadius at `centre`, as the distance grid a fused volume
// gives (16 mm samples, truncated at 32 mm, unobserved deep inside).
SdfGrid BallGrid(const Eigen::Vector3f& centre) {
  SdfGrid g;
  g.voxel_m = 0.016f;
  g.origin = centre - Eigen::Vector3f::Constant(0.3f);
  g.nx = g.ny = g.nz = 38;
  g.sdf.resize(g.size());
  for (int z = 0; z < g.nz; ++z)
    for (int y = 0; y < g.ny; ++y)
      for (int x = 0; x < g.nx; ++x) {
        const Eigen::Vector3f p = g.origin + g.voxel_m * Eigen::Vector3f(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
        const float d = (p - centre).norm() - kRadius;
        g.sdf[g.Index(x, y, z)] = d < -0.05f ? std::nanf("") : std::clamp(d, -0.032f, 0.032f);
      }
  return g;
}

net::SitePublisherOptions SurfaceOptions() {
  net::SitePublisherOptions o;
  o.geometry.codec = protocol::GeometryCodec::kG3;
  o.reduced.enabled = false;
  o.color = false;
  return o;
}

net::ClientOptions Viewer(net::Server* server) {
  net::ClientOptions o;
  o.port = server->port();
  o.token = "view-secret";
  return o;
}

// A site (G3 publisher) and one connected viewer.
struct SiteAndViewer {
  std::unique_ptr<net::Server> server;
  std::unique_ptr<net::SitePublisher> pub;
  std::unique_ptr<net::SiteClient> viewer;
};
void Connect(SiteAndViewer* c) {
  auto server = test::StartServerRetrying(test::LoopbackConfig());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  c->server = std::move(server).value();
  c->pub = std::make_unique<net::SitePublisher>(c->server.get(), SurfaceOptions());
  auto viewer = net::SiteClient::Start(Viewer(c->server.get()));
  ASSERT_TRUE(viewer.ok());
  c->viewer = std::move(viewer).value();
  ASSERT_TRUE(c->viewer->WaitConnected(10));
  ASSERT_TRUE(test::Eventually([&] { return c->server->num_subscribed(3) == 1; }));
}

TEST(FanoutSurfaceTest, ViewersGetTheSurfaceFromTheGrid) {
  SiteAndViewer c;
  ASSERT_NO_FATAL_FAILURE(Connect(&c));
  ASSERT_EQ(c.viewer->welcome()->geometry_codec, protocol::GeometryCodec::kG3);
  // The stand-in mesh goes with the grid (regions and logs use it); what
  // travels is the grid's surface.
  const Mesh stand_in = test::NoisySphere(10, 12);
  for (int64_t index = 0; index < 5; ++index) {
    const Eigen::Vector3f centre(0.01f * static_cast<float>(index), 1.0f, 2.0f);
    const SdfGrid grid = BallGrid(centre);
    net::PublishTimings t;
    ASSERT_TRUE(c.pub->Publish(index, net::WallUs(), stand_in, {}, &t, &grid).ok());
    EXPECT_GT(t.geometry_bytes, 100u);
    net::ReceivedFrame f;
    ASSERT_TRUE(c.viewer->WaitFrame(&f, 5.0)) << "frame " << index;
    ASSERT_TRUE(f.has_mesh);
    ASSERT_GT(f.mesh.num_triangles(), 1000u) << "frame " << index;
    ASSERT_EQ(f.mesh.normals.size(), f.mesh.num_vertices());
    double worst = 0;
    for (const auto& p : f.mesh.positions) worst = std::max(worst, std::abs(static_cast<double>((p - centre).norm() - kRadius)));
    EXPECT_LT(worst, 0.004) << "frame " << index;
  }
  // A frame without its grid is refused, naming what is missing.
  net::PublishTimings t;
  const Status s = c.pub->Publish(5, net::WallUs(), stand_in, {}, &t);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("G3"), std::string::npos) << s.ToString();
}

TEST(FanoutSurfaceTest, ASurfaceTooWideForG3GoesOutAsG1) {
  SiteAndViewer c;
  ASSERT_NO_FATAL_FAILURE(Connect(&c));
  // Two balls at opposite corners of a 262³ grid (4.2 m at 16 mm): more
  // than G3's grid limit even when cut to the surface.
  const float voxel = 0.016f;
  SdfGrid wide;
  wide.voxel_m = voxel;
  wide.nx = wide.ny = wide.nz = 262;
  wide.sdf.assign(wide.size(), std::nanf(""));
  for (const int corner : {8, 253}) {
    const SdfGrid ball = BallGrid(Eigen::Vector3f::Constant(voxel * static_cast<float>(corner)));
    const int o = static_cast<int>(std::lround(ball.origin.x() / voxel));
    for (int z = 0; z < ball.nz; ++z)
      for (int y = 0; y < ball.ny; ++y)
        for (int x = 0; x < ball.nx; ++x)
          if (o + x >= 0 && o + y >= 0 && o + z >= 0 && o + x < 262 && o + y < 262 && o + z < 262)
            wide.sdf[wide.Index(o + x, o + y, o + z)] = ball.sdf[ball.Index(x, y, z)];
  }
  const Mesh stand_in = test::NoisySphere(10, 12);
  net::PublishTimings t;
  ASSERT_TRUE(c.pub->Publish(0, net::WallUs(), stand_in, {}, &t, &wide).ok());
  EXPECT_TRUE(t.geometry_fallback);
  net::ReceivedFrame f;
  ASSERT_TRUE(c.viewer->WaitFrame(&f, 5.0));
  ASSERT_TRUE(f.has_mesh);
  EXPECT_EQ(f.mesh.num_triangles(), stand_in.num_triangles()) << "the mesh, as G1";
  // The next frame that fits is G3 again.
  const SdfGrid grid = BallGrid(Eigen::Vector3f(0.0f, 1.0f, 2.0f));
  ASSERT_TRUE(c.pub->Publish(1, net::WallUs(), stand_in, {}, &t, &grid).ok());
  EXPECT_FALSE(t.geometry_fallback);
  ASSERT_TRUE(c.viewer->WaitFrame(&f, 5.0));
  ASSERT_GT(f.mesh.num_triangles(), 1000u);
  EXPECT_NE(f.mesh.num_triangles(), stand_in.num_triangles());
}

TEST(FanoutSurfaceTest, AViewerWithoutG3IsRefusedNamingTheCodec) {
  auto server = test::StartServerRetrying(test::LoopbackConfig());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  net::SitePublisher pub(server->get(), SurfaceOptions());
  net::ClientOptions o = Viewer(server->get());
  o.capabilities.geometry = {protocol::GeometryCodec::kG1, protocol::GeometryCodec::kG0};
  auto viewer = net::SiteClient::Start(o);
  ASSERT_TRUE(viewer.ok());
  EXPECT_FALSE((*viewer)->WaitConnected(5.0));
  EXPECT_EQ((*viewer)->state(), net::ClientState::kRefused);
  ASSERT_TRUE((*viewer)->refusal().has_value());
  EXPECT_EQ((*viewer)->refusal()->reason, protocol::RefuseReason::kNoCommonCodec);
  EXPECT_NE((*viewer)->refusal()->message.find("G3"), std::string::npos) << (*viewer)->refusal()->message;
}

TEST(FanoutSurfaceTest, AReducedLayerInG3AndV1ReachesOnlyTheViewersThatDecodeIt) {
  net::ServerConfig cfg = test::LoopbackConfig();
  cfg.layers.adaptive = false;  // viewers move by their quality cap only
  auto server = test::StartServerRetrying(cfg);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  net::Server* srv = server->get();
  net::SitePublisherOptions o;  // full layer: G1 + C1
  o.reduced.frame_divisor = 1;
  o.reduced.geometry_codec = protocol::GeometryCodec::kG3;
  o.reduced.color_codec = protocol::ColorCodec::kV1;
  net::SitePublisher pub(srv, o);
  EXPECT_TRUE(net::PublisherNeedsField(o));

  net::ClientOptions can = Viewer(srv);
  can.name = "can";
  can.max_pending_frames = 64;
  net::ClientOptions cannot = can;
  cannot.name = "cannot";
  cannot.capabilities.geometry = {protocol::GeometryCodec::kG1, protocol::GeometryCodec::kG0};
  cannot.capabilities.color = {protocol::ColorCodec::kC1, protocol::ColorCodec::kC0};
  auto a = net::SiteClient::Start(can);
  auto b = net::SiteClient::Start(cannot);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_TRUE((*a)->WaitConnected(10));
  ASSERT_TRUE((*b)->WaitConnected(10)) << "the full layer's codecs are the handshake's";
  ASSERT_TRUE(test::Eventually([&] { return srv->num_subscribed(3) == 2; }));
  (*a)->SetQuality(0);
  (*b)->SetQuality(0);
  ASSERT_TRUE(test::Eventually([&] { return srv->ViewersOnLayer(1) == 1; }));

  const Mesh stand_in = test::NoisySphere(10, 12);
  const SdfGrid grid = BallGrid(Eigen::Vector3f(0.0f, 1.0f, 2.0f));
  ImageRgb8 image[2];
  ImageGray8 mask[2];
  net::PublishTimings t;
  EXPECT_EQ(pub.Publish(0, net::WallUs(), stand_in, {}, &t).code(), StatusCode::kInvalidArgument)
      << "the reduced layer's G3 needs the grid";
  for (int64_t i = 1; i <= 12; ++i) {
    for (int p = 0; p < 2; ++p) test::MaskedImage(160, 120, &image[p], &mask[p], static_cast<uint32_t>(p + 1 + i % 5));
    ASSERT_TRUE(pub.Publish(i, net::WallUs(), stand_in, {{0, &image[0], &mask[0]}, {1, &image[1], &mask[1]}}, &t, &grid).ok());
    EXPECT_TRUE(t.reduced) << "frame " << i;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  // "can" decodes the reduced layer: the grid's surface and V1 pictures.
  int surfaces = 0, meshes = 0;
  net::ReceivedFrame f;
  test::Eventually([&] {
    while ((*a)->PollFrame(&f)) {
      if (f.frame_index == 0) continue;  // (refused above: never sent)
      EXPECT_TRUE(f.has_mesh && f.has_color) << "frame " << f.frame_index;
      EXPECT_EQ(f.images.size(), 2u) << "frame " << f.frame_index << ": a picture did not decode";
      if (f.mesh.num_triangles() > 1000 && f.mesh.num_triangles() != stand_in.num_triangles()) ++surfaces;
    }
    while ((*b)->PollFrame(&f)) {
      EXPECT_EQ(f.mesh.num_triangles(), stand_in.num_triangles()) << "frame " << f.frame_index << ": not G1";
      EXPECT_EQ(f.images.size(), 2u);
      ++meshes;
    }
    return surfaces >= 10 && meshes >= 12;
  });
  EXPECT_GE(surfaces, 10);
  EXPECT_EQ(meshes, 12) << "the viewer without G3 and V1 stays on the full layer, every frame";
  EXPECT_EQ((*a)->stats().layer, 1);
  EXPECT_EQ((*b)->stats().layer, 0);
  EXPECT_EQ((*a)->stats().decode_errors, 0u);
  EXPECT_EQ((*a)->stats().color_images_waiting, 0u) << "the reduced layer's video started at a key frame";
  EXPECT_EQ((*b)->stats().decode_errors, 0u);
}

}  // namespace
}  // namespace holo
