// Rigs: the calibrated pods of a capture site, loaded from YAML rig files
// (config/rigs/*.yaml; format in docs/rig-format.md).
#pragma once

#include <string>
#include <vector>

#include "common/camera.h"
#include "common/status.h"

namespace holo {

struct PodCalibration {
  int id = 0;
  std::string name;
  Intrinsics depth;  // depth camera
  Intrinsics color;  // color camera
  // Maps depth-camera coordinates to color-camera coordinates.
  Pose color_from_depth = Pose::Identity();
  // Pose of the depth camera in the site's world frame (z up, metres).
  Pose world_from_depth = Pose::Identity();

  CameraModel DepthCamera() const { return {depth, world_from_depth}; }
  CameraModel ColorCamera() const { return {color, world_from_depth * color_from_depth.inverse()}; }
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
