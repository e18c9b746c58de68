// The render host's image side of offloaded rendering: render the scene at a
// (predicted) head pose into an enlarged field of view, and the
// RenderedFrame message (protocol/messages.h) that carries the image (JPEG:
// the protocol's C1 colour codec, libturbojpeg), the pose and FOV it was
// rendered with and, optionally, its depth (LZ4 of uint16 mm) for depth
// reprojection. The thin client decodes it back into a RenderedView and
// reprojects (reproject.h).
#pragma once

#include <cstdint>
#include <functional>

#include "client/pose/head_pose.h"
#include "client/reproject/fov.h"
#include "common/camera.h"
#include "common/image.h"
#include "common/mesh.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::reproject {

// One rendered image and what it was rendered with.
struct RenderedView {
  CameraModel camera;  // undistorted intrinsics from the FOV + world_from_camera
  FieldOfView fov;
  ImageRgb8 color;
  ImageDepth16 depth;  // camera z, mm (0 = nothing); may be empty
  ImageGray8 mask;     // 255 where the scene covers the pixel; may be empty
  int64_t frame_index = 0;
  int64_t pose_time_us = 0;
};

// Renders a scene from a camera: colour, depth (mm) and coverage mask; any
// output may be null.
using SceneRenderFn = std::function<Status(const CameraModel&, ImageRgb8*, ImageDepth16*, ImageGray8*)>;
// A SceneRenderFn drawing `mesh` (borrowed: must outlive the function) with
// the CPU mesh renderer (texture/mesh_renderer.h), black background.
SceneRenderFn MeshSceneRenderer(const Mesh& mesh);

// Renders at `world_from_camera` with field of view `fov` at `width` ×
// `height` into `out` (its buffers are reused). InvalidArgument for a bad FOV
// or size; the renderer's errors otherwise.
Status RenderAtPose(const SceneRenderFn& render, const Pose& world_from_camera, const FieldOfView& fov, int width,
                    int height, RenderedView* out);

struct FrameEncodeOptions {
  int jpeg_quality = 90;
  bool chroma_420 = true;
  // Send the depth (LZ4 of uint16 mm) for depth reprojection / the plane distance.
  bool send_depth = true;
  // Encode only the covered pixels (mask) when the view has a mask: the
  // C1 codec then sends the bounding box of the content and the mask.
  bool use_mask = true;
};

// The wire form of `view`. InvalidArgument if the view is empty or larger than the protocol limits.
StatusOr<protocol::RenderedFrame> EncodeRenderedView(const RenderedView& view, const FrameEncodeOptions& options = {});
// Decodes and validates a RenderedFrame from the network into `out`: the
// FOV tangents, a unit quaternion, finite position, the image size matching
// width × height, the depth blob decompressing to exactly width × height ×
// 2 bytes. Safe on untrusted input (DataLoss / UnsupportedVersion naming the field).
Status DecodeRenderedFrame(const protocol::RenderedFrame& frame, RenderedView* out, const protocol::Limits& limits = {});

// The thin client's pose message (protocol ClientPose) from a head-pose
// sample, the display FOV and the expected display time (0 = unknown).
protocol::ClientPose ToClientPose(const pose::PoseSample& sample, const FieldOfView& fov, int64_t predicted_display_us);
// Back to a sample (and its FOV if `fov` is not null), validated: finite
// position, unit quaternion (±1e-3), FOV tangents in (0, 100]. Safe on
// untrusted input (DataLoss naming the field).
StatusOr<pose::PoseSample> FromClientPose(const protocol::ClientPose& message, FieldOfView* fov = nullptr);

}  // namespace holo::reproject
