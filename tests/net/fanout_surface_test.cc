// The live path with G3 geometry (protocol/surface_codec.h): a site that
// publishes the stream mesh's distance grid reaches its native viewers as a
// mesh on the surface, a frame without its grid is refused with a reason,
// and a viewer that cannot decode G3 (one that lists only G1 and G0) is
// refused with a message naming the codec.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

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

}  // namespace
}  // namespace holo
