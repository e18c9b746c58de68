// Encodes a capture site's output once per frame — the mesh with the
// geometry codec (G1 + colours by default) and, when the pods' colour images
// come with foreground masks, one ColorFrame of C1 images — and publishes it
// to the session server's fan-out. Times every step.
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include "common/image.h"
#include "common/mesh.h"
#include "common/status.h"
#include "protocol/color_codec.h"
#include "protocol/geometry_codec.h"
#include "server/net/session_server.h"

namespace holo::net {

struct SitePublisherOptions {
  protocol::GeometryEncodeOptions geometry;  // default G1, 1 mm, normals recomputed, colours
  bool color = true;                         // send C1 images of the pods (when masks exist)
  protocol::ColorEncodeOptions color_options;
};

struct PublishTimings {
  double geometry_ms = 0;   // geometry encode
  double color_ms = 0;      // colour encode, all pods
  double publish_ms = 0;    // wire buffer + enqueue to every viewer
  size_t geometry_bytes = 0;
  size_t color_bytes = 0;
  size_t viewers = 0;       // viewers the frame was offered to
};

// One pod's colour image and its foreground mask (same size, 255 = foreground).
struct PodColor {
  uint16_t pod_id = 0;
  const ImageRgb8* image = nullptr;
  const ImageGray8* mask = nullptr;
};

class SitePublisher {
 public:
  SitePublisher(Server* server, SitePublisherOptions options);
  // `capture_wall_us`: when the frame was captured, on the wall clock (WallUs).
  // Pods whose mask is missing or of another size are left out of the ColorFrame.
  Status Publish(int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh, const std::vector<PodColor>& pods,
                 PublishTimings* timings);

 private:
  Server* server_;
  SitePublisherOptions options_;
  std::vector<uint8_t> geometry_;
  // One colour encoder per pod: C1 reuses each pod's Huffman tables between frames.
  std::map<uint16_t, protocol::ColorEncoder> color_encoders_;
};

}  // namespace holo::net
