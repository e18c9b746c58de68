#include "client/offload/gl_scene.h"

#include <epoxy/gl.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "client/render/gl_context.h"
#include "client/render/renderer.h"

namespace holo::offload {

struct GlMeshRenderer::Impl {
  std::unique_ptr<render::GlContext> context;
  std::unique_ptr<render::Renderer> renderer;
  std::unique_ptr<render::OffscreenTarget> target;
  int64_t mesh_id = -1;
  std::vector<float> depth_rows;
};

GlMeshRenderer::~GlMeshRenderer() = default;

StatusOr<std::unique_ptr<GlMeshRenderer>> GlMeshRenderer::Create() {
  std::unique_ptr<GlMeshRenderer> r(new GlMeshRenderer());
  r->impl_ = std::make_unique<Impl>();
  auto ctx = render::CreateHeadlessContext();
  if (!ctx.ok()) return Unavailable("GL renderer: " + ctx.status().ToString());
  r->impl_->context = std::move(*ctx);
  HOLO_RETURN_IF_ERROR(r->impl_->context->MakeCurrent());
  auto renderer = render::Renderer::Create();
  if (!renderer.ok()) return Unavailable("GL renderer: " + renderer.status().ToString());
  r->impl_->renderer = std::move(*renderer);
  return r;
}

std::string GlMeshRenderer::Describe() const { return impl_->context->Describe(); }

Status GlMeshRenderer::Render(const Mesh& mesh, int64_t mesh_id, const CameraModel& camera, ImageRgb8* color,
                              ImageDepth16* depth, ImageGray8* mask) {
  Impl& m = *impl_;
  const int w = camera.intrinsics.width, h = camera.intrinsics.height;
  if (w < 1 || h < 1) return InvalidArgument("GL renderer: empty camera");
  if (!m.target || m.target->width() != w || m.target->height() != h) {
    HOLO_ASSIGN_OR_RETURN(m.target, render::OffscreenTarget::Create(w, h));
  }
  if (mesh_id != m.mesh_id) {
    HOLO_RETURN_IF_ERROR(m.renderer->SetRemoteMesh(mesh));
    m.mesh_id = mesh_id;
  }
  render::RenderSettings settings;
  settings.mode = render::ColorMode::kVertexColor;
  settings.background = {0, 0, 0};
  m.target->Bind();
  HOLO_RETURN_IF_ERROR(m.renderer->Render(camera, settings, {0, 0, w, h}));
  ImageRgb8 local;
  ImageRgb8* out = color ? color : &local;
  HOLO_RETURN_IF_ERROR(m.target->ReadRgb(out));
  if (depth || mask) {
    // Window depth d → camera z = 2fn / ((f + n) − (2d − 1)(f − n)) (the projection of client/render/view.cc).
    m.depth_rows.resize(static_cast<size_t>(w) * h);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadPixels(0, 0, w, h, GL_DEPTH_COMPONENT, GL_FLOAT, m.depth_rows.data());
    if (glGetError() != GL_NO_ERROR) return Internal("GL renderer: reading the depth buffer failed");
    const double n = settings.near_m, f = settings.far_m;
    if (depth) depth->Resize(w, h);
    if (mask) mask->Resize(w, h);
    for (int y = 0; y < h; ++y) {
      const float* src = m.depth_rows.data() + static_cast<size_t>(h - 1 - y) * w;
      for (int x = 0; x < w; ++x) {
        const double d = src[x];
        const bool covered = d < 1.0;
        uint16_t mm = 0;
        if (covered) {
          const double z = 2 * f * n / ((f + n) - (2 * d - 1) * (f - n));
          mm = static_cast<uint16_t>(std::clamp(std::lround(z * 1000.0), 1L, 65535L));
        }
        if (depth) depth->data()[static_cast<size_t>(y) * w + x] = mm;
        if (mask) mask->data()[static_cast<size_t>(y) * w + x] = covered ? 255 : 0;
      }
    }
  }
  return OkStatus();
}

}  // namespace holo::offload
