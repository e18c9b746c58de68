#include "client/reproject/rendered_view.h"

#include <cmath>
#include <cstring>
#include <string>

#include <lz4.h>

#include "protocol/color_codec.h"
#include "texture/mesh_renderer.h"

namespace holo::reproject {

SceneRenderFn MeshSceneRenderer(const Mesh& mesh) {
  return [&mesh](const CameraModel& camera, ImageRgb8* color, ImageDepth16* depth, ImageGray8* mask) {
    return RenderMesh(mesh, camera, color, depth, mask);
  };
}

Status RenderAtPose(const SceneRenderFn& render, const Pose& world_from_camera, const FieldOfView& fov, int width,
                    int height, RenderedView* out) {
  HOLO_RETURN_IF_ERROR(fov.Check());
  if (width < 2 || height < 2 || width > 8192 || height > 8192) {
    return InvalidArgument("RenderAtPose: size " + std::to_string(width) + "x" + std::to_string(height) +
                           " outside 2..8192");
  }
  if (out == nullptr) return InvalidArgument("RenderAtPose: null output");
  out->fov = fov;
  out->camera.intrinsics = IntrinsicsFromFov(fov, width, height);
  out->camera.world_from_camera = world_from_camera;
  return render(out->camera, &out->color, &out->depth, &out->mask);
}

StatusOr<protocol::RenderedFrame> EncodeRenderedView(const RenderedView& view, const FrameEncodeOptions& options) {
  const int w = view.color.width(), h = view.color.height();
  if (w < 1 || h < 1 || w > 8192 || h > 8192) return InvalidArgument("EncodeRenderedView: bad image size");
  HOLO_RETURN_IF_ERROR(view.fov.Check());
  protocol::RenderedFrame f;
  f.frame_index = view.frame_index;
  f.pose_time_us = view.pose_time_us;
  const Eigen::Vector3f t = view.camera.world_from_camera.translation();
  f.position = {t.x(), t.y(), t.z()};
  const Eigen::Quaternionf q(view.camera.world_from_camera.linear());
  f.rotation = {q.w(), q.x(), q.y(), q.z()};
  f.fov_tan = view.fov.ToTan();
  f.width = static_cast<uint16_t>(w);
  f.height = static_cast<uint16_t>(h);
  f.codec = protocol::ColorCodec::kC1;
  protocol::ColorEncodeOptions co;
  co.codec = protocol::ColorCodec::kC1;
  co.jpeg_quality = options.jpeg_quality;
  co.chroma_420 = options.chroma_420;
  static const ImageGray8 kNoMask;
  const ImageGray8& mask = options.use_mask && view.mask.width() == w && view.mask.height() == h ? view.mask : kNoMask;
  HOLO_RETURN_IF_ERROR(protocol::EncodeColor(view.color, mask, co, &f.image));
  if (options.send_depth && view.depth.width() == w && view.depth.height() == h) {
    const int src_bytes = w * h * 2;
    f.depth.resize(static_cast<size_t>(LZ4_compressBound(src_bytes)));
    const int n = LZ4_compress_default(reinterpret_cast<const char*>(view.depth.data()),
                                       reinterpret_cast<char*>(f.depth.data()), src_bytes,
                                       static_cast<int>(f.depth.size()));
    if (n <= 0) return Internal("EncodeRenderedView: LZ4 compression failed");
    f.depth.resize(static_cast<size_t>(n));
  }
  return f;
}

Status DecodeRenderedFrame(const protocol::RenderedFrame& f, RenderedView* out, const protocol::Limits& limits) {
  if (out == nullptr) return InvalidArgument("DecodeRenderedFrame: null output");
  const FieldOfView fov = FieldOfView::FromTan(f.fov_tan);
  if (Status s = fov.Check(); !s.ok()) return DataLoss("RenderedFrame: " + s.message());
  for (float v : f.position) {
    if (!std::isfinite(v) || std::abs(v) > 1e6f) return DataLoss("RenderedFrame: position is not finite or too large");
  }
  Eigen::Quaternionf q(f.rotation[0], f.rotation[1], f.rotation[2], f.rotation[3]);
  if (!q.coeffs().allFinite() || std::abs(q.norm() - 1.0f) > 1e-3f) {
    return DataLoss("RenderedFrame: rotation is not a unit quaternion (norm " + std::to_string(q.norm()) + ")");
  }
  if (f.width < 2 || f.height < 2) return DataLoss("RenderedFrame: image smaller than 2x2");
  if (f.image.empty() || f.image[0] != static_cast<uint8_t>(f.codec)) {
    return DataLoss("RenderedFrame: codec field does not match the image blob");
  }
  HOLO_RETURN_IF_ERROR(protocol::DecodeColor(f.image, &out->color, &out->mask, limits));
  if (out->color.width() != f.width || out->color.height() != f.height) {
    return DataLoss("RenderedFrame: image is " + std::to_string(out->color.width()) + "x" +
                    std::to_string(out->color.height()) + ", header says " + std::to_string(f.width) + "x" +
                    std::to_string(f.height));
  }
  if (f.depth.empty()) {
    out->depth.Resize(0, 0);
  } else {
    const size_t bytes = static_cast<size_t>(f.width) * f.height * 2;
    if (f.depth.size() > static_cast<size_t>(LZ4_compressBound(static_cast<int>(bytes)))) {
      return DataLoss("RenderedFrame: depth blob larger than any LZ4 block of the image's depth");
    }
    out->depth.Resize(f.width, f.height);
    const int n = LZ4_decompress_safe(reinterpret_cast<const char*>(f.depth.data()),
                                      reinterpret_cast<char*>(out->depth.data()), static_cast<int>(f.depth.size()),
                                      static_cast<int>(bytes));
    if (n != static_cast<int>(bytes)) {
      out->depth.Resize(0, 0);
      return DataLoss("RenderedFrame: depth does not decompress to " + std::to_string(bytes) + " bytes");
    }
  }
  out->fov = fov;
  out->frame_index = f.frame_index;
  out->pose_time_us = f.pose_time_us;
  out->camera.intrinsics = IntrinsicsFromFov(fov, f.width, f.height);
  out->camera.world_from_camera = Pose::Identity();
  out->camera.world_from_camera.linear() = q.normalized().toRotationMatrix();
  out->camera.world_from_camera.translation() = Eigen::Vector3f(f.position[0], f.position[1], f.position[2]);
  return OkStatus();
}

protocol::ClientPose ToClientPose(const pose::PoseSample& sample, const FieldOfView& fov, int64_t predicted_display_us) {
  protocol::ClientPose m;
  m.time_us = sample.time_us;
  m.predicted_display_us = predicted_display_us;
  m.position = {static_cast<float>(sample.position.x()), static_cast<float>(sample.position.y()),
                static_cast<float>(sample.position.z())};
  const Eigen::Quaterniond q = sample.rotation.normalized();
  m.rotation = {static_cast<float>(q.w()), static_cast<float>(q.x()), static_cast<float>(q.y()),
                static_cast<float>(q.z())};
  m.fov_tan = fov.ToTan();
  return m;
}

StatusOr<pose::PoseSample> FromClientPose(const protocol::ClientPose& m, FieldOfView* fov) {
  for (float v : m.position) {
    if (!std::isfinite(v) || std::abs(v) > 1e6f) return DataLoss("ClientPose: position is not finite or too large");
  }
  const Eigen::Quaterniond q(m.rotation[0], m.rotation[1], m.rotation[2], m.rotation[3]);
  if (!q.coeffs().allFinite() || std::abs(q.norm() - 1.0) > 1e-3) {
    return DataLoss("ClientPose: rotation is not a unit quaternion (norm " + std::to_string(q.norm()) + ")");
  }
  const FieldOfView f = FieldOfView::FromTan(m.fov_tan);
  if (Status s = f.Check(); !s.ok()) return DataLoss("ClientPose: " + s.message());
  if (fov) *fov = f;
  pose::PoseSample s;
  s.time_us = m.time_us;
  s.position = Eigen::Vector3d(m.position[0], m.position[1], m.position[2]);
  s.rotation = q.normalized();
  return s;
}

}  // namespace holo::reproject
