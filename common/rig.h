// Rigs: the calibrated pods of a capture site, loaded from YAML rig files
// (config/rigs/*.yaml; format in docs/rig-format.md).
#pragma once

#include <string>
#include <vector>

#include "common/camera.h"
#include "common/status.h"

namespace holo {

// The near-infrared stereo pair of an active-stereo pod (docs/rig-format.md).
// The left IR camera sits at the depth camera's pose (world_from_depth): the
// depth a stereo matcher computes in it is the pod's depth image. The right
// IR camera is the left one moved `baseline_m` along the left camera's +x
// axis (a rectified pair: same intrinsics, no distortion, rows aligned), so a
// point at depth z has disparity fx·baseline/z pixels.
struct ProjectorCalibration {
  // Projector centre in the left IR camera's frame, metres.
  Eigen::Vector3f position = Eigen::Vector3f(0.04f, 0.0f, 0.0f);
  // Angular pitch of the speckle pattern's dot grid, milliradians (at the
  // optical axis); each grid cell holds at most one dot.
  double dot_pitch_mrad = 8.0;
  // Fraction of grid cells that hold a dot, (0, 1].
  double dot_density = 0.5;
  // Irradiance of a dot on a surface 1 m away, facing the projector, as a
  // fraction of the IR sensor's full scale; falls off with distance².
  double power_at_1m = 3.0;
};
struct StereoCalibration {
  bool enabled = false;  // false: the pod has no IR pair (depth arrives ready-made)
  Intrinsics ir;         // both IR cameras; rectified: no distortion
  double baseline_m = 0;
  ProjectorCalibration projector;
  // OK, or InvalidArgument naming the field: "baseline_m must be in [0.01, 1], got 0".
  Status Check() const;
};

struct PodCalibration {
  int id = 0;
  std::string name;
  Intrinsics depth;  // depth camera
  Intrinsics color;  // color camera
  // Maps depth-camera coordinates to color-camera coordinates.
  Pose color_from_depth = Pose::Identity();
  // Pose of the depth camera in the site's world frame (z up, metres).
  Pose world_from_depth = Pose::Identity();
  // Active-stereo pods only (stereo.enabled).
  StereoCalibration stereo;

  CameraModel DepthCamera() const { return {depth, world_from_depth}; }
  CameraModel ColorCamera() const { return {color, world_from_depth * color_from_depth.inverse()}; }
  // The IR cameras of a stereo pod (left at the depth camera's pose).
  CameraModel LeftIrCamera() const { return {stereo.ir, world_from_depth}; }
  CameraModel RightIrCamera() const;
  // True when depth is already registered to color: same intrinsics, identity extrinsics.
  bool IsRegistered() const;
};

struct Rig {
  std::string name;
  std::vector<PodCalibration> pods;

  // Rig with every camera's resolution scaled by `s` (0.5: VGA → QVGA).
  Rig Scaled(double s) const;
  // OK, or InvalidArgument naming the pod and field.
  Status Check() const;
};

// Parses a rig from YAML text. `source_name` (usually the file path) prefixes
// every error: "studio-8.yaml: pods[2].depth.fx: must be > 0, got -1".
StatusOr<Rig> ParseRigYaml(const std::string& yaml_text, const std::string& source_name);
// Reads and parses a rig file. NotFound if it cannot be read.
StatusOr<Rig> LoadRig(const std::string& path);
// YAML text that ParseRigYaml reads back to an equal rig (poses as
// translation + quaternion).
std::string RigToYaml(const Rig& rig);
Status SaveRig(const std::string& path, const Rig& rig);

// Path of a rig shipped in config/rigs/ ("studio-8" → ".../config/rigs/studio-8.yaml").
std::string ShippedRigPath(const std::string& name);

}  // namespace holo
