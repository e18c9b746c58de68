// Importers for public single-camera RGB-D layouts (TUM RGB-D, Redwood /
// Open3D), and an in-memory FrameSource that serves what they import.
//
// Several frames of one static scene taken from known poses can stand in for
// several calibrated pods: an importer turns each selected frame into one pod
// of a Rig (world_from_depth = the frame's ground-truth camera pose, in the
// dataset's own world frame) and the frames into one RgbdFrameSet.
//
// Every importer is safe on untrusted folders: a missing file, a malformed
// line, a wrong image size or bit depth, or a count mismatch between images
// and poses gives a Status naming the file (and line) and the problem.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/camera.h"
#include "common/frame_source.h"
#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"

namespace holo {

// Frames of one static scene as pods.
struct ImportedScene {
  // One pod per imported frame; depth registered to color (same intrinsics,
  // identity color_from_depth).
  Rig rig;
  // frames.frames[k] is pod k; frame_index 0; timestamps are each frame's own.
  RgbdFrameSet frames;
  // Where each pod came from: the depth file, relative to the dataset folder.
  std::vector<std::string> source_files;
  // False when the dataset had no poses (all world_from_depth are identity).
  bool has_poses = false;
};

struct TumImportOptions {
  // Pinhole intrinsics of the (registered) depth and color images, pixels.
  // Default: the generic Kinect values TUM recommends for unknown sequences.
  double fx = 525.0, fy = 525.0, cx = 319.5, cy = 239.5;
  // Depth units per metre in the depth PNGs (TUM: 5000). Converted to mm
  // with round(d * 1000 / depth_units_per_metre); values beyond 65535 mm
  // become 0 (invalid).
  double depth_units_per_metre = 5000.0;
  // Maximum |t_rgb - t_depth| for an rgb and a depth image to be associated, s.
  double max_time_difference_s = 0.02;
  // Maximum distance from a depth timestamp to the nearest ground-truth pose
  // (or, when interpolating, to each of the two bracketing poses), s.
  double max_pose_time_difference_s = 0.05;
  // Ground truth (groundtruth.txt): required, or used only when present.
  bool require_poses = false;
  // Indices into the associated (rgb, depth) pairs, in depth time order;
  // empty = all pairs. At most 64 frames (a rig's pod limit).
  std::vector<int> frames;

  // Intrinsics of the TUM Freiburg sensors (`sequence` 1, 2 or 3; others
  // keep the generic values). fr1/fr2 distortion is not modelled.
  static TumImportOptions Freiburg(int sequence);
  Status Check() const;
};

// Reads a TUM RGB-D sequence folder: rgb.txt and depth.txt ("timestamp
// filename" lines, '#' comments), groundtruth.txt ("timestamp tx ty tz qx qy
// qz qw", optional unless `require_poses`). Each depth image is associated
// with the rgb image nearest in time (one-to-one, within
// max_time_difference_s); its pose is interpolated between the ground-truth
// poses that bracket its timestamp (nearest pose when it is outside them).
// Errors: NotFound (missing file), DataLoss (malformed line, image with the
// wrong size or bit depth), InvalidArgument (bad options, no frame selected).
StatusOr<ImportedScene> ImportTum(const std::string& dir, const TumImportOptions& options = {});

struct RedwoodImportOptions {
  // Open3D PinholeCameraIntrinsic JSON, relative to the folder. Ignored when
  // `intrinsics` is set.
  std::string intrinsic_file = "camera_intrinsic.json";
  std::optional<Intrinsics> intrinsics;
  // Redwood .log trajectory (camera-to-world per frame), relative to the
  // folder; empty = no poses (identity).
  std::string trajectory_file = "trajectory.log";
  // Depth units per metre in the depth PNGs (Redwood: 1000 = millimetres).
  double depth_units_per_metre = 1000.0;
  // Indices into the sorted frames; empty = all. At most 64 frames.
  std::vector<int> frames;
  Status Check() const;
};

// Reads an Open3D/Redwood folder: color/ and depth/ (images matched by sorted
// file name: .png, .jpg, .jpeg), the intrinsic JSON and the trajectory. The
// numbers of color images, depth images and trajectory poses must agree.
StatusOr<ImportedScene> ImportRedwood(const std::string& dir, const RedwoodImportOptions& options = {});

// Parsers of the text formats, exposed for tests and tools. `name` prefixes
// errors. Safe on untrusted text.
//
// Redwood .log: blocks of one "id id id+1" line then four rows of a 4x4
// camera-to-world matrix. Checks the last row is 0 0 0 1 and the rotation is
// orthonormal (1e-3).
StatusOr<std::vector<Pose>> ParseRedwoodTrajectory(const std::string& text, const std::string& name);
// Open3D PinholeCameraIntrinsic JSON (width, height, intrinsic_matrix as 9
// numbers, column-major).
StatusOr<Intrinsics> ParseOpen3dIntrinsicJson(const std::string& text, const std::string& name);

// Serves a fixed list of frame sets (e.g. an imported scene) from memory.
class MemoryFrameSource final : public FrameSource {
 public:
  // Checks that every set has one frame per pod, in pod order, with the
  // rig's image sizes (masks empty or depth-sized). InvalidArgument otherwise.
  static StatusOr<std::unique_ptr<MemoryFrameSource>> Create(Rig rig, std::vector<RgbdFrameSet> sets);
  // One frame set: the imported frames as pods.
  static StatusOr<std::unique_ptr<MemoryFrameSource>> FromScene(ImportedScene scene);

  MemoryFrameSource(const MemoryFrameSource&) = delete;
  MemoryFrameSource& operator=(const MemoryFrameSource&) = delete;

  const Rig& rig() const override { return rig_; }
  // Copies the next set into `out` (reusing its buffers).
  Status Next(RgbdFrameSet* out) override;
  int64_t num_frames() const override { return static_cast<int64_t>(sets_.size()); }
  Status Seek(int64_t index) override;

 private:
  MemoryFrameSource() = default;
  Rig rig_;
  std::vector<RgbdFrameSet> sets_;
  int64_t cursor_ = 0;
};

}  // namespace holo
