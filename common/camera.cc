#include "common/camera.h"

#include <cmath>

namespace holo {

bool Intrinsics::HasDistortion() const {
  for (double c : distortion)
    if (c != 0.0) return true;
  return false;
}

Status Intrinsics::Check() const {
  if (width <= 0 || width > 16384)
    return InvalidArgument("width must be in [1, 16384], got " + FormatNumber(width));
  if (height <= 0 || height > 16384)
    return InvalidArgument("height must be in [1, 16384], got " + FormatNumber(height));
  if (!(fx > 0) || !std::isfinite(fx)) return InvalidArgument("fx must be > 0, got " + FormatNumber(fx));
  if (!(fy > 0) || !std::isfinite(fy)) return InvalidArgument("fy must be > 0, got " + FormatNumber(fy));
  if (!std::isfinite(cx) || cx < -width || cx > 2.0 * width)
    return InvalidArgument("cx must lie near the image (width " + FormatNumber(width) + "), got " + FormatNumber(cx));
  if (!std::isfinite(cy) || cy < -height || cy > 2.0 * height)
    return InvalidArgument("cy must lie near the image (height " + FormatNumber(height) + "), got " + FormatNumber(cy));
  for (size_t i = 0; i < distortion.size(); ++i) {
    if (!std::isfinite(distortion[i]) || std::abs(distortion[i]) > 10.0)
      return InvalidArgument("distortion[" + FormatNumber(static_cast<double>(i)) +
                             "] must be finite and |.| <= 10, got " + FormatNumber(distortion[i]));
  }
  return OkStatus();
}

Intrinsics Intrinsics::Scaled(double s) const {
  Intrinsics out = *this;
  out.width = static_cast<int>(std::lround(width * s));
  out.height = static_cast<int>(std::lround(height * s));
  out.fx = fx * s;
  out.fy = fy * s;
  // Pixel centres at integer coordinates: scale about the corner (-0.5, -0.5).
  out.cx = (cx + 0.5) * s - 0.5;
  out.cy = (cy + 0.5) * s - 0.5;
  return out;
}

Intrinsics Intrinsics::FromFov(int width, int height, double hfov_deg) {
  Intrinsics k;
  k.width = width;
  k.height = height;
  k.fx = k.fy = 0.5 * width / std::tan(0.5 * hfov_deg * M_PI / 180.0);
  k.cx = 0.5 * (width - 1);
  k.cy = 0.5 * (height - 1);
  return k;
}

Eigen::Vector2d Distort(const std::array<double, 5>& d, const Eigen::Vector2d& u) {
  const double x = u.x(), y = u.y();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
  const double xd = x * radial + 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x);
  const double yd = y * radial + d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y;
  return {xd, yd};
}

Eigen::Vector2d Undistort(const std::array<double, 5>& d, const Eigen::Vector2d& distorted) {
  // Newton iteration with a numeric Jacobian: converges in a few steps.
  Eigen::Vector2d u = distorted;
  for (int iter = 0; iter < 20; ++iter) {
    const Eigen::Vector2d f = Distort(d, u) - distorted;
    if (f.squaredNorm() < 1e-24) break;
    const double h = 1e-7;
    Eigen::Matrix2d j;
    j.col(0) = (Distort(d, u + Eigen::Vector2d(h, 0)) - Distort(d, u)) / h;
    j.col(1) = (Distort(d, u + Eigen::Vector2d(0, h)) - Distort(d, u)) / h;
    u -= j.inverse() * f;
  }
  return u;
}

bool CameraModel::ProjectCamera(const Eigen::Vector3f& p, Eigen::Vector2f* pixel) const {
  if (p.z() <= 1e-6f) return false;
  Eigen::Vector2d n(p.x() / static_cast<double>(p.z()), p.y() / static_cast<double>(p.z()));
  if (intrinsics.HasDistortion()) n = Distort(intrinsics.distortion, n);
  (*pixel) << static_cast<float>(intrinsics.fx * n.x() + intrinsics.cx),
      static_cast<float>(intrinsics.fy * n.y() + intrinsics.cy);
  return true;
}

bool CameraModel::ProjectWorld(const Eigen::Vector3f& p_world, Eigen::Vector2f* pixel) const {
  return ProjectCamera(world_from_camera.inverse() * p_world, pixel);
}

Eigen::Vector3f CameraModel::UnprojectCamera(const Eigen::Vector2f& pixel, float depth) const {
  Eigen::Vector2d n((pixel.x() - intrinsics.cx) / intrinsics.fx, (pixel.y() - intrinsics.cy) / intrinsics.fy);
  if (intrinsics.HasDistortion()) n = Undistort(intrinsics.distortion, n);
  return Eigen::Vector3f(static_cast<float>(n.x()) * depth, static_cast<float>(n.y()) * depth, depth);
}

Eigen::Vector3f CameraModel::UnprojectWorld(const Eigen::Vector2f& pixel, float depth) const {
  return world_from_camera * UnprojectCamera(pixel, depth);
}

Eigen::Vector3f CameraModel::RayCamera(const Eigen::Vector2f& pixel) const {
  return UnprojectCamera(pixel, 1.0f).normalized();
}

}  // namespace holo
