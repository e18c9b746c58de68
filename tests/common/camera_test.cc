#include <random>

#include <gtest/gtest.h>

#include "common/camera.h"
#include "common/pose.h"

namespace holo {
namespace {

CameraModel DistortedCamera() {
  CameraModel cam;
  cam.intrinsics.width = 640;
  cam.intrinsics.height = 480;
  cam.intrinsics.fx = 520;
  cam.intrinsics.fy = 522;
  cam.intrinsics.cx = 318.2;
  cam.intrinsics.cy = 241.7;
  // Typical Kinect-like lens: mild barrel distortion and a little tangential.
  cam.intrinsics.distortion = {0.21, -0.52, 0.0012, -0.0008, 0.41};
  cam.world_from_camera = PoseFromTranslationRotvec({0.3f, -1.2f, 0.8f}, {0.1f, -0.4f, 0.2f});
  return cam;
}

TEST(CameraTest, ProjectUnprojectRoundTripWithDistortion) {
  const CameraModel cam = DistortedCamera();
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector2f px(u(rng) * 639.0f, u(rng) * 479.0f);
    const float depth = 0.5f + 3.0f * u(rng);
    const Eigen::Vector3f p_world = cam.UnprojectWorld(px, depth);
    Eigen::Vector2f back;
    ASSERT_TRUE(cam.ProjectWorld(p_world, &back));
    EXPECT_NEAR(back.x(), px.x(), 1e-3f) << "pixel " << px.transpose();
    EXPECT_NEAR(back.y(), px.y(), 1e-3f) << "pixel " << px.transpose();
    // Depth is the z coordinate in the camera frame.
    EXPECT_NEAR((cam.world_from_camera.inverse() * p_world).z(), depth, 1e-4f);
  }
}

TEST(CameraTest, DistortionMovesPixelsOutwardForBarrelCoefficients) {
  const CameraModel cam = DistortedCamera();
  CameraModel pinhole = cam;
  pinhole.intrinsics.distortion = {0, 0, 0, 0, 0};
  const Eigen::Vector3f corner_ray(0.5f, 0.4f, 1.0f);
  Eigen::Vector2f a, b;
  ASSERT_TRUE(cam.ProjectCamera(corner_ray, &a));
  ASSERT_TRUE(pinhole.ProjectCamera(corner_ray, &b));
  // k1 > 0: points far from the centre land farther out than with a pinhole.
  const Eigen::Vector2f c(cam.intrinsics.cx, cam.intrinsics.cy);
  EXPECT_GT((a - c).norm(), (b - c).norm() + 5.0f);
}

TEST(CameraTest, PinholeProjectionMatchesFormula) {
  CameraModel cam;
  cam.intrinsics = Intrinsics::FromFov(320, 240, 60.0);
  Eigen::Vector2f px;
  ASSERT_TRUE(cam.ProjectCamera({0.2f, -0.1f, 2.0f}, &px));
  EXPECT_NEAR(px.x(), cam.intrinsics.fx * 0.1 + cam.intrinsics.cx, 1e-4);
  EXPECT_NEAR(px.y(), cam.intrinsics.fy * -0.05 + cam.intrinsics.cy, 1e-4);
  EXPECT_FALSE(cam.ProjectCamera({0.0f, 0.0f, -1.0f}, &px)) << "points behind the camera do not project";
}

TEST(CameraTest, ScaledIntrinsicsKeepTheSameRays) {
  Intrinsics k = Intrinsics::FromFov(640, 480, 62.0);
  k.cx = 321.3;
  const Intrinsics half = k.Scaled(0.5);
  EXPECT_EQ(half.width, 320);
  EXPECT_EQ(half.height, 240);
  CameraModel a{k, Pose::Identity()}, b{half, Pose::Identity()};
  // The pixel (x, y) at full resolution covers the same ray as ((x+0.5)/2-0.5, ...) at half.
  const Eigen::Vector3f ra = a.RayCamera({100.0f, 50.0f});
  const Eigen::Vector3f rb = b.RayCamera({(100.0f + 0.5f) * 0.5f - 0.5f, (50.0f + 0.5f) * 0.5f - 0.5f});
  EXPECT_LT((ra - rb).norm(), 1e-5f);
}

TEST(CameraTest, CheckNamesTheBadField) {
  Intrinsics k = Intrinsics::FromFov(640, 480, 60.0);
  EXPECT_TRUE(k.Check().ok());
  k.fx = -1;
  const Status s = k.Check();
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("fx"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("-1"), std::string::npos) << s.message();
  k = Intrinsics::FromFov(640, 480, 60.0);
  k.width = 0;
  EXPECT_NE(k.Check().message().find("width"), std::string::npos);
}

TEST(PoseTest, CompositionAndInverse) {
  const Pose a = PoseFromTranslationRotvec({1, 2, 3}, {0.3f, 0.0f, 0.0f});
  const Pose b = PoseFromTranslationRotvec({-0.5f, 0.2f, 0.0f}, {0.0f, 0.0f, 1.2f});
  const Eigen::Vector3f p(0.7f, -0.3f, 2.0f);
  // (a*b)*p == a*(b*p)
  EXPECT_LT(((a * b) * p - a * (b * p)).norm(), 1e-5f);
  // a⁻¹·a = identity
  EXPECT_LT(((a.inverse() * a).matrix() - Eigen::Matrix4f::Identity()).norm(), 1e-5f);
  // Rotation distances add up along one axis.
  const Pose r1 = PoseFromTranslationRotvec({0, 0, 0}, {0, 0, 0.4f});
  const Pose r2 = PoseFromTranslationRotvec({0, 0, 0}, {0, 0, 0.7f});
  EXPECT_NEAR(RotationDistance(r1, r2), 0.3f, 1e-5f);
  EXPECT_NEAR(RotationDistance(r1 * r2, Pose::Identity()), 1.1f, 1e-5f);
  EXPECT_NEAR(TranslationDistance(a, b), (Eigen::Vector3f(1.5f, 1.8f, 3.0f)).norm(), 1e-5f);
}

TEST(PoseTest, LookAtPointsTheOpticalAxisAtTheTarget) {
  const Eigen::Vector3f eye(2.5f, 0.0f, 0.9f), target(0.0f, 0.0f, 1.0f);
  const Pose pose = LookAt(eye, target);
  CameraModel cam{Intrinsics::FromFov(640, 480, 60.0), pose};
  Eigen::Vector2f px;
  ASSERT_TRUE(cam.ProjectWorld(target, &px));
  EXPECT_NEAR(px.x(), cam.intrinsics.cx, 1e-3);
  EXPECT_NEAR(px.y(), cam.intrinsics.cy, 1e-3);
  // World up (z) appears as image up (negative y).
  ASSERT_TRUE(cam.ProjectWorld(target + Eigen::Vector3f(0, 0, 0.3f), &px));
  EXPECT_LT(px.y(), cam.intrinsics.cy - 10);
  EXPECT_NEAR(pose.linear().determinant(), 1.0f, 1e-5f);
}

}  // namespace
}  // namespace holo
