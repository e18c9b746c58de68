#include "client/tools/viewer_app.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <epoxy/gl.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <nlohmann/json.hpp>

#include "client/render/gl_context.h"
#include "client/render/overlay.h"
#include "client/render/renderer.h"
#include "client/render/view.h"
#include "client/tools/synthetic_source.h"
#include "common/clock.h"
#include "common/image_io.h"
#include "common/metrics/mesh_shapes.h"
#include "common/pose.h"
// Recorded head traces come from the pose library when it is part of the
// build (client/pose, the prediction work); without it --pose-trace is refused.
#if __has_include("client/pose/trace.h")
#include "client/pose/trace.h"
#define HOLO_CLIENT_HAVE_TRACE 1
#else
#define HOLO_CLIENT_HAVE_TRACE 0
#endif

namespace holo::client {
namespace {

using render::ColorMode;

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t i = std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size() - 1) + 0.5));
  return v[i];
}

// A table for the miniature room: top at `top` (centre of the top face),
// 1.4 × 1.0 m, on four legs.
Mesh MakeTable(const Eigen::Vector3f& top) {
  Mesh table = metrics::MakeBoxMesh(top - Eigen::Vector3f(0, 0, 0.02f), Eigen::Vector3f(1.4f, 1.0f, 0.04f));
  table.colors.assign(table.num_vertices(), {150, 105, 65});
  const float h = top.z() - 0.04f;
  for (int sx : {-1, 1}) {
    for (int sy : {-1, 1}) {
      Mesh leg = metrics::MakeBoxMesh(top + Eigen::Vector3f(sx * 0.62f, sy * 0.42f, -0.04f - h / 2),
                                      Eigen::Vector3f(0.06f, 0.06f, h));
      leg.colors.assign(leg.num_vertices(), {110, 75, 45});
      table.Append(leg);
    }
  }
  // A floor around it, so the table stands somewhere.
  Mesh floor = metrics::MakePlaneMesh(Eigen::Vector3f(top.x(), top.y(), 0.0f), 6.0f, 6.0f, 12, 12);
  floor.colors.assign(floor.num_vertices(), {70, 72, 78});
  table.Append(floor);
  return table;
}

struct FrameStats {
  std::vector<double> produce_ms, upload_ms, render_ms, latency_ms, loop_ms;
  int64_t drops = 0;
  int64_t frames = 0;
};

class Viewer {
 public:
  explicit Viewer(const ViewerOptions& o) : o_(o) {}

  Status Init() {
    if (o_.width < 16 || o_.height < 16 || o_.width > 8192 || o_.height > 8192) {
      return InvalidArgument("--width/--height must be in 16..8192, got " + std::to_string(o_.width) + "x" +
                             std::to_string(o_.height));
    }
    if (o_.color == "projective") {
      mode_ = ColorMode::kProjective;
    } else if (o_.color == "vertex") {
      mode_ = ColorMode::kVertexColor;
    } else {
      return InvalidArgument("--color must be projective or vertex, got '" + o_.color + "'");
    }
    HOLO_ASSIGN_OR_RETURN(layout_, render::MakeMosaicLayout(o_.views, o_.width, o_.height));
    if (o_.miniature_scale != 0.0f) {
      mini_.scale = o_.miniature_scale;
      mini_.position = o_.miniature_at;
      mini_.yaw_deg = o_.miniature_yaw_deg;
      HOLO_RETURN_IF_ERROR(mini_.Check().WithContext("--miniature"));
    } else if (o_.remote_placed) {
      mini_.scale = 1.0f;
      mini_.position = o_.remote_at;
      mini_.yaw_deg = o_.remote_yaw_deg;
      HOLO_RETURN_IF_ERROR(mini_.Check().WithContext("--remote-at"));
    }
    if (!o_.pose_trace.empty()) {
#if HOLO_CLIENT_HAVE_TRACE
      auto trace = pose::ReadHeadTrace(o_.pose_trace);
      if (!trace.ok()) return trace.status().WithContext("--pose-trace");
      trace_ = std::move(*trace);
#else
      return Unavailable("--pose-trace needs the head-trace reader (client/pose), which this build does not have");
#endif
    }
    HOLO_ASSIGN_OR_RETURN(source_, SyntheticSource::Create(o_.source, o_.threads));

    // Context: headless (EGL surfaceless; an invisible GLFW window as the
    // fallback when there is a display) or a window.
    if (o_.headless) {
      auto egl = render::CreateHeadlessContext();
      if (egl.ok()) {
        context_ = std::move(*egl);
      } else {
        auto hidden = render::CreateWindowContext(o_.width, o_.height, "holoport-client", false);
        if (!hidden.ok()) {
          return Unavailable("headless rendering is not available: " + egl.status().message() + "; and " +
                             hidden.status().message());
        }
        context_ = std::move(*hidden);
      }
    } else {
      HOLO_ASSIGN_OR_RETURN(context_, render::CreateWindowContext(o_.width, o_.height, "Holoport viewer"));
    }
    HOLO_RETURN_IF_ERROR(context_->MakeCurrent());
    HOLO_ASSIGN_OR_RETURN(renderer_, render::Renderer::Create());
    if (o_.overlay) {
      HOLO_ASSIGN_OR_RETURN(overlay_, render::Overlay::Create());
    }
    if (o_.headless) {
      HOLO_ASSIGN_OR_RETURN(target_, render::OffscreenTarget::Create(o_.width, o_.height));
    }

    if (o_.local == "table") {
      HOLO_RETURN_IF_ERROR(renderer_->SetLocalMesh(MakeTable(mini_.position)));
      have_local_ = true;
    } else if (o_.local.rfind("synthetic", 0) == 0) {
      // The local site live: a second studio (its own seed and people), its
      // mesh replaced every frame.
      HOLO_ASSIGN_OR_RETURN(local_source_, SyntheticSource::Create(o_.local, o_.threads));
      have_local_ = true;
    } else if (!o_.local.empty() && o_.local != "none") {
      auto mesh = ReadPly(o_.local);
      if (!mesh.ok()) return mesh.status().WithContext("--local");
      HOLO_RETURN_IF_ERROR(renderer_->SetLocalMesh(*mesh).WithContext("--local " + o_.local));
      have_local_ = true;
    }
    // Orbit defaults: around the people, between the two sites' people, or
    // around the table top.
    if (o_.remote_placed && o_.miniature_scale == 0.0f) {
      orbit_target_ = 0.5f * o_.remote_at + Eigen::Vector3f(0, 0, 1.0f);
      orbit_radius_ = 3.0f + 0.5f * o_.remote_at.head<2>().norm();
    }
    if (o_.miniature_scale != 0.0f) {
      const float s = mini_.scale;
      orbit_target_ = mini_.position + Eigen::Vector3f(0, 0, 0.9f * s);
      orbit_radius_ = 3.5f * s + 0.8f;
      orbit_height_ = mini_.position.z() + 0.6f;
    }
    controller_.SetOrbit(orbit_target_, std::hypot(orbit_radius_, orbit_height_ - orbit_target_.z()), 20.0f,
                         std::atan2(orbit_height_ - orbit_target_.z(), orbit_radius_) * 180.0f / static_cast<float>(M_PI));
    std::printf("holoport-client: %s, source %s (%zu pods), %dx%d, %d view(s), %s%s\n",
                context_->Describe().c_str(), o_.source.c_str(), source_->rig().pods.size(), o_.width, o_.height,
                o_.views, render::ColorModeName(mode_), o_.miniature_scale != 0.0f ? ", miniature" : "");
    return OkStatus();
  }

  // world_from_camera of the centre view at time t (seconds from start).
  Pose ViewPose(double t) const {
    if (!trace_.empty()) {
#if HOLO_CLIENT_HAVE_TRACE
      const int64_t t_us = trace_.front().time_us + static_cast<int64_t>(t * 1e6);
      return pose::InterpolatePose(trace_, t_us).ToPose();
#endif
    }
    if (interactive_) return controller_.WorldFromCamera();
    const float az = (20.0f + 360.0f * static_cast<float>(t) / 12.0f) * static_cast<float>(M_PI) / 180.0f;
    const Eigen::Vector3f eye = orbit_target_ + Eigen::Vector3f(orbit_radius_ * std::cos(az),
                                                                orbit_radius_ * std::sin(az),
                                                                orbit_height_ - orbit_target_.z());
    return LookAt(eye, orbit_target_);
  }

  Status Upload(const StreamFrame& frame) {
    if (local_source_) {
      // The local site's frame of the same instant (its own capture, not timed as the stream's).
      HOLO_RETURN_IF_ERROR(local_source_->Produce(frame.index, &local_frame_).WithContext("--local"));
      HOLO_RETURN_IF_ERROR(renderer_->SetLocalMesh(local_frame_.mesh));
    }
    Stopwatch sw;
    HOLO_RETURN_IF_ERROR(renderer_->SetRemoteMesh(frame.mesh));
    std::vector<const ImageRgb8*> images;
    for (const auto& im : frame.pod_images) images.push_back(&im);
    HOLO_RETURN_IF_ERROR(renderer_->SetPodImages(source_->rig(), images));
    if (mode_ == ColorMode::kProjective) HOLO_RETURN_IF_ERROR(renderer_->UpdateVisibility());
    glFinish();
    stats_.upload_ms.push_back(sw.ElapsedMs());
    return OkStatus();
  }

  // Draws all views and the overlay into the bound framebuffer (fb size).
  Status Draw(double t, int fb_width, int fb_height) {
    render::RenderSettings settings;
    settings.mode = mode_;
    settings.local_from_remote =
        o_.miniature_scale != 0.0f || o_.remote_placed ? mini_.LocalFromRemote() : Eigen::Matrix4f::Identity();
    settings.composite_local = have_local_;
    settings.show_local = !o_.see_through;
    auto layout = render::MakeMosaicLayout(o_.views, fb_width, fb_height);
    if (!layout.ok()) return layout.status();
    render::MosaicOptions mo;
    mo.spacing_m = o_.view_spacing_m;
    mo.hfov_deg = o_.hfov_deg;
    const Pose center = ViewPose(t);
    mo.convergence_m = std::max(0.2f, (center.translation() - orbit_target_).norm());
    std::vector<CameraModel> cams;
    if (o_.views == 1) {
      CameraModel c;
      c.intrinsics = Intrinsics::FromFov(layout->tile_width, layout->tile_height, o_.hfov_deg);
      c.world_from_camera = center;
      cams.push_back(c);
    } else {
      cams = render::MosaicCameras(center, *layout, mo);
    }
    // Clear the whole framebuffer once (mosaic cells without a view stay dark).
    glViewport(0, 0, fb_width, fb_height);
    glDisable(GL_SCISSOR_TEST);
    glClearColor(0, 0, 0, 1);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    for (int i = 0; i < layout->views; ++i) {
      const render::Viewport vp{layout->TileX(i), fb_height - layout->TileY(i) - layout->tile_height,
                                layout->tile_width, layout->tile_height};
      HOLO_RETURN_IF_ERROR(renderer_->Render(cams[i], settings, vp));
    }
    if (overlay_ && show_overlay_) {
      const int scale = fb_height >= 600 && o_.views == 1 ? 2 : 1;
      HOLO_RETURN_IF_ERROR(overlay_->Draw(OverlayText(), 10 * scale, 10 * scale, scale, fb_width, fb_height,
                                          {255, 240, 120}));
    }
    return OkStatus();
  }

  std::string OverlayText() const {
    // Figures of the previous displayed frame ("-" before the first).
    char fps[32] = "-", rms[32] = "-", lat[32] = "-";
    if (!stats_.render_ms.empty()) {
      std::snprintf(fps, sizeof fps, "%.1f", recent_fps_);
      std::snprintf(rms, sizeof rms, "%.1f", stats_.render_ms.back());
      std::snprintf(lat, sizeof lat, "%.0f", stats_.latency_ms.back());
    }
    char buf[512];
    std::snprintf(buf, sizeof buf,
                  "HOLOPORT VIEWER  %s\nFPS %s  RENDER %s MS\nLATENCY %s MS CAPTURE->DISPLAY\n"
                  "BITRATE N/A (LOCAL SOURCE)  DROPS %lld\n%zu TRIS  %s  %d VIEW%s%s",
                  o_.source.c_str(), fps, rms, lat, static_cast<long long>(stats_.drops),
                  renderer_->remote_triangles(), mode_ == ColorMode::kProjective ? "PROJECTIVE" : "VERTEX COLOUR",
                  o_.views, o_.views == 1 ? "" : "S", o_.miniature_scale != 0.0f ? "  MINIATURE" : "");
    return buf;
  }

  void NoteDisplayed(const StreamFrame& frame, double loop_ms) {
    const int64_t now = RealClock::Instance().NowUs();
    stats_.latency_ms.push_back((now - frame.capture_us) / 1000.0);
    stats_.loop_ms.push_back(loop_ms);
    const size_t n = std::min<size_t>(stats_.loop_ms.size(), 15);
    double sum = 0;
    for (size_t i = stats_.loop_ms.size() - n; i < stats_.loop_ms.size(); ++i) sum += stats_.loop_ms[i];
    recent_fps_ = sum > 0 ? 1000.0 * n / sum : 0;
    ++stats_.frames;
  }

  int RunHeadless() {
    const int frames = o_.frames > 0 ? o_.frames : 30;
    std::error_code ec;
    std::filesystem::create_directories(o_.out_dir, ec);
    if (ec) return Fail(Unavailable("--out " + o_.out_dir + ": cannot create: " + ec.message()));
    StreamFrame frame;
    ImageRgb8 image;
    for (int i = 0; i < frames; ++i) {
      Stopwatch loop;
      if (Status s = source_->Produce(i, &frame); !s.ok()) return Fail(s);
      stats_.produce_ms.push_back(frame.produce_ms);
      if (Status s = Upload(frame); !s.ok()) return Fail(s);
      target_->Bind();
      Stopwatch rs;
      if (Status s = Draw(i / source_->fps(), o_.width, o_.height); !s.ok()) return Fail(s);
      glFinish();
      stats_.render_ms.push_back(rs.ElapsedMs());
      NoteDisplayed(frame, loop.ElapsedMs());
      if (o_.write_png) {
        if (Status s = target_->ReadRgb(&image); !s.ok()) return Fail(s);
        char name[64];
        std::snprintf(name, sizeof name, "frame_%04d.png", i);
        const std::string path = (std::filesystem::path(o_.out_dir) / name).string();
        if (Status s = WriteImageRgb8(path, image); !s.ok()) return Fail(s);
        pngs_.push_back(name);
      }
      if ((i + 1) % 10 == 0 || i + 1 == frames) {
        std::printf("frame %d/%d: render %.1f ms, latency %.1f ms\n", i + 1, frames, stats_.render_ms.back(),
                    stats_.latency_ms.back());
        std::fflush(stdout);
      }
    }
    return WriteStats();
  }

  int RunInteractive() {
    interactive_ = trace_.empty();
    GLFWwindow* w = context_->window();
    glfwSetWindowUserPointer(w, this);
    glfwSetCursorPosCallback(w, [](GLFWwindow* win, double x, double y) {
      auto* self = static_cast<Viewer*>(glfwGetWindowUserPointer(win));
      if (glfwGetMouseButton(win, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS) {
        self->controller_.Rotate(static_cast<float>(x - self->mouse_x_), static_cast<float>(y - self->mouse_y_));
      }
      self->mouse_x_ = x;
      self->mouse_y_ = y;
    });
    glfwSetScrollCallback(w, [](GLFWwindow* win, double, double dy) {
      static_cast<Viewer*>(glfwGetWindowUserPointer(win))->controller_.Zoom(static_cast<float>(dy));
    });
    glfwSetKeyCallback(w, [](GLFWwindow* win, int key, int, int action, int) {
      if (action != GLFW_PRESS) return;
      auto* self = static_cast<Viewer*>(glfwGetWindowUserPointer(win));
      if (key == GLFW_KEY_ESCAPE || key == GLFW_KEY_Q) glfwSetWindowShouldClose(win, GLFW_TRUE);
      if (key == GLFW_KEY_F) {
        self->controller_.SetMode(self->controller_.mode() == render::CameraController::Mode::kOrbit
                                      ? render::CameraController::Mode::kFly
                                      : render::CameraController::Mode::kOrbit);
      }
      if (key == GLFW_KEY_T) {
        self->mode_ = self->mode_ == ColorMode::kProjective ? ColorMode::kVertexColor : ColorMode::kProjective;
      }
      if (key == GLFW_KEY_O) self->show_overlay_ = !self->show_overlay_;
    });
    const int64_t start = RealClock::Instance().NowUs();
    int64_t last_index = -1;
    StreamFrame frame;
    Stopwatch loop;
    const double move_speed = o_.miniature_scale != 0.0f ? 0.5 : 1.5;  // m/s
    while (!glfwWindowShouldClose(w) && (o_.frames <= 0 || stats_.frames < o_.frames)) {
      const double dt = loop.ElapsedMs() / 1000.0;
      loop.Restart();
      glfwPollEvents();
      const float step = static_cast<float>(move_speed * dt);
      auto key = [w](int k) { return glfwGetKey(w, k) == GLFW_PRESS ? 1.0f : 0.0f; };
      controller_.Move(step * (key(GLFW_KEY_W) - key(GLFW_KEY_S)), step * (key(GLFW_KEY_D) - key(GLFW_KEY_A)),
                       step * (key(GLFW_KEY_E) - key(GLFW_KEY_C)));
      const double t = (RealClock::Instance().NowUs() - start) / 1e6;
      const int64_t index = static_cast<int64_t>(t * source_->fps());
      if (index > last_index) {
        if (last_index >= 0) stats_.drops += index - last_index - 1;
        if (Status s = source_->Produce(index, &frame); !s.ok()) return Fail(s);
        stats_.produce_ms.push_back(frame.produce_ms);
        if (Status s = Upload(frame); !s.ok()) return Fail(s);
        last_index = index;
      }
      int fbw = 0, fbh = 0;
      glfwGetFramebufferSize(w, &fbw, &fbh);
      if (fbw < 16 || fbh < 16) continue;  // minimised
      glBindFramebuffer(GL_FRAMEBUFFER, 0);
      Stopwatch rs;
      if (Status s = Draw(t, fbw, fbh); !s.ok()) return Fail(s);
      glfwSwapBuffers(w);
      glFinish();
      stats_.render_ms.push_back(rs.ElapsedMs());
      NoteDisplayed(frame, loop.ElapsedMs());
    }
    return WriteStats();
  }

  int WriteStats() {
    nlohmann::json j;
    j["source"] = o_.source;
    j["workload"] = source_->workload();
    j["gl_renderer"] = render::CurrentGlRenderer();
    j["context"] = context_->Describe();
    j["frames"] = stats_.frames;
    j["width"] = o_.width;
    j["height"] = o_.height;
    j["views"] = o_.views;
    j["mosaic"] = {{"cols", layout_.cols}, {"rows", layout_.rows}, {"tile_width", layout_.tile_width},
                   {"tile_height", layout_.tile_height}};
    j["mode"] = render::ColorModeName(mode_);
    j["triangles"] = renderer_->remote_triangles();
    j["local_triangles"] = have_local_ ? renderer_->local_triangles() : 0;
    j["miniature_scale"] = o_.miniature_scale;
    j["camera"] = trace_.empty() ? (interactive_ ? "interactive" : "orbit") : "trace:" + o_.pose_trace;
    double loop_sum = 0;
    for (double v : stats_.loop_ms) loop_sum += v;
    j["fps"] = loop_sum > 0 ? 1000.0 * stats_.frames / loop_sum : 0.0;
    j["render_ms_median"] = Percentile(stats_.render_ms, 0.5);
    j["render_ms_p95"] = Percentile(stats_.render_ms, 0.95);
    j["upload_ms_median"] = Percentile(stats_.upload_ms, 0.5);
    j["produce_ms_median"] = Percentile(stats_.produce_ms, 0.5);
    j["latency_ms_median"] = Percentile(stats_.latency_ms, 0.5);
    j["latency_ms_p95"] = Percentile(stats_.latency_ms, 0.95);
    j["latency_definition"] =
        "capture (start of producing the frame: studio render + texturing) to display (rendered, glFinish)";
    j["drops"] = stats_.drops;
    j["bitrate_mbps"] = nullptr;
    j["bitrate_note"] = "local synthetic source: nothing is received over a network";
    if (!pngs_.empty()) j["pngs"] = pngs_;
    std::error_code ec;
    std::filesystem::create_directories(o_.out_dir, ec);
    const std::string path = (std::filesystem::path(o_.out_dir) / "stats.json").string();
    std::ofstream f(path);
    f << j.dump(2) << "\n";
    if (!f) return Fail(Unavailable(path + ": cannot write"));
    std::printf("%lld frames, %.1f fps, render %.1f ms (median), latency %.1f ms (median), drops %lld; stats in %s\n",
                static_cast<long long>(stats_.frames), j["fps"].get<double>(), j["render_ms_median"].get<double>(),
                j["latency_ms_median"].get<double>(), static_cast<long long>(stats_.drops), path.c_str());
    return 0;
  }

  int Fail(const Status& s) {
    std::fprintf(stderr, "holoport-client: %s\n", s.ToString().c_str());
    return 1;
  }

 private:
  ViewerOptions o_;
  ColorMode mode_ = ColorMode::kProjective;
  render::MosaicLayout layout_;
  render::Miniature mini_;
  render::CameraController controller_;
  Eigen::Vector3f orbit_target_ = Eigen::Vector3f(0, 0, 1.0f);
  float orbit_radius_ = 3.0f, orbit_height_ = 1.7f;
#if HOLO_CLIENT_HAVE_TRACE
  std::vector<pose::PoseSample> trace_;
#else
  std::vector<int> trace_;
#endif
  std::unique_ptr<SyntheticSource> source_;
  std::unique_ptr<SyntheticSource> local_source_;
  StreamFrame local_frame_;
  std::unique_ptr<render::GlContext> context_;
  std::unique_ptr<render::Renderer> renderer_;
  std::unique_ptr<render::Overlay> overlay_;
  std::unique_ptr<render::OffscreenTarget> target_;
  bool have_local_ = false;
  bool interactive_ = false;
  bool show_overlay_ = true;
  double mouse_x_ = 0, mouse_y_ = 0;
  double recent_fps_ = 0;
  FrameStats stats_;
  std::vector<std::string> pngs_;
};

}  // namespace

int RunViewer(const ViewerOptions& options) {
  Viewer viewer(options);
  if (Status s = viewer.Init(); !s.ok()) return viewer.Fail(s);
  return options.headless ? viewer.RunHeadless() : viewer.RunInteractive();
}

}  // namespace holo::client
