// Encodes a capture site's output once per frame — the mesh with the
// geometry codec (G1 + colours by default) and, when the pods' colour images
// come with foreground masks, one ColorFrame of C1 images or of V1 video
// frames — and publishes it to the session server's fan-out. Times every step.
// With V1 each pod is one inter-frame stream: the publisher sends a key frame
// on every pod when a viewer joins or asks for one (Server's
// keyframe_requests), at most one forced key frame per 250 ms.
#pragma once

#include <cstdint>
#include <chrono>
#include <map>
#include <memory>
#include <vector>

#include "common/image.h"
#include "common/mesh.h"
#include "common/status.h"
#include "net/session_server.h"
#include "protocol/color_codec.h"
#include "protocol/geometry_codec.h"
#include "protocol/video_codec.h"

namespace holo::net {

struct SitePublisherOptions {
  protocol::GeometryEncodeOptions geometry;  // default G1, 1 mm, normals recomputed, colours
  bool color = true;                         // send C1 images of the pods (when masks exist)
  protocol::ColorEncodeOptions color_options;  // codec kC1 (default), kC0 or kV1
  protocol::VideoEncodeOptions video;          // when color_options.codec is kV1
};

struct PublishTimings {
  double geometry_ms = 0;   // geometry encode
  double color_ms = 0;      // colour encode, all pods
  double geometry_cpu_ms = 0, color_cpu_ms = 0;  // the same, CPU time of the encoding thread
  double publish_ms = 0;    // wire buffer + enqueue to every viewer
  size_t geometry_bytes = 0;
  size_t color_bytes = 0;
  size_t viewers = 0;       // viewers the frame was offered to
  bool color_keyframe = false;  // V1: this frame's colour is a key frame on every pod
};

// One pod's colour image and its foreground mask (same size, 255 = foreground).
struct PodColor {
  uint16_t pod_id = 0;
  const ImageRgb8* image = nullptr;
  const ImageGray8* mask = nullptr;
};

// One frame encoded for the wire, before it is handed to the fan-out.
struct EncodedFrame {
  int64_t frame_index = 0;
  int64_t capture_wall_us = 0;
  protocol::GeometryCodec codec = protocol::GeometryCodec::kG1;
  std::vector<uint8_t> geometry;
  protocol::ColorFrame color;  // no images: no ColorFrame is sent
  PublishTimings timings;      // encode part filled by Encode
};

class SitePublisher {
 public:
  SitePublisher(Server* server, SitePublisherOptions options);
  // `capture_wall_us`: when the frame was captured, on the wall clock (WallUs).
  // Pods whose mask is missing or of another size are left out of the ColorFrame.
  // Publish = Encode + PublishEncoded.
  Status Publish(int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh, const std::vector<PodColor>& pods,
                 PublishTimings* timings);
  // Encodes into `out` (its buffers reused). Not thread-safe: one thread
  // encodes (the per-pod colour encoders keep state between frames).
  Status Encode(int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh, const std::vector<PodColor>& pods,
                EncodedFrame* out);
  // Hands an encoded frame to every viewer's queue; fills publish_ms and
  // viewers of `out->timings`. May run on another thread than Encode.
  void PublishEncoded(EncodedFrame* frame);

 private:
  Server* server_;
  SitePublisherOptions options_;
  EncodedFrame scratch_;  // Publish's
  // One colour encoder per pod: C1 reuses each pod's Huffman tables between frames.
  std::map<uint16_t, protocol::ColorEncoder> color_encoders_;
  // V1: one video encoder per pod stream.
  std::map<uint16_t, std::unique_ptr<protocol::VideoEncoder>> video_encoders_;
  uint64_t keyframe_requests_seen_ = 0;
  std::chrono::steady_clock::time_point last_forced_keyframe_{};
};

}  // namespace holo::net
