// RGB-D frames as delivered by one pod, and synchronized sets of all pods.
#pragma once

#include <cstdint>
#include <vector>

#include "common/image.h"

namespace holo {

struct RgbdFrame {
  int pod_id = 0;
  // Capture time of the exposure, microseconds on the capture clock.
  int64_t timestamp_us = 0;
  ImageRgb8 color;    // in the pod's color camera
  ImageDepth16 depth; // in the pod's depth camera, millimetres, 0 = invalid
  ImageGray8 mask;    // optional foreground mask (empty if none), depth camera
};

// One synchronized frame of every pod of a rig, ordered by pod id.
struct RgbdFrameSet {
  int64_t frame_index = 0;
  std::vector<RgbdFrame> frames;
};

}  // namespace holo
