// Rigid poses (SE3). Convention: a pose named `a_from_b` maps points in frame
// b to frame a: p_a = a_from_b * p_b. Camera poses are world_from_camera.
// Camera frame: x right, y down, z forward (OpenCV convention). Units: metres.
#pragma once

#include <Eigen/Geometry>

namespace holo {

using Pose = Eigen::Isometry3f;

// A pose whose camera sits at `eye` and looks at `target`, with image "up"
// as close to `world_up` as possible (camera y axis points down).
Pose LookAt(const Eigen::Vector3f& eye, const Eigen::Vector3f& target,
            const Eigen::Vector3f& world_up = Eigen::Vector3f::UnitZ());

// Pose from translation and rotation vector (axis * angle, radians).
Pose PoseFromTranslationRotvec(const Eigen::Vector3f& t, const Eigen::Vector3f& rotvec);

// Rotation angle (radians) and translation distance between two poses.
float RotationDistance(const Pose& a, const Pose& b);
float TranslationDistance(const Pose& a, const Pose& b);

}  // namespace holo
