// Fields of view as the protocol carries them (ClientPose / RenderedFrame
// fov_tan: tangents of the half angles left, right, up, down) and the
// pinhole intrinsics they give at a resolution.
#pragma once

#include <array>

#include "common/camera.h"
#include "common/status.h"

namespace holo::reproject {

struct FieldOfView {
  // Tangents of the half angles, all > 0: left, right, up, down.
  float left = 1, right = 1, up = 1, down = 1;

  // Symmetric FOV from the horizontal angle (degrees) and the aspect
  // (width / height) of square pixels.
  static FieldOfView FromHorizontalDeg(double hfov_deg, double aspect);
  static FieldOfView FromTan(const std::array<float, 4>& t) { return {t[0], t[1], t[2], t[3]}; }
  std::array<float, 4> ToTan() const { return {left, right, up, down}; }
  // InvalidArgument unless every tangent is finite and in (0, 100].
  Status Check() const;
  // Every tangent scaled by (1 + margin): the over-rendered FOV.
  FieldOfView Enlarged(double margin) const;
  double HorizontalDeg() const;
};

// Intrinsics whose image (pixel centres at integers, edges at −0.5 and
// width − 0.5) spans exactly `fov` at `width` × `height` (no distortion).
Intrinsics IntrinsicsFromFov(const FieldOfView& fov, int width, int height);
// The FOV of undistorted `intrinsics` (inverse of IntrinsicsFromFov).
FieldOfView FovFromIntrinsics(const Intrinsics& intrinsics);
// Resolution that keeps the angular pixel density of `width` × `height` at
// `fov` when rendering `enlarged` (rounded to even numbers).
std::array<int, 2> ResolutionForFov(const FieldOfView& fov, int width, int height, const FieldOfView& enlarged);

}  // namespace holo::reproject
