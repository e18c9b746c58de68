// Head poses as the client sees them: a time-stamped 6-DoF sample per display
// or tracker tick, and the conversions between the (x, y, z, yaw, pitch, roll)
// form of traces and the protocol and the camera pose a renderer needs.
//
// Frames. World: z up (metres), like the studio. A head pose is the pose of
// the eye (the render camera): world_from_camera with the OpenCV camera
// convention (x right, y down, z forward), as everywhere in holo.
// Euler form (traces, protocol HeadPose): yaw about world +z (0 = looking
// along world +x, positive = turning left), then pitch (positive = looking
// up), then roll about the line of sight (positive = right ear down).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "common/pose.h"

namespace holo::pose {

// One head pose at one time. Double precision: predictors difference
// samples a few milliseconds apart.
struct PoseSample {
  int64_t time_us = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();                // eye, world metres
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();     // world_from_camera, unit

  // world_from_camera as the float pose the renderers take.
  holo::Pose ToPose() const;
  static PoseSample FromPose(int64_t time_us, const holo::Pose& world_from_camera);
};

// Euler angles (radians) → world_from_camera rotation, as described above.
Eigen::Quaterniond RotationFromYawPitchRoll(double yaw, double pitch, double roll);
// Inverse of RotationFromYawPitchRoll; pitch in [-π/2, π/2], yaw and roll in (-π, π].
Eigen::Vector3d YawPitchRollFromRotation(const Eigen::Quaterniond& q);

// Rotation vector (axis·angle, radians, angle ≤ π) of a unit quaternion, and back.
Eigen::Vector3d LogRotation(const Eigen::Quaterniond& q);
Eigen::Quaterniond ExpRotation(const Eigen::Vector3d& rotvec);

// Angle between two rotations, radians.
double AngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);

// The pose at `time_us` from time-ordered `samples`: linear in position,
// slerp in rotation between the two neighbours; the first / last sample
// outside their range. HOLO_CHECKs that `samples` is not empty.
PoseSample InterpolatePose(const std::vector<PoseSample>& samples, int64_t time_us);

// A feed of time-stamped poses for a viewer: the interactive camera, a
// trace player or a tracker pushes samples; the renderer and the predictor
// read the newest. Not thread-safe (one owner thread).
class PoseFeed {
 public:
  // Appends `sample`. Returns false (and ignores it) if its time is not
  // after the newest sample's, or its rotation is not a unit quaternion.
  bool Push(const PoseSample& sample);
  bool empty() const { return samples_.empty(); }
  const PoseSample& newest() const { return samples_.back(); }
  // Samples kept, oldest first (at most `capacity`).
  const std::vector<PoseSample>& samples() const { return samples_; }
  void set_capacity(size_t capacity) { capacity_ = capacity < 2 ? 2 : capacity; }

 private:
  std::vector<PoseSample> samples_;
  size_t capacity_ = 256;
};

}  // namespace holo::pose
