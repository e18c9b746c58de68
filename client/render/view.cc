#include "client/render/view.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace holo::render {
namespace {
constexpr float kDegToRad = static_cast<float>(M_PI) / 180.0f;
}

Eigen::Matrix4f ProjectionFromIntrinsics(const Intrinsics& intr, float near_m, float far_m) {
  const float w = static_cast<float>(intr.width), h = static_cast<float>(intr.height);
  const float fx = static_cast<float>(intr.fx), fy = static_cast<float>(intr.fy);
  const float cx = static_cast<float>(intr.cx), cy = static_cast<float>(intr.cy);
  Eigen::Matrix4f p = Eigen::Matrix4f::Zero();
  // Window x = u + 0.5 (pixel centres at integer u): x_ndc = 2 (u + 0.5) / w - 1.
  p(0, 0) = 2.0f * fx / w;
  p(0, 2) = 2.0f * (cx + 0.5f) / w - 1.0f;
  // Image rows grow downwards, window y upwards: y_ndc = 1 - 2 (v + 0.5) / h.
  p(1, 1) = -2.0f * fy / h;
  p(1, 2) = 1.0f - 2.0f * (cy + 0.5f) / h;
  p(2, 2) = (far_m + near_m) / (far_m - near_m);
  p(2, 3) = -2.0f * far_m * near_m / (far_m - near_m);
  p(3, 2) = 1.0f;
  return p;
}

Eigen::Matrix4f ViewProjection(const CameraModel& camera, float near_m, float far_m) {
  return ProjectionFromIntrinsics(camera.intrinsics, near_m, far_m) * camera.world_from_camera.inverse().matrix();
}

void CameraController::SetOrbit(const Eigen::Vector3f& target, float distance_m, float yaw_deg, float pitch_deg) {
  target_ = target;
  distance_ = std::max(0.05f, distance_m);
  yaw_deg_ = yaw_deg;
  pitch_deg_ = std::clamp(pitch_deg, -89.0f, 89.0f);
  eye_ = Eye();
}

void CameraController::SetMode(Mode m) {
  if (m == mode_) return;
  if (m == Mode::kFly) {
    eye_ = Eye();
  } else {
    // Orbit around the point the fly camera looks at, at the same distance.
    target_ = eye_ + distance_ * Forward();
  }
  mode_ = m;
}

Eigen::Vector3f CameraController::Forward() const {
  // Direction from the eye to the target.
  const float y = yaw_deg_ * kDegToRad, p = pitch_deg_ * kDegToRad;
  return -Eigen::Vector3f(std::cos(p) * std::cos(y), std::cos(p) * std::sin(y), std::sin(p));
}

Eigen::Vector3f CameraController::Eye() const {
  if (mode_ == Mode::kFly) return eye_;
  return target_ - distance_ * Forward();
}

void CameraController::Rotate(float dx_px, float dy_px) {
  constexpr float kDegPerPx = 0.3f;
  if (mode_ == Mode::kOrbit) {
    yaw_deg_ -= kDegPerPx * dx_px;
    pitch_deg_ = std::clamp(pitch_deg_ + kDegPerPx * dy_px, -89.0f, 89.0f);
  } else {
    yaw_deg_ += kDegPerPx * dx_px;
    pitch_deg_ = std::clamp(pitch_deg_ + kDegPerPx * dy_px, -89.0f, 89.0f);
  }
}

void CameraController::Zoom(float steps) {
  if (mode_ == Mode::kOrbit) {
    distance_ = std::clamp(distance_ * std::pow(0.9f, steps), 0.05f, 100.0f);
  } else {
    eye_ += 0.1f * steps * Forward();
  }
}

void CameraController::Move(float forward_m, float right_m, float up_m) {
  const Eigen::Vector3f f = Forward();
  Eigen::Vector3f flat(f.x(), f.y(), 0);
  if (flat.norm() < 1e-6f) flat = Eigen::Vector3f::UnitX();
  flat.normalize();
  const Eigen::Vector3f right = flat.cross(Eigen::Vector3f::UnitZ());
  const Eigen::Vector3f delta = forward_m * (mode_ == Mode::kFly ? f : flat) + right_m * right + up_m * Eigen::Vector3f::UnitZ();
  if (mode_ == Mode::kFly) {
    eye_ += delta;
  } else {
    target_ += delta;
  }
}

Pose CameraController::WorldFromCamera() const {
  const Eigen::Vector3f eye = Eye();
  return LookAt(eye, eye + Forward());
}

StatusOr<MosaicLayout> MakeMosaicLayout(int views, int width, int height) {
  if (views < 1 || views > 64) return InvalidArgument("views must be in 1..64, got " + std::to_string(views));
  MosaicLayout m;
  m.views = views;
  m.cols = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(views))));
  m.rows = (views + m.cols - 1) / m.cols;
  m.tile_width = width / m.cols;
  m.tile_height = height / m.rows;
  if (m.tile_width < 16 || m.tile_height < 16) {
    return InvalidArgument("image " + std::to_string(width) + "x" + std::to_string(height) + " is too small for " +
                           std::to_string(views) + " views (tiles would be " + std::to_string(m.tile_width) + "x" +
                           std::to_string(m.tile_height) + ", need at least 16x16)");
  }
  return m;
}

std::vector<CameraModel> MosaicCameras(const Pose& center, const MosaicLayout& layout, const MosaicOptions& options) {
  std::vector<CameraModel> cams;
  const Intrinsics tile = Intrinsics::FromFov(layout.tile_width, layout.tile_height, options.hfov_deg);
  for (int i = 0; i < layout.views; ++i) {
    const float offset = (static_cast<float>(i) - 0.5f * static_cast<float>(layout.views - 1)) * options.spacing_m;
    CameraModel c;
    c.intrinsics = tile;
    // A point on the centre axis at distance D is at x = -offset in this view:
    // u = fx·(-offset)/D + cx' must equal cx.
    c.intrinsics.cx = tile.cx + tile.fx * offset / options.convergence_m;
    c.world_from_camera = center * Eigen::Translation3f(offset, 0, 0);
    cams.push_back(c);
  }
  return cams;
}

Status Miniature::Check() const {
  if (!(scale > 0.0f && scale <= 10.0f)) return InvalidArgument("miniature scale must be in (0, 10], got " + std::to_string(scale));
  if (!pivot.allFinite() || !position.allFinite() || !std::isfinite(yaw_deg)) {
    return InvalidArgument("miniature placement must be finite");
  }
  return OkStatus();
}

Eigen::Matrix4f Miniature::LocalFromRemote() const {
  Eigen::Affine3f t = Eigen::Translation3f(position) * Eigen::AngleAxisf(yaw_deg * kDegToRad, Eigen::Vector3f::UnitZ()) *
                      Eigen::Scaling(scale) * Eigen::Translation3f(-pivot);
  return t.matrix();
}

}  // namespace holo::render
