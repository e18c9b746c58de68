#include "audio/room.h"

#include <gtest/gtest.h>

#include <numbers>

namespace holo::audio {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

TEST(Room, FaceToFaceLinkPutsTheRemoteSpeakerBehindTheDisplayFacingUs) {
  // Remote user 1 m in front of their display (display at origin, user on +x),
  // looking at it (yaw π: towards −x).
  const protocol::HeadPose remote{1.0f, 0.0f, 1.6f, kPi, 0, 0};
  const SpeakerPlacement s = PlaceRemoteSpeaker(remote, FaceToFaceLink(0.5f));
  EXPECT_TRUE(s.position.isApprox(Eigen::Vector3f(-1.5f, 0.0f, 1.6f), 1e-5f)) << s.position.transpose();
  EXPECT_TRUE(s.facing.isApprox(Eigen::Vector3f::UnitX(), 1e-5f)) << s.facing.transpose();
  // The local user 1 m in front of the local display, looking at it, hears
  // them straight ahead; a remote step to their own right (+y remote, as they face −x) is to
  // our left.
  const protocol::HeadPose local{1.0f, 0.0f, 1.6f, kPi, 0, 0};
  EXPECT_NEAR(AzimuthDeg(local, s.position), 0.0f, 1e-3f);
  const protocol::HeadPose remote_left{1.0f, 0.5f, 1.6f, kPi, 0, 0};
  EXPECT_LT(AzimuthDeg(local, PlaceRemoteSpeaker(remote_left, FaceToFaceLink(0.5f)).position), -5.0f);
}

TEST(Room, GeneralLinkIsRotationPlusTranslation) {
  RoomLink link;
  link.local_from_remote.linear() = Eigen::AngleAxisf(kPi / 2, Eigen::Vector3f::UnitZ()).toRotationMatrix();
  link.local_from_remote.translation() = Eigen::Vector3f(2, 3, 0);
  const SpeakerPlacement s = PlaceRemoteSpeaker({1, 0, 1.7f, 0, 0, 0}, link);
  EXPECT_TRUE(s.position.isApprox(Eigen::Vector3f(2, 4, 1.7f), 1e-5f)) << s.position.transpose();
  EXPECT_TRUE(s.facing.isApprox(Eigen::Vector3f::UnitY(), 1e-5f)) << s.facing.transpose();
}

TEST(Room, HeadAngles) {
  EXPECT_TRUE(HeadToRoom({0, 0, 0, kPi / 2, 0, 0}).linear().col(0).isApprox(Eigen::Vector3f::UnitY(), 1e-5f));
  EXPECT_GT(HeadToRoom({0, 0, 0, 0, 0.3f, 0}).linear().col(0).z(), 0.2f);  // pitch up
  EXPECT_NEAR(AzimuthDeg({0, 0, 0, 0, 0, 0}, {0, -1, 0}), 90.0f, 1e-3f);   // right
  EXPECT_NEAR(AzimuthDeg({0, 0, 0, 0, 0, 0}, {0, 1, 0}), -90.0f, 1e-3f);
}

}  // namespace
}  // namespace holo::audio
