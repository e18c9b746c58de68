#include "client/reproject/fov.h"

#include <cmath>
#include <string>

namespace holo::reproject {

FieldOfView FieldOfView::FromHorizontalDeg(double hfov_deg, double aspect) {
  const double h = std::tan(hfov_deg * M_PI / 360.0);
  const double v = h / aspect;
  return {static_cast<float>(h), static_cast<float>(h), static_cast<float>(v), static_cast<float>(v)};
}

Status FieldOfView::Check() const {
  const char* names[4] = {"left", "right", "up", "down"};
  const float v[4] = {left, right, up, down};
  for (int i = 0; i < 4; ++i) {
    if (!std::isfinite(v[i]) || !(v[i] > 0) || v[i] > 100) {
      return InvalidArgument(std::string("fov tangent ") + names[i] + " must be in (0, 100], got " + std::to_string(v[i]));
    }
  }
  return OkStatus();
}

FieldOfView FieldOfView::Enlarged(double margin) const {
  const float s = static_cast<float>(1.0 + margin);
  return {left * s, right * s, up * s, down * s};
}

double FieldOfView::HorizontalDeg() const { return (std::atan(left) + std::atan(right)) * 180.0 / M_PI; }

Intrinsics IntrinsicsFromFov(const FieldOfView& fov, int width, int height) {
  Intrinsics k;
  k.width = width;
  k.height = height;
  k.fx = width / static_cast<double>(fov.left + fov.right);
  k.fy = height / static_cast<double>(fov.up + fov.down);
  k.cx = k.fx * fov.left - 0.5;
  k.cy = k.fy * fov.up - 0.5;
  return k;
}

FieldOfView FovFromIntrinsics(const Intrinsics& k) {
  FieldOfView f;
  f.left = static_cast<float>((k.cx + 0.5) / k.fx);
  f.right = static_cast<float>((k.width - 0.5 - k.cx) / k.fx);
  f.up = static_cast<float>((k.cy + 0.5) / k.fy);
  f.down = static_cast<float>((k.height - 0.5 - k.cy) / k.fy);
  return f;
}

std::array<int, 2> ResolutionForFov(const FieldOfView& fov, int width, int height, const FieldOfView& enlarged) {
  const double sx = (enlarged.left + enlarged.right) / static_cast<double>(fov.left + fov.right);
  const double sy = (enlarged.up + enlarged.down) / static_cast<double>(fov.up + fov.down);
  const int w = 2 * static_cast<int>(std::lround(width * sx / 2));
  const int h = 2 * static_cast<int>(std::lround(height * sy / 2));
  return {w, h};
}

}  // namespace holo::reproject
