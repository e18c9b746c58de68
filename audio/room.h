// Room frames for voice. Every site's room frame is right-handed, metres,
// z up; a head with yaw = pitch = roll = 0 looks along +x with +y on its
// left. Yaw turns left (counter-clockwise seen from above), pitch > 0 looks
// up, roll > 0 tilts the head to its right. Intrinsic Z-Y-X order:
// room_from_head = Rz(yaw) · Ry(−pitch) · Rx(roll).
#pragma once

#include <Eigen/Geometry>

#include "protocol/messages.h"

namespace holo::audio {

// room_from_head for `pose` (x forward, y left, z up in the head frame).
Eigen::Isometry3f HeadToRoom(const protocol::HeadPose& pose);

// Where a remote speaker is in the local room.
struct SpeakerPlacement {
  Eigen::Vector3f position = Eigen::Vector3f::Zero();       // mouth ≈ head centre, local room, metres
  Eigen::Vector3f facing = Eigen::Vector3f::UnitX();        // unit vector the speaker's face points along
  Eigen::Vector3f up = Eigen::Vector3f::UnitZ();            // unit vector, top of the speaker's head
};

// The call configuration maps the remote room into the local one:
// p_local = local_from_remote · p_remote (rotation + translation).
struct RoomLink {
  Eigen::Isometry3f local_from_remote = Eigen::Isometry3f::Identity();
};

// Face-to-face call through a pair of displays at each room's origin, both
// rooms' users standing on +x looking towards −x at their display: the remote
// room is turned 180° about z and pushed back by `gap_m` along −x, so a
// remote user 1 m in front of their display appears 1 m + `gap_m` behind the
// local display, facing the local user.
RoomLink FaceToFaceLink(float gap_m = 0.0f);

// A remote head pose as a source in the local room.
SpeakerPlacement PlaceRemoteSpeaker(const protocol::HeadPose& remote_head, const RoomLink& link);

// The listener-relative direction of `p` (local room) for a listener with
// head pose `listener`: azimuth in degrees, + to the listener's right, 0 ahead.
float AzimuthDeg(const protocol::HeadPose& listener, const Eigen::Vector3f& p);

}  // namespace holo::audio
