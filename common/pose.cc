#include "common/pose.h"

#include <algorithm>
#include <cmath>

namespace holo {

Pose LookAt(const Eigen::Vector3f& eye, const Eigen::Vector3f& target, const Eigen::Vector3f& world_up) {
  Eigen::Vector3f z = (target - eye).normalized();
  Eigen::Vector3f up = world_up.normalized();
  if (std::abs(z.dot(up)) > 0.999f) up = Eigen::Vector3f::UnitY();
  Eigen::Vector3f x = z.cross(up).normalized();  // camera right
  Eigen::Vector3f y = z.cross(x);                // camera down
  Pose pose = Pose::Identity();
  pose.linear().col(0) = x;
  pose.linear().col(1) = y;
  pose.linear().col(2) = z;
  pose.translation() = eye;
  return pose;
}

Pose PoseFromTranslationRotvec(const Eigen::Vector3f& t, const Eigen::Vector3f& rotvec) {
  Pose pose = Pose::Identity();
  const float angle = rotvec.norm();
  if (angle > 1e-12f) pose.linear() = Eigen::AngleAxisf(angle, rotvec / angle).toRotationMatrix();
  pose.translation() = t;
  return pose;
}

float RotationDistance(const Pose& a, const Pose& b) {
  const Eigen::Matrix3f r = a.linear().transpose() * b.linear();
  const float c = std::clamp((r.trace() - 1.0f) * 0.5f, -1.0f, 1.0f);
  return std::acos(c);
}

float TranslationDistance(const Pose& a, const Pose& b) {
  return (a.translation() - b.translation()).norm();
}

}  // namespace holo
