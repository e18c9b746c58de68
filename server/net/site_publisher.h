// Encodes a capture site's output once per frame — the mesh with the
// geometry codec (G1 + colours by default) and, when the pods' colour images
// come with foreground masks, one ColorFrame of C1 images or of V1 video
// frames — and publishes it to the session server's fan-out. Times every step.
// With V1 each pod is one inter-frame stream: the publisher sends a key frame
// on every pod when a viewer joins or asks for one (Server's
// keyframe_requests), at most one forced key frame per 250 ms.
//
// Quality layers: with `reduced` enabled the site publishes two layers, the
// full one (layer 0) and a reduced one (layer 1: coarser geometry steps,
// lower colour quality, every n-th frame), each encoded once whatever the
// number of viewers, and the reduced one only while a viewer receives it or
// is being moved to it (Server::ViewersOnLayer). The session server moves
// each viewer between them (net/layer_control.h).
#pragma once

#include <cstdint>
#include <atomic>
#include <chrono>
#include <map>
#include <memory>
#include <optional>
#include <vector>

#include "common/image.h"
#include "common/mesh.h"
#include "common/sdf_grid.h"
#include "common/status.h"
#include "common/worker_pool.h"
#include "net/session_server.h"
#include "protocol/color_codec.h"
#include "protocol/geometry_codec.h"
#include "protocol/surface_codec.h"
#include "protocol/video_codec.h"

namespace holo::net {

// The reduced layer (layer 1) relative to the full one.
struct ReducedLayerOptions {
  bool enabled = true;
  double position_step_scale = 2.0;  // G1 position step × this
  int jpeg_quality = 35;             // C1 quality, 1..100
  // V1: the full layer's CRF (the codec's default 24 when -1) + this, ≤ 51.
  // 0: at S8-QVGA a reduced layer of G3 + V1 at CRF 32 showed the viewer
  // 19.72 dB, at CRF 36 19.33 and at CRF 40 18.8, against 19.98 for G1 + C1
  // (holoport-bench live --viewer-quality 0, docs/sessions.md); the layer's
  // bytes come mostly from its frame rate and geometry.
  int crf_offset = 0;
  int frame_divisor = 2;             // every n-th frame (1..8): 30 fps → 15
  // The reduced layer's codecs where they differ from the full layer's
  // (unset: the same). The reduced layer exists for links that cannot take
  // the full one, so it may spend CPU on fewer bytes (G3 + V1: about a
  // quarter of G1 + C1's) while the full layer keeps the cheaper codecs; it
  // is encoded only while a viewer receives it. G3 needs the stream mesh's
  // grid with every frame (Publish's `field`). A viewer whose Hello does not
  // list these codecs stays on the full layer.
  std::optional<protocol::GeometryCodec> geometry_codec;  // kG1 or kG3
  std::optional<protocol::ColorCodec> color_codec;        // kC1 or kV1
  Status Check() const;
};

// A live site's stream mesh has a 16 mm grid (S8-QVGA) and a Chamfer
// distance to the truth of ~5.5 mm: G1 quantizes it in 2 mm steps (error
// ≤ 1.7 mm), which saves ~3.7 KB per frame against 1 mm for no change in
// the viewer's picture (holoport-bench client, stream part).
// The pods' images carry the fine appearance. C1 quality 45 (holoport-server
// --jpeg-quality) keeps a 30 fps S8-QVGA call under 12 Mbit/s (11.7; 12.6 at
// quality 55); the viewer's picture loses 0.014–0.03 dB PSNR and
// 0.003–0.004 SSIM against 55 (holoport-bench client, stream part, fused
// frames 20, 40, 70, 110).
// V1 at CRF 32 (x264 veryfast, 4:4:4) shows the viewer a picture no worse
// than the uncompressed images (S8-QVGA −0.18 dB, S8-VGA +0.23 dB at the
// viewer) in 8.7 KB (S8-QVGA) and 32.7 KB (S8-VGA) per frame; CRF 24, the
// codec's own default, spends ~2x the bytes for no visible gain.
constexpr double kSitePositionStepMm = 2.0;
constexpr int kSiteJpegQuality = 45;
constexpr int kSiteVideoCrf = 32;
inline protocol::GeometryEncodeOptions SiteGeometryOptions() {
  protocol::GeometryEncodeOptions g;
  g.position_step_m = static_cast<float>(kSitePositionStepMm * 1e-3);
  return g;
}
inline protocol::VideoEncodeOptions SiteVideoOptions() {
  protocol::VideoEncodeOptions v;
  v.crf = kSiteVideoCrf;
  return v;
}
inline protocol::ColorEncodeOptions SiteColorOptions() {
  protocol::ColorEncodeOptions c;
  c.jpeg_quality = kSiteJpegQuality;
  return c;
}

struct SitePublisherOptions {
  // Default G1, 2 mm (kSitePositionStepMm), normals recomputed, colours.
  // Codec kG3 codes the stream mesh's distance grid instead of the mesh
  // (protocol/surface_codec.h): every frame must then come with its grid.
  protocol::GeometryEncodeOptions geometry = SiteGeometryOptions();
  // G3's options (when geometry.codec is kG3); the reduced layer scales
  // the value step by reduced.position_step_scale.
  protocol::SurfaceEncodeOptions surface;
  bool color = true;                         // send C1 images of the pods (when masks exist)
  // Codec kC1 (default, quality kSiteJpegQuality), kC0 or kV1.
  protocol::ColorEncodeOptions color_options = SiteColorOptions();
  protocol::VideoEncodeOptions video = SiteVideoOptions();  // when color_options.codec is kV1
  ReducedLayerOptions reduced;
};

// The encoder options of one layer (0 full, 1 reduced) of a site publishing
// with `options`: what SitePublisher encodes each layer with, for tools
// that measure the layers without a server.
struct LayerEncodeOptions {
  protocol::GeometryEncodeOptions geometry;
  protocol::SurfaceEncodeOptions surface;
  protocol::ColorEncodeOptions color;
  protocol::VideoEncodeOptions video;
};
LayerEncodeOptions EncodeOptionsOfLayer(const SitePublisherOptions& options, int layer);
// Whether some layer codes the stream mesh's grid (G3): Publish then needs
// the grid with every frame.
bool PublisherNeedsField(const SitePublisherOptions& options);

struct PublishTimings {
  double geometry_ms = 0;   // geometry encode
  double color_ms = 0;      // colour encode, all pods
  double geometry_cpu_ms = 0, color_cpu_ms = 0;  // the same, CPU time of the encoding thread
  double publish_ms = 0;    // wire buffer + enqueue to every viewer
  size_t geometry_bytes = 0;
  size_t color_bytes = 0;
  size_t viewers = 0;       // viewers the frame was offered to
  bool color_keyframe = false;  // V1: this frame's colour is a key frame on every pod
  // G3 could not code this frame's grid (its surface spans more than the
  // format allows): the frame went out as G1 instead.
  bool geometry_fallback = false;
  // The reduced layer, when it was encoded with this frame (its encode
  // time is not in geometry_ms/color_ms).
  bool reduced = false;
  double reduced_ms = 0, reduced_cpu_ms = 0;
  size_t reduced_bytes = 0;
};

// One pod's colour image and its foreground mask (same size, 255 = foreground).
struct PodColor {
  uint16_t pod_id = 0;
  const ImageRgb8* image = nullptr;
  const ImageGray8* mask = nullptr;
};

// One frame encoded for the wire, before it is handed to the fan-out.
struct EncodedFrame {
  int layer = 0;             // 0 full, 1 reduced
  bool independent = true;   // decodes without earlier frames (VideoFrame::independent)
  int64_t frame_index = 0;
  int64_t capture_wall_us = 0;
  protocol::GeometryCodec codec = protocol::GeometryCodec::kG1;
  std::vector<uint8_t> geometry;
  protocol::ColorFrame color;  // no images: no ColorFrame is sent
  PublishTimings timings;      // encode part filled by Encode
  // The reduced layer of the same frame, when encoded (0 or 1 entries).
  std::vector<EncodedFrame> reduced;
};

class SitePublisher {
 public:
  SitePublisher(Server* server, SitePublisherOptions options);
  // `capture_wall_us`: when the frame was captured, on the wall clock (WallUs).
  // Pods whose mask is missing or of another size are left out of the ColorFrame.
  // Publish = Encode + PublishEncoded. `field`: the grid `mesh` was
  // extracted from (FrameWork::stream_field), required with G3, unused otherwise.
  Status Publish(int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh, const std::vector<PodColor>& pods,
                 PublishTimings* timings, const SdfGrid* field = nullptr);
  // Encodes into `out` (its buffers reused). Not thread-safe: one thread
  // encodes (the per-pod colour encoders keep state between frames).
  Status Encode(int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh, const std::vector<PodColor>& pods,
                EncodedFrame* out, const SdfGrid* field = nullptr);
  // Hands an encoded frame (and its reduced layer) to every viewer's queue;
  // fills publish_ms and viewers of `out->timings`. May run on another
  // thread than Encode.
  void PublishEncoded(EncodedFrame* frame);

  // Frames encoded per layer so far (each once, whatever the audience).
  int64_t frames_encoded(int layer) const { return encoded_[layer == 0 ? 0 : 1].load(); }

 private:
  // One layer's encoders and its key frame bookkeeping.
  struct LayerState : LayerEncodeOptions {
    // One colour encoder per pod: C1 reuses each pod's Huffman tables between frames.
    std::map<uint16_t, protocol::ColorEncoder> color_encoders;
    // V1: one video encoder per pod stream.
    std::map<uint16_t, std::unique_ptr<protocol::VideoEncoder>> video_encoders;
    uint64_t keyframe_requests_seen = 0;
    std::chrono::steady_clock::time_point last_forced_keyframe{};
  };
  Status EncodeLayer(int layer, int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh, const SdfGrid* field,
                     const std::vector<PodColor>& pods, EncodedFrame* out);

  Server* server_;
  SitePublisherOptions options_;
  EncodedFrame scratch_;  // Publish's
  LayerState layers_[2];
  WorkerPool pool_{2};  // geometry and colour of a layer at once
  std::atomic<int64_t> encoded_[2] = {0, 0};
  int64_t frames_seen_ = 0;
  bool needs_field_ = false;  // PublisherNeedsField(options_): some layer is G3
  uint64_t geometry_fallbacks_ = 0;  // G3 frames sent as G1 (EncodeLayer)
};

}  // namespace holo::net
