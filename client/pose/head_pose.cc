#include "client/pose/head_pose.h"

#include <algorithm>
#include <cmath>

#include "common/status.h"

namespace holo::pose {
namespace {

// head_from_camera: the head frame has x forward, y left, z up; the camera
// x right, y down, z forward.
Eigen::Matrix3d HeadFromCamera() {
  Eigen::Matrix3d m;
  m << 0, 0, 1,  //
      -1, 0, 0,  //
      0, -1, 0;
  return m;
}

}  // namespace

holo::Pose PoseSample::ToPose() const {
  holo::Pose p = holo::Pose::Identity();
  p.linear() = rotation.normalized().toRotationMatrix().cast<float>();
  p.translation() = position.cast<float>();
  return p;
}

PoseSample PoseSample::FromPose(int64_t time_us, const holo::Pose& world_from_camera) {
  PoseSample s;
  s.time_us = time_us;
  s.position = world_from_camera.translation().cast<double>();
  s.rotation = Eigen::Quaterniond(world_from_camera.linear().cast<double>()).normalized();
  return s;
}

Eigen::Quaterniond RotationFromYawPitchRoll(double yaw, double pitch, double roll) {
  const Eigen::Matrix3d world_from_head = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                                           Eigen::AngleAxisd(-pitch, Eigen::Vector3d::UnitY()) *
                                           Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                                              .toRotationMatrix();
  return Eigen::Quaterniond(world_from_head * HeadFromCamera()).normalized();
}

Eigen::Vector3d YawPitchRollFromRotation(const Eigen::Quaterniond& q) {
  const Eigen::Matrix3d r = q.normalized().toRotationMatrix() * HeadFromCamera().transpose();
  const double theta = std::asin(std::clamp(-r(2, 0), -1.0, 1.0));  // = -pitch
  const double yaw = std::atan2(r(1, 0), r(0, 0));
  const double roll = std::atan2(r(2, 1), r(2, 2));
  return {yaw, -theta, roll};
}

Eigen::Vector3d LogRotation(const Eigen::Quaterniond& q_in) {
  Eigen::Quaterniond q = q_in.normalized();
  if (q.w() < 0) q.coeffs() = -q.coeffs();  // shortest arc: angle ≤ π
  const Eigen::Vector3d v = q.vec();
  const double s = v.norm();
  if (s < 1e-12) return 2.0 * v;  // first order; exact in the limit
  const double angle = 2.0 * std::atan2(s, q.w());
  return v * (angle / s);
}

Eigen::Quaterniond ExpRotation(const Eigen::Vector3d& rotvec) {
  const double angle = rotvec.norm();
  if (angle < 1e-12) {
    Eigen::Quaterniond q(1.0, 0.5 * rotvec.x(), 0.5 * rotvec.y(), 0.5 * rotvec.z());
    return q.normalized();
  }
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle, rotvec / angle));
}

double AngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return LogRotation(a.conjugate() * b).norm();
}

PoseSample InterpolatePose(const std::vector<PoseSample>& samples, int64_t time_us) {
  HOLO_CHECK(!samples.empty());
  if (time_us <= samples.front().time_us) return samples.front();
  if (time_us >= samples.back().time_us) return samples.back();
  const auto it = std::upper_bound(samples.begin(), samples.end(), time_us,
                                   [](int64_t t, const PoseSample& s) { return t < s.time_us; });
  const PoseSample& b = *it;
  const PoseSample& a = *(it - 1);
  const double u = static_cast<double>(time_us - a.time_us) / static_cast<double>(b.time_us - a.time_us);
  PoseSample out;
  out.time_us = time_us;
  out.position = a.position + u * (b.position - a.position);
  out.rotation = a.rotation.slerp(u, b.rotation).normalized();
  return out;
}

bool PoseFeed::Push(const PoseSample& sample) {
  if (!samples_.empty() && sample.time_us <= samples_.back().time_us) return false;
  if (!sample.position.allFinite() || !sample.rotation.coeffs().allFinite() ||
      std::abs(sample.rotation.norm() - 1.0) > 1e-3) {
    return false;
  }
  if (samples_.size() >= capacity_) samples_.erase(samples_.begin(), samples_.begin() + (samples_.size() - capacity_ + 1));
  samples_.push_back(sample);
  return true;
}

}  // namespace holo::pose
