// Reprojection, fields of view and the RenderedFrame wire form. No timing.
#include <cmath>
#include <limits>
#include <random>
#include <variant>

#include <gtest/gtest.h>

#include "client/pose/head_pose.h"
#include "client/reproject/fov.h"
#include "client/reproject/rendered_view.h"
#include "client/reproject/reproject.h"
#include "common/metrics/image_metrics.h"
#include "protocol/messages.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::reproject {
namespace {

constexpr double kDeg = M_PI / 180.0;

class ReprojectTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto w = GetWorkload("S8-QVGA");
    ASSERT_TRUE(w.ok());
    StudioOptions so = w->studio;
    so.threads = 2;
    studio_ = SyntheticStudio::Create(w->rig, so).value().release();
    mesh_ = new Mesh(studio_->ForegroundMesh(40));
  }
  static void TearDownTestSuite() {
    delete mesh_;
    delete studio_;
  }
  static SceneRenderFn Foreground() { return MeshSceneRenderer(*mesh_); }
  static SceneRenderFn Studio() {
    return [](const CameraModel& cam, ImageRgb8* c, ImageDepth16* d, ImageGray8* m) {
      studio_->RenderView(40, cam, c, d, nullptr);
      if (m) m->Resize(cam.intrinsics.width, cam.intrinsics.height, 255);
      return OkStatus();
    };
  }
  static Pose Eye(double yaw_deg, const Eigen::Vector3f& offset = Eigen::Vector3f::Zero()) {
    // Standing 2.6 m from the centre, looking towards it, turned by `yaw_deg`.
    Pose p = LookAt(Eigen::Vector3f(-2.6f, 0, 1.6f) + offset, Eigen::Vector3f(0, 0, 1.1f) + offset);
    p.linear() = Eigen::AngleAxisf(static_cast<float>(yaw_deg * kDeg), Eigen::Vector3f::UnitZ()) * p.linear();
    return p;
  }
  static SyntheticStudio* studio_;
  static Mesh* mesh_;
};
SyntheticStudio* ReprojectTest::studio_ = nullptr;
Mesh* ReprojectTest::mesh_ = nullptr;

constexpr ReprojectMethod kAllMethods[] = {ReprojectMethod::kNone, ReprojectMethod::kRotation, ReprojectMethod::kPlane,
                                           ReprojectMethod::kDepth};

double Psnr(const ImageRgb8& a, const ImageRgb8& b, const ImageGray8* mask = nullptr) {
  return metrics::ComputePsnr(a, b, mask).value();
}

TEST(Fov, IntrinsicsRoundTrip) {
  const FieldOfView f{0.8f, 1.1f, 0.6f, 0.5f};
  const Intrinsics k = IntrinsicsFromFov(f, 640, 360);
  const FieldOfView g = FovFromIntrinsics(k);
  EXPECT_NEAR(g.left, f.left, 1e-6);
  EXPECT_NEAR(g.right, f.right, 1e-6);
  EXPECT_NEAR(g.up, f.up, 1e-6);
  EXPECT_NEAR(g.down, f.down, 1e-6);
  // The left image edge (x = −0.5) is at tangent −left.
  EXPECT_NEAR((-0.5 - k.cx) / k.fx, -f.left, 1e-9);
  const FieldOfView d = FieldOfView::FromHorizontalDeg(90, 16.0 / 9.0);
  EXPECT_NEAR(d.left, 1.0, 1e-6);
  EXPECT_NEAR(d.up, 9.0 / 16.0, 1e-6);
  EXPECT_NEAR(d.HorizontalDeg(), 90.0, 1e-4);
  const auto size = ResolutionForFov(d, 640, 360, d.Enlarged(0.25));
  EXPECT_EQ(size[0], 800);
  EXPECT_EQ(size[1], 450);
  EXPECT_FALSE((FieldOfView{1, 1, -1, 1}).Check().ok());
  EXPECT_FALSE((FieldOfView{1, 1, 1, std::nanf("")}).Check().ok());
}

TEST_F(ReprojectTest, IdentityIsExact) {
  RenderedView v;
  ASSERT_TRUE(RenderAtPose(Studio(), Eye(0), FieldOfView::FromHorizontalDeg(80, 16.0 / 9), 160, 90, &v).ok());
  for (ReprojectMethod m : kAllMethods) {
    ReprojectOptions o;
    o.method = m;
    ImageRgb8 out;
    ImageGray8 valid;
    ReprojectStats stats;
    ASSERT_TRUE(Reproject(v.color, &v.depth, v.camera, v.camera, o, &out, &valid, &stats).ok());
    EXPECT_EQ(out, v.color) << ReprojectMethodName(m);
    EXPECT_EQ(stats.black_border_fraction, 0.0);
    for (uint8_t x : valid.storage()) ASSERT_EQ(x, 255);
  }
}

TEST_F(ReprojectTest, RotationHomographyMatchesTheRenderAtTheNewPose) {
  const FieldOfView fov = FieldOfView::FromHorizontalDeg(80, 16.0 / 9);
  RenderedView a, b;
  ASSERT_TRUE(RenderAtPose(Studio(), Eye(0), fov, 320, 180, &a).ok());
  ASSERT_TRUE(RenderAtPose(Studio(), Eye(6), fov, 320, 180, &b).ok());
  const double stale = Psnr(a.color, b.color);
  for (ReprojectMethod m : {ReprojectMethod::kRotation, ReprojectMethod::kPlane, ReprojectMethod::kDepth}) {
    ReprojectOptions o;
    o.method = m;
    ImageRgb8 out;
    ImageGray8 valid;
    ReprojectStats stats;
    ASSERT_TRUE(Reproject(a.color, &a.depth, a.camera, b.camera, o, &out, &valid, &stats).ok());
    const double p = Psnr(out, b.color, &valid);
    EXPECT_GT(p, stale + 8.0) << ReprojectMethodName(m) << " " << p << " vs stale " << stale;
    EXPECT_GT(p, 26.0) << ReprojectMethodName(m);
    // Turned left by 6° out of 80°: a strip on the left has no source,
    // (tan 40° − tan 34°) / (2 tan 40°) ≈ 0.098 of the width (more at the
    // corners: the camera looks down a little, the turn is about world z).
    EXPECT_NEAR(stats.black_border_fraction, 0.105, 0.02) << ReprojectMethodName(m);
    size_t invalid = 0;
    for (uint8_t x : valid.storage()) invalid += x == 0;
    EXPECT_NEAR(static_cast<double>(invalid) / valid.num_pixels(), stats.black_border_fraction, 1e-9);
    EXPECT_EQ(valid.at(2, 90), 0);
    EXPECT_EQ(valid.at(317, 90), 255);
  }
}

TEST_F(ReprojectTest, DepthHandlesParallaxBetterThanAPlane) {
  // Step 15 cm sideways: the people (≈2.6 m) and the wall behind them
  // (≈5.9 m) shift by different amounts.
  const FieldOfView fov = FieldOfView::FromHorizontalDeg(80, 16.0 / 9);
  RenderedView a, b;
  ASSERT_TRUE(RenderAtPose(Studio(), Eye(0), fov, 320, 180, &a).ok());
  ASSERT_TRUE(RenderAtPose(Studio(), Eye(0, Eigen::Vector3f(0, 0.15f, 0)), fov, 320, 180, &b).ok());
  double psnr[4] = {};
  for (ReprojectMethod m : kAllMethods) {
    ReprojectOptions o;
    o.method = m;
    ImageRgb8 out;
    ImageGray8 valid;
    ASSERT_TRUE(Reproject(a.color, &a.depth, a.camera, b.camera, o, &out, &valid).ok());
    psnr[static_cast<int>(m)] = Psnr(out, b.color, &valid);
  }
  EXPECT_GT(psnr[2], psnr[0] + 1.0) << "plane vs none";
  EXPECT_GT(psnr[3], psnr[2] + 1.0) << "depth vs plane";
}

TEST_F(ReprojectTest, RejectsBadInput) {
  RenderedView v;
  ASSERT_TRUE(RenderAtPose(Foreground(), Eye(0), FieldOfView::FromHorizontalDeg(80, 16.0 / 9), 64, 36, &v).ok());
  ImageRgb8 out;
  ReprojectOptions o;
  o.method = ReprojectMethod::kDepth;
  EXPECT_FALSE(Reproject(v.color, nullptr, v.camera, v.camera, o, &out).ok());
  o.method = ReprojectMethod::kPlane;
  CameraModel wrong = v.camera;
  wrong.intrinsics.width = 65;
  EXPECT_FALSE(Reproject(v.color, nullptr, wrong, v.camera, o, &out).ok());
  ImageDepth16 small(10, 10);
  EXPECT_FALSE(Reproject(v.color, &small, v.camera, v.camera, o, &out).ok());
  o.plane_distance_m = -1;
  EXPECT_FALSE(Reproject(v.color, nullptr, v.camera, v.camera, o, &out).ok());
  EXPECT_FALSE(ParseReprojectMethod("warp").ok());
  EXPECT_FALSE(RenderAtPose(Foreground(), Eye(0), FieldOfView{1, 1, 0, 1}, 64, 36, &v).ok());
}

TEST_F(ReprojectTest, RenderedFrameRoundTrip) {
  RenderedView v;
  const FieldOfView fov = FieldOfView::FromHorizontalDeg(90, 16.0 / 9).Enlarged(0.2);
  ASSERT_TRUE(RenderAtPose(Foreground(), Eye(3), fov, 320, 180, &v).ok());
  v.frame_index = 77;
  v.pose_time_us = 123456;
  auto wire = EncodeRenderedView(v);
  ASSERT_TRUE(wire.ok()) << wire.status().ToString();
  EXPECT_FALSE(wire->depth.empty());
  const std::vector<uint8_t> bytes = protocol::EncodePayload(*wire);
  auto payload = protocol::DecodePayload(protocol::MessageType::kRenderedFrame, bytes);
  ASSERT_TRUE(payload.ok()) << payload.status().ToString();
  RenderedView r;
  ASSERT_TRUE(DecodeRenderedFrame(std::get<protocol::RenderedFrame>(*payload), &r).ok());
  EXPECT_EQ(r.frame_index, 77);
  EXPECT_EQ(r.pose_time_us, 123456);
  EXPECT_EQ(r.depth, v.depth);
  EXPECT_LT((r.camera.world_from_camera.matrix() - v.camera.world_from_camera.matrix()).norm(), 1e-5);
  EXPECT_NEAR(r.camera.intrinsics.fx, v.camera.intrinsics.fx, 1e-3);
  EXPECT_NEAR(r.camera.intrinsics.cx, v.camera.intrinsics.cx, 1e-3);
  EXPECT_GT(Psnr(r.color, v.color), 35.0);
  EXPECT_EQ(r.mask, v.mask);
  // Without depth.
  FrameEncodeOptions no_depth;
  no_depth.send_depth = false;
  auto wire2 = EncodeRenderedView(v, no_depth);
  ASSERT_TRUE(wire2.ok());
  EXPECT_TRUE(wire2->depth.empty());
  ASSERT_TRUE(DecodeRenderedFrame(*wire2, &r).ok());
  EXPECT_TRUE(r.depth.empty());
}

TEST_F(ReprojectTest, RenderedFrameValidation) {
  RenderedView v;
  ASSERT_TRUE(RenderAtPose(Foreground(), Eye(0), FieldOfView::FromHorizontalDeg(90, 16.0 / 9), 96, 54, &v).ok());
  const protocol::RenderedFrame good = EncodeRenderedView(v).value();
  RenderedView r;
  auto expect_error = [&](protocol::RenderedFrame f, const std::string& what) {
    const Status s = DecodeRenderedFrame(f, &r);
    EXPECT_FALSE(s.ok()) << what;
    EXPECT_NE(s.message().find(what), std::string::npos) << s.message();
  };
  protocol::RenderedFrame f = good;
  f.rotation = {2, 0, 0, 0};
  expect_error(f, "unit quaternion");
  f = good;
  f.fov_tan[2] = -0.5f;
  expect_error(f, "fov tangent up");
  f = good;
  f.position[1] = std::nanf("");
  expect_error(f, "position");
  f = good;
  f.width = 97;
  expect_error(f, "header says 97x54");
  f = good;
  f.depth.resize(f.depth.size() / 2);
  expect_error(f, "depth does not decompress");
  f = good;
  f.depth.assign(100000, 0xff);
  expect_error(f, "depth blob larger");
  f = good;
  f.codec = protocol::ColorCodec::kC0;
  expect_error(f, "codec field");
  f = good;
  f.image.clear();
  expect_error(f, "codec field");
  // Random byte flips in the blobs: an error or a decoded frame, never a crash.
  std::mt19937 rng(5);
  for (int i = 0; i < 300; ++i) {
    f = good;
    std::vector<uint8_t>& blob = i % 2 ? f.image : f.depth;
    for (int k = 0; k < 3; ++k) blob[rng() % blob.size()] ^= static_cast<uint8_t>(1u << (rng() % 8));
    (void)DecodeRenderedFrame(f, &r);
  }
  // Every truncation of the encoded payload is refused by the protocol decoder.
  const std::vector<uint8_t> bytes = protocol::EncodePayload(good);
  for (size_t n = 0; n < bytes.size(); n += 7) {
    const std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(n));
    EXPECT_FALSE(protocol::DecodePayload(protocol::MessageType::kRenderedFrame, prefix).ok()) << n;
  }
}

TEST(ClientPoseMessage, RoundTripAndValidation) {
  pose::PoseSample s;
  s.time_us = 987654;
  s.position = Eigen::Vector3d(-2.5, 0.25, 1.7);
  s.rotation = pose::RotationFromYawPitchRoll(0.3, -0.1, 0.05);
  const FieldOfView fov = FieldOfView::FromHorizontalDeg(90, 16.0 / 9);
  const protocol::ClientPose m = ToClientPose(s, fov, 1030000);
  auto payload = protocol::DecodePayload(protocol::MessageType::kClientPose, protocol::EncodePayload(m));
  ASSERT_TRUE(payload.ok());
  FieldOfView back_fov;
  auto back = FromClientPose(std::get<protocol::ClientPose>(*payload), &back_fov);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->time_us, s.time_us);
  EXPECT_LT((back->position - s.position).norm(), 1e-6);
  EXPECT_LT(pose::AngleBetween(back->rotation, s.rotation), 1e-6);
  EXPECT_EQ(back_fov.ToTan(), fov.ToTan());
  protocol::ClientPose bad = m;
  bad.rotation = {0, 0, 0, 0};
  EXPECT_FALSE(FromClientPose(bad).ok());
  bad = m;
  bad.fov_tan[0] = 0;
  EXPECT_FALSE(FromClientPose(bad).ok());
  bad = m;
  bad.position[2] = std::numeric_limits<float>::infinity();
  EXPECT_FALSE(FromClientPose(bad).ok());
}

}  // namespace
}  // namespace holo::reproject
