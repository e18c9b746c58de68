#include "audio/room.h"

#include <cmath>
#include <numbers>

namespace holo::audio {

Eigen::Isometry3f HeadToRoom(const protocol::HeadPose& p) {
  Eigen::Isometry3f t = Eigen::Isometry3f::Identity();
  t.linear() = (Eigen::AngleAxisf(p.yaw, Eigen::Vector3f::UnitZ()) *
                Eigen::AngleAxisf(-p.pitch, Eigen::Vector3f::UnitY()) *
                Eigen::AngleAxisf(p.roll, Eigen::Vector3f::UnitX()))
                   .toRotationMatrix();
  t.translation() = Eigen::Vector3f(p.x, p.y, p.z);
  return t;
}

RoomLink FaceToFaceLink(float gap_m) {
  RoomLink link;
  link.local_from_remote.linear() =
      Eigen::AngleAxisf(std::numbers::pi_v<float>, Eigen::Vector3f::UnitZ()).toRotationMatrix();
  link.local_from_remote.translation() = Eigen::Vector3f(-gap_m, 0.0f, 0.0f);
  return link;
}

SpeakerPlacement PlaceRemoteSpeaker(const protocol::HeadPose& remote_head, const RoomLink& link) {
  const Eigen::Isometry3f local_from_head = link.local_from_remote * HeadToRoom(remote_head);
  SpeakerPlacement s;
  s.position = local_from_head.translation();
  s.facing = local_from_head.linear().col(0).normalized();
  s.up = local_from_head.linear().col(2).normalized();
  return s;
}

float AzimuthDeg(const protocol::HeadPose& listener, const Eigen::Vector3f& p) {
  const Eigen::Vector3f h = HeadToRoom(listener).inverse() * p;  // x forward, y left
  return static_cast<float>(std::atan2(-h.y(), h.x()) * 180.0 / std::numbers::pi);
}

}  // namespace holo::audio
