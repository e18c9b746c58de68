// The render host's OpenGL path: the viewer's renderer (client/render,
// per-vertex colour) in a headless EGL context, reading back colour, depth
// (mm, from the depth buffer) and a coverage mask. One per render thread
// (the context is current on the thread that created it).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "common/camera.h"
#include "common/image.h"
#include "common/mesh.h"
#include "common/status.h"

namespace holo::offload {

class GlMeshRenderer {
 public:
  // Unavailable with the reason when no headless GL context can be made.
  static StatusOr<std::unique_ptr<GlMeshRenderer>> Create();
  ~GlMeshRenderer();
  // Renders `mesh` (uploaded again only when `mesh_id` changes) from `camera`
  // on black; any output may be null.
  Status Render(const Mesh& mesh, int64_t mesh_id, const CameraModel& camera, ImageRgb8* color, ImageDepth16* depth,
                ImageGray8* mask);
  std::string Describe() const;
  struct Impl;

 private:
  GlMeshRenderer() = default;
  std::unique_ptr<Impl> impl_;
};

}  // namespace holo::offload
