#include "client/tools/viewer_app.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <csignal>
#include <thread>
#include <mutex>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <epoxy/gl.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <nlohmann/json.hpp>

#include "audio/room.h"
#include "client/net/broadcast_player.h"
#include "audio/wav.h"
#include "client/net/participant.h"
#include "client/net/site_av_sync.h"
#include "client/render/gl_context.h"
#include "client/render/overlay.h"
#include "client/render/region_boxes.h"
#include "client/render/renderer.h"
#include "client/render/view.h"
#include "client/tools/synthetic_source.h"
#include "common/clock.h"
#include "common/image_io.h"
#include "common/log.h"
#include "common/metrics/mesh_shapes.h"
#include "common/pose.h"
#include "common/quantile.h"
#include "net/site_client.h"
#include "net/wire_message.h"
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

std::atomic<bool> g_viewer_stop{false};

using render::ColorMode;

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

bool SameIntrinsics(const Intrinsics& a, const Intrinsics& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy && a.cx == b.cx &&
         a.cy == b.cy && a.distortion == b.distortion;
}

// Same calibration (a site re-sends its rig after every reconnect).
bool SameRig(const Rig& a, const Rig& b) {
  if (a.name != b.name || a.pods.size() != b.pods.size()) return false;
  for (size_t i = 0; i < a.pods.size(); ++i) {
    const PodCalibration &p = a.pods[i], &q = b.pods[i];
    if (p.id != q.id || !SameIntrinsics(p.depth, q.depth) || !SameIntrinsics(p.color, q.color) ||
        !p.color_from_depth.matrix().isApprox(q.color_from_depth.matrix(), 1e-6f) ||
        !p.world_from_depth.matrix().isApprox(q.world_from_depth.matrix(), 1e-6f)) {
      return false;
    }
  }
  return true;
}

struct FrameStats {
  std::vector<double> produce_ms, upload_ms, render_ms, latency_ms, loop_ms;
  std::vector<double> bake_ms;  // the atlas bake of each mesh (part of upload_ms)
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
    if (o_.color == "projective" || o_.color == "projective-fragment") {
      mode_ = ColorMode::kProjective;
      bake_ = o_.color == "projective";
    } else if (o_.color == "vertex") {
      mode_ = ColorMode::kVertexColor;
    } else {
      return InvalidArgument("--color must be projective, projective-fragment or vertex, got '" + o_.color + "'");
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
    net_mode_ = !o_.connect.empty() || !o_.call.empty() || !o_.http.empty();
    if (net_mode_) {
      HOLO_RETURN_IF_ERROR(StartNetwork());
    } else {
      HOLO_ASSIGN_OR_RETURN(source_, SyntheticSource::Create(o_.source, o_.threads));
    }

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
    HOLO_ASSIGN_OR_RETURN(region_boxes_, render::RegionBoxes::Create());
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
    spdlog::info("holoport-client: {}, source {} ({} pods), {}x{}, {} view(s), {}{}", context_->Describe(),
                 SourceName(), CurrentRig().pods.size(), o_.width, o_.height, o_.views, render::ColorModeName(mode_),
                 o_.miniature_scale != 0.0f ? ", miniature" : "");
    return OkStatus();
  }

  std::string SourceName() const {
    if (!o_.call.empty()) return "call " + o_.call;
    if (!o_.connect.empty()) return "site " + o_.connect;
    if (!o_.http.empty()) return "broadcast " + o_.http;
    return o_.source;
  }
  const Rig& CurrentRig() const { return net_mode_ ? net_rig_ : source_->rig(); }

  // --connect / --call: start the client(s); waits for the first Welcome
  // (refusals and unreachable sites are errors here; later losses reconnect).
  Status StartNetwork() {
    net::ClientOptions co;
    co.name = o_.name;
    co.quality = o_.quality;
    co.backoff_initial_s = 0.2;
    co.backoff_max_s = 2.0;
    co.connect_timeout_s = 3.0;
    // Vertex colour needs no pod images: do not subscribe to them (saves the
    // bandwidth and the C1 decoding of every frame).
    if (mode_ == ColorMode::kVertexColor) co.subscribe = net::kSubscribeGeometry | net::kSubscribeAudio;
    net::ClientCallbacks cb;
    cb.on_state = [this](net::ClientState st, const Status& why) {
      net_state_ = static_cast<int>(st);
      if (st == net::ClientState::kConnected) {
        spdlog::info("holoport-client: connected to {}", SourceName());
      } else if (st == net::ClientState::kBackoff || st == net::ClientState::kRefused) {
        spdlog::warn("holoport-client: site connection {}{}{}{}", net::ClientStateName(st), why.ok() ? "" : ": ",
                     why.ok() ? "" : why.message().c_str(),
                     st == net::ClientState::kBackoff ? " (showing the last frame; reconnecting with backoff)" : "");
      }
    };
    cb.on_rig = [this](const Rig& rig) {
      std::lock_guard<std::mutex> l(rig_mu_);
      pending_rig_ = rig;
      rig_pending_ = true;
    };
    // Active regions: the newest report is drawn (LatestRegions); entries and
    // exits are listed in the overlay, newest last.
    cb.on_regions = [this](const net::ReceivedRegions& r) {
      std::lock_guard<std::mutex> l(regions_mu_);
      for (const auto& g : r.regions.regions) {
        if (g.state != protocol::RegionState::kEnter && g.state != protocol::RegionState::kLeave) continue;
        std::string name = g.name;
        for (auto& c : name) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
        char line[160];
        std::snprintf(line, sizeof line, "%s %s  FRAME %lld  %.2f L  +%.0f MS", g.state == protocol::RegionState::kEnter ? "ENTER" : "LEAVE",
                      name.c_str(), static_cast<long long>(r.regions.frame_index), g.occupied_litres,
                      static_cast<double>(r.received_us - r.capture_time_us) * 1e-3);
        region_events_.push_back(line);
        ++region_events_total_;
        while (region_events_.size() > 4) region_events_.pop_front();
      }
    };
    if (!o_.call.empty()) {
      HOLO_ASSIGN_OR_RETURN(net::CallConfig call, net::LoadCallConfig(o_.call));
      net::ParticipantOptions po;
      po.call = call;
      po.name = o_.name;
      po.audio_in = o_.audio_in;
      po.audio_out = o_.audio_out;
      po.aec = o_.aec;
      po.aec_filter_ms = o_.aec_filter_ms;
      po.hrtf_sofa = o_.hrtf_sofa;
      po.view_template = co;
      po.av_sync = SyncOptions();
      po.voice.inject_delay_ms = o_.delay_voice_ms;
      if (o_.head_placed) {
        // The default head's sway and glances around the given place and heading.
        const Eigen::Vector3f at = o_.head_at;
        const float yaw = o_.head_yaw_deg * 3.14159265f / 180.0f;
        po.head = [at, yaw](int64_t t_us) {
          protocol::HeadPose p = net::SyntheticHead(static_cast<double>(t_us % 3600000000LL) / 1e6, 0.0f);
          p.x = at.x();
          p.y += at.y();
          p.z = at.z();
          p.yaw = p.yaw - 3.14159265f + yaw;
          return p;
        };
      }
      HOLO_ASSIGN_OR_RETURN(participant_, net::Participant::Start(po, cb));
      client_ = &participant_->viewer();
      // The remote room through the call's room transform (rendering and voices alike).
      call_local_from_remote_ = call.room.local_from_remote.matrix();
    } else if (!o_.http.empty()) {
      // The broadcast's messages go through the same decode and delivery path
      // as a site connection (SiteClient fed by the HTTP player). A part's
      // frames arrive at once: the pull queue holds them (a 250 ms part is
      // 8 frames) and SyncOptions() paces them at their capture rhythm.
      co.fed = true;
      co.max_pending_frames = std::max<size_t>(co.max_pending_frames, 16);
      HOLO_ASSIGN_OR_RETURN(own_client_, net::SiteClient::Start(co, cb));
      client_ = own_client_.get();
      net::BroadcastPlayerOptions bo;
      bo.url = o_.http;
      net::SiteClient* fed = own_client_.get();
      HOLO_ASSIGN_OR_RETURN(player_, net::BroadcastPlayer::Start(bo, [fed](const protocol::Header& h,
                                                                           std::span<const uint8_t> payload,
                                                                           int64_t received_us) {
        net::RawMessage m;
        m.header = h;
        m.payload.assign(payload.begin(), payload.end());
        m.received_us = received_us;
        fed->Feed(std::move(m));
      }));
      // The Rig comes with the first part: wait for it like for a site's Welcome.
      const double wait_rig = o_.connect_timeout_s > 0 ? o_.connect_timeout_s : 1e9;
      const auto t0 = std::chrono::steady_clock::now();
      while (!own_client_->rig() && !g_viewer_stop &&
             std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < wait_rig)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      if (!own_client_->rig()) {
        const auto ps = player_->stats();
        return Unavailable("no broadcast from " + o_.http + " within " + std::to_string(static_cast<int>(wait_rig)) +
                           " s" + (ps.last_error.empty() ? std::string() : ": " + ps.last_error));
      }
    } else {
      if (!net::ParseSiteAddress(o_.connect, &co.host, &co.port)) {
        return InvalidArgument("--connect: expected HOST:PORT, got '" + o_.connect + "'");
      }
      co.token = !o_.token.empty() ? o_.token
                                   : (std::getenv("HOLO_VIEWER_TOKEN") ? std::getenv("HOLO_VIEWER_TOKEN") : "");
      HOLO_ASSIGN_OR_RETURN(own_client_, net::SiteClient::Start(co, cb));
      client_ = own_client_.get();
    }
    spdlog::info("holoport-client: connecting to {} ...", SourceName());
    const double wait = o_.connect_timeout_s > 0 ? o_.connect_timeout_s : 1e9;
    if (!client_->WaitConnected(wait)) {
      const Status why = client_->status();
      return Unavailable("could not join " + SourceName() + " within " + std::to_string(static_cast<int>(wait)) +
                         " s: " + (why.ok() ? std::string("no answer") : why.message()));
    }
    // The site sends its rig right after Welcome; wait a moment for it.
    for (int i = 0; i < 100 && !client_->rig(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (auto rig = client_->rig()) {
      net_rig_ = *rig;
      std::lock_guard<std::mutex> l(rig_mu_);
      rig_pending_ = false;
    }
    // Voice and picture in sync: the site's voices play on their own thread
    // (a call participant plays them itself), pictures come out of
    // NextFrame when they are due.
    net::SiteAvSyncOptions so;
    so.sync = SyncOptions();
    so.voice.inject_delay_ms = o_.delay_voice_ms;
    so.inject_picture_delay_ms = o_.delay_picture_ms;
    so.play_voice = participant_ == nullptr;
    if (so.play_voice && !o_.audio_out.empty()) {
      so.on_voice = [this](const net::RemoteVoices::Block& b) {
        std::lock_guard<std::mutex> l(voice_out_mu_);
        // Blocks of one 20 ms step share their playout time: mix them.
        if (b.playout_us != voice_out_last_us_ || voice_out_.size() < b.pcm.size()) {
          voice_out_.insert(voice_out_.end(), b.pcm.begin(), b.pcm.end());
          voice_out_last_us_ = b.playout_us;
        } else {
          float* mix = voice_out_.data() + voice_out_.size() - b.pcm.size();
          for (size_t i = 0; i < b.pcm.size(); ++i) mix[i] += b.pcm[i];
        }
      };
    }
    HOLO_ASSIGN_OR_RETURN(av_sync_, net::SiteAvSync::Start(client_, so,
                                                          participant_ ? &participant_->av_sync() : nullptr));
    net_start_us_ = net::WallUs();
    return OkStatus();
  }

  audio::AvSyncOptions SyncOptions() const {
    audio::AvSyncOptions s = o_.sync;
    s.pace_pictures = s.pace_pictures || !o_.http.empty();
    return s;
  }

  // world_from_camera of the centre view at time t (seconds from start).
  Pose ViewPose(double t) const {
    if (participant_ && !interactive_) {
      // The own head (x forward, y left, z up) → camera (x right, y down, z forward).
      const Eigen::Isometry3f head = audio::HeadToRoom(participant_->OwnHead());
      Eigen::Matrix3f cam_to_head;
      cam_to_head << 0, 0, 1, -1, 0, 0, 0, -1, 0;
      Pose p = Pose::Identity();
      p.linear() = head.linear() * cam_to_head;
      p.translation() = head.translation();
      return p;
    }
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
    if (mode_ == ColorMode::kVertexColor && frame.mesh.colors.empty() && !frame.mesh.empty() && !warned_no_colors_) {
      warned_no_colors_ = true;
      spdlog::warn("holoport-client: {} sends no vertex colours (the site colours nothing unless run with "
                   "--mesh-colors): the person is shown uncoloured; --color projective colours it from the pods' images",
                   SourceName());
    }
    HOLO_RETURN_IF_ERROR(renderer_->SetRemoteMesh(frame.mesh));
    std::vector<const ImageRgb8*> images;
    for (const auto& im : frame.pod_images) images.push_back(&im);
    std::vector<const ImageGray8*> masks;
    if (frame.pod_masks.size() == frame.pod_images.size())
      for (const auto& m : frame.pod_masks) masks.push_back(&m);
    frame_has_images_ = !images.empty();
    if (frame_has_images_) {
      Status st = renderer_->SetPodImages(CurrentRig(), images, masks);
      if (!st.ok()) {
        // E.g. images of another rig than the one announced: vertex colour for this frame.
        if (!image_error_reported_) {
          spdlog::warn("holoport-client: pod images unusable ({}); showing vertex colour until they match the rig",
                       st.message());
          image_error_reported_ = true;
        }
        frame_has_images_ = false;
      }
    }
    // The per-mesh work (pods' visibility maps; with the atlas also the pod
    // selection and the bake) belongs to the upload, not to the frames drawn.
    if (mode_ == ColorMode::kProjective && frame_has_images_) {
      render::ProjectiveOptions po;
      po.bake = bake_;
      HOLO_RETURN_IF_ERROR(bake_ ? renderer_->UpdateAtlas(po) : renderer_->UpdateVisibility(po));
      if (bake_ && !renderer_->atlas_stats().fallback) stats_.bake_ms.push_back(renderer_->atlas_stats().bake_ms);
    }
    glFinish();
    stats_.upload_ms.push_back(sw.ElapsedMs());
    return OkStatus();
  }

  // Draws all views and the overlay into the bound framebuffer (fb size).
  Status Draw(double t, int fb_width, int fb_height) {
    render::RenderSettings settings;
    settings.mode = frame_has_images_ ? mode_ : ColorMode::kVertexColor;
    settings.projective.bake = bake_;
    settings.local_from_remote =
        o_.miniature_scale != 0.0f || o_.remote_placed ? mini_.LocalFromRemote() : Eigen::Matrix4f::Identity();
    if (participant_ && o_.miniature_scale == 0.0f && !o_.remote_placed) settings.local_from_remote = call_local_from_remote_;
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
      net::ReceivedRegions rr;
      if (net_mode_ && client_ != nullptr && client_->LatestRegions(&rr))
        HOLO_RETURN_IF_ERROR(region_boxes_->Draw(rr.regions.regions, cams[i], settings.local_from_remote,
                                                 settings.near_m, settings.far_m, vp));
    }
    if (overlay_ && show_overlay_) {
      const int scale = fb_height >= 600 && o_.views == 1 ? 2 : 1;
      HOLO_RETURN_IF_ERROR(overlay_->Draw(OverlayText(), 10 * scale, 10 * scale, scale, fb_width, fb_height,
                                          {255, 240, 120}));
    }
    return OkStatus();
  }

  std::string OverlayText() const {
    if (net_mode_) return NetOverlayText();
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

  std::string NetOverlayText() const {
    char fps[32] = "-", rms[32] = "-", lat[32] = "-";
    if (!stats_.render_ms.empty()) {
      std::snprintf(fps, sizeof fps, "%.1f", recent_fps_);
      std::snprintf(rms, sizeof rms, "%.1f", stats_.render_ms.back());
    }
    if (!stats_.latency_ms.empty()) std::snprintf(lat, sizeof lat, "%.0f", stats_.latency_ms.back());
    const auto st = static_cast<net::ClientState>(net_state_.load());
    std::string status = "LIVE";
    if (st != net::ClientState::kConnected) {
      status = std::string("CONNECTION LOST (") + net::ClientStateName(st) + ") - LAST FRAME SHOWN, RECONNECTING";
    } else if (showing_stale_) {
      status = "WAITING FOR FRAMES - LAST FRAME SHOWN";
    }
    for (auto& c : status) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    char audio[320] = "";
    if (participant_) {
      const net::ParticipantStats ps = participant_->stats();
      std::snprintf(audio, sizeof audio, "\nVOICE SENT %lld  HEARD %lld  AUDIO DELAY %.0f MS  AZIMUTH %.0f",
                    static_cast<long long>(ps.voice_frames_sent), static_cast<long long>(ps.remote_audio_frames),
                    ps.audio_delay_ms, ps.remote_audio_frames ? ps.remote_azimuth_deg : 0.0f);
    }
    if (av_sync_) {
      const audio::AvSyncStats as = av_sync_->stats();
      if (as.offsets > 0) {
        char sync[160];
        std::snprintf(sync, sizeof sync, "\nA/V OFFSET %+.0f MS (P50)  VOICE +%.0f MS  PICTURE +%.0f MS%s",
                      as.av_offset_ms_p50, std::max(0.0, as.voice_target_ms - as.voice_natural_ms),
                      as.picture_sync_delay_ms, o_.sync.enabled ? "" : "  (SYNC OFF)");
        std::strncat(audio, sync, sizeof audio - std::strlen(audio) - 1);
      }
    }
    std::string src = SourceName();
    for (auto& c : src) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    // Active regions: each with its state, then the latest entries and exits.
    std::string regions;
    net::ReceivedRegions rr;
    if (client_ != nullptr && client_->LatestRegions(&rr) && !rr.regions.regions.empty()) {
      regions = "\nREGIONS";
      for (const auto& g : rr.regions.regions) {
        std::string name = g.name;
        for (auto& c : name) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
        char item[128];
        if (render::RegionOccupied(g))
          std::snprintf(item, sizeof item, "  %s: OCCUPIED %.1f L", name.c_str(), g.occupied_litres);
        else
          std::snprintf(item, sizeof item, "  %s: EMPTY", name.c_str());
        regions += item;
      }
      std::lock_guard<std::mutex> l(regions_mu_);
      for (const auto& e : region_events_) regions += "\n  " + e;
    }
    // The site's quality layer this viewer receives, when the site has layers.
    char layer[48] = "";
    if (net_mode_ && client_) {
      const net::ClientStats cs = client_->stats();
      if (cs.num_layers > 1)
        std::snprintf(layer, sizeof layer, "  LAYER %s", cs.layer == 0 ? "FULL" : "REDUCED");
    }
    char buf[800];
    std::snprintf(buf, sizeof buf,
                  "HOLOPORT VIEWER  %s\n%s\nFPS %s  RENDER %s MS\nLATENCY %s MS CAPTURE->DISPLAY\n"
                  "BITRATE %.2f MBIT/S  DROPS %lld%s\n%zu TRIS  %s%s",
                  src.c_str(), status.c_str(), fps, rms, lat, recent_mbps_, static_cast<long long>(stats_.drops), layer,
                  renderer_->remote_triangles(),
                  frame_has_images_ && mode_ == ColorMode::kProjective ? "PROJECTIVE" : "VERTEX COLOUR", audio);
    return buf + regions;
  }

  // Received frame → what the renderer takes (pod images in rig order; none
  // if any pod's image is missing or has another size than the rig says).
  void ToStreamFrame(net::ReceivedFrame& f, StreamFrame* out) {
    out->index = f.frame_index;
    out->mesh = std::move(f.mesh);
    out->pod_images.clear();
    out->pod_masks.clear();
    const Rig& rig = net_rig_;
    if (!f.has_color || rig.pods.empty()) return;
    // A pod whose picture is missing from this frame (V1: its stream waits
    // for a key frame) shows its last picture, as the codec's rules say.
    for (auto& im : f.images) last_images_[im.pod_id] = std::move(im);
    std::vector<ImageRgb8> ordered;
    std::vector<ImageGray8> masks;
    for (const auto& pod : rig.pods) {
      auto it = last_images_.find(static_cast<uint16_t>(pod.id));
      const net::DecodedImage* found = it == last_images_.end() ? nullptr : &it->second;
      if (found == nullptr || found->image.width() != pod.color.width || found->image.height() != pod.color.height) {
        if (!image_error_reported_) {
          spdlog::warn(
              "holoport-client: frame {}: pod {} image {}; showing vertex colour until images match the "
              "rig",
              f.frame_index, pod.id, found == nullptr ? "missing" : "does not match the rig's colour camera size");
          image_error_reported_ = true;
        }
        return;
      }
      ordered.push_back(found->image);
      masks.push_back(found->mask);
    }
    out->pod_images = std::move(ordered);
    out->pod_masks = std::move(masks);
    image_error_reported_ = false;
  }

  // Applies a rig announced mid-stream (on the render thread).
  void CheckRigChange() {
    Rig rig;
    {
      std::lock_guard<std::mutex> l(rig_mu_);
      if (!rig_pending_) return;
      rig = std::move(pending_rig_);
      rig_pending_ = false;
    }
    if (Status s = rig.Check(); !s.ok()) {
      spdlog::warn("holoport-client: the site sent an invalid rig ({}); keeping the previous one", s.message());
      return;
    }
    if (SameRig(rig, net_rig_)) return;  // re-sent after a reconnect
    if (!net_rig_.pods.empty()) {
      ++rig_changes_;
      spdlog::info(
          "holoport-client: rig changed mid-stream: '{}' ({} pods) -> '{}' ({} pods); projective texturing "
          "uses the new calibration from the next frame",
          net_rig_.name, net_rig_.pods.size(), rig.name, rig.pods.size());
    }
    net_rig_ = std::move(rig);
  }

  // The last frame's capture → display latency, or "n/a" while no frame had
  // a capture time on the wall clock.
  std::string LatencyText() const {
    return stats_.latency_ms.empty() ? "n/a" : fmt::format("{:.0f} ms", stats_.latency_ms.back());
  }

  void NoteNetDisplayed(const net::ReceivedFrame& f, double loop_ms) {
    // capture (site clock) → display: the client's latency to reception is
    // already corrected by its clock-offset estimate; add the time since.
    if (f.latency_known) stats_.latency_ms.push_back(f.latency_ms + (net::WallUs() - f.received_us) / 1000.0);
    // A reduced quality layer carries every n-th frame only: those gaps are
    // the layer's rate, not drops.
    const int64_t step = client_ ? std::max(1, client_->stats().layer_step) : 1;
    if (last_index_ >= 0 && f.frame_index > last_index_)
      stats_.drops += std::max<int64_t>(0, f.frame_index - last_index_ - step);
    last_index_ = f.frame_index;
    ++frames_new_;
    // Network mode: the fps shown is new site frames displayed per second
    // (redraws of the frame already shown for a moving head do not count).
    new_frame_us_.push_back(net::WallUs());
    if (new_frame_us_.size() > 16) new_frame_us_.erase(new_frame_us_.begin());
    if (first_new_us_ == 0) first_new_us_ = new_frame_us_.back();
    last_new_us_ = new_frame_us_.back();
    const size_t n = new_frame_us_.size();
    recent_fps_ = n > 1 ? 1e6 * static_cast<double>(n - 1) / static_cast<double>(new_frame_us_.back() - new_frame_us_.front()) : 0;
    NoteLoop(loop_ms, /*update_fps=*/false);
  }

  void NoteLoop(double loop_ms, bool update_fps = true) {
    stats_.loop_ms.push_back(loop_ms);
    ++stats_.frames;
    if (!update_fps) return;
    const size_t n = std::min<size_t>(stats_.loop_ms.size(), 15);
    double sum = 0;
    for (size_t i = stats_.loop_ms.size() - n; i < stats_.loop_ms.size(); ++i) sum += stats_.loop_ms[i];
    recent_fps_ = sum > 0 ? 1000.0 * n / sum : 0;
  }

  void UpdateBitrate() {
    const int64_t now = net::WallUs();
    if (now - rate_t_us_ < 1000000) return;
    const uint64_t bytes = client_->stats().bytes_received;
    if (rate_t_us_ > 0) recent_mbps_ = (bytes - rate_bytes_) * 8.0 / static_cast<double>(now - rate_t_us_);
    rate_t_us_ = now;
    rate_bytes_ = bytes;
  }

  Status SavePng(const std::string& name, ImageRgb8* image) {
    HOLO_RETURN_IF_ERROR(target_->ReadRgb(image));
    const std::string path = (std::filesystem::path(o_.out_dir) / name).string();
    HOLO_RETURN_IF_ERROR(WriteImageRgb8(path, *image));
    pngs_.push_back(name);
    if (o_.contact_sheet && sheet_tiles_.size() < 16) {
      // Quarter size for the sheet.
      ImageRgb8 small(image->width() / 4, image->height() / 4);
      for (int y = 0; y < small.height(); ++y) {
        for (int x = 0; x < small.width(); ++x)
          for (int c = 0; c < 3; ++c) small.at(x, y, c) = image->at(4 * x + 2, 4 * y + 2, c);
      }
      sheet_tiles_.push_back(std::move(small));
    }
    return OkStatus();
  }

  Status WriteContactSheet() {
    if (sheet_tiles_.empty()) return OkStatus();
    const int cols = std::min<int>(4, static_cast<int>(sheet_tiles_.size()));
    const int rows = (static_cast<int>(sheet_tiles_.size()) + cols - 1) / cols;
    const int tw = sheet_tiles_[0].width(), th = sheet_tiles_[0].height();
    ImageRgb8 sheet(cols * tw + (cols + 1) * 4, rows * th + (rows + 1) * 4);
    for (int y = 0; y < sheet.height(); ++y) {
      for (int x = 0; x < sheet.width(); ++x)
        for (int c = 0; c < 3; ++c) sheet.at(x, y, c) = 20;
    }
    for (size_t i = 0; i < sheet_tiles_.size(); ++i) {
      const int cx = 4 + static_cast<int>(i % cols) * (tw + 4), cy = 4 + static_cast<int>(i / cols) * (th + 4);
      for (int y = 0; y < th; ++y) {
        for (int x = 0; x < tw; ++x)
          for (int c = 0; c < 3; ++c) sheet.at(cx + x, cy + y, c) = sheet_tiles_[i].at(x, y, c);
      }
    }
    const std::string path = (std::filesystem::path(o_.out_dir) / "contact_sheet.png").string();
    return WriteImageRgb8(path, sheet);
  }

  // The network loop (headless or window): shows the newest received frame;
  // while the site is away it keeps showing the last one and says so.
  int RunNetwork() {
    const bool window = !o_.headless;
    GLFWwindow* w = window ? context_->window() : nullptr;
    if (window) {
      interactive_ = false;
      glfwSetWindowUserPointer(w, this);
      glfwSetKeyCallback(w, [](GLFWwindow* win, int key, int, int action, int) {
        if (action != GLFW_PRESS) return;
        auto* self = static_cast<Viewer*>(glfwGetWindowUserPointer(win));
        if (key == GLFW_KEY_ESCAPE || key == GLFW_KEY_Q) glfwSetWindowShouldClose(win, GLFW_TRUE);
        if (key == GLFW_KEY_T) {
          self->mode_ = self->mode_ == ColorMode::kProjective ? ColorMode::kVertexColor : ColorMode::kProjective;
        }
        if (key == GLFW_KEY_O) self->show_overlay_ = !self->show_overlay_;
      });
    }
    std::error_code ec;
    std::filesystem::create_directories(o_.out_dir, ec);
    if (ec && o_.headless) return Fail(Unavailable("--out " + o_.out_dir + ": cannot create: " + ec.message()));
    const int max_frames = o_.frames > 0 ? o_.frames : (o_.seconds > 0 ? 0 : (window ? 0 : 30));
    const int64_t start = net::WallUs();
    ImageRgb8 image;
    StreamFrame frame;
    net::ReceivedFrame rf;
    bool have_frame = false;
    int64_t last_render_us = 0;
    int64_t displayed_new = 0;
    Stopwatch loop;
    int last_progress_s = -1;
    while (!g_viewer_stop.load()) {
      if (window && glfwWindowShouldClose(w)) break;
      const int64_t now = net::WallUs();
      const double t = (now - start) / 1e6;
      if (o_.seconds > 0 && t >= o_.seconds) break;
      if (max_frames > 0 && displayed_new >= max_frames) break;
      if (window) glfwPollEvents();
      CheckRigChange();
      UpdateBitrate();
      bool fresh = false;
      const int64_t render_start_us = net::WallUs();
      if (av_sync_->NextFrame(&rf)) {
        if (!rf.has_mesh || rf.mesh.positions.empty()) continue;  // nothing to show in it
        net::ReceivedFrame keep_times;  // times/index only are used below (no mesh/image copies)
        keep_times.frame_index = rf.frame_index;
        keep_times.capture_time_us = rf.capture_time_us;
        keep_times.received_us = rf.received_us;
        keep_times.latency_ms = rf.latency_ms;
        keep_times.latency_known = rf.latency_known;
        keep_times.wire_bytes = rf.wire_bytes;
        keep_times.has_mesh = rf.has_mesh;
        keep_times.has_color = rf.has_color;
        ToStreamFrame(rf, &frame);
        if (Status s = Upload(frame); !s.ok()) {
          spdlog::warn("holoport-client: frame {} not shown: {}", keep_times.frame_index, s.message());
          ++bad_frames_;
          continue;
        }
        last_rf_ = std::move(keep_times);
        have_frame = true;
        fresh = true;
        showing_stale_ = false;
      } else {
        // Nothing new: in a call the head moves, so redraw at ~15 Hz; a lost
        // site is redrawn once a second with the notice (the last frame stays).
        const bool connected = static_cast<net::ClientState>(net_state_.load()) == net::ClientState::kConnected;
        const int64_t period = !connected ? 1000000 : (participant_ ? 66000 : 1000000);
        if (!have_frame || now - last_render_us < period) {
          if (window) {
            glfwWaitEventsTimeout(0.005);
          } else {
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
          }
          continue;
        }
        showing_stale_ = connected && now - last_render_us >= 1000000;
        if (!connected) ++stale_renders_;
      }
      int fbw = o_.width, fbh = o_.height;
      if (window) {
        glfwGetFramebufferSize(w, &fbw, &fbh);
        if (fbw < 16 || fbh < 16) continue;
        glBindFramebuffer(GL_FRAMEBUFFER, 0);
      } else {
        target_->Bind();
      }
      Stopwatch rs;
      if (Status s = Draw(t, fbw, fbh); !s.ok()) return Fail(s);
      if (window) glfwSwapBuffers(w);
      glFinish();
      stats_.render_ms.push_back(rs.ElapsedMs());
      last_render_us = net::WallUs();
      const double loop_ms = loop.ElapsedMs();
      loop.Restart();
      if (fresh) {
        av_sync_->Displayed(last_rf_, render_start_us, last_render_us);
        NoteNetDisplayed(last_rf_, loop_ms);
        ++displayed_new;
      } else {
        NoteLoop(loop_ms);
      }
      bool due = false;
      if (fresh && o_.png_interval_s > 0) {
        due = last_png_us_ == 0 || net::WallUs() - last_png_us_ >= static_cast<int64_t>(o_.png_interval_s * 1e6);
      } else if (fresh) {
        due = (displayed_new - 1) % std::max(1, o_.png_every) == 0;
      }
      if (due) last_png_us_ = net::WallUs();
      if (o_.headless && o_.write_png &&
          (due || (!fresh && stale_renders_ % 5 == 1 &&
                                                                             static_cast<net::ClientState>(
                                                                                 net_state_.load()) !=
                                                                                 net::ClientState::kConnected))) {
        char name[64];
        std::snprintf(name, sizeof name, "frame_%05lld%s.png", static_cast<long long>(stats_.frames - 1),
                      fresh ? "" : "_stale");
        if (Status s = SavePng(name, &image); !s.ok()) return Fail(s);
      }
      if (static_cast<int>(t) / 5 != last_progress_s) {
        last_progress_s = static_cast<int>(t) / 5;
        spdlog::info("{:.0f} s: {} frames shown ({} new), {:.1f} fps, latency {}, {:.2f} Mbit/s, drops {}", t,
                     stats_.frames, displayed_new, recent_fps_, LatencyText(), recent_mbps_, stats_.drops);
      }
    }
    net_elapsed_s_ = (net::WallUs() - start) / 1e6;
    Status audio_status;
    av_sync_->Stop();
    if (participant_) audio_status = participant_->Stop();
    if (!participant_ && !o_.audio_out.empty()) {
      std::lock_guard<std::mutex> l(voice_out_mu_);
      audio_status = audio::WriteWav(o_.audio_out, voice_out_, 1, audio::kSampleRate);
    }
    client_->Stop();
    if (Status s = WriteContactSheet(); !s.ok()) return Fail(s);
    const int rc = WriteStats();
    if (!audio_status.ok()) return Fail(audio_status.WithContext("--audio-out"));
    return rc;
  }

  void NoteDisplayed(const StreamFrame& frame, double loop_ms) {
    const int64_t now = RealClock::Instance().NowUs();
    stats_.latency_ms.push_back((now - frame.capture_us) / 1000.0);
    NoteLoop(loop_ms);
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
        spdlog::info("frame {}/{}: render {:.1f} ms, latency {:.1f} ms", i + 1, frames, stats_.render_ms.back(),
                     stats_.latency_ms.back());
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
    j["source"] = SourceName();
    j["workload"] = net_mode_ ? std::string("network") : source_->workload();
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
    j["camera"] = participant_ ? std::string("own head (synthetic head motion)")
                               : (trace_.empty() ? (interactive_ ? "interactive" : "orbit") : "trace:" + o_.pose_trace);
    double loop_sum = 0;
    for (double v : stats_.loop_ms) loop_sum += v;
    // fps: new frames displayed per second (network: new site frames; the
    // synthetic stand-in draws a new frame every loop). redraws_per_s: every
    // render, including redraws of an old frame for a moving head.
    j["redraws_per_s"] = loop_sum > 0 ? 1000.0 * stats_.frames / loop_sum : 0.0;
    j["fps"] = j["redraws_per_s"];
    if (net_mode_)
      j["fps"] = frames_new_ > 1 && last_new_us_ > first_new_us_
                     ? 1e6 * static_cast<double>(frames_new_ - 1) / static_cast<double>(last_new_us_ - first_new_us_)
                     : 0.0;
    j["fps_definition"] = "new frames displayed per second (not redraws of a frame already shown)";
    j["render_ms_median"] = Quantile(stats_.render_ms, 0.5);
    j["render_ms_p95"] = Quantile(stats_.render_ms, 0.95);
    j["upload_ms_median"] = Quantile(stats_.upload_ms, 0.5);
    j["upload_definition"] =
        "per received mesh: mesh and pod images to GL, the pods' visibility maps, and with --color projective "
        "the pod selection and the atlas bake (bake_ms_median)";
    if (!stats_.bake_ms.empty()) {
      j["bake_ms_median"] = Quantile(stats_.bake_ms, 0.5);
      j["atlas_texels"] = renderer_->atlas_stats().texels;
    }
    j["produce_ms_median"] = Quantile(stats_.produce_ms, 0.5);
    j["latency_ms_median"] = Quantile(stats_.latency_ms, 0.5);
    j["latency_ms_p95"] = Quantile(stats_.latency_ms, 0.95);
    j["latency_definition"] =
        "capture (start of producing the frame: studio render + texturing) to display (rendered, glFinish)";
    j["drops"] = stats_.drops;
    if (net_mode_) {
      const net::ClientStats cs = client_->stats();
      j["latency_definition"] =
          "capture (site clock) to display (rendered, glFinish), through the client's clock-offset estimate";
      j["frames_new"] = frames_new_;
      j["last_frame_index"] = last_index_;
      j["frames_received"] = cs.frames_received;
      j["drops_definition"] =
          "frames of the site's sequence this viewer never displayed (gaps in frame indices; on a reduced quality "
          "layer, beyond the frames the layer leaves out)";
      j["frames_dropped_local"] = cs.frames_dropped_local;
      j["bitrate_mbps"] = net_elapsed_s_ > 0 ? cs.bytes_received * 8.0 / (net_elapsed_s_ * 1e6) : 0.0;
      j["bytes_received"] = cs.bytes_received;
      j["connects"] = cs.connects;
      j["connect_failures"] = cs.connect_failures;
      j["decode_errors"] = cs.decode_errors;
      j["regions_received"] = cs.regions_received;
      {
        std::lock_guard<std::mutex> l(regions_mu_);
        j["region_events"] = region_events_total_;
      }
      j["color_images_waiting"] = cs.color_images_waiting;
      j["keyframe_requests"] = cs.keyframe_requests;
      j["layers"] = cs.num_layers;
      j["layer"] = cs.layer;
      j["layer_changes"] = cs.layer_changes;
      j["bad_frames"] = bad_frames_;
      j["stale_renders"] = stale_renders_;
      j["rig_changes"] = rig_changes_;
      j["rig_pods"] = net_rig_.pods.size();
      j["rtt_min_ms"] = cs.rtt_min_ms;
      j["clock_offset_us"] = cs.clock_offset_us;
      j["seconds"] = net_elapsed_s_;
      if (player_) {
        const net::BroadcastPlayerStats bs = player_->stats();
        j["broadcast"] = {{"manifests", bs.manifests},
                          {"parts", bs.parts},
                          {"messages", bs.messages},
                          {"bytes", bs.bytes},
                          {"http_errors", bs.http_errors},
                          {"not_found", bs.not_found},
                          {"damaged_parts", bs.damaged_parts},
                          {"refused", bs.refused},
                          {"joins", bs.follower.joins},
                          {"catch_ups", bs.follower.catch_ups},
                          {"skips", bs.follower.skips},
                          {"discontinuities", bs.follower.discontinuities},
                          {"latency_ms_p50", Quantile(bs.latency_ms, 0.5)},
                          {"latency_ms_p99", Quantile(bs.latency_ms, 0.99)},
                          {"latency_definition",
                           "packager receive time of a part's last message to the part's arrival here (Unix clocks)"},
                          {"last_error", bs.last_error}};
      }
      {
        const audio::AvSyncStats as = av_sync_->stats();
        const net::RemoteVoicesStats vs = av_sync_->voice_stats();
        j["av_sync"] = {{"enabled", o_.sync.enabled},
                        {"hold_pictures", o_.sync.hold_pictures},
                        {"av_offset_ms_p50", as.av_offset_ms_p50},
                        {"av_offset_ms_p99", as.av_offset_ms_p99},
                        {"av_offset_ms_p1", as.av_offset_ms_p1},
                        {"unsynced_offset_ms_p50", as.unsynced_offset_ms_p50},
                        {"av_offset_definition",
                         "voice playout time minus picture display time for the same capture instant, over the "
                         "pictures displayed while a voice played; positive = voice late"},
                        {"offsets", as.offsets},
                        {"offsets_voice_early_over_45ms", as.offsets_early},
                        {"offsets_voice_late_over_125ms", as.offsets_late},
                        {"voice_sync_delay_ms_median", as.voice_sync_delay_ms},
                        {"picture_sync_delay_ms_median", as.picture_sync_delay_ms},
                        {"picture_delay_ms_median", as.picture_delay_ms},
                        {"voice_natural_delay_ms", as.voice_natural_ms},
                        {"voice_delay_ms", as.voice_delay_ms},
                        {"pictures_displayed", as.pictures},
                        {"pictures_held", as.pictures_held},
                        {"pictures_hold_capped", as.pictures_hold_capped},
                        {"voice_delay_capped", as.voice_delay_capped},
                        {"pictures_skipped", av_sync_->pictures_skipped()},
                        {"max_voice_delay_ms", o_.sync.max_voice_delay_ms},
                        {"max_picture_delay_ms", o_.sync.max_picture_delay_ms},
                        {"injected_voice_delay_ms", o_.delay_voice_ms},
                        {"injected_picture_delay_ms", o_.delay_picture_ms}};
        if (!participant_) {
          j["voice"] = {{"frames", vs.frames},      {"speakers", vs.speakers},
                        {"concealed", vs.concealed}, {"late", vs.late},
                        {"underflows", vs.underflows}, {"sync_expands", vs.sync_expands},
                        {"sync_drops", vs.sync_drops}, {"sync_rebuffers", vs.sync_rebuffers},
                        {"wav", o_.audio_out}};
        }
      }
      if (participant_) {
        const net::ParticipantStats ps = participant_->stats();
        j["audio"] = {{"voice_frames_sent", ps.voice_frames_sent},
                      {"remote_audio_frames", ps.remote_audio_frames},
                      {"remote_speakers", ps.remote_speakers},
                      {"network_ms_median", ps.audio_network_ms_median},
                      {"jitter_buffer_ms_median", ps.jitter_buffer_ms_median},
                      {"audio_delay_ms", ps.audio_delay_ms},
                      {"concealed", ps.concealed},
                      {"late", ps.late},
                      {"underflows", ps.underflows},
                      {"output_seconds", ps.output_seconds},
                      {"output_rms", ps.output_rms},
                      {"hrtf", ps.hrtf_status},
                      {"aec", o_.aec},
                      {"aec_delay_ms", ps.aec_delay_ms},
                      {"remote_voice_position_m", {ps.remote_x, ps.remote_y, ps.remote_z}},
                      {"remote_voice_azimuth_deg", ps.remote_azimuth_deg},
                      {"wav", o_.audio_out}};
      }
    } else {
      j["bitrate_mbps"] = nullptr;
      j["bitrate_note"] = "local synthetic source: nothing is received over a network";
    }
    if (!pngs_.empty()) j["pngs"] = pngs_;
    std::error_code ec;
    std::filesystem::create_directories(o_.out_dir, ec);
    const std::string path = (std::filesystem::path(o_.out_dir) / "stats.json").string();
    std::ofstream f(path);
    f << j.dump(2) << "\n";
    if (!f) return Fail(Unavailable(path + ": cannot write"));
    spdlog::info("{} frames, {:.1f} fps, render {:.1f} ms (median), latency {}, drops {}; stats in {}",
                 stats_.frames, j["fps"].get<double>(), j["render_ms_median"].get<double>(),
                 stats_.latency_ms.empty() ? std::string("n/a")
                                            : fmt::format("{:.1f} ms (median)", Quantile(stats_.latency_ms, 0.5)),
                 stats_.drops, path);
    return 0;
  }

  int Fail(const Status& s) {
    spdlog::error("holoport-client: {}", s.ToString());
    return 1;
  }

 private:
  ViewerOptions o_;
  ColorMode mode_ = ColorMode::kProjective;
  bool bake_ = true;  // projective colours baked once per mesh (--color projective)
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
  // Network mode.
  bool net_mode_ = false;
  std::unique_ptr<net::Participant> participant_;
  std::unique_ptr<net::SiteClient> own_client_;
  std::unique_ptr<net::BroadcastPlayer> player_;  // --http: feeds own_client_
  std::unique_ptr<net::SiteAvSync> av_sync_;       // voice and picture in sync (network mode)
  std::mutex voice_out_mu_;
  std::vector<float> voice_out_;  // --audio-out without --call: the site's voices, mono
  int64_t voice_out_last_us_ = -1;
  net::SiteClient* client_ = nullptr;
  Eigen::Matrix4f call_local_from_remote_ = Eigen::Matrix4f::Identity();
  std::atomic<int> net_state_{static_cast<int>(net::ClientState::kConnecting)};
  std::mutex rig_mu_;
  Rig pending_rig_;
  bool rig_pending_ = false;
  Rig net_rig_;
  net::ReceivedFrame last_rf_;
  int64_t net_start_us_ = 0, last_index_ = -1, frames_new_ = 0, bad_frames_ = 0, stale_renders_ = 0,
          rig_changes_ = 0;
  int64_t rate_t_us_ = 0;
  uint64_t rate_bytes_ = 0;
  double recent_mbps_ = 0, net_elapsed_s_ = 0;
  int64_t last_png_us_ = 0;
  bool showing_stale_ = false;
  bool frame_has_images_ = true;
  bool warned_no_colors_ = false;
  bool image_error_reported_ = false;
  std::map<uint16_t, net::DecodedImage> last_images_;  // per pod: the last picture received
  std::vector<ImageRgb8> sheet_tiles_;
  StreamFrame local_frame_;
  std::unique_ptr<render::GlContext> context_;
  std::unique_ptr<render::Renderer> renderer_;
  std::unique_ptr<render::Overlay> overlay_;
  std::unique_ptr<render::RegionBoxes> region_boxes_;
  mutable std::mutex regions_mu_;
  std::deque<std::string> region_events_;  // latest entries and exits, for the overlay (under regions_mu_)
  int64_t region_events_total_ = 0;        // under regions_mu_
  std::unique_ptr<render::OffscreenTarget> target_;
  bool have_local_ = false;
  bool interactive_ = false;
  bool show_overlay_ = true;
  double mouse_x_ = 0, mouse_y_ = 0;
  double recent_fps_ = 0;
  std::vector<int64_t> new_frame_us_;  // display times of the last new network frames
  int64_t first_new_us_ = 0, last_new_us_ = 0;
  FrameStats stats_;
  std::vector<std::string> pngs_;
};

}  // namespace

int RunViewer(const ViewerOptions& options) {
  Viewer viewer(options);
  if (Status s = viewer.Init(); !s.ok()) return viewer.Fail(s);
  if (!options.connect.empty() || !options.call.empty() || !options.http.empty()) {
    std::signal(SIGINT, [](int) { g_viewer_stop = true; });
    std::signal(SIGTERM, [](int) { g_viewer_stop = true; });
    return viewer.RunNetwork();
  }
  return options.headless ? viewer.RunHeadless() : viewer.RunInteractive();
}

}  // namespace holo::client
