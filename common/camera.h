// Pinhole camera with Brown–Conrady distortion (OpenCV's k1 k2 p1 p2 k3).
#pragma once

#include <array>
#include <string>

#include <Eigen/Core>

#include "common/pose.h"
#include "common/status.h"

namespace holo {

struct Intrinsics {
  int width = 0;
  int height = 0;
  // Focal lengths and principal point, pixels. Pixel centres are at integer
  // coordinates: the top-left pixel covers [-0.5, 0.5)².
  double fx = 0, fy = 0, cx = 0, cy = 0;
  // Brown–Conrady coefficients k1, k2, p1, p2, k3 (OpenCV order). All zero =
  // no distortion.
  std::array<double, 5> distortion{0, 0, 0, 0, 0};

  bool HasDistortion() const;
  // OK, or InvalidArgument naming the field: "fx must be > 0, got -1".
  Status Check() const;
  // Intrinsics for the image scaled by `s` (e.g. 0.5 for half resolution).
  Intrinsics Scaled(double s) const;
  // Square pixels, no distortion, horizontal field of view `hfov_deg`.
  static Intrinsics FromFov(int width, int height, double hfov_deg);
};

// Applies distortion to normalized image coordinates (x/z, y/z).
Eigen::Vector2d Distort(const std::array<double, 5>& d, const Eigen::Vector2d& undistorted);
// Inverts Distort by fixed-point iteration; accurate to ~1e-9 within the
// image for realistic lens coefficients.
Eigen::Vector2d Undistort(const std::array<double, 5>& d, const Eigen::Vector2d& distorted);

// A camera: intrinsics plus its world_from_camera pose.
struct CameraModel {
  Intrinsics intrinsics;
  Pose world_from_camera = Pose::Identity();

  // Pixel coordinates of a point in camera coordinates. Returns false for
  // points at or behind the camera (z <= 1e-6). Does not clip to the image.
  bool ProjectCamera(const Eigen::Vector3f& p_camera, Eigen::Vector2f* pixel) const;
  // Same for a point in world coordinates.
  bool ProjectWorld(const Eigen::Vector3f& p_world, Eigen::Vector2f* pixel) const;
  // Point in camera coordinates at `pixel` with depth (z, metres) `depth`.
  Eigen::Vector3f UnprojectCamera(const Eigen::Vector2f& pixel, float depth) const;
  // Same, in world coordinates.
  Eigen::Vector3f UnprojectWorld(const Eigen::Vector2f& pixel, float depth) const;
  // Unit ray direction in camera coordinates through `pixel`.
  Eigen::Vector3f RayCamera(const Eigen::Vector2f& pixel) const;
  Eigen::Vector3f Center() const { return world_from_camera.translation(); }
};

}  // namespace holo
