// Reprojection of an image rendered at an older (or predicted) head pose to
// the newest pose, on the CPU (runs anywhere and in tests; a shader port is
// the same arithmetic per pixel).
//   none      the image as rendered, cropped to the display FOV: what a thin
//             client without reprojection shows (the "stale" image)
//   rotation  homography for the rotation only (scene at infinity)
//   plane     Holoportation's approach: the image as a texture on a plane
//             facing the render camera at the point-of-interest distance,
//             seen from the new pose (exact for rotation, and for
//             translation at that depth)
//   depth     forward warp of every pixel with its depth (z-buffered
//             splats), the background (no depth) by the rotation
//             homography: handles parallax at every depth; disocclusions
//             take the background colour
// Pixels of the output that no source pixel covers (outside the rendered
// FOV, or behind the source camera) are the "black border": `fill` colour and
// 0 in the `valid` mask.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "common/camera.h"
#include "common/image.h"
#include "common/status.h"

namespace holo::reproject {

enum class ReprojectMethod { kNone, kRotation, kPlane, kDepth };
const char* ReprojectMethodName(ReprojectMethod m);  // "none", "rotation", "plane", "depth"
StatusOr<ReprojectMethod> ParseReprojectMethod(const std::string& name);

// Resampling filter of the source image.
enum class ReprojectFilter { kBilinear, kBicubic };

struct ReprojectOptions {
  ReprojectMethod method = ReprojectMethod::kPlane;
  ReprojectFilter filter = ReprojectFilter::kBilinear;
  // Plane distance (source camera z, metres) when the source has no depth;
  // with depth, the median depth of the covered pixels is used.
  float plane_distance_m = 2.0f;
  // Colour of output pixels without a source ("black border").
  std::array<uint8_t, 3> fill = {0, 0, 0};
  // depth: colour of disoccluded pixels (the scene's background).
  std::array<uint8_t, 3> background = {0, 0, 0};
  Status Check() const;
};

struct ReprojectStats {
  // Fraction of output pixels with no source (outside the rendered image).
  double black_border_fraction = 0;
  // depth: fraction of output pixels that were disoccluded (foreground in
  // the source moved away, nothing known behind it).
  double hole_fraction = 0;
  // The plane distance used (plane), metres.
  float plane_distance_m = 0;
};

// Reprojects `source` (rendered with `source_camera`: undistorted
// intrinsics + world_from_camera) to `target_camera` (its resolution and
// intrinsics give the output size). `source_depth` (camera z in mm, 0 = no
// surface, same size as `source`) may be null or empty; kDepth requires it.
// `valid` may be null. InvalidArgument for mismatched sizes, distorted or
// bad intrinsics, bad options.
Status Reproject(const ImageRgb8& source, const ImageDepth16* source_depth, const CameraModel& source_camera,
                 const CameraModel& target_camera, const ReprojectOptions& options, ImageRgb8* out,
                 ImageGray8* valid = nullptr, ReprojectStats* stats = nullptr);

// Median of the non-zero depths (metres), or `fallback` if there is none.
float MedianDepthM(const ImageDepth16& depth, float fallback);

}  // namespace holo::reproject
