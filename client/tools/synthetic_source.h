// The stand-in stream for the viewer: what a site server would send per
// frame — the foreground mesh with the server texturer's per-vertex colours,
// and the pods' (colour-calibrated) images for projective texturing — taken
// from the synthetic studio's exact ground truth (studio/).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/image.h"
#include "common/mesh.h"
#include "common/rig.h"
#include "common/status.h"

namespace holo {
class SyntheticStudio;
class Texturer;
struct RgbdFrameSet;
}  // namespace holo

namespace holo::client {

struct StreamFrame {
  int64_t index = 0;
  int64_t capture_us = 0;  // RealClock time at which the frame started to be produced
  double produce_ms = 0;   // studio render + texturing
  Mesh mesh;
  std::vector<ImageRgb8> pod_images;  // one per pod of the rig, colour camera
  // Their foreground masks (same sizes, 255 = foreground), as the colour
  // codecs decode them; empty: none (every pixel usable).
  std::vector<ImageGray8> pod_masks;
};

class SyntheticSource {
 public:
  ~SyntheticSource();
  // `spec`: "synthetic" or "synthetic:WORKLOAD" (S8-QVGA, S8-VGA, S4-QVGA).
  static StatusOr<std::unique_ptr<SyntheticSource>> Create(const std::string& spec, int threads = 2);
  const Rig& rig() const { return rig_; }
  const std::string& workload() const { return workload_; }
  double fps() const { return fps_; }
  // Produces frame `index` of the studio's animation into `out` (buffers reused).
  Status Produce(int64_t index, StreamFrame* out);

 private:
  SyntheticSource() = default;
  std::string workload_;
  Rig rig_;
  double fps_ = 30;
  std::unique_ptr<SyntheticStudio> studio_;
  std::unique_ptr<Texturer> texturer_;
  std::unique_ptr<RgbdFrameSet> frames_;
};

}  // namespace holo::client
