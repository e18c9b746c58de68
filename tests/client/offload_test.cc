// Networked render offload over loopback (client/offload, docs/offload.md):
// a site server publishing the synthetic studio's ground-truth foreground
// mesh, a render host subscribed to it, thin clients. Count-based; no timing
// in any assertion.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "client/net/raw_peer.h"
#include "client/offload/gl_scene.h"
#include "client/offload/render_host.h"
#include "client/offload/thin_client.h"
#include "common/metrics/image_metrics.h"
#include "net/net_fixtures.h"
#include "net/session_server.h"
#include "net/wire_message.h"
#include "server/net/site_publisher.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::offload {
namespace {

// One quality layer: what is checked here is every frame on the full layer,
// not the layer policy (tests/net/fanout_layers_test.cc), which could move a
// viewer slowed by a loaded machine to the reduced layer.
net::SitePublisherOptions FullLayerOnly() {
  net::SitePublisherOptions o;
  o.reduced.enabled = false;
  return o;
}

// test::Eventually with this file's longer default wait.
bool Eventually(const std::function<bool()>& pred, double timeout_s = 10.0) {
  return test::Eventually(pred, timeout_s);
}

using Log = test::LogCapture;

const Mesh& StudioMesh() {
  static const Mesh mesh = [] {
    auto workload = GetWorkload("S8-QVGA");
    HOLO_CHECK(workload.ok());
    StudioOptions so = workload->studio;
    so.threads = 2;
    auto studio = SyntheticStudio::Create(workload->rig, so);
    HOLO_CHECK(studio.ok());
    return (*studio)->ForegroundMesh(0);
  }();
  return mesh;
}

// A site server publishing the studio's ground-truth foreground mesh at 20 Hz.
class Site {
 public:
  explicit Site(uint16_t port = 0) {
    net::ServerConfig c;
    c.port = port;
    c.publisher_token = "pub";
    c.viewer_token = "view";
    c.ping_interval_s = 0.1;
    c.threads = 1;
    net::ServerHooks hooks;
    hooks.log = [](const std::string&) {};
    auto s = test::StartServerRetrying(c, hooks);  // the port of a stopped site may take a moment
    HOLO_CHECK_MSG(s.ok(), s.status().ToString());
    server_ = std::move(*s);
    thread_ = std::thread([this] {
      net::SitePublisher pub(server_.get(), FullLayerOnly());
      for (int64_t i = 0; !stop_; ++i) {
        net::PublishTimings t;
        (void)pub.Publish(i, net::WallUs(), StudioMesh(), {}, &t);
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
    });
  }
  ~Site() { Stop(); }
  void Stop() {
    if (stop_.exchange(true)) return;
    thread_.join();
    server_->Stop();
  }
  uint16_t port() const { return server_->port(); }

 private:
  std::unique_ptr<net::Server> server_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

RenderHostOptions HostOptions(uint16_t site_port, pose::PredictorModel model, double margin, Log* log) {
  RenderHostOptions o;
  o.site.port = site_port;
  o.site.token = "view";
  o.site.backoff_initial_s = 0.05;
  o.site.backoff_max_s = 0.2;
  o.predictor = model;
  o.margin = margin;
  o.width = 160;
  o.log = log->Hook();
  return o;
}

// Yaw turning at a constant 60°/s, 2.6 m in front of the studio centre.
std::vector<pose::PoseSample> RotatingTrace() {
  std::vector<pose::PoseSample> t;
  for (int i = 0; i <= 90 * 60; ++i) {
    pose::PoseSample s;
    s.time_us = int64_t{i} * 1000000 / 90;
    const double yaw = 0.35 * std::sin(s.time_us * 1e-6 * 60.0 * M_PI / 180.0 / 0.35);
    s.position = Eigen::Vector3d(-2.6, 0, 1.3);
    s.rotation = pose::RotationFromYawPitchRoll(yaw, 0, 0);
    t.push_back(s);
  }
  return t;
}

ThinClientOptions ThinOptions(uint16_t port, int frames) {
  ThinClientOptions o;
  o.port = port;
  o.token = "view";
  o.width = 160;
  o.height = 90;
  o.rate_hz = 30;
  o.frames = frames;
  o.trace = RotatingTrace();
  o.trace_start_s = 1.0;
  return o;
}

TEST(OffloadTest, ThinClientGetsFramesAtItsPoseAndReprojectionBeatsStale) {
  Site site;
  Log log;
  auto host = RenderHost::Start(HostOptions(site.port(), pose::PredictorModel::kNone, 0.0, &log));
  ASSERT_TRUE(host.ok()) << host.status().ToString();
  ASSERT_TRUE(Eventually([&] { return (*host)->stats().site_frames > 0; }));

  ThinClientOptions o = ThinOptions((*host)->port(), 40);
  o.receive_delay_ms = 60;
  o.keep_stale = true;
  const reproject::FieldOfView fov = reproject::FieldOfView::FromHorizontalDeg(o.hfov_deg, 16.0 / 9.0);
  int checked = 0, reproj_better = 0;
  double sum_stale = 0, sum_reproj = 0;
  reproject::RenderedView truth;
  auto r = RunThinClient(o, [&](const DisplayedFrame& d) {
    // Without prediction the host renders exactly at the pose the client sent at pose_time_us.
    const pose::PoseSample sent = pose::InterpolatePose(o.trace, d.pose_time_us);
    const Pose& used = d.source.camera.world_from_camera;
    EXPECT_LT((used.translation().cast<double>() - sent.position).norm(), 1e-4);
    EXPECT_LT(pose::AngleBetween(Eigen::Quaterniond(used.linear().cast<double>()), sent.rotation), 1e-4);
    // And with the client's FOV (margin 0).
    EXPECT_NEAR(d.source.fov.left, fov.left, 1e-4);
    EXPECT_EQ(d.source.color.width(), 160);
    if (d.index % 4 != 0) return;
    auto mesh = (*host)->MeshForFrame(d.frame_index);
    ASSERT_NE(mesh, nullptr);
    ASSERT_TRUE(reproject::RenderAtPose(reproject::MeshSceneRenderer(*mesh), d.true_pose.ToPose(), fov, 160, 90, &truth).ok());
    const double stale = *metrics::ComputePsnr(d.stale, truth.color);
    const double reproj = *metrics::ComputePsnr(d.shown, truth.color);
    sum_stale += stale;
    sum_reproj += reproj;
    reproj_better += reproj > stale ? 1 : 0;
    ++checked;
  });
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->displayed, 40);
  EXPECT_GT(r->frames_used, 5);
  ASSERT_EQ(checked, 10);
  EXPECT_GT(sum_reproj / checked, sum_stale / checked + 3.0) << "stale " << sum_stale / checked << " dB";
  EXPECT_GE(reproj_better, 8);
  const RenderHostStats s = (*host)->stats();
  EXPECT_EQ(s.thin_accepted, 1u);
  ASSERT_EQ(s.clients.size(), 1u);
  EXPECT_GT(s.clients[0].poses, 30u);
  EXPECT_GE(s.clients[0].frames_sent, static_cast<uint64_t>(r->frames_received));
  EXPECT_GT(s.clients[0].reported_latency_ms, 60.0);  // the client's pose→photon includes the simulated 60 ms
}

TEST(OffloadTest, PredictingHostRendersNearTheSentPoseWithEnlargedFov) {
  Site site;
  Log log;
  auto host = RenderHost::Start(HostOptions(site.port(), pose::PredictorModel::kKalman, 0.25, &log));
  ASSERT_TRUE(host.ok()) << host.status().ToString();
  ThinClientOptions o = ThinOptions((*host)->port(), 20);
  const reproject::FieldOfView fov = reproject::FieldOfView::FromHorizontalDeg(o.hfov_deg, 16.0 / 9.0);
  int n = 0;
  auto r = RunThinClient(o, [&](const DisplayedFrame& d) {
    const pose::PoseSample sent = pose::InterpolatePose(o.trace, d.pose_time_us);
    const Pose& used = d.source.camera.world_from_camera;
    // Predicted ahead by the horizon (≤ a few hundred ms at ≤ 60°/s): within 15° of the sent pose.
    EXPECT_LT(pose::AngleBetween(Eigen::Quaterniond(used.linear().cast<double>()), sent.rotation), 15 * M_PI / 180);
    EXPECT_NEAR(d.source.fov.left, fov.left * 1.25, 1e-3);
    EXPECT_EQ(d.source.color.width(), 200);  // same pixel density over the enlarged FOV
    ++n;
  });
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(n, 20);
}

TEST(OffloadTest, StereoRendersBothEyesAtTheirPoses) {
  Site site;
  Log log;
  RenderHostOptions ho = HostOptions(site.port(), pose::PredictorModel::kNone, 0.0, &log);
  ho.stereo = true;
  ho.ipd_m = 0.064;
  auto host = RenderHost::Start(ho);
  ASSERT_TRUE(host.ok()) << host.status().ToString();
  ThinClientOptions o = ThinOptions((*host)->port(), 20);
  o.stereo = true;
  o.ipd_m = 0.064;
  int both = 0;
  auto r = RunThinClient(o, [&](const DisplayedFrame& d) {
    if (d.source_right.color.empty()) return;
    const pose::PoseSample sent = pose::InterpolatePose(o.trace, d.pose_time_us);
    const Eigen::Vector3d left = d.source.camera.world_from_camera.translation().cast<double>();
    const Eigen::Vector3d expected_left = sent.position + sent.rotation * Eigen::Vector3d(-0.032, 0, 0);
    EXPECT_LT((left - expected_left).norm(), 1e-4);
    if (d.source_right.pose_time_us == d.pose_time_us) {
      const Eigen::Vector3d right = d.source_right.camera.world_from_camera.translation().cast<double>();
      EXPECT_LT((right - left).norm() - 0.064, 1e-4);
      EXPECT_GT((right - left).norm() - 0.064, -1e-4);
    }
    EXPECT_EQ(d.shown_right.width(), 160);
    ++both;
  });
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_GT(both, 10);
}

TEST(OffloadTest, GlRendererMatchesTheCpuRenderer) {
  if (auto gl = GlMeshRenderer::Create(); !gl.ok()) {
    GTEST_SKIP() << "no headless GL (scripts/setup.sh installs Mesa EGL; the CPU-renderer tests still run): " << gl.status().ToString();
  }
  Site site;
  Log log;
  RenderHostOptions ho = HostOptions(site.port(), pose::PredictorModel::kNone, 0.0, &log);
  ho.renderer = HostRenderer::kGl;
  auto host = RenderHost::Start(ho);
  ASSERT_TRUE(host.ok()) << host.status().ToString();
  ThinClientOptions o = ThinOptions((*host)->port(), 12);
  int checked = 0;
  double psnr_sum = 0, depth_diff_sum = 0;
  reproject::RenderedView cpu;
  auto r = RunThinClient(o, [&](const DisplayedFrame& d) {
    if (d.index % 3 != 0) return;
    auto mesh = (*host)->MeshForFrame(d.frame_index);
    ASSERT_NE(mesh, nullptr);
    ASSERT_TRUE(reproject::RenderAtPose(reproject::MeshSceneRenderer(*mesh), d.source.camera.world_from_camera, d.source.fov,
                                        d.source.color.width(), d.source.color.height(), &cpu).ok());
    psnr_sum += *metrics::ComputePsnr(d.source.color, cpu.color);
    ASSERT_FALSE(d.source.depth.empty());
    depth_diff_sum += std::abs(reproject::MedianDepthM(d.source.depth, 0) - reproject::MedianDepthM(cpu.depth, 0));
    ++checked;
  });
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(checked, 4);
  const auto stats = (*host)->stats();
  ASSERT_EQ(stats.clients.size(), 1u);
  EXPECT_EQ(stats.clients[0].renderer.rfind("gl", 0), 0u) << stats.clients[0].renderer;
  std::printf("GL vs CPU render: %.2f dB, median depth difference %.4f m\n", psnr_sum / checked, depth_diff_sum / checked);
  EXPECT_GT(psnr_sum / checked, 25.0);
  EXPECT_LT(depth_diff_sum / checked, 0.01);
}

TEST(OffloadTest, MalformedClientPoseClosesOnlyThatThinClient) {
  Site site;
  Log log;
  auto host = RenderHost::Start(HostOptions(site.port(), pose::PredictorModel::kKalman, 0.25, &log));
  ASSERT_TRUE(host.ok()) << host.status().ToString();
  ASSERT_TRUE(Eventually([&] { return (*host)->stats().site_frames > 0; }));
  // A good thin client runs throughout.
  StatusOr<ThinClientResult> good = Unavailable("not run");
  std::thread good_thread([&] { good = RunThinClient(ThinOptions((*host)->port(), 30)); });

  // Wrong token: refused.
  {
    auto peer = net::RawPeer::Connect("127.0.0.1", (*host)->port());
    ASSERT_TRUE(peer.ok());
    ASSERT_TRUE((*peer)->SendHello(protocol::Role::kThinClient, "wrong", "intruder").ok());
    auto m = (*peer)->ReadMessage(5.0);
    ASSERT_TRUE(m.ok()) << m.status().ToString();
    ASSERT_TRUE(std::holds_alternative<protocol::Refuse>(m->payload));
    EXPECT_EQ(std::get<protocol::Refuse>(m->payload).reason, protocol::RefuseReason::kBadToken);
  }
  // A thin client sending a non-unit quaternion.
  auto bad = net::RawPeer::Connect("127.0.0.1", (*host)->port());
  ASSERT_TRUE(bad.ok());
  ASSERT_TRUE((*bad)->SendHello(protocol::Role::kThinClient, "view", "bad-client").ok());
  auto welcome = (*bad)->ReadMessage(5.0);
  ASSERT_TRUE(welcome.ok()) << welcome.status().ToString();
  ASSERT_TRUE(std::holds_alternative<protocol::Welcome>(welcome->payload));
  protocol::ClientPose p;
  p.time_us = 1000;
  p.rotation = {2, 0, 0, 0};
  ASSERT_TRUE((*bad)->SendMessage(p).ok());
  EXPECT_TRUE((*bad)->WaitClosed(5.0));
  // "thin client 2 (bad-client, …) closed: malformed message: DataLoss: client_pose.rotation: quaternion is not unit length"
  EXPECT_TRUE(Eventually([&] { return log.Contains("(bad-client, ") && log.Contains("client_pose.rotation"); }))
      << "no clear error in the log";

  // One sending garbage instead of a frame header after its Welcome.
  auto garbage = net::RawPeer::Connect("127.0.0.1", (*host)->port());
  ASSERT_TRUE(garbage.ok());
  ASSERT_TRUE((*garbage)->SendHello(protocol::Role::kThinClient, "view", "garbage-client").ok());
  ASSERT_TRUE((*garbage)->ReadMessage(5.0).ok());
  const std::vector<uint8_t> junk(64, 0x5a);
  ASSERT_TRUE((*garbage)->Send(junk).ok());
  EXPECT_TRUE((*garbage)->WaitClosed(5.0));
  EXPECT_TRUE(Eventually([&] { return log.Contains("(garbage-client, ") && log.Contains("magic"); }))
      << "no clear error in the log";

  good_thread.join();
  ASSERT_TRUE(good.ok()) << good.status().ToString();
  EXPECT_EQ(good->displayed, 30);
  const RenderHostStats s = (*host)->stats();
  EXPECT_EQ(s.thin_closed_on_error, 2u);
  EXPECT_EQ(s.thin_refused, 1u);
  EXPECT_EQ(s.thin_accepted, 3u);
}

TEST(OffloadTest, SiteGoingAwayIsReportedAndTheHostReconnects) {
  Log log;
  auto site = std::make_unique<Site>();
  const uint16_t port = site->port();
  auto host = RenderHost::Start(HostOptions(port, pose::PredictorModel::kKalman, 0.25, &log));
  ASSERT_TRUE(host.ok()) << host.status().ToString();
  ASSERT_TRUE(Eventually([&] { return (*host)->stats().site_frames > 0; }));
  site.reset();
  EXPECT_TRUE(Eventually([&] { return log.Contains("site: connection lost"); })) << "no report of the lost site";
  const uint64_t before = (*host)->stats().site_frames;
  site = std::make_unique<Site>(port);
  EXPECT_TRUE(Eventually([&] { return (*host)->site()->stats().connects >= 2; }));
  EXPECT_TRUE(Eventually([&] { return (*host)->stats().site_frames > before; }));
  // Thin clients are served again after the reconnect.
  auto r = RunThinClient(ThinOptions((*host)->port(), 10));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->displayed, 10);
}

}  // namespace
}  // namespace holo::offload
