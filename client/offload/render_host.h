// The render host of networked render offload (docs/offload.md): subscribes
// to a site's stream (SiteClient, role render host), accepts thin clients on
// its own TCP listener (Hello with role thin client + token → Welcome), and
// for each thin client renders the newest site mesh at the pose predicted
// for the client's display time, into an enlarged FOV, and sends it as a
// RenderedFrame (JPEG + LZ4 depth, the pose and FOV used). CPU renderer
// (client/reproject RenderAtPose); mono, or both eyes with `stereo`.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "client/pose/predictor.h"
#include "client/reproject/rendered_view.h"
#include "common/mesh.h"
#include "common/status.h"
#include "net/site_client.h"

namespace holo::offload {

// cpu: the CPU mesh renderer (client/reproject); gl: the viewer's OpenGL
// renderer in a headless EGL context (per-vertex colour), an error if there
// is none; auto: gl if a context can be made, else cpu.
enum class HostRenderer { kCpu, kGl, kAuto };
StatusOr<HostRenderer> ParseHostRenderer(const std::string& name);

struct RenderHostOptions {
  net::ClientOptions site;             // the site to subscribe to (role is forced to render host)
  std::string listen_host = "127.0.0.1";
  uint16_t listen_port = 0;            // 0: any free port (port())
  std::string token;                   // thin clients' token (empty: the site token)
  double margin = 0.25;                // FOV tangents × (1 + margin)
  pose::PredictorModel predictor = pose::PredictorModel::kKalman;
  // Pixels across the thin client's horizontal FOV (height from its aspect);
  // the enlarged render keeps that pixel density.
  int width = 640;
  int max_thin_clients = 8;
  double handshake_timeout_s = 5.0;
  double idle_timeout_s = 10.0;        // no message from a thin client for that long → closed
  double ping_interval_s = 0.5;        // RTT to each thin client
  // Added to the measured horizon (e.g. a known display pipeline delay), ms.
  double extra_horizon_ms = 0;
  // Both eyes: each predicted head pose is rendered twice, the eyes ±ipd/2
  // along the camera's x axis; RenderedFrames on stream 1 (left) and 2
  // (right). Mono: the head pose itself, stream 0.
  bool stereo = false;
  HostRenderer renderer = HostRenderer::kCpu;
  double ipd_m = 0.064;
  reproject::FrameEncodeOptions encode;
  std::function<void(const std::string&)> log;  // default: the log (common/log.h)
  Status Check() const;
};

struct ThinClientStats {
  uint64_t id = 0;
  std::string name, peer;
  uint64_t poses = 0, frames_sent = 0, bytes_sent = 0;
  double rtt_ms = -1;
  double render_ms = 0, encode_ms = 0;  // EWMA
  double horizon_ms = 0;                // last prediction horizon used
  double reported_latency_ms = -1;      // pose→photon reported by the client (Stats)
  bool open = true;
  std::string close_reason;
  std::string renderer;                 // "cpu" or "gl (…context…)"
};

struct RenderHostStats {
  uint64_t thin_accepted = 0, thin_refused = 0, thin_closed_on_error = 0;
  uint64_t site_frames = 0;
  int64_t last_site_frame = -1;
  std::vector<ThinClientStats> clients;
};

class RenderHost {
 public:
  static StatusOr<std::unique_ptr<RenderHost>> Start(RenderHostOptions options);
  ~RenderHost();  // Stop()
  RenderHost(const RenderHost&) = delete;
  RenderHost& operator=(const RenderHost&) = delete;
  void Stop();
  uint16_t port() const { return port_; }
  net::SiteClient* site() { return site_.get(); }
  RenderHostStats stats() const;
  // The decoded site mesh of `frame_index` if still kept (the last 16), for
  // measuring against a ground-truth render of what the host drew.
  std::shared_ptr<const Mesh> MeshForFrame(int64_t frame_index) const;
  struct Impl;

 private:
  RenderHost() = default;
  std::unique_ptr<Impl> impl_;
  std::unique_ptr<net::SiteClient> site_;
  uint16_t port_ = 0;
};

}  // namespace holo::offload
